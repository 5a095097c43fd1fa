// Single-photo estimation facade (mr/estimate.h) over photo/geometry and photo/illumination.
#include "mr/estimate.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <limits>
#include <numbers>
#include <optional>
#include <vector>

#include "core/cv_bridge.h"
#include "mr/cancel.h"
#include "mr/error.h"
#include "mr/fog.h"
#include "mr/scene_json.h"
#include "photo/airlight.h"
#include "photo/clouds.h"
#include "photo/frame_border.h"
#include "photo/geometry.h"
#include "photo/horizon.h"
#include "photo/illumination.h"
#include "photo/lamps.h"
#include "photo/people.h"
#include "photo/sky_mask.h"
#include "photo/sky_matte.h"
#include "photo/subject.h"
#include "photo/vegetation.h"

namespace mr {

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr double kInfinity = std::numeric_limits<double>::infinity();

std::string fmt(const char* format, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

void check_camera(const Camera& camera) {
  if (camera.width <= 0 || camera.height <= 0 || !(camera.focal_px > 0) ||
      !std::isfinite(camera.focal_px) || !std::isfinite(camera.cx) || !std::isfinite(camera.cy))
    throw Error(ErrorCode::invalid_argument, "estimate: invalid camera (" +
                                                 std::to_string(camera.width) + "x" +
                                                 std::to_string(camera.height) + ", focal " +
                                                 fmt("%g", camera.focal_px) + " px)");
}

// Mean-free helper: the photo's RGB pixels inside a polygon (pixel centres, even-odd rule).
std::vector<std::array<float, 3>> pixels_in(const Image& photo,
                                            const std::vector<PixelPoint>& poly) {
  double x0 = 1e300, y0 = 1e300, x1 = -1e300, y1 = -1e300;
  for (const auto& p : poly) {
    x0 = std::min(x0, p[0]), x1 = std::max(x1, p[0]);
    y0 = std::min(y0, p[1]), y1 = std::max(y1, p[1]);
  }
  std::vector<std::array<float, 3>> out;
  const int xa = std::max(0, int(std::floor(x0))),
            xb = std::min(photo.width() - 1, int(std::ceil(x1)));
  const int ya = std::max(0, int(std::floor(y0))),
            yb = std::min(photo.height() - 1, int(std::ceil(y1)));
  for (int y = ya; y <= yb; ++y)
    for (int x = xa; x <= xb; ++x)
      if (photo::inside_polygon(poly, x, y))
        out.push_back({photo.at(x, y, 0), photo.at(x, y, 1), photo.at(x, y, 2)});
  return out;
}

// Overcast fall-back: the sky radiance is taken from the sky pixels only when the automatic
// sky mask found at least this many of them and this fraction of the image (fewer: a sliver
// whose colour is mostly edge, haze or a bright facade; mr fog then uses the dark channel prior).
constexpr std::size_t kMinOvercastSkyPixels = 64;
constexpr double kMinOvercastSkyFraction = 0.01;

// Per-channel median of the photo (scene-linear RGB) over the pixels where the distance map is
// +inf (the sky), over at most about a million of them (an even stride); non-finite values are
// skipped, negative medians clamped to 0. The median ignores birds, wires and a bright sun halo
// up to half the sky.
Rgb median_sky_radiance(const Image& photo, const Image& distance_m) {
  std::size_t count = 0;
  for (const float d : distance_m.pixels()) count += std::isinf(d) && d > 0;
  const std::size_t stride = std::max<std::size_t>(1, count / 1'000'000 + (count % 1'000'000 != 0));
  std::array<std::vector<float>, 3> values;
  for (auto& v : values) v.reserve(count / stride + 1);
  std::size_t k = 0;
  for (int y = 0; y < photo.height(); ++y)
    for (int x = 0; x < photo.width(); ++x) {
      const float d = distance_m.at(x, y, 0);
      if (!(std::isinf(d) && d > 0) || k++ % stride != 0) continue;
      for (int c = 0; c < 3; ++c)
        if (const float v = photo.at(x, y, c); std::isfinite(v)) values[c].push_back(v);
    }
  Rgb out{0, 0, 0};
  for (int c = 0; c < 3; ++c) {
    auto& v = values[c];
    if (v.empty()) continue;
    auto mid = v.begin() + std::ptrdiff_t(v.size() / 2);
    std::nth_element(v.begin(), mid, v.end());
    float m = *mid;
    if (v.size() % 2 == 0) m = 0.5f * (m + *std::max_element(v.begin(), mid));
    out[c] = std::max(0.0f, m);
  }
  // Overcast, the sky pixels are the light itself (no object colour mixed in, so no pull toward
  // grey), but a mask that takes in a clear blue sky or a sunset band would give the fog their
  // Rayleigh blue or orange: the chroma bound of every automatic fog colour still applies.
  photo::NeutralPrior bound_only;
  bound_only.knee_fraction = 1;
  return photo::neutral_fog_colour(out, bound_only);
}

}  // namespace

const char* to_string(EstimateSource source) noexcept {
  switch (source) {
    case EstimateSource::annotations:
      return "annotations";
    case EstimateSource::known_length:
      return "known_length";
    case EstimateSource::fallback:
      return "fallback";
    case EstimateSource::horizontal_vps:
      return "horizontal_vps";
    case EstimateSource::horizontal_vp_and_zenith:
      return "horizontal_vp_and_zenith";
    case EstimateSource::zenith:
      return "zenith";
    case EstimateSource::horizontal_vp_level:
      return "horizontal_vp_level";
    case EstimateSource::interior_box:
      return "interior_box";
  }
  return "?";
}

CameraPose pose_from_horizon(const Camera& camera, const std::array<PixelPoint, 2>& horizon,
                             double camera_height_m) {
  check_camera(camera);
  if (!(camera_height_m > 0) || !std::isfinite(camera_height_m))
    throw Error(ErrorCode::invalid_argument,
                "/camera_height_m: must be > 0, found " + fmt("%g", camera_height_m));
  const photo::PitchRoll pr = photo::pitch_roll_from_horizon(camera, horizon);
  CameraPose pose;
  pose.position_m = {0, camera_height_m, 0};
  pose.yaw_deg = 0;
  pose.pitch_deg = pr.pitch_deg;
  pose.roll_deg = pr.roll_deg;
  return pose;
}

namespace {

EstimateSource source_of(photo::HorizonCue cue) {
  switch (cue) {
    case photo::HorizonCue::horizontal_vps:
      return EstimateSource::horizontal_vps;
    case photo::HorizonCue::horizontal_vp_and_zenith:
      return EstimateSource::horizontal_vp_and_zenith;
    case photo::HorizonCue::zenith:
      return EstimateSource::zenith;
    case photo::HorizonCue::horizontal_vp_level:
      return EstimateSource::horizontal_vp_level;
    case photo::HorizonCue::none:
      break;
  }
  return EstimateSource::fallback;
}

// An estimate's progress (mr/cancel.h): as each step starts, (its name, steps finished, steps
// planned); at the end, (the last step, planned, planned). A requested token stops the estimate
// at the next step.
class Steps {
 public:
  Steps(const CancelToken* cancel, std::size_t planned) : cancel_(cancel), planned_(planned) {}
  void start(const char* name) {
    throw_if_cancelled(cancel_, "estimate");
    if (current_) ++done_;
    current_ = name;
    report_progress(cancel_, name, std::min(done_, planned_ - 1), planned_);
  }
  void finish() {
    if (current_) report_progress(cancel_, current_, planned_, planned_);
  }

 private:
  const CancelToken* cancel_;
  std::size_t planned_, done_ = 0;
  const char* current_ = nullptr;
};

// A horizon guessed with less confidence than this may be lowered to below the sky it cuts
// (the level fall-back has 0.1; cues from lines 0.15 and up), when the sky reaches it in at least
// this fraction of the columns and continues below it by at least this fraction of the height,
// filling at least kMinSkyBelowGuessFraction of the band between the guess and the new line.
constexpr double kWeakHorizonConfidence = 0.2;
constexpr double kMinSkyAtGuessFraction = 0.25;
constexpr double kMinHorizonDropFraction = 0.02;
constexpr double kMinSkyBelowGuessFraction = 0.75;
// A horizon measured from the photo's lines errs by a few percent of the height (rocket's dusk
// sky goes on 5.6 % below its own): sky going on below it by this fraction of the height is a
// surface it cuts across (basketball's office wall: 36 %; EstimateOptions::wall_not_sky).
constexpr double kMinWallDropFraction = 0.15;
// A sky under this share of the frame needs a clear sky's evidence (EstimateOptions::
// little_sky_evidence): tuning friends 3.4 % and brushes 1.6 % (not sky), scenetext06 4.8 %
// (a blue sky across the top, kept).
constexpr double kLittleSkyFraction = 0.05;
constexpr double kLittleSkyOpenTopFraction = 0.5;
// A frame whose sky and cloud bank cover this much of it (its subject, a bird or a kite, the
// rest) is all sky, or a ceiling.
constexpr double kAllSkyFraction = 0.9;
// The probe's sky joined to the mask's, reaching the guess where the mask's does not, in at
// least this fraction of the columns, is sky above the guess (join_sky_cut_by_a_guess): as
// much evidence as the lowering asks of the mask's own sky (kMinSkyAtGuessFraction). A cloud
// deck the guess cut spans a good part of the frame (valendas: 35 % of its columns); at 5 %, a
// pale sliver along a canyon's far rim under a weak line cue (grand_canyon: 61 of 800 columns)
// was joined, and the band judged in those columns let the horizon drop 16 px under the rim:
// haze created edges 0.0006 -> 0.24 % (gallery/results/deck23_tune.md).
constexpr double kMinSkyCutByTheGuessFraction = kMinSkyAtGuessFraction;

// A level sky line (EstimateOptions::level_sky_line): the sky's lowest row, in the columns
// where the sky ends above a weak guess, lies within a tolerance (px: 2, or the height / 250
// where that is more) of one straight line, of slope at most kLevelLineMaxSlope (5 degrees), in
// at least kLevelLineMinColumns of the columns and kLevelLineMinSideColumns of the columns in
// each outer third, with an RMS residual of at most half the tolerance; the sky reaches the
// guess in at most kLevelLineMaxAtGuess of the columns. Tuning half: cold_water's sea line, 78
// % of the columns within 2 px, RMS 0.73 px; the treelines and ridges under other guesses fit
// 7-44 % (airport_snow 38 %, sunset_aitzol 44 % with an RMS of 1.8 px).
constexpr double kLevelLineMaxSlope = 0.087;
constexpr double kLevelLineMinColumns = 0.5;
constexpr double kLevelLineMinSideColumns = 0.1;
constexpr double kLevelLineMaxAtGuess = 0.05;

// The sky's lower edge as a straight line y = a + b x (pixel centres), when it is one (above).
struct LevelSkyLine {
  bool found = false;
  double a = 0, b = 0;
};
LevelSkyLine level_sky_line(const std::vector<std::uint8_t>& sky, int w, int h,
                            const std::function<double(double)>& guess_y) {
  std::vector<int> xs, bottom;
  for (int x = 0; x < w; ++x) {
    const int guess = std::clamp(int(std::floor(guess_y(x))), 0, h);
    for (int y = guess - 1; y >= 0; --y)
      if (sky[std::size_t(y) * w + x]) {
        xs.push_back(x), bottom.push_back(y);
        break;
      }
  }
  LevelSkyLine out;
  const double tol = std::max(2.0, h / 250.0);
  if (double(xs.size()) < kLevelLineMinColumns * w) return out;
  // The best line through the bottoms: for each slope (steps of one pixel across the width),
  // the intercept window of +-tol holding the most of them; then least squares on those.
  const int k = int(std::ceil(tol));
  std::size_t best = 0;
  for (double b = -kLevelLineMaxSlope; b <= kLevelLineMaxSlope; b += 1.0 / w) {
    std::vector<int> hist(std::size_t(h + 2 * w + 2), 0);
    const int shift = int(std::ceil(kLevelLineMaxSlope * w)) + 1;
    for (std::size_t i = 0; i < xs.size(); ++i) {
      const int r = int(std::lround(bottom[i] - b * xs[i])) + shift;
      if (r >= 0 && r < int(hist.size())) ++hist[std::size_t(r)];
    }
    std::size_t run = 0;
    for (int r = 0; r < int(hist.size()); ++r) {
      run += std::size_t(hist[std::size_t(r)]);
      if (r > 2 * k) run -= std::size_t(hist[std::size_t(r - 2 * k - 1)]);
      if (run > best) best = run, out.a = r - k - shift, out.b = b;
    }
  }
  std::vector<std::size_t> inliers;
  for (int iteration = 0; iteration < 3; ++iteration) {
    inliers.clear();
    for (std::size_t i = 0; i < xs.size(); ++i)
      if (std::abs(bottom[i] - (out.a + out.b * xs[i])) <= tol) inliers.push_back(i);
    if (inliers.size() < 2) return out;
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    for (const std::size_t i : inliers) {
      sx += xs[i], sy += bottom[i], sxx += double(xs[i]) * xs[i], sxy += double(xs[i]) * bottom[i];
    }
    const double n = double(inliers.size()), den = n * sxx - sx * sx;
    if (den <= 0) return out;
    out.b = (n * sxy - sx * sy) / den;
    out.a = (sy - out.b * sx) / n;
  }
  double sq = 0;
  std::size_t left = 0, right = 0;
  for (const std::size_t i : inliers) {
    const double r = bottom[i] - (out.a + out.b * xs[i]);
    sq += r * r;
    left += 3 * xs[i] < w;
    right += 3 * xs[i] > 2 * w;
  }
  out.found = std::abs(out.b) <= kLevelLineMaxSlope &&
              double(inliers.size()) >= kLevelLineMinColumns * w &&
              double(left) >= kLevelLineMinSideColumns * w &&
              double(right) >= kLevelLineMinSideColumns * w &&
              std::sqrt(sq / double(inliers.size())) <= 0.5 * tol;
  return out;
}

// The geometry's steps: horizon, sky mask, depth, refine.
constexpr std::size_t kGeometrySteps = 4;

// Issue 11 (far shores, helper shore15): how plainly the photo below row `axis` is the mirror
// image of the photo above it, in the columns x - half_width .. x + half_width and the `rows`
// rows on either side (row axis - 1 - k against row axis + k): the normalized cross-correlation
// of the three channels, each less its mean over its side, in [-1, 1]. Calm water is a mirror
// at its own plane: a point of a far shore standing H above the water at distance d is seen H/d
// above its waterline and its reflection H/d below it (the camera's own height shifts both by
// the same h/d), so about the waterline the two are symmetric, row for row. The reflection is
// darker (the Fresnel reflectance of water at grazing angles), tinted and blurred a little by
// ripples; the correlation allows any gain and offset per side, and `photo` comes blurred
// vertically. A dark field under a dark ridge matches it in brightness, but not the ridge's
// outline mirrored: its correlation is low. 0 where a side is flat (nothing to compare).
float mirror_correlation(const cv::Mat& photo, int x, int axis, int rows, int half_width) {
  const int x0 = std::max(0, x - half_width), x1 = std::min(photo.cols - 1, x + half_width);
  if (rows < 2 || axis - rows < 0 || axis + rows > photo.rows) return 0.0f;
  const int n = (x1 - x0 + 1) * rows;
  double sa[3] = {0, 0, 0}, sb[3] = {0, 0, 0};
  for (int k = 0; k < rows; ++k) {
    const cv::Vec3f* above = photo.ptr<cv::Vec3f>(axis - 1 - k);
    const cv::Vec3f* below = photo.ptr<cv::Vec3f>(axis + k);
    for (int xx = x0; xx <= x1; ++xx)
      for (int c = 0; c < 3; ++c) sa[c] += above[xx][c], sb[c] += below[xx][c];
  }
  double ab = 0, aa = 0, bb = 0;
  for (int k = 0; k < rows; ++k) {
    const cv::Vec3f* above = photo.ptr<cv::Vec3f>(axis - 1 - k);
    const cv::Vec3f* below = photo.ptr<cv::Vec3f>(axis + k);
    for (int xx = x0; xx <= x1; ++xx)
      for (int c = 0; c < 3; ++c) {
        const double a = above[xx][c] - sa[c] / n, b = below[xx][c] - sb[c] / n;
        ab += a * b, aa += a * a, bb += b * b;
      }
  }
  // (A side flat to within 0.2 % in linear units carries no outline to mirror.)
  const double floor = 3.0 * n * 0.002 * 0.002;
  if (aa <= floor || bb <= floor) return 0.0f;
  // Water reflects a fraction of what it mirrors (its Fresnel reflectance, below 1), so the
  // reflection's contrast is at most the original's: a brighter, more contrasted "reflection"
  // (a bright guard rail under a dark ridge: storm_pano) is none. Ripples' glints and the
  // water's own colour are allowed 20 % over it; the score falls to 0 at 40 % over.
  const double gain = std::sqrt(bb / aa);
  const double plausible = std::clamp((1.4 - gain) / 0.2, 0.0, 1.0);
  return float(plausible * ab / std::sqrt(aa * bb));
}

// The photo's first three channels (a grey one repeated), scene-linear, blurred vertically over
// `blur_rows` rows: ripples blur a reflection vertically, and mirror_correlation compares both
// sides blurred alike.
cv::Mat vertically_blurred_rgb(const Image& photo, int blur_rows) {
  const int w = photo.width(), h = photo.height();
  const int c1 = std::min(1, photo.channels() - 1), c2 = std::min(2, photo.channels() - 1);
  cv::Mat rgb(h, w, CV_32FC3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float* p = photo.pixel(x, y);
      rgb.at<cv::Vec3f>(y, x) = cv::Vec3f(p[0], p[c1], p[c2]);
    }
  cv::blur(rgb, rgb, cv::Size(1, blur_rows | 1));
  return rgb;
}

// Issue 11 (darkesthour: a lake at blue hour under the level fall-back). The lake mirrors the
// sky as smoothly as the sky itself, so the sky "continued" below the guess down to the frame's
// bottom and the horizon was lowered out of the frame: all of it sky, the lake and the far
// shore veiled flat. Calm water's surface is a mirror line: the photo under it is the photo
// over it flipped (mirror_correlation). The row in [from_row, to_row] about which it is most
// plainly so, over the median of the columns (boxes of 2 half_width + 1 across, `rows` = a tenth
// of the height or what the frame holds on either side, at least a twentieth below it), when
// that median is at least kMinWaterMirror; -1 when no row is. An all-sky frame or a cloud deck
// over land mirrors nothing (the tuning half's lowered horizons: at most 0.43).
constexpr float kMinWaterMirror = 0.8f;
int water_mirror_row(const cv::Mat& rgb, int from_row, int to_row) {
  const int w = rgb.cols, h = rgb.rows, half_width = std::max(4, w / 80);
  const int min_below = std::max(2, h / 20);
  from_row = std::max(from_row, min_below), to_row = std::min(to_row, h - min_below);
  std::vector<float> column_scores;
  auto score = [&](int axis) {
    const int rows = std::min({axis, h - axis, std::max(2, h / 10)});
    column_scores.clear();
    for (int x = half_width; x + half_width < w; x += 2 * half_width)
      column_scores.push_back(mirror_correlation(rgb, x, axis, rows, half_width));
    if (column_scores.empty()) return 0.0f;
    const auto mid = column_scores.begin() + std::ptrdiff_t(column_scores.size() / 2);
    std::nth_element(column_scores.begin(), mid, column_scores.end());
    return *mid;
  };
  // Every other row, then the best one's neighbours (a mirror's peak is a few rows wide: the
  // vertical blur).
  int best = -1;
  float best_score = kMinWaterMirror;
  for (int axis = from_row; axis <= to_row; axis += 2)
    if (const float s = score(axis); s >= best_score) best = axis, best_score = s;
  if (best < 0) return -1;
  for (const int axis : {best - 1, best + 1})
    if (axis >= from_row && axis <= to_row)
      if (const float s = score(axis); s > best_score) best = axis, best_score = s;
  return best;
}

// Issue 11 (valendas: a storm's cloud deck over mountains under the level fall-back horizon):
// the mask clips the sky at a guessed horizon, so a dark cloud deck reaching the guess "stands"
// on it (the mask's floating-cloud rule: held up by the horizon), and a pale sky under the deck
// is cut off from the top border by it: both stayed surfaces, a few metres away, and the fog
// showed the guess as a step (dense fog), the deck as a block (the night). The probe (the mask
// with its horizon below the frame) judges them without the guess. Where, in at least
// `min_columns` columns, the probe's sky joined to the mask's (one 8-connected component of the
// probe) reaches the guess (within `near` rows) and the mask's own sky does not, that joined
// sky above the horizon is sky (its matte the probe's); returns those columns (0: unchanged).
// A tower, a ridge or a tree reaching the guess goes on below it down to the land and stands
// on it in the probe too, so it is in no sky component of the probe.
int join_sky_cut_by_a_guess(photo::SkyMask& mask, const photo::SkyMask& probe,
                            const std::array<PixelPoint, 2>& horizon, int near, int min_columns) {
  const int w = mask.width, h = mask.height;
  if (probe.sky.size() != mask.sky.size() || w < 1 || h < 1) return 0;
  const double slope =
      (horizon[1][1] - horizon[0][1]) / std::max(1.0, horizon[1][0] - horizon[0][0]);
  auto horizon_y = [&](int x) { return horizon[0][1] + (x - horizon[0][0]) * slope; };
  cv::Mat labels;
  const int n = cv::connectedComponents(
      cv::Mat(h, w, CV_8U, const_cast<std::uint8_t*>(probe.sky.data())), labels, 8, CV_32S);
  std::vector<std::uint8_t> joined(std::size_t(n), 0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (mask.sky[std::size_t(y) * w + x]) joined[std::size_t(labels.at<int>(y, x))] = 1;
  joined[0] = 0;
  int columns = 0;
  for (int x = 0; x < w; ++x) {
    const int row = int(std::floor(horizon_y(x)));
    if (row < near || row >= h) continue;
    bool mask_reaches = false, joined_reaches = false;
    for (int r = row; r >= row - near; --r) {
      mask_reaches |= mask.sky[std::size_t(r) * w + x] != 0;
      joined_reaches |= joined[std::size_t(labels.at<int>(r, x))] != 0;
    }
    columns += joined_reaches && !mask_reaches;
  }
  if (columns < std::max(1, min_columns)) return 0;
  std::size_t pixels = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      if (double(y) < horizon_y(x) && joined[std::size_t(labels.at<int>(y, x))]) {
        mask.sky[i] = 1;
        mask.alpha[i] = std::max(mask.alpha[i], probe.alpha[i]);
      }
      pixels += mask.sky[i];
    }
  mask.pixels = pixels;
  return columns;
}

// The row (floored) of the line through `line`'s two points at column x.
int row_of_line(const std::array<PixelPoint, 2>& line, double x) {
  const double slope = (line[1][1] - line[0][1]) / std::max(1.0, line[1][0] - line[0][0]);
  return int(std::floor(line[0][1] + (x - line[0][0]) * slope));
}

// Issue 11: how the sky goes on below a line it reaches. `reaching`: per column, whether the
// mask's sky reaches the line (within `near` rows above it) and the probe's sky (the mask found
// with its horizon below the frame: every pixel above it) goes on below it there; `columns`:
// how many columns the mask's sky reaches it in; `drop`: the median, over those columns, of
// the rows the probe's sky goes on below the line (0 where it does not); `band_fraction`: the
// probe's share of the band between the line and `drop` rows below it, in those columns.
// Nothing (columns 0) when the mask's sky reaches the line in fewer than `min_fraction` of
// the columns: the probe costs about a third of the estimate's CPU time.
struct SkyBelowLine {
  std::vector<std::uint8_t> reaching;
  int columns = 0;
  double drop = 0, band_fraction = 0;
};
SkyBelowLine sky_below_line(const Image& photo, const photo::SkyMask& mask,
                            const std::array<PixelPoint, 2>& line,
                            const photo::SkyMaskOptions& sky_options, double min_fraction,
                            int near = 4) {
  SkyBelowLine out;
  const int w = mask.width, h = mask.height;
  auto line_row = [&](int x) { return row_of_line(line, x); };
  std::vector<int> reach_row(std::size_t(w), -1);  // the mask's sky row near the line
  for (int x = 0; x < w; ++x) {
    const int row = line_row(x);
    if (row < near || row >= h - 1) continue;
    for (int r = row; r >= row - near && reach_row[std::size_t(x)] < 0; --r)
      if (mask.sky[std::size_t(r) * w + x]) reach_row[std::size_t(x)] = r;
    out.columns += reach_row[std::size_t(x)] >= 0;
  }
  if (out.columns < min_fraction * w || out.columns == 0) {
    out.columns = 0;
    return out;
  }
  const double below_frame = h + 1.0;
  const photo::SkyMask probe = photo::estimate_sky_mask(
      photo.view(), {PixelPoint{0, below_frame}, PixelPoint{w - 1.0, below_frame}}, sky_options);
  out.reaching.assign(std::size_t(w), 0);
  std::vector<int> drops;
  for (int x = 0; x < w; ++x) {
    int row = reach_row[std::size_t(x)];
    if (row < 0) continue;
    if (probe.sky[std::size_t(row) * w + x])
      while (row + 1 < h && probe.sky[std::size_t(row + 1) * w + x]) ++row;
    drops.push_back(std::max(0, row - line_row(x)));
    out.reaching[std::size_t(x)] = drops.back() > 0;
  }
  std::nth_element(drops.begin(), drops.begin() + std::ptrdiff_t(drops.size() / 2), drops.end());
  out.drop = drops[drops.size() / 2];
  std::size_t band = 0, band_sky = 0;
  for (int x = 0; x < w; ++x) {
    if (reach_row[std::size_t(x)] < 0) continue;
    const int y0 = line_row(x);
    for (int y = std::max(0, y0 + 1); y <= std::min(h - 1, y0 + int(out.drop)); ++y)
      ++band, band_sky += probe.sky[std::size_t(y) * w + x];
  }
  out.band_fraction = band ? double(band_sky) / double(band) : 0.0;
  return out;
}

// Takes out of `mask` the 8-connected components of its matte (alpha > 0: the sky and the soft
// band along its edges) that reach `line` (within `near` rows above it) in a column marked in
// `columns`; returns the sky pixels taken out.
std::size_t drop_sky_reaching_line(photo::SkyMask& mask, const std::array<PixelPoint, 2>& line,
                                   const std::vector<std::uint8_t>& columns, int near = 4) {
  const int w = mask.width, h = mask.height;
  const std::size_t count = std::size_t(w) * h;
  if (columns.size() != std::size_t(w) || mask.sky.size() != count || mask.alpha.size() != count)
    return 0;
  cv::Mat matte(h, w, CV_8U), labels;
  for (std::size_t i = 0; i < count; ++i) matte.data[i] = mask.sky[i] != 0 || mask.alpha[i] > 0;
  const int n = cv::connectedComponents(matte, labels, 8, CV_32S);
  std::vector<std::uint8_t> drop(std::size_t(n), 0);
  for (int x = 0; x < w; ++x) {
    if (!columns[std::size_t(x)]) continue;
    const int row = row_of_line(line, x);
    for (int r = std::min(row, h - 1); r >= std::max(0, row - near); --r)
      drop[std::size_t(labels.at<int>(r, x))] = 1;
  }
  drop[0] = 0;
  std::size_t dropped = 0, pixels = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      if (drop[std::size_t(labels.at<int>(y, x))]) {
        dropped += mask.sky[i];
        mask.sky[i] = 0;
        mask.alpha[i] = 0.0f;
      }
      pixels += mask.sky[i];
    }
  mask.pixels = pixels;
  mask.gap_pixels = std::min(mask.gap_pixels, pixels);
  return dropped;
}

GeometryEstimate geometry(const Image* photo, const Camera& camera, const Annotations& annotations,
                          const EstimateOptions& options, Steps& steps) {
  steps.start("horizon");
  check_camera(camera);
  validate_annotations(annotations, "");
  const bool automatic = photo && options.automatic;
  if (photo && (photo->width() != camera.width || photo->height() != camera.height))
    throw Error(ErrorCode::size_mismatch, "estimate: photo is " + std::to_string(photo->width()) +
                                              "x" + std::to_string(photo->height()) +
                                              ", camera is " + std::to_string(camera.width) + "x" +
                                              std::to_string(camera.height));
  GeometryEstimate g;
  g.pose.position_m = {0, 1, 0};
  std::optional<photo::AutoHorizon> auto_horizon;
  if (!annotations.horizon && automatic) {
    auto_horizon = photo::estimate_horizon(photo->view(), camera);
    g.horizon_rejected_roll_deg = auto_horizon->rejected_roll_deg;
    if (auto_horizon->cue == photo::HorizonCue::none) auto_horizon.reset();
  }
  if (annotations.horizon) {
    g.pose = pose_from_horizon(camera, *annotations.horizon, 1.0);
    g.horizon_source = EstimateSource::annotations;
    g.confidence = 1;
  } else if (auto_horizon) {
    g.pose = pose_from_horizon(camera, auto_horizon->points, 1.0);
    g.horizon_source = source_of(auto_horizon->cue);
    g.confidence = auto_horizon->confidence;
  } else {
    g.pose.pitch_deg = g.pose.roll_deg = 0;  // level: the horizon through the principal point
    g.horizon_source = EstimateSource::fallback;
    g.confidence = 0.1;
  }
  double height = options.default_camera_height_m;
  g.height_source = EstimateSource::fallback;
  if (annotations.camera_height_m) {
    height = *annotations.camera_height_m;
    g.height_source = EstimateSource::annotations;
  } else if (annotations.known_length) {
    height = photo::camera_height_from_known_length(camera, g.pose, *annotations.known_length);
    g.height_source = EstimateSource::known_length;
  } else if (const auto& box = annotations.interior_box;
             box && box->ceiling_height_m && box->ceiling_point) {
    // The marked ceiling gives its height in camera heights; the known ceiling height scales it.
    height = *box->ceiling_height_m / photo::ceiling_over_camera_height(camera, g.pose, *box);
    g.height_source = EstimateSource::interior_box;
  }
  if (!(height > 0) || !std::isfinite(height))
    throw Error(ErrorCode::invalid_argument,
                "default_camera_height_m: must be > 0, found " + fmt("%g", height));
  g.pose.position_m = {0, height, 0};
  steps.start("sky mask");
  g.horizon = photo::horizon_of_pose(camera, g.pose);
  photo::DistanceMap map = photo::distance_map(camera, g.pose, annotations);
  g.distance_m = std::move(map.distance_m);
  g.sky_pixels = map.counts[int(photo::Coverage::sky)];
  g.ground_pixels = map.counts[int(photo::Coverage::ground)];
  g.plane_pixels = map.counts[int(photo::Coverage::plane)];
  g.hint_pixels = map.counts[int(photo::Coverage::hint)];
  g.room_pixels = map.counts[int(photo::Coverage::room)];
  if (map.room) {
    const photo::Room& room = *map.room;
    g.room_ceiling_height_m = room.ceiling_height_m;
    // The edges, clipped to 5 cm in front of the camera before projecting.
    const auto [fwd_axis, right_axis, up_axis] = g.pose.axes();
    auto add_edge = [&](Vec3 a, Vec3 b) {
      const Vec3& o = g.pose.position_m;
      auto depth = [&](const Vec3& p) {
        return (p.x - o.x) * fwd_axis.x + (p.y - o.y) * fwd_axis.y + (p.z - o.z) * fwd_axis.z;
      };
      const double near = 0.05, da = depth(a), db = depth(b);
      if (da < near && db < near) return;
      if (da < near || db < near) {
        const double t = (near - da) / (db - da);
        const Vec3 m{a.x + t * (b.x - a.x), a.y + t * (b.y - a.y), a.z + t * (b.z - a.z)};
        (da < near ? a : b) = m;
      }
      const auto pa = photo::project(camera, g.pose, a), pb = photo::project(camera, g.pose, b);
      if (pa && pb) g.room_edges.push_back({*pa, *pb});
    };
    const double top = room.ceiling_height_m.value_or(2 * height);
    for (std::size_t i = 0; i + 1 < room.floor_m.size(); ++i) {
      const Vec3 &a = room.floor_m[i], &b = room.floor_m[i + 1];
      add_edge(a, b);
      if (room.ceiling_height_m) add_edge({a.x, top, a.z}, {b.x, top, b.z});
    }
    for (std::size_t i = 1; i + 1 < room.floor_m.size(); ++i) {
      const Vec3& a = room.floor_m[i];
      add_edge(a, {a.x, top, a.z});
    }
  }
  // Indoors the room covers every pixel: no sky to find, no billboards.
  if (!automatic || map.room) return g;

  // The automatic sky: carve it out of the planes. What is above the horizon and not sky is
  // structure: standing on the ground where it meets it (ground_contact), else on the far
  // billboard; the ground behind a column's structure takes the structure's distance.
  photo::SkyMaskOptions sky_options;
  sky_options.inside_frame_border = options.frame_border;
  photo::SkyMask mask = photo::estimate_sky_mask(photo->view(), g.horizon, sky_options);
  g.sky_from_mask = true;
  // Issue 11 (a camera looking up into an all-sky frame; a weak horizon above the land): the
  // sky is only ever seen above the horizon. Where a guessed horizon (the level fall-back, or
  // a cue of very low confidence) cuts through open sky, the sky found without it continues
  // below it with no edge; below the guess it became a ground plane (an unveiled band of sky
  // under the haze's veil, a hard line between them) and clouds reaching the guess were
  // "standing on the ground". The horizon is then lowered (same roll) to the median lowest row
  // that sky reaches, continuously from the guess, in the columns where it reaches the guess.
  // The photo blurred vertically over a line's width, for the mirror tests (the water under a
  // lowered horizon, the far shores below): made once, when first asked for.
  cv::Mat blurred_rgb_once;
  auto blurred_rgb = [&]() -> const cv::Mat& {
    if (blurred_rgb_once.empty())
      blurred_rgb_once = vertically_blurred_rgb(*photo, std::max(3, camera.height / 100));
    return blurred_rgb_once;
  };
  std::vector<std::uint8_t> cloud_bank;  // the bank the guess was lowered under, if any
  photo::Silhouette backlit;             // backlit land the guess was lowered to, if any
  if (!annotations.horizon && g.confidence < kWeakHorizonConfidence) {
    const int w = camera.width, h = camera.height;
    const double slope0 =
        (g.horizon[1][1] - g.horizon[0][1]) / std::max(1.0, g.horizon[1][0] - g.horizon[0][0]);
    auto guess_y = [&](double x) { return g.horizon[0][1] + (x - g.horizon[0][0]) * slope0; };
    std::vector<int> reach;  // per column reaching the guess: rows of sky below it
    int at_guess = 0;
    photo::SkyMask probe;
    // The mask's edge sits a few pixels above the line it is clipped to (working resolution,
    // the matte's refinement): the sky "reaches" the guess when it is within kNear rows of it.
    constexpr int kNear = 4;
    auto reaches = [&](int x) {
      const int row = int(std::floor(guess_y(x)));
      if (row < kNear || row >= h - 1) return -1;
      for (int r = row; r >= row - kNear; --r)
        if (mask.sky[std::size_t(r) * w + x]) return r;
      return -1;
    };
    for (int x = 0; x < w; ++x) at_guess += reaches(x) >= 0;
    // Columns where the probe's sky, not the mask's, reaches the guess (join_sky_cut_by_a_guess).
    int cut_columns = 0;
    const int min_cut_columns = int(std::ceil(kMinSkyCutByTheGuessFraction * w));
    if (at_guess >= kMinSkyAtGuessFraction * w) {
      const double below = h + 1.0;  // the probe: every pixel is above its horizon
      probe = photo::estimate_sky_mask(
          photo->view(), {PixelPoint{0, below}, PixelPoint{w - 1.0, below}}, sky_options);
      if (options.sky_cut_by_a_guess)
        cut_columns = join_sky_cut_by_a_guess(mask, probe, g.horizon, kNear, min_cut_columns);
      for (int x = 0; x < w; ++x) {
        int row = reaches(x);
        if (row < 0 || !probe.sky[std::size_t(row) * w + x]) continue;
        while (row + 1 < h && probe.sky[std::size_t(row + 1) * w + x]) ++row;
        reach.push_back(row - int(std::floor(guess_y(x))));
      }
    }
    // The guess moved to `line` (same camera height): the pose, the plane's distances and the
    // sky mask clipped to the new line.
    auto move_horizon = [&](const std::array<PixelPoint, 2>& line) {
      g.pose = pose_from_horizon(camera, line, g.pose.position_m.y);
      g.horizon = photo::horizon_of_pose(camera, g.pose);
      map = photo::distance_map(camera, g.pose, annotations);
      g.distance_m = std::move(map.distance_m);
      g.sky_pixels = map.counts[int(photo::Coverage::sky)];
      g.ground_pixels = map.counts[int(photo::Coverage::ground)];
      g.plane_pixels = map.counts[int(photo::Coverage::plane)];
      g.hint_pixels = map.counts[int(photo::Coverage::hint)];
      mask = photo::estimate_sky_mask(photo->view(), g.horizon, sky_options);
    };
    auto lower = [&](double drop) {
      move_horizon({PixelPoint{g.horizon[0][0], g.horizon[0][1] + drop + 1},
                    PixelPoint{g.horizon[1][0], g.horizon[1][1] + drop + 1}});
      g.horizon_lowered_px = drop + 1;
    };
    if (!reach.empty()) {
      std::nth_element(reach.begin(), reach.begin() + std::ptrdiff_t(reach.size() / 2),
                       reach.end());
      double drop = reach[reach.size() / 2];
      // The horizon is a line across the whole frame, and open sky below it is sky in
      // (nearly) every column: lowered only when the band between the guess and the lowered
      // line is mostly sky. A smooth bluish band running diagonally through the frame (the
      // CLI tests' gradient pattern: 46 % of the band), or a sea reflecting the sky between
      // a pier's poles (61 %), continues below the guess in part of the columns only; an
      // all-sky frame (99 %) or the glow under clouds down to the land (89 %) fills it.
      // Where the joined sky reached the guess, the band is judged in the columns the sky
      // reaches the guess in: land standing above the guess elsewhere (valendas' peaks) stands
      // on whatever horizon lies below it.
      std::size_t band = 0, band_sky = 0;
      for (int x = 0; x < w; ++x) {
        if (cut_columns > 0 && reaches(x) < 0) continue;
        const int y0 = int(std::floor(guess_y(x)));
        for (int y = std::max(0, y0 + 1); y <= std::min(h - 1, y0 + int(drop)); ++y)
          ++band, band_sky += probe.sky[std::size_t(y) * w + x];
      }
      if (drop >= kMinHorizonDropFraction * h &&
          double(band_sky) >= kMinSkyBelowGuessFraction * double(band)) {
        // Sky mirrored in calm water goes on below the horizon as smoothly as above it: the
        // horizon goes only as far down as the water's mirror line (water_mirror_row); one at or
        // just above the guess (within two lines' widths) leaves the guess where it is.
        bool lower_it = true;
        if (options.water_mirror) {
          const int guess_row = int(std::floor(guess_y(0.5 * (w - 1))));
          const int line_px = std::max(3, h / 100);
          const int axis =
              water_mirror_row(blurred_rgb(), guess_row - 2 * line_px, guess_row + int(drop) + 1);
          if (axis >= 0) {
            drop = std::min(drop, double(axis - guess_row - 1));
            lower_it = drop >= 1;
            g.lowered_to_water = lower_it;
          }
        }
        if (lower_it) lower(drop);
        if (lower_it && cut_columns > 0) join_sky_cut_by_a_guess(mask, probe, g.horizon, kNear, 1);
      }
    }
    // Issue 11: a cloud bank on the guessed line (god_rays' backlit bank under the level
    // fall-back), not open sky: above the guess it was a structure, below it the ground plane,
    // and its outline a created edge against the veiled sky, under a sun an occluder casting
    // streak fans. Where the bank is ringed by sky and fills the frame below the guess (no
    // land seen under it), the horizon goes below the frame and the bank is sky
    // (photo/clouds.h; a bank over land is left alone: CloudBankOptions::lower_to_land).
    if (g.horizon_lowered_px == 0) {
      // The sky: what the mask found above the guess, and the probe's below it when it was
      // run (the bank's tests read bank and sky below the guess alike; a probe of its own
      // would cost a third of the estimate's CPU time on every photo under the fall-back).
      std::vector<std::uint8_t> sky = mask.sky;
      for (std::size_t i = 0; i < sky.size() && i < probe.sky.size(); ++i) sky[i] |= probe.sky[i];
      photo::CloudBank bank = photo::find_cloud_bank(photo->view(), g.horizon, sky);
      if (bank.drop_px > 0) {
        // The sky found above the guess stays sky: with the line below the frame the mask
        // loses blue patches that reach neither the top border nor a clipped horizon (god_rays'
        // openings in the bank: none left, the frame a bounded scene).
        const photo::SkyMask above_guess = mask;
        lower(bank.drop_px);
        cloud_bank = std::move(bank.bank);
        std::size_t pixels = 0;
        for (std::size_t i = 0; i < mask.sky.size() && i < above_guess.sky.size(); ++i) {
          if (above_guess.sky[i]) mask.sky[i] = 1;
          mask.alpha[i] = std::max(mask.alpha[i], above_guess.alpha[i]);
          pixels += mask.sky[i];
        }
        mask.pixels = pixels;
      } else if (options.backlit_land) {
        // Issue 11 (after_the_rain: a storm's dark cumulus over a sunset, the land a black
        // silhouette under it). No line cue; the level fall-back through the frame's middle cut
        // the cumulus, which stood on the ground plane 8 m away, clear under the haze's veil
        // over the sky around it (0.075 % created edges along its rims). Backlit land is the
        // darkest part of the frame, and its skyline is where the horizon of a level camera
        // lies: the guess is lowered to the median skyline, and what stands above it and is
        // not as dark as the land (clouds, the glow down to where the land dips) is sky
        // (photo/horizon.h, find_silhouette). The same sky as the bank's (no bank: unchanged).
        photo::Silhouette land = photo::find_silhouette(photo->view(), sky);
        const double drop = land.skyline_row - guess_y(0.5 * (w - 1)) - 1;
        if (drop >= kMinHorizonDropFraction * h) {
          lower(drop);
          std::size_t pixels = 0;
          for (std::size_t i = 0; i < mask.sky.size(); ++i) {
            if (land.sky_alpha[i] > 0) {
              mask.sky[i] = 1;
              mask.alpha[i] = land.sky_alpha[i];
            }
            pixels += mask.sky[i];
          }
          mask.pixels = pixels;
          g.backlit_land = true;
          backlit = std::move(land);
        }
      }
    }
    // Issue 11 (tuning cold_water: people wading in a sea under an overcast sky, no line cue):
    // the level fall-back through the frame's middle lay 36 px under the sea line, so the
    // sea's far band stood as a wall above the horizon, and the sea under the guess ran to 14-30
    // m where it is kilometres away: in dense fog the far sea and the people along the sea line
    // stayed plain while a woman 3 m away was veiled. A sea's (or a salt flat's, a snowfield's)
    // horizon is where the sky ends along a straight, level line: the guess is raised to it.
    // Land's skylines (ridges, treelines, roofs) are not that straight (level_sky_line above),
    // and a sky that goes on down to the guess is for the lowering above.
    if (g.horizon_lowered_px == 0 && options.level_sky_line &&
        double(at_guess) <= kLevelLineMaxAtGuess * w) {
      const LevelSkyLine line = level_sky_line(mask.sky, w, h, guess_y);
      // The line is the sky's last row: the horizon lies on its lower edge (+ 1).
      const double centre = 0.5 * (w - 1), raise = guess_y(centre) - (line.a + line.b * centre + 1);
      if (line.found && raise >= kMinHorizonDropFraction * h) {
        move_horizon(
            {PixelPoint{0, line.a + 1}, PixelPoint{w - 1.0, line.a + 1 + line.b * (w - 1)}});
        g.horizon_raised_px = raise;
      }
    }
  }
  // Issue 11 (basketball: an office's white wall taken for an overcast sky): the sky is only
  // ever seen above the horizon, and ends there (land, a shore, a cloud bank: an edge). A pale,
  // smooth surface that a horizon the photo's lines measured cuts across goes on below it with
  // no edge: a wall, a ceiling, a screen. Where the mask's sky reaches such a horizon in at
  // least kMinSkyAtGuessFraction of the columns and the probe's sky (the mask without a
  // horizon) goes on below it there by at least kMinWallDropFraction of the height, filling
  // kMinSkyBelowGuessFraction of the band (as the weak guess's lowering asks), the sky
  // components that reach the horizon are that surface, not sky.
  if (options.wall_not_sky && !annotations.horizon && g.confidence >= kWeakHorizonConfidence &&
      mask.pixels > 0) {
    const SkyBelowLine below =
        sky_below_line(*photo, mask, g.horizon, sky_options, kMinSkyAtGuessFraction);
    if (below.columns > 0 && below.drop >= kMinWallDropFraction * camera.height &&
        below.band_fraction >= kMinSkyBelowGuessFraction) {
      // Calm water mirroring an overcast sky goes on below the horizon as smoothly as a wall
      // (water_mirror_row): where the photo below mirrors the photo above about a row between
      // two lines' widths above the horizon and the sky's end below it, that is water, and the
      // sky above it stays sky.
      const int horizon_row = row_of_line(g.horizon, 0.5 * (camera.width - 1));
      const int line_px = std::max(3, camera.height / 100);
      const bool mirrored =
          options.water_mirror && water_mirror_row(blurred_rgb(), horizon_row - 2 * line_px,
                                                   horizon_row + int(below.drop)) >= 0;
      if (!mirrored)
        g.wall_not_sky_pixels = drop_sky_reaching_line(mask, g.horizon, below.reaching);
    }
  }
  // Issue 11 (tuning friends: two dogs leaning out of a window in a white wooden wall, 3.4 % of
  // the frame "sky", a white curtain's strip in the window; brushes: a backdrop's clipped patch
  // between paint brushes): a photo with a little sky is an outdoor scene with a horizon, so
  // everything above that horizon stood on the far billboard, 46 m away, and dense fog erased
  // the dogs metres from the camera. A sky that small is mostly a pale or clipped patch
  // between near things. Under kLittleSkyFraction of the frame, the mask's sky is kept only
  // with a clear sky's evidence (photo/sky_mask.h, keep_evident_sky: blue and reaching the top
  // border along 15 % of the width) or running along half the top border (an overcast strip
  // over a valley); without any left, the scene is bounded (below). Dropping a real sky costs a
  // lighter fog; keeping a curtain as sky veils the subject.
  // An annotated horizon says the photo is an outdoor scene with one: the rule stays out.
  if (options.little_sky_evidence && photo && !annotations.horizon && mask.pixels > 0 &&
      double(mask.pixels) < kLittleSkyFraction * double(mask.sky.size())) {
    photo::CloseUpSkyOptions evidence;
    evidence.keep_open_top_fraction = kLittleSkyOpenTopFraction;
    g.little_sky_dropped_pixels =
        photo::keep_evident_sky(photo->view(), mask, evidence).dropped_pixels;
  }
  // A frame that the sky (with a cloud bank) fills from top to bottom, the weak horizon lowered
  // out of it, but that holds lamps is a ceiling seen from below (photo/sky_mask.h,
  // count_lamps_in_sky): it has no sky, and is a bounded scene.
  if (options.lamps_not_sky && g.horizon_lowered_px > 0) {
    std::size_t all_sky = 0;
    for (std::size_t i = 0; i < mask.sky.size(); ++i)
      all_sky += mask.sky[i] || (i < cloud_bank.size() && cloud_bank[i]);
    if (double(all_sky) >= kAllSkyFraction * double(mask.sky.size()) &&
        photo::count_lamps_in_sky(photo->view(), mask.sky) >= 2) {
      std::fill(mask.sky.begin(), mask.sky.end(), std::uint8_t(0));
      std::fill(mask.alpha.begin(), mask.alpha.end(), 0.0f);
      mask.pixels = mask.gap_pixels = 0;
      cloud_bank.clear();
      g.lamps_not_sky = true;
    }
  }
  // Issue 11 item 3: the sky seen through trees (under a canopy, between trunks, through
  // leaves) is sky, so the occluder mesh has holes there and sun shafts pass (photo/vegetation.h).
  const photo::VegetationOptions vegetation_options;
  photo::Vegetation vegetation;
  if (options.vegetation) {
    vegetation = photo::estimate_vegetation(photo->view(), g.horizon, mask.sky, vegetation_options);
    for (std::size_t i = 0; i < vegetation.sky_gap.size(); ++i)
      if (vegetation.sky_gap[i] && !mask.sky[i]) {
        mask.sky[i] = 1;
        mask.alpha[i] = 1.0f;
        ++mask.pixels;
      }
    g.vegetation_pixels = vegetation.vegetation_pixels;
    g.vegetation_gap_pixels = vegetation.gap_pixels;
  }
  // Issue 11 (helper haze11b): the matte's ramp running past a sharp edge into the surface
  // (photo/sky_matte.h, trim_matte_spill).
  if (options.trim_matte_spill) photo::trim_matte_spill(photo->view(), mask.alpha);
  steps.start("depth");
  const int w = camera.width, h = camera.height;
  const std::size_t n = std::size_t(w) * h;
  const double depression = options.billboard_depression_deg;
  if (!(depression > 0 && depression < 90))
    throw Error(ErrorCode::invalid_argument,
                "billboard_depression_deg: must be in (0, 90), found " + fmt("%g", depression));
  // Issue 11: a close-up or an interior, where the sky mask finds (next to) no sky, has no
  // horizon to run the ground to.
  constexpr double kBoundedSkyFraction = 0.002;
  bool bounded = double(mask.pixels) < kBoundedSkyFraction * double(n);
  // Issue 11 item 3: the scale of a scene nobody measured. A photo without any sky shows no
  // horizon and no ground running to it: an interior, a close-up, a wall, a field seen from
  // above. Its far billboard at the outdoor default (46 m from 1.6 m) makes a close-up vanish
  // in dense fog and puts a night look's lamps tens of metres into it; such a scene is metres
  // deep. Scaling the camera height scales every distance of the ground plane, the billboards
  // and the annotated planes alike (exactly: they are all linear in it), so the depth's shape
  // (and whether it jumps anywhere) does not change, only its metres. Only a guessed height is
  // rescaled; a distance hint fixes the scale, so the photo keeps the default then.
  // A background blurred far beyond the subject's sharp edges is a shallow depth of field: a
  // close-up (photo/geometry.h, estimate_defocus), sky or not.
  for (const double v : {options.bounded_scene_depth_m, options.closeup_scene_depth_m})
    if (!(v > 0) || !std::isfinite(v))
      throw Error(ErrorCode::invalid_argument,
                  "bounded_scene_depth_m, closeup_scene_depth_m: must be > 0, found " +
                      fmt("%g", v));
  if (g.height_source == EstimateSource::fallback && annotations.distance_hints.empty()) {
    const photo::Defocus defocus = photo::estimate_defocus(photo->view(), mask.sky);
    g.defocused_fraction = defocus.blurred_fraction();
    g.sharp_fraction = defocus.sharp_fraction();
    // ... with the subject filling most of the frame: a landscape with a wide sky whose smooth
    // glow and calm water pass for blur (a lake at twilight) is not a close-up.
    const double blurred = defocus.blurred_fraction(), sharp = defocus.sharp_fraction();
    const bool closeup =
        ((blurred >= options.closeup_min_defocused && sharp >= options.closeup_min_sharp) ||
         (blurred >= options.closeup_small_subject_defocused &&
          sharp >= options.closeup_small_subject_sharp)) &&
        double(mask.pixels) <= options.closeup_max_sky_fraction * double(n);
    double limit_m = kInfinity;
    std::string cue;
    if (closeup) {
      // Issue 11: a close-up's smooth, blurred background passes for sky (lavender, green-grey
      // or pale bokeh); seen through the whole fog layer it would be a flat, hard-edged patch
      // of fog colour beside a subject metres away. Only a clear blue sky across the top stays
      // sky; the rest is the background surface at the close-up's bounded depth
      // (photo/sky_mask.h, keep_evident_sky).
      const photo::CloseUpSky kept = photo::keep_evident_sky(photo->view(), mask);
      bounded = double(mask.pixels) < kBoundedSkyFraction * double(n);
      limit_m = options.closeup_scene_depth_m;
      cue = "close-up (" + fmt("%.0f", 100 * defocus.blurred_fraction()) +
            " % of the frame strongly out of focus, " +
            fmt("%.0f", 100 * defocus.sharp_fraction()) + " % sharp";
      if (kept.dropped_pixels > 0)
        cue += "; " + fmt("%.1f", 100.0 * double(kept.dropped_pixels) / double(n)) +
               " % of the frame blurred background, not sky";
      cue += ")";
    } else if (bounded) {
      limit_m = options.bounded_scene_depth_m;
      cue = "no sky: a bounded scene";
    }
    const double scale = limit_m / (height / std::tan(depression * kDeg));
    if (scale < 1) {
      height *= scale;
      g.pose.position_m.y = height;
      for (float& d : g.distance_m.pixels())
        if (std::isfinite(d)) d = float(d * scale);
      g.scale_cue = cue + ", far billboard at " + fmt("%g", limit_m) + " m";
    }
  }
  const double far_forward = height / std::tan(depression * kDeg);
  const Vec3 f = g.pose.axes()[0];
  const double fl = std::hypot(f.x, f.z);
  const Vec3 fwd{f.x / fl, 0, f.z / fl};  // the camera's horizontal viewing direction
  // Distance along the ray to the vertical plane facing the camera `forward` metres ahead.
  auto billboard = [&](int x, int y, double forward) {
    const Vec3 d = g.pose.ray_direction(camera, x, y);
    const double along = d.x * fwd.x + d.z * fwd.z;
    return float(forward / std::max(along, 0.05));  // rays nearly sideways: 20 x forward at most
  };
  const double slope =
      (g.horizon[1][1] - g.horizon[0][1]) / std::max(1.0, g.horizon[1][0] - g.horizon[0][0]);
  auto horizon_y = [&](double x) { return g.horizon[0][1] + (x - g.horizon[0][0]) * slope; };

  // The forward distance of the ground at pixel centre column x, row y (a pixel edge), no
  // farther than the far billboard: a contact just below the horizon is the least certain (a
  // pixel there spans many metres), and fog should err towards too much. 0: none.
  const Vec3 camera_position = g.pose.position_m;
  auto ground_forward = [&](int x, double y) {
    const auto gp = photo::ground_point(camera, g.pose, {double(x), y});
    const double fd =
        gp ? (gp->x - camera_position.x) * fwd.x + (gp->z - camera_position.z) * fwd.z : 0.0;
    return fd > 0 && std::isfinite(fd) ? std::min(fd, far_forward) : 0.0;
  };
  // Row-major, 1 = of the ground's colour below the horizon (photo/sky_mask.h, GroundMask);
  // empty where the ground's colours were not modelled.
  std::vector<std::uint8_t> ground_coloured;
  // Per pixel: the forward distance of the structure it is on where it meets the ground (0:
  // none found).
  std::vector<float> contact_forward(n, 0.0f);
  // A subject standing in the bottom band (below): 1 on its pixels, empty where none was found.
  std::vector<std::uint8_t> subject;
  // Without any sky the horizon is a guess (no ground is seen running to it) and everything
  // above it is "structure": a snow field seen from above, the back wall of a bar. Its
  // contacts would be wherever a dark trunk or a table leg happens to reach below the guessed
  // horizon, each making a column of its own depth from the top of the frame down: vertical
  // seams with no edge in the photo. Such a scene keeps the far billboard over the ground
  // plane (bounded, see above), which is continuous.
  if (options.ground_contact && !bounded) {
    const photo::GroundMask ground =
        photo::estimate_ground_mask(photo->view(), g.horizon, mask.sky);
    if (ground.valid) {
      ground_coloured = ground.ground;
      // Issue 11 (a person sitting on a beach, her feet out of the frame): a subject standing
      // in the bottom band (photo/subject.h) hides the ground under it, so it stands no farther
      // than the bottom row's ground (as any structure running off the bottom, below). Through
      // a head or a shoulder it touches the far land behind it (dunes, people on a beach) and
      // is one structure with it. Its foot is its own: the joined structure's contacts leave
      // out the columns whose foot is the subject's (else the far land stood at the subject's
      // distance), and the subject's pixels take the bottom row's ground after (else, the
      // joined structure rising too little above the horizon for a foot at the frame's bottom
      // to count, the subject stood on the far billboard above the horizon and on the ground
      // plane below it: a line across the person at the horizon's row in dense fog). It stays
      // in the structure: a facade beside a shop front has its contacts through it, and cut
      // off from them went to the far billboard. (Only with a measured horizon, as the bottom
      // row's contact below.)
      std::vector<double> subject_forward;
      if (ground.standing_subject && g.horizon_source != EstimateSource::fallback) {
        subject = photo::find_standing_subject(photo->view(), g.horizon, mask.sky, ground).pixels;
        subject_forward.assign(std::size_t(w), 0.0);
        for (int x = 0; x < w && !subject.empty(); ++x)
          subject_forward[std::size_t(x)] = ground_forward(x, h - 0.5);
        for (int y = 0; y < h && !subject.empty(); ++y)
          for (int x = 0; x < w; ++x)
            if (!(subject_forward[std::size_t(x)] > 0)) subject[std::size_t(y) * w + x] = 0;
      }
      // Structure: not sky, not annotated; below the horizon where not ground-coloured.
      cv::Mat structure(h, w, CV_8U, cv::Scalar(0));
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
          const std::size_t i = std::size_t(y) * w + x;
          const auto c = map.coverage[i];
          structure.at<std::uint8_t>(y, x) =
              !mask.sky[i] &&
              (c == photo::Coverage::sky || (c == photo::Coverage::ground && !ground.ground[i]));
        }
      cv::Mat labels, stats, centroids;
      const int count =
          cv::connectedComponentsWithStats(structure, labels, stats, centroids, 8, CV_32S);
      // Only components that rise above the horizon stand on the ground; blobs entirely below
      // it (markings, shadows, low objects) stay ground.
      std::vector<std::uint8_t> rises(std::size_t(count), 0);
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
          if (map.coverage[std::size_t(y) * w + x] == photo::Coverage::sky)
            rises[std::size_t(labels.at<int>(y, x))] = 1;
      rises[0] = 0;  // the background
      // Trees: structures that are mostly foliage. Their trunks meet the ground in a few of
      // their columns only (the canopy spans many more), which for other structures means
      // foreground clutter touching a facade; a tree stands where its trunks do.
      std::vector<std::size_t> foliage(std::size_t(count), 0);
      if (options.vegetation)
        for (int y = 0; y < h; ++y)
          for (int x = 0; x < w; ++x)
            foliage[std::size_t(labels.at<int>(y, x))] +=
                vegetation.vegetation[std::size_t(y) * w + x] == 2;  // green
      std::vector<std::uint8_t> tree(std::size_t(count), 0);
      for (int l = 1; l < count; ++l)
        tree[std::size_t(l)] =
            rises[std::size_t(l)] &&
            double(foliage[std::size_t(l)]) >=
                vegetation_options.tree_min_fraction * stats.at<int>(l, cv::CC_STAT_AREA);
      std::vector<std::size_t> offset(std::size_t(count), 0);
      std::size_t total = 0;
      for (int l = 1; l < count; ++l)
        if (rises[l]) offset[l] = total, total += std::size_t(stats.at<int>(l, cv::CC_STAT_WIDTH));
      std::vector<int> subject_foot(std::size_t(count), 0);  // columns whose foot is the subject's
      // The lowest and the highest row of each rising component in each of its columns.
      std::vector<int> lowest(total, -1), highest(total, -1);
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
          const int l = labels.at<int>(y, x);
          if (rises[std::size_t(l)]) {
            const std::size_t k = offset[l] + std::size_t(x - stats.at<int>(l, cv::CC_STAT_LEFT));
            lowest[k] = y;
            if (highest[k] < 0) highest[k] = y;
          }
        }
      // Its contact: the pixel edge below that row, when it is below the horizon and the pixel
      // beneath is ground-coloured (a structure running off the bottom has no contact).
      std::vector<double> forward(total, 0.0);
      for (int l = 1; l < count; ++l) {
        if (!rises[l]) continue;
        const int left = stats.at<int>(l, cv::CC_STAT_LEFT),
                  width = stats.at<int>(l, cv::CC_STAT_WIDTH);
        for (int k = 0; k < width; ++k) {
          const int x = left + k, yc = lowest[offset[l] + k];
          if (yc < 0 || !(yc >= horizon_y(x) + 1)) continue;
          // Issue 11 item 2 (a person or a plant in front of the sky, its foot out of the
          // frame): what covers the bottom row below the horizon hides the ground there, so it
          // stands no farther than that ground: the bottom edge of the frame is its contact,
          // an upper bound (fog errs towards too much). Without it, such a subject went to the
          // far billboard and vanished in dense fog. Only with a measured horizon (annotated,
          // or from the photo's lines): under the level fall-back the bottom row may be above
          // the true horizon (a camera looking up into a canopy), and there is no ground there.
          // (Also not when the ground's colour model found a subject standing in the bottom
          // band: under the fall-back, a backlit cloud bank reaching the bottom of a sky photo
          // passed for such a subject and stood on the bottom edge, a flat near patch in haze.)
          if (yc + 1 >= h) {
            if (g.horizon_source == EstimateSource::fallback) continue;
          } else if (!ground.ground[std::size_t(yc + 1) * w + x]) {
            continue;
          }
          // A standing subject's foot is its own (above), not that of what it touches; the
          // share of contacts asked below is of the columns whose foot is not the subject's.
          if (!subject.empty() && subject[std::size_t(yc) * w + x]) {
            ++subject_foot[std::size_t(l)];
            continue;
          }
          // Issue 11 item 3: something standing on the ground rises above the horizon by a fair
          // part of what it spans below it; the sea up to a boat, a person or a low wall do not,
          // and made into a billboard they become a wall of columns with seams between them.
          // Running off the frame's bottom, its span below the horizon is the frame's, not its
          // own: what rises is the subject as a whole (a person's head, not each shoulder).
          const double rise =
              horizon_y(x) - (yc + 1 >= h ? double(stats.at<int>(l, cv::CC_STAT_TOP))
                                          : double(highest[offset[l] + k]));
          if (!(rise >= options.min_rise_ratio * (yc + 0.5 - horizon_y(x)))) continue;
          forward[offset[l] + k] = ground_forward(x, yc + 0.5);
        }
      }
      // Smoothed: the median of the contacts within a few columns of the same component; its
      // columns without a contact take the nearest column's that has one. A component with
      // contacts in fewer than kMinContactColumns of its columns (a facade behind hedges and
      // cars, touching the ground-coloured band here and there) keeps the far billboard: its
      // few contacts are more likely foreground clutter than its own foot.
      constexpr double kMinContactColumns = 0.3;
      const int half = std::max(2, w / 100);
      std::vector<double> smooth(total, 0.0), window;
      for (int l = 1; l < count; ++l) {
        if (!rises[l]) continue;
        const int width = stats.at<int>(l, cv::CC_STAT_WIDTH);
        const double* fw = forward.data() + offset[l];
        double* sm = smooth.data() + offset[l];
        int valid = 0;
        for (int k = 0; k < width; ++k) valid += fw[k] > 0;
        if (valid == 0 || (!tree[std::size_t(l)] &&
                           valid < kMinContactColumns * (width - subject_foot[std::size_t(l)])))
          continue;
        if (tree[std::size_t(l)]) {
          // A tree (or a stand of them joined by their canopy) stands at one distance: the
          // median of its trunks' contacts. Per-column contacts would give its canopy columns
          // of different depth, seams in haze where the photo has none.
          g.tree_pixels += std::size_t(stats.at<int>(l, cv::CC_STAT_AREA));
          window.clear();
          for (int k = 0; k < width; ++k)
            if (fw[k] > 0) window.push_back(fw[k]);
          std::nth_element(window.begin(), window.begin() + std::ptrdiff_t(window.size() / 2),
                           window.end());
          std::fill(sm, sm + width, window[window.size() / 2]);
          continue;
        }
        for (int k = 0; k < width; ++k) {
          if (!(fw[k] > 0)) continue;
          window.clear();
          for (int j = std::max(0, k - half); j <= std::min(width - 1, k + half); ++j)
            if (fw[j] > 0) window.push_back(fw[j]);
          std::nth_element(window.begin(), window.begin() + std::ptrdiff_t(window.size() / 2),
                           window.end());
          sm[k] = window[window.size() / 2];
        }
        // Issue 11 item 3: per-column contacts (and the nearest contact copied into the columns
        // without one) make a staircase: each step a vertical seam from the structure's top
        // down to its foot, wherever the photo has one there or not, and the refinement cannot
        // smooth it inside texture (foliage, a snow field), whose every edge stops it. A
        // structure's forward distance is a smooth function of the column instead: robust
        // local lines in inverse forward distance over the columns (exact for one vertical
        // plane seen level: 1 / z is linear in x; a corner rounded over w / 12 columns), no
        // nearer than its nearest contact and no farther than the far billboard.
        const std::vector<double> fitted =
            photo::robust_inverse_line(sm, width, std::max(8, w / 12));
        double nearest = far_forward;
        for (int k = 0; k < width; ++k)
          if (sm[k] > 0) nearest = std::min(nearest, sm[k]);
        for (int k = 0; k < width; ++k)
          sm[k] = std::clamp(fitted[std::size_t(k)], nearest, far_forward);
      }
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
          const int l = labels.at<int>(y, x);
          if (rises[std::size_t(l)])
            contact_forward[std::size_t(y) * w + x] =
                float(smooth[offset[l] + std::size_t(x - stats.at<int>(l, cv::CC_STAT_LEFT))]);
        }
      if (!subject.empty())
        for (int y = 0; y < h; ++y)
          for (int x = 0; x < w; ++x)
            if (subject[std::size_t(y) * w + x])
              contact_forward[std::size_t(y) * w + x] = float(subject_forward[std::size_t(x)]);
    }
  }

  constexpr int kFar = 5, kContact = 6, kPerson = 7;
  std::vector<std::uint8_t> pixel_class(n, 0);              // what decided each pixel's distance
  std::vector<double> column_forward(std::size_t(w), 0.0);  // the structure above the horizon
  std::vector<int> column_cov(std::size_t(w), 0);
  std::size_t counts[8] = {};  // sky, ground, plane, hint, room, far, contact, person
  // Ground pixels behind a billboard: the billboard's distance over the ground plane's (< 1).
  std::vector<float> ground_ratio(n, 0.0f);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      float& d = g.distance_m.at(x, y, 0);
      int cov = int(map.coverage[i]);
      const bool open =
          map.coverage[i] == photo::Coverage::sky || map.coverage[i] == photo::Coverage::ground;
      if (mask.sky[i] && map.coverage[i] == photo::Coverage::plane) {
        d = std::numeric_limits<float>::infinity(), cov = int(photo::Coverage::sky);
      } else if (open && contact_forward[i] > 0) {
        d = billboard(x, y, contact_forward[i]), cov = kContact;
      } else if (!mask.sky[i] && map.coverage[i] == photo::Coverage::sky) {
        d = billboard(x, y, far_forward), cov = kFar;
      } else if (map.coverage[i] == photo::Coverage::ground && column_forward[std::size_t(x)] > 0) {
        const float b = billboard(x, y, column_forward[std::size_t(x)]);
        if (b < d) ground_ratio[i] = b / d, d = b, cov = column_cov[std::size_t(x)];
      } else if (map.coverage[i] == photo::Coverage::ground && bounded) {
        // No sky: nothing in the photo is known to be far, and a ground plane running to
        // the horizon behind a table top or a wall would end in a seam where it meets the far
        // billboard above the horizon; the far billboard closes the scene (bounded depth).
        const float b = billboard(x, y, far_forward);
        if (b < d) ground_ratio[i] = b / d, d = b, cov = kFar;
      }
      ++counts[cov];
      pixel_class[i] = std::uint8_t(cov);
      // The pixel just above the horizon in this column decides whether a structure stands there.
      const double yh = horizon_y(x);
      if (y < yh && y + 1 >= yh) {
        column_cov[std::size_t(x)] = cov;
        // With the refinement, the far billboard does not cut the ground behind it: what
        // stands there is unknown (a sunset band over the sea, far hills), a band of ground
        // at its made-up distance would end in a seam at the next column without it, and the
        // refinement joins the billboard to the ground wherever the photo has no edge.
        column_forward[std::size_t(x)] = cov == kFar ? (options.refine_depth ? 0.0 : far_forward)
                                         : cov == kContact ? contact_forward[i]
                                                           : 0.0;
      }
    }
  }
  // Issue 11 (a couple at a canyon's rim, their horizon guessed from a jacket's zip, on the far
  // billboard and gone in dense fog; a studio portrait): people near the camera stand at their
  // faces' distance (photo/people.h), a plane facing the camera. Annotations win. Not in a
  // bounded scene (no sky: an interior, a close-up): its fog deepens gently from the frame's
  // bottom, where a person stands nearest anyway, and a person cut out of it would outline
  // every head against a wall metres behind with new contrast.
  // Per pixel, a distance the refinement and the bounds below leave as it is (0: none).
  std::vector<float> kept_distance;
  // Nor where open sky is under 5 % of the frame: a scene nearly all surface (a close-up of paint
  // brushes whose bright patch passed for sky, with a false face among the brushes) is metres
  // deep everywhere, and a cut-out there is a block of new contrast.
  constexpr double kPeopleMinSkyFraction = 0.05;
  if (options.people && !bounded && double(mask.pixels) >= kPeopleMinSkyFraction * double(n)) {
    const photo::People people = photo::find_people(photo->view(), camera.focal_px, mask.sky);
    // Pixel i (x, y) is on a person at distance d, which the refinement keeps.
    auto stand_person = [&](std::size_t i, int x, int y, float d) {
      if (kept_distance.empty()) kept_distance.assign(n, 0.0f);
      g.distance_m.at(x, y, 0) = d;
      kept_distance[i] = d;
      --counts[pixel_class[i]];
      ++counts[kPerson];
      pixel_class[i] = kPerson;
      ground_ratio[i] = 0;
    };
    // A person the ground's colour model already found standing in the bottom band (above)
    // keeps that subject's pixels and distance: two outlines of one person would disagree.
    std::vector<std::uint8_t> skip(people.persons.size() + 1, 0);
    for (std::size_t k = 0; k < people.persons.size() && !subject.empty(); ++k) {
      const auto& f = people.persons[k].face;
      std::size_t inside = 0, all = 0;
      for (int y = f[1] + f[3] / 4; y < f[1] + f[3] * 3 / 4; ++y)
        for (int x = f[0] + f[2] / 4; x < f[0] + f[2] * 3 / 4; ++x, ++all)
          inside += subject[std::size_t(y) * w + x];
      skip[k + 1] = 2 * inside >= all;
    }
    for (int y = 0; y < h && !people.pixels.empty(); ++y)
      for (int x = 0; x < w; ++x) {
        const std::size_t i = std::size_t(y) * w + x;
        const int k = people.pixels[i];
        const auto cov = map.coverage[i];
        if (k == 0 || skip[std::size_t(k)] || cov == photo::Coverage::plane ||
            cov == photo::Coverage::hint)
          continue;
        if (mask.sky[i]) {  // under a person's chin (photo/people.h): not sky
          mask.sky[i] = 0, mask.alpha[i] = 0, --mask.pixels;
          ground_ratio[i] = 0;
        }
        stand_person(
            i, x, y,
            float(people.persons[std::size_t(k - 1)].depth_m * camera.z_to_distance(x, y)));
      }
    // Issue 11 (cold_water: people wading with their backs to the camera, their heads at the
    // horizon's row, ran from their feet's distance up to the far sea's, heads lost in dense
    // fog): people standing on the ground, found by their figures (photo/people.h), stand where
    // their feet meet the ground, a plane facing the camera. Needs the ground's colours (the
    // foot is on them).
    if (options.standing_people && !ground_coloured.empty()) {
      std::vector<std::uint8_t> taken(n, 0);
      for (std::size_t i = 0; i < n; ++i)
        taken[i] = (!people.pixels.empty() && people.pixels[i]) || (!subject.empty() && subject[i]);
      const photo::StandingPeople standing = photo::find_standing_people(
          photo->view(), camera.focal_px, mask.sky, taken, [&](int x, int y) {
            return y >= 0 && y < h && ground_coloured[std::size_t(y) * w + x]
                       ? ground_forward(x, y + 0.5)
                       : 0.0;
          });
      for (int y = 0; y < h && !standing.pixels.empty(); ++y)
        for (int x = 0; x < w; ++x) {
          const std::size_t i = std::size_t(y) * w + x;
          const int k = standing.pixels[i];
          const auto cov = map.coverage[i];
          if (k == 0 || mask.sky[i] || cov == photo::Coverage::plane ||
              cov == photo::Coverage::hint)
            continue;
          stand_person(i, x, y, billboard(x, y, standing.persons[std::size_t(k - 1)].forward_m));
        }
      g.standing_people = standing.persons.size();
    }
  }
  g.people_pixels = counts[kPerson];
  g.sky_pixels = counts[0];
  g.ground_pixels = counts[1];
  g.plane_pixels = counts[2];
  g.hint_pixels = counts[3];
  g.billboard_pixels = counts[kFar];
  g.contact_pixels = counts[kContact];
  g.sky_gap_pixels = mask.gap_pixels;

  // Issue 11 items 3 and 4: the soft sky matte, a confidence per pixel, and the depth refined
  // against the photo so that it jumps only where the photo has an edge.
  g.sky_alpha = Image(w, h, 1, {"A"});
  g.depth_confidence = Image(w, h, 1, {"Y"});
  const photo::DepthRefineOptions refine;
  std::vector<float> q(n), c(n);
  std::vector<std::uint8_t> blended(n, 0);  // on the sky's blurred edge
  // Moved farther by the sea horizon's or a far shore's bound below: written back even where
  // the ground's confidence is 1 (the refinement keeps such pixels exactly), else the bound's
  // gradual return to the plane below a tall shore's reflection was cut off along the row of
  // 4 degrees, a straight step in the water (summer_1am: 47 m over 23 m in one row).
  std::vector<std::uint8_t> sea_bounded(n, 0);
  // Issue 11 item 3 (helper bounded13): a bounded scene (no sky: an interior, a still life, a
  // close-up) has a guessed horizon and no pixel of known distance. Refined against the photo,
  // the guessed ground's near distances ran up through whatever the photo bounds by edges (a
  // clip hanging in a plant, a saucer's rim, a spoon) into the far billboard above the horizon:
  // clear cut-outs outlined in dense fog, and a band where the two met. Nothing there says
  // where the depth jumps, so it jumps nowhere: the ground plane and the far billboard joined
  // smoothly (photo/geometry.h, bounded_inverse_distance), a fog that deepens gently up the
  // frame. Annotated planes and distance hints keep the refinement that joins them to it.
  const bool smooth_bounded = options.refine_depth && options.smooth_bounded_depth && bounded &&
                              g.plane_pixels == 0 && g.hint_pixels == 0;
  if (!(options.bounded_soft_rows >= 0) || !std::isfinite(options.bounded_soft_rows))
    throw Error(ErrorCode::invalid_argument,
                "bounded_soft_rows: must be >= 0, found " + fmt("%g", options.bounded_soft_rows));
  const double soft_rows = options.bounded_soft_rows * h;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      const float d = g.distance_m.at(x, y, 0);
      const int cls = pixel_class[i];
      const float alpha = mask.alpha[i];
      g.sky_alpha.at(x, y, 0) = alpha;
      float conf = cls == kFar ? 0.05f : cls == kContact ? 0.3f : 1.0f;
      if (cls == int(photo::Coverage::ground) || ground_ratio[i] > 0) {
        // Near the horizon a pixel of the ground spans many metres (at 2 degrees below it, 4 %
        // of its distance), whether the ground runs flat to the horizon is a guess, and a flat
        // ground there makes the fog jump from clear to opaque within a pixel or two in haze:
        // the confidence ramps from 0 at the horizon to 1 at twice the far billboard's
        // depression (4 degrees: 23 m from 1.6 m), and the refinement smooths what is above.
        const double below =
            std::asin(std::clamp(-g.pose.ray_direction(camera, x, y).y, -1.0, 1.0));
        const float ground_conf = float(std::clamp(below / (2 * depression * kDeg), 0.0, 1.0));
        // A ground pixel cut by a billboard in front of it (the ground behind a structure, or
        // a bounded scene's far billboard): the billboard's confidence where it is well in
        // front, rising continuously to the ground's where the two meet (ratio 1), so the
        // refinement does not cut a seam along the line where they cross.
        const float r = ground_ratio[i];
        conf = r > 0 ? std::max(conf, ground_conf * r * r * r * r) : ground_conf;
      }
      float inv = std::isfinite(d) && d > 0 ? 1.0f / d : 0.0f;
      if (smooth_bounded && std::isfinite(d) &&
          (cls == kFar || cls == int(photo::Coverage::ground))) {
        const Vec3 r = g.pose.ray_direction(camera, x, y);
        inv = float(photo::bounded_inverse_distance(r.y, r.x * fwd.x + r.z * fwd.z, height,
                                                    far_forward, camera.focal_px, soft_rows));
      }
      if (std::isfinite(d) && alpha > 0 && cls != int(photo::Coverage::hint) &&
          cls != int(photo::Coverage::plane)) {
        // A blurred sky edge: the surface's inverse distance fades to the sky's 0 as the
        // matte rises to 0.5 (where the binary mask turns to sky), so the fog does too.
        const float keep = std::max(0.0f, 1.0f - 2.0f * alpha);
        inv *= keep;
        conf *= keep;
        blended[i] = 1;
      }
      q[i] = inv;
      c[i] = conf;
    }
  steps.start("refine");
  // (The sky fold of issue 11 item 4 below, computed here: a far band's walk up to the sky
  // passes through what the fold makes sky, a glow the mask left out.)
  std::vector<float> fold;
  if (options.refine_depth && options.sky_fold && mask.pixels > 0) {
    fold = photo::sky_proximity(photo->view(), mask.sky);
    for (std::size_t i = 0; i < n; ++i) {
      const int cls = pixel_class[i];
      fold[i] =
          cls == int(photo::Coverage::hint) || cls == int(photo::Coverage::plane) || cls == kPerson
              ? 1.0f
              : photo::sky_fold(fold[i]);
    }
  }
  // Sky, or a surface the fold takes to the sky's distance (a glow over the horizon).
  constexpr float kSkyLikeFold = 0.05f;
  auto sky_like = [&](std::size_t i) {
    return mask.sky[i] || (!fold.empty() && fold[i] <= kSkyLikeFold);
  };
  if (options.refine_depth && !smooth_bounded) {
    const std::vector<float> q_plane = q;  // before the refinement: the ground plane's
    if (subject.empty() && kept_distance.empty()) {
      q = photo::refine_inverse_distance(photo->view(), q, c, refine);
    } else {
      // The subject and people keep their distance, and lend none to what is around them:
      // where an outline is faint (blonde hair against sand) the inverse distance, tens of
      // times the far land's, spread into the far land beside the head, a clear window in
      // dense fog.
      auto own = [&](std::size_t i) {
        return (!subject.empty() && subject[i]) || (!kept_distance.empty() && kept_distance[i] > 0);
      };
      std::vector<float> weight = c;
      for (std::size_t i = 0; i < n; ++i)
        if (own(i)) weight[i] = 0;
      q = photo::refine_inverse_distance(photo->view(), q, weight, refine);
      for (std::size_t i = 0; i < n; ++i)
        if (own(i)) q[i] = q_plane[i];
    }
    // Only under a horizon that says where the water meets the sky (annotated, or found with
    // some confidence): under a guessed one (the level fall-back, a weak cue, one lowered
    // under the sky it cut) the ground's plane is a guess too (a dark ridge under a glow).
    const bool horizon_known = annotations.horizon || g.confidence >= kWeakHorizonConfidence;
    if (options.sea_horizon && horizon_known && mask.pixels > 0) {
      // Issue 11 (sea horizons in haze, helper sea11): near the horizon the ground's confidence
      // ramps to 0 and the refinement fills mirror-smooth water up to a faint far shore line
      // with the nearer water's distance (60 m where the plane says hundreds), while the sky
      // above the line, seen along the layer's slant path, is opaque in haze: a step in the fog
      // at a line the photo hardly shows. The plane itself, seen from 1.6 m, runs from clear to
      // opaque within a few pixels (its inverse distance falls linearly to 0 at the horizon;
      // transmittance exp(-sigma / q)). Where the photo's water mirrors the sky, the optical
      // depth must meet the sky's at the horizon and return gently: the inverse distance is at
      // most the plane's times the ground's confidence (quadratic in the depression, reaching
      // the plane at 2x the billboard's depression), so the fog fades over tens of pixels.
      // Only under an open horizon (sky within a thin line's width above it; a shore's trees or
      // a pier standing there keep the refinement's distance), smoothed across columns, and
      // only where the pixel mirrors the sky (luma within 80 % of the pixel mirrored about the
      // horizon, blurred: a pier's dark deck on the water does not; coldripple).
      const int line_px = std::max(3, h / 100);  // a far shore's line, not a structure
      std::vector<float> open(std::size_t(w), 0.0f);
      // Issue 11 (far shores, helper shore14): the rows of a thin band of far land resting on
      // the horizon in each column (band_top to band_bottom; -1: none). Whatever stands on the
      // horizon and rises less above it than the far billboard's depression before the open
      // sky is seen (a far shore's trees, hills, a skyline) is kilometres away when water
      // mirrors it in front: from the horizon a structure on the ground rises by its height
      // over its distance, so 2 degrees is 35 m at 1 km and a near object standing on the water
      // (a person, a post, a boat) spans far more below the horizon than above it, which a
      // contact nearer than the far billboard shows; such a column is no band.
      const int band_px = std::max(line_px, int(camera.focal_px * std::tan(depression * kDeg)));
      std::vector<int> band_top(std::size_t(w), -1), band_bottom(std::size_t(w), -1),
          band_foot(std::size_t(w), -1);
      for (int x = 0; x < w; ++x) {
        const int yh = int(std::ceil(horizon_y(x))) - 1;
        for (int y = std::max(0, yh - line_px); y <= std::min(h - 1, yh); ++y)
          if (mask.sky[std::size_t(y) * w + x]) open[std::size_t(x)] = 1.0f;
        // (A band lower than a line's width leaves the column open, and is a band all the same.)
        if (!options.far_shore || yh < 0 || yh >= h) continue;
        // (Helper shore15: a column whose horizon the sky fold, not the sky mask, takes to the
        // sky (far hills faded into a glow: summer_1am's left third) is a band of no height
        // here: the fold's sky is as far as the sky, and water mirroring it is open water.
        // One the sky mask meets is sea11's open water, as before.)
        if (mask.sky[std::size_t(yh) * w + x] ||
            (sky_like(std::size_t(yh) * w + x) && open[std::size_t(x)] > 0))
          continue;
        int y = yh;
        for (; y >= 0 && yh - y <= band_px; --y) {
          const std::size_t i = std::size_t(y) * w + x;
          if (sky_like(i)) break;
          const int cls = pixel_class[i];
          if (cls != kFar && !(cls == kContact && contact_forward[i] >= 0.99f * far_forward)) break;
        }
        if (y < 0 || !sky_like(std::size_t(y) * w + x)) continue;  // not open sky above it
        band_top[std::size_t(x)] = y + 1, band_bottom[std::size_t(x)] = yh;
        // Its foot below the horizon: the structure standing on the far billboard's contact
        // (a shore's dark foot, its reflection joined to it), and ground cut by it.
        int foot = yh;
        for (int yf = yh + 1; yf < h; ++yf) {
          const std::size_t i = std::size_t(yf) * w + x;
          if (!((pixel_class[i] == kContact && contact_forward[i] >= 0.99f * far_forward) ||
                ground_ratio[i] > 0))
            break;
          foot = yf;
        }
        band_foot[std::size_t(x)] = foot;
      }
      // Issue 11 (helper shore15): each band column's waterline and how plainly the water under
      // it mirrors the band. The horizon found from the photo's lines can lie a few pixels off
      // the waterline (summer_1am: 5-6 px above it), and a reflection starts at the waterline,
      // not at the horizon: the waterline is the row within a line's width of the horizon about
      // which the photo below is most like the photo above flipped (the band, with a line's
      // width of the sky over it: the band's top outline must be mirrored too), correlated over
      // a box of columns (mirror_correlation); per column the median of its neighbours' rows,
      // since a shore's waterline is one level line. A dark field under a dark ridge matches
      // the ridge in brightness (storm_pano) but not its outline: its correlation is low.
      std::vector<int> waterline(std::size_t(w), -1);
      std::vector<float> band_mirror(std::size_t(w), 0.0f);
      if (options.far_shore) {
        // Ripples blur a reflection vertically: both sides blurred alike over a line's width.
        const cv::Mat& rgb = blurred_rgb();
        const int search = 2 * line_px, half_width = std::max(4, w / 80);
        std::vector<std::vector<float>> score(static_cast<std::size_t>(w));
        std::vector<int> best(std::size_t(w), -1);
        for (int x = 0; x < w; ++x) {
          const int top = band_top[std::size_t(x)];
          if (top < 0) continue;
          const int yh = band_bottom[std::size_t(x)] + 1;  // the horizon's first row below
          auto& s = score[std::size_t(x)];
          s.assign(std::size_t(2 * search + 1), 0.0f);
          float best_score = -2.0f;
          for (int k = 0; k <= 2 * search; ++k) {
            const int axis = yh - search + k;
            if (axis <= top) continue;
            s[std::size_t(k)] = mirror_correlation(rgb, x, axis, axis - top + line_px, half_width);
            if (s[std::size_t(k)] > best_score)
              best_score = s[std::size_t(k)], best[std::size_t(x)] = k;
          }
        }
        std::vector<int> near;
        for (int x = 0; x < w; ++x) {
          if (band_top[std::size_t(x)] < 0) continue;
          near.clear();
          for (int xx = std::max(0, x - half_width); xx <= std::min(w - 1, x + half_width); ++xx)
            if (best[std::size_t(xx)] >= 0) near.push_back(best[std::size_t(xx)]);
          std::nth_element(near.begin(), near.begin() + near.size() / 2, near.end());
          const int k = near[near.size() / 2];
          waterline[std::size_t(x)] = band_bottom[std::size_t(x)] + 1 - search + k;
          // Calm water repeats the band's outline almost exactly: mirrored from a
          // correlation of 0.8, plainly from 0.87 (the tuning half: summer_1am's far shore
          // 0.88-0.99, storm_pano's field under its ridge at most 0.77).
          constexpr float kMinMirrorCorrelation = 0.8f, kMirrorCorrelation = 0.87f;
          const float mirror =
              std::clamp((score[std::size_t(x)][std::size_t(k)] - kMinMirrorCorrelation) /
                             (kMirrorCorrelation - kMinMirrorCorrelation),
                         0.0f, 1.0f);
          band_mirror[std::size_t(x)] = mirror;
          // A band the water mirrors is a far shore: the column's horizon is open water's
          // (what stands on it is as far as the sky for the fog); one it does not mirror (a
          // ridge over a field) leaves the column as it was.
          open[std::size_t(x)] = std::max(open[std::size_t(x)], mirror);
        }
        // A band no water mirrors is no far shore: its column stays as without the rule.
        for (int x = 0; x < w; ++x)
          if (band_top[std::size_t(x)] >= 0 && !(band_mirror[std::size_t(x)] > 0))
            band_top[std::size_t(x)] = band_bottom[std::size_t(x)] = -1;
      }
      // Means of a per-column value over columns [a, b) (clipped to the frame; 0 when empty),
      // from its prefix sums.
      const int reach = std::max(1, w / 20);
      auto column_prefix = [w](const std::vector<float>& v) {
        std::vector<float> prefix(std::size_t(w) + 1, 0.0f);
        for (int x = 0; x < w; ++x)
          prefix[std::size_t(x) + 1] = prefix[std::size_t(x)] + v[std::size_t(x)];
        return prefix;
      };
      auto column_mean = [w](const std::vector<float>& prefix, int a, int b) {
        a = std::max(0, a), b = std::min(w, b);
        return b > a ? (prefix[std::size_t(b)] - prefix[std::size_t(a)]) / float(b - a) : 0.0f;
      };
      // The mean of a per-column value over a box of 1/10 of the width: no seam across columns.
      auto box_across_columns = [&](const std::vector<float>& v) {
        const std::vector<float> prefix = column_prefix(v);
        std::vector<float> mean(static_cast<std::size_t>(w));
        for (int x = 0; x < w; ++x)
          mean[std::size_t(x)] = column_mean(prefix, x - reach, x + reach + 1);
        return mean;
      };
      // Squared: the bound fades in across columns.
      open = box_across_columns(open);
      for (float& m : open) m *= m;
      constexpr float kMirrorLumaTolerance = 0.8f;  // |la - lb| / max(la, lb) at which it is 0
      cv::Mat mirrors(h, w, CV_32F, cv::Scalar(0)), sky_mirrors(h, w, CV_32F, cv::Scalar(0));
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
          const int ym = int(std::lround(2 * horizon_y(x) - y));
          if (!(y > horizon_y(x)) || ym < 0 || ym >= h) continue;
          // The sky, what the fold makes sky, or in a far band's column the band (its
          // reflection). (What the fold makes sky counted in band columns only before
          // 2026-12-04: the water under summer_1am's left sixth, where far hills faded into the
          // glow are fold sky down to the horizon, mirrored nothing, kept its plane's 25 m
          // between veiled water, and showed as a pale patch in the night look.)
          const std::size_t im = std::size_t(ym) * w + x;
          const bool sky_m = sky_like(im);
          const bool band = ym >= band_top[std::size_t(x)] && ym <= band_bottom[std::size_t(x)];
          if (!sky_m && !band) continue;
          const float* a = photo->pixel(x, y);
          const float* b = photo->pixel(x, ym);
          const float la = 0.2126f * a[0] + 0.7152f * a[1] + 0.0722f * a[2];
          const float lb = 0.2126f * b[0] + 0.7152f * b[1] + 0.0722f * b[2];
          const float dl = std::abs(la - lb) / std::max({la, lb, 1e-6f});
          mirrors.at<float>(y, x) = std::clamp(1.0f - dl / kMirrorLumaTolerance, 0.0f, 1.0f);
          if (options.far_shore && mask.sky[im])
            sky_mirrors.at<float>(y, x) = mirrors.at<float>(y, x);
        }
      const cv::Size mirror_box(std::max(3, w / 40) | 1, std::max(3, h / 80) | 1);
      cv::blur(mirrors, mirrors, mirror_box);
      if (options.far_shore) cv::blur(sky_mirrors, sky_mirrors, mirror_box);
      std::vector<float> band_weight(std::size_t(w), 0.0f);
      std::vector<int> band_reflection(std::size_t(w), -1);  // the reflection's last row
      for (int x = 0; x < w; ++x) {
        const int top = band_top[std::size_t(x)];
        if (top < 0) continue;
        // The reflection: the band's top mirrored about the waterline (2 axis - 1 - top), and
        // a line's width more for the blur of the water's ripples.
        const int axis = waterline[std::size_t(x)];
        const int reflection = std::max(band_foot[std::size_t(x)], 2 * axis - 1 - top + line_px);
        band_reflection[std::size_t(x)] = reflection;
        // The mirror test: the water under the waterline mirrors the band's outline (its
        // colour and texture correlated, mirror_correlation).
        const float mirror = band_mirror[std::size_t(x)];
        // (The water in front is not tested against the sky's brightness as well: sea11's
        // luma test passed a dark field under a dark storm sky, storm_pano, and held calm
        // water mirroring a glow at half weight, summer_1am; the band's mirror is the test.)
        band_weight[std::size_t(x)] = mirror;
      }
      // Each column's band weight (band_near) and how much of the water's sea bound it phases
      // in (band_beside). Under a plainly mirrored band (the mean mirror weight over the reach
      // on the band's better side near 1: a band's last column has the band on one side only),
      // where the band ends (a point, a gap) the photo has the band's edge: both sides of it
      // take the band's rule at full weight (a weight of 1 bounds the reflection's distance by
      // the band's, whatever the refinement made of it), columns beside it take the nearest band
      // column's rows fading over twice the box's reach (a smoothstep), and the band's own
      // columns get the open water's bound first as the columns beside them do, so that the
      // return to the open water's rule happens beside the band, across water the photo shows
      // as one surface. (A box smoothed across the end gave both sides half weight, where the
      // refined distances differ by the reflection's edge: the water stepped from kilometres
      // to tens of metres at the band's last column, summer_1am's vertical seam in dense fog
      // and pale block in the night look.) A weak band (a jetty's end the mirror test half
      // passes, a column or two of rocket's horizon) keeps the box-smoothed weight on its own
      // columns and nothing beside them: its weight fluctuates from column to column, and at
      // full weight each fluctuation became a streak of far water in the jetty.
      const std::vector<float> band_smooth = box_across_columns(band_weight);
      std::vector<int> nearest_band(std::size_t(w), -1);
      for (int x = 0, last = -1; x < w; ++x) {
        if (band_top[std::size_t(x)] >= 0) last = x;
        nearest_band[std::size_t(x)] = last;
      }
      for (int x = w - 1, next = -1; x >= 0; --x) {
        if (band_top[std::size_t(x)] >= 0) next = x;
        const int prev = nearest_band[std::size_t(x)];
        if (next >= 0 && (prev < 0 || next - x < x - prev)) nearest_band[std::size_t(x)] = next;
      }
      constexpr float kPlainBandLow = 0.5f, kPlainBand = 0.9f;  // the mean mirror weight
      std::vector<float> band_near(std::size_t(w), 0.0f), band_beside = band_smooth,
                                                          band_plain(std::size_t(w), 0.0f);
      {
        const std::vector<float> prefix = column_prefix(band_weight);
        auto smoothstep = [](double t) {
          t = std::clamp(t, 0.0, 1.0);
          return float(t * t * (3 - 2 * t));
        };
        for (int x = 0; x < w; ++x) {
          const int xb = nearest_band[std::size_t(x)];
          if (xb < 0) continue;
          const float extent = std::max(column_mean(prefix, xb - reach, xb + 1),
                                        column_mean(prefix, xb, xb + reach + 1));
          const float plain = smoothstep((extent - kPlainBandLow) / (kPlainBand - kPlainBandLow));
          band_plain[std::size_t(x)] = plain;
          const float smoothed =
              x == xb ? std::min(band_weight[std::size_t(x)], band_smooth[std::size_t(x)]) : 0.0f;
          const float full = x == xb ? std::min(band_weight[std::size_t(x)], extent)
                                     : extent * smoothstep(1 - std::abs(x - xb) / (2.0 * reach));
          band_near[std::size_t(x)] = smoothed + plain * (full - smoothed);
          band_beside[std::size_t(x)] +=
              plain * (band_near[std::size_t(x)] - band_smooth[std::size_t(x)]);
        }
      }
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
          const std::size_t i = std::size_t(y) * w + x;
          // (A band's own columns only under a plain band: see band_near.)
          const float on_band = band_top[std::size_t(x)] >= 0 ? band_plain[std::size_t(x)] : 1.0f;
          if (pixel_class[i] != int(photo::Coverage::ground) || ground_ratio[i] > 0 || blended[i] ||
              !(on_band > 0))
            continue;
          const float weight = on_band * open[std::size_t(x)] * mirrors.at<float>(y, x);
          // Near a far shore's columns the same water continues under the horizon: the band
          // weight phases in their bound there (the confidence squared, blended in log inverse
          // distance), so that where a band ends its water's fog does not step from one bound
          // to the other. 0 away from bands: as sea11.
          const float beside = on_band * band_beside[std::size_t(x)];
          const float bound = c[i] * q_plane[i] * std::pow(c[i], beside);
          const float q_before = q[i];
          if (q[i] > bound) q[i] = (1 - weight) * q[i] + weight * bound;
          if (beside > 0 && q[i] > bound)
            q[i] = bound > 0 ? q[i] * std::pow(bound / q[i], beside) : (1 - beside) * q[i];
          if (q[i] != q_before) sea_bounded[i] = 1;
        }
      // The band itself: as far as the horizon where the water at its foot mirrors it (the
      // water's bound there is a few kilometres), no nearer than the sea's geometric horizon
      // seen from the camera's height, sqrt(2 R h) (4.5 km from 1.6 m; a shore farther than
      // that shows its foot hidden behind the sea's curve, still on the horizon). Below it, its
      // foot, its reflection and the water in front get the open water's bound (the plane's
      // inverse distance times the ground's confidence, meeting the band's at the horizon).
      // Blended in log inverse distance: the band's refined distance is tens of metres, and a
      // linear blend at 90 % weight would leave it within a tenth of that, clear in haze.
      constexpr double kEarthRadiusM = 6.371e6;
      const float q_far = float(1.0 / std::sqrt(2 * kEarthRadiusM * height));
      // Per column: how plainly the water in front mirrors the band and the sky (band_near:
      // the band's own columns and, fading, those beside it, which take the nearest band
      // column's rows), so that where a band ends (a taller structure, a gap) its distance
      // returns gradually, not in a vertical seam.
      for (int x = 0; x < w; ++x) {
        const bool own_band = band_top[std::size_t(x)] >= 0;
        const int xb = nearest_band[std::size_t(x)];
        if (xb < 0) continue;
        const int top = band_top[std::size_t(xb)], bottom = band_bottom[std::size_t(xb)];
        const int axis = waterline[std::size_t(xb)], mirrored_top = 2 * axis - 1 - top;
        const int reflection = band_reflection[std::size_t(xb)];
        const float mirror = band_near[std::size_t(x)];
        if (!(mirror > 0)) continue;
        // The return below the reflection ends by the row where the ground's confidence reaches
        // 1 (2x the billboard's depression), from which the plane is kept as it is: ending
        // later, beside whatever stands in the water there and keeps its own distance (reeds,
        // posts), it left the water between them far and them near, a speckle of pale blocks
        // (summer_1am's reeds in the night look), and cut off along that row, a straight step.
        int full_row = reflection + 1;
        while (full_row < h && std::asin(std::clamp(-g.pose.ray_direction(camera, x, full_row).y,
                                                    -1.0, 1.0)) < 2 * depression * kDeg)
          ++full_row;
        const int return_rows =
            std::max(1, std::min(2 * (reflection - bottom), full_row - reflection));
        for (int y = top; y < h; ++y) {
          const std::size_t i = std::size_t(y) * w + x;
          const int cls = pixel_class[i];
          // Beside the band only its water (the ground below the horizon, a contact at the far
          // billboard's distance): what stands there (a tower's steel and the far billboard
          // seen through it) is no band and keeps its distance.
          if (!own_band &&
              (y <= bottom || !(cls == int(photo::Coverage::ground) ||
                                (cls == kContact && contact_forward[i] >= 0.99f * far_forward))))
            continue;
          float bound = q_far, weight = mirror;
          if (y > bottom && cls != kFar) {  // (the far billboard ends at the pixel's centre)
            if (!(cls == int(photo::Coverage::ground) ||
                  (cls == kContact && contact_forward[i] >= 0.99f * far_forward)))
              continue;
            const double down = -g.pose.ray_direction(camera, x, y).y;
            const double below = std::asin(std::clamp(down, -1.0, 1.0));
            const double conf = std::clamp(below / (2 * depression * kDeg), 0.0, 1.0);
            const float water_bound = float(conf * conf * std::max(0.0, down) / height);
            if (y < axis) {
              // Above the waterline: the band itself (below a horizon found too high).
            } else if (y <= mirrored_top) {
              // The band's reflection: along the mirrored ray (camera to water to shore) it is
              // as far as the band, and no nearer than the open water's bound.
              bound = std::min(q_far, water_bound);
            } else {
              // Below it the water mirrors the sky and has the open water's bound (sea11: the
              // plane's inverse distance times the ground's confidence), hundreds of metres a
              // band's height below a tall band. The reflection's lower edge is blurred by the
              // water's ripples and is a faint line in the photo: the distance returns from the
              // band's to the water's bound over twice as many rows as the band is tall (blended
              // in log inverse distance; at most down to full_row), with the band's mirror
              // weight, not in a step.
              const float fade =
                  std::clamp(1.0f - float(y - reflection) / float(return_rows), 0.0f, 1.0f);
              const float reflected = std::min(q_far, water_bound);
              bound =
                  water_bound > 0 ? water_bound * std::pow(reflected / water_bound, fade) : 0.0f;
              weight = open[std::size_t(x)] *
                       std::max(std::min(mirror, sky_mirrors.at<float>(y, x)), mirror * fade);
            }
          }
          if (q[i] > bound) {
            const float q_before = q[i];
            q[i] = bound > 0 ? q[i] * std::pow(bound / q[i], weight) : (1 - weight) * q[i];
            if (q[i] != q_before) sea_bounded[i] = 1;
          }
        }
      }
    }
  }
  // Issue 11 item 4: a surface that meets the sky where the photo shows no edge (a calm sea
  // under a hazy sky, a hill fading into it) goes to the sky's distance there, so that the fog,
  // opaque in the sky, is continuous across the boundary (photo/geometry.h, sky_fold).
  for (std::size_t i = 0; i < fold.size(); ++i) q[i] *= fold[i];
  // Farther than this a surface is as good as sky for any fog that is not almost clear air.
  constexpr float kMaxFiniteDistanceM = 1e5f;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      g.depth_confidence.at(x, y, 0) = c[i];
      float& d = g.distance_m.at(x, y, 0);
      if (!std::isfinite(d)) continue;  // sky stays sky
      if (!kept_distance.empty() && kept_distance[i] > 0) {
        // Its own distance whatever a bound of the water or the sky did around it; on the sky's
        // blurred edge (hair) as the matte asks (above).
        d = kept_distance[i] / std::max(1e-3f, 1.0f - 2.0f * mask.alpha[i]);
        continue;
      }
      const bool refined = options.refine_depth && photo::refine_keep_weight(c[i]) < 1.0f;
      const bool folded = !fold.empty() && fold[i] < 1.0f;
      if (!refined && !blended[i] && !folded && !smooth_bounded && !sea_bounded[i])
        continue;  // kept exactly
      d = std::min(kMaxFiniteDistanceM, q[i] > 0 ? 1.0f / q[i] : kMaxFiniteDistanceM);
    }
  // Full-size maps read for the last time above, released: the cloud test below is the
  // estimate's peak on a large photo (24 MP: 2.3 GB in use).
  const auto release = [](auto& map) { std::decay_t<decltype(map)>().swap(map); };
  release(fold), release(contact_forward), release(ground_ratio), release(blended);
  release(sea_bounded), release(subject), release(kept_distance);
  // Issue 11 (sun bank): the fragments of clouds the sky mask left out, held up by nothing and
  // joined to the sky by the refinement, are sky: not floating occluders (photo/clouds.h).
  if (options.refine_depth && mask.pixels > 0) {
    std::vector<float> ratio(n);
    std::vector<std::uint8_t> above(n), standing(n);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const std::size_t i = std::size_t(y) * w + x;
        ratio[i] = g.distance_m.at(x, y, 0) / billboard(x, y, far_forward);
        above[i] = y < horizon_y(x);
        standing[i] = pixel_class[i] == kContact;
      }
    // Under a guessed horizon no ground was seen: a cumulus cut off by the frame's bottom in an
    // all-sky frame (the guess lowered below it) stood on the frame as a surface (photo/clouds.h).
    photo::FloatingCloudOptions cloud_options;
    cloud_options.guessed_horizon = !annotations.horizon && g.confidence < kWeakHorizonConfidence;
    cloud_options.bank = cloud_bank;
    const std::vector<std::uint8_t> cloud = photo::floating_clouds(
        photo->view(), ratio, above, vegetation.vegetation, standing, cloud_options);
    // photo/sky_matte.h mixes the fog of each pixel of the sky's blurred band with that of the
    // nearest all-surface pixel (alpha 0); where that was the cloud's, it would now be some
    // surface far away (a dark ghost of the cloud's band in the sun bank): that band is sky.
    std::vector<std::uint8_t> was_surface(n);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        was_surface[std::size_t(y) * w + x] = g.sky_alpha.at(x, y, 0) <= 0.0f;
    std::size_t made_sky = 0;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const std::size_t i = std::size_t(y) * w + x;
        if (!cloud[i]) continue;
        g.distance_m.at(x, y, 0) = std::numeric_limits<float>::infinity();
        g.sky_alpha.at(x, y, 0) = 1.0f;
        g.depth_confidence.at(x, y, 0) = 1.0f;
        ++made_sky;
        // Only structures are above the horizon without an annotation: the far billboard's
        // pixels and those standing where they meet the ground.
        const int cls = pixel_class[i];
        std::size_t* from = cls == kFar       ? &g.billboard_pixels
                            : cls == kContact ? &g.contact_pixels
                            : cls == kPerson  ? &g.people_pixels
                                              : nullptr;
        if (from && *from > 0) --*from, ++g.sky_pixels;
      }
    if (made_sky > 0) {
      const std::vector<std::int32_t> nearest = photo::nearest_source(w, h, was_surface);
      for (int y = 0; y < h && !nearest.empty(); ++y)
        for (int x = 0; x < w; ++x) {
          const std::size_t i = std::size_t(y) * w + x;
          float& a = g.sky_alpha.at(x, y, 0);
          if (a > 0 && a < 1 && !std::isfinite(g.distance_m.at(x, y, 0)) && nearest[i] >= 0 &&
              cloud[std::size_t(nearest[i])])
            a = 1.0f;
        }
    }
  }
  // Issue 11 (after_the_rain): backlit land recedes to its skyline, as far hills do in a
  // silhouette (photo/horizon.h, receding_skyline). Under the refinement the black land, which
  // has no edge inside, took one distance of about 25 m up to its skyline: clear and black
  // under the haze's veil right above it (0.035 % created edges where a dark cloud sat on the
  // skyline); the ground plane itself veils the land along the straight horizon row instead
  // (0.16 %). Each column's land is the ground of a horizon kBacklitSkylineDepressionDeg above
  // its smoothed skyline, so the veil follows the skyline's shape.
  if (g.backlit_land) {
    constexpr double kBacklitSkylineDepressionDeg = 0.5;
    const double offset_px = camera.focal_px * std::tan(kBacklitSkylineDepressionDeg * kDeg);
    const std::vector<double> skyline = photo::receding_skyline(backlit.column_skyline);
    for (int y = 0; y < h && skyline.size() == std::size_t(w); ++y)
      for (int x = 0; x < w; ++x) {
        float& d = g.distance_m.at(x, y, 0);
        // The land and what it encloses (a lit window), not the sky found above it.
        if (backlit.sky_alpha[std::size_t(y) * w + x] > 0 || !std::isfinite(d)) continue;
        const double below = std::max(1.0, y + 0.5 - skyline[std::size_t(x)] + offset_px);
        d = billboard(x, y, height * camera.focal_px / below);
      }
  }
  // Issue 11 (a scanned print's dark top edge): the frame's border is not the scene
  // (photo/frame_border.h; the sky mask was found inside it). It is veiled as the farthest of
  // the picture's edge pixels beside it (within 2 % of the frame along the edge), so that the
  // print is veiled alike and a strip down a side does not flicker between a near person's
  // distance and the far land behind. (As sky, distance +inf, the border lent its darkness to
  // the sky's matte under it: a dark line in haze.)
  if (const photo::FrameBorder border =
          options.frame_border ? photo::find_frame_border(photo->view()) : photo::FrameBorder{};
      border.any()) {
    const Rect r = border.inside(w, h);
    const int reach = std::max(1, int(0.02 * std::max(w, h)));
    for (int y = 0; y < h && r.width > 0 && r.height > 0; ++y)
      for (int x = 0; x < w; ++x) {
        if (!border.contains(x, y, w, h)) continue;
        const int sx = std::clamp(x, r.x, r.x + r.width - 1);
        const int sy = std::clamp(y, r.y, r.y + r.height - 1);
        // Along the edge the border pixel faces: rows for a side strip, columns for a band.
        const bool side = sx != x && sy == y;
        int bx = sx, by = sy;
        for (int t = -reach; t <= reach; ++t) {
          const int cx = side ? sx : std::clamp(sx + t, r.x, r.x + r.width - 1);
          const int cy = side ? std::clamp(sy + t, r.y, r.y + r.height - 1) : sy;
          if (!(g.distance_m.at(cx, cy, 0) <= g.distance_m.at(bx, by, 0))) bx = cx, by = cy;
        }
        g.distance_m.at(x, y, 0) = g.distance_m.at(bx, by, 0);
        g.sky_alpha.at(x, y, 0) = g.sky_alpha.at(bx, by, 0);
        g.depth_confidence.at(x, y, 0) = g.depth_confidence.at(bx, by, 0);
        ++g.frame_border_pixels;
      }
  }
  return g;
}

}  // namespace

GeometryEstimate estimate_geometry(const Camera& camera, const Annotations& annotations,
                                   const EstimateOptions& options) {
  Steps steps(options.cancel, kGeometrySteps);
  GeometryEstimate g = geometry(nullptr, camera, annotations, options, steps);
  steps.finish();
  return g;
}

GeometryEstimate estimate_geometry(const Image& photo, const Camera& camera,
                                   const Annotations& annotations, const EstimateOptions& options) {
  Steps steps(options.cancel, kGeometrySteps);
  GeometryEstimate g = geometry(&photo, camera, annotations, options, steps);
  steps.finish();
  return g;
}

SceneEstimate estimate_scene(const Image& photo, const Camera& camera,
                             const Annotations& annotations, const EstimateOptions& options) {
  check_camera(camera);
  if (photo.width() != camera.width || photo.height() != camera.height)
    throw Error(ErrorCode::size_mismatch, "estimate: photo is " + std::to_string(photo.width()) +
                                              "x" + std::to_string(photo.height()) +
                                              ", camera is " + std::to_string(camera.width) + "x" +
                                              std::to_string(camera.height));
  if (photo.channels() < 3)
    throw Error(ErrorCode::invalid_argument, "estimate: the photo has " +
                                                 std::to_string(photo.channels()) +
                                                 " channel(s); RGB is needed");
  SceneEstimate est;
  Steps steps(options.cancel, kGeometrySteps + 1);
  est.geometry = geometry(&photo, camera, annotations, options, steps);
  steps.start("light");  // the sun, the sky, the lamps
  const GeometryEstimate& g = est.geometry;
  est.scene.pose = g.pose;
  // The scene records the camera it was estimated with (a focal length from vanishing points
  // would otherwise be lost when the scene is reused: mr fog --scene, mr-studio projects).
  est.scene.camera = scene_camera(camera);
  const std::string horizon_how =
      g.horizon_source == EstimateSource::annotations ? "annotated"
      : g.horizon_source == EstimateSource::horizontal_vps
          ? "automatic, through two horizontal vanishing points"
      : g.horizon_source == EstimateSource::horizontal_vp_and_zenith
          ? "automatic, from a horizontal and the vertical vanishing point"
      : g.horizon_source == EstimateSource::zenith ? "automatic, from the vertical vanishing point"
      : g.horizon_source == EstimateSource::horizontal_vp_level
          ? "automatic, level through a horizontal vanishing point"
      : options.automatic && std::isfinite(g.horizon_rejected_roll_deg)
          ? "not annotated; the lines' horizon (roll " + fmt("%.1f", g.horizon_rejected_roll_deg) +
                " deg) is not a photo's, they are not verticals or level; assumed level through "
                "the image centre"
      : options.automatic ? "not annotated, no usable lines; assumed level through the image centre"
                          : "not annotated; assumed level through the image centre";
  est.notes.push_back(
      std::string("horizon: ") + horizon_how + " (" + to_string(g.horizon_source) + ")" +
      (g.horizon_raised_px > 0
           ? ", raised " + fmt("%.0f", g.horizon_raised_px) + " px to the sky's level line"
           : "") +
      (g.horizon_lowered_px > 0 ? ", lowered " + fmt("%.0f", g.horizon_lowered_px) +
                                      (g.backlit_land       ? " px to the backlit land's skyline"
                                       : g.lowered_to_water ? " px to the water's mirror line"
                                                            : " px to below the sky it cut")
                                : std::string()) +
      (g.lamps_not_sky ? "; the frame, all sky-like, holds lamps: a ceiling, no sky"
                       : std::string()) +
      (g.wall_not_sky_pixels > 0
           ? "; " +
                 fmt("%.1f",
                     100.0 * double(g.wall_not_sky_pixels) / double(g.distance_m.pixels().size())) +
                 " % of the frame, sky-like, goes on far below it: a wall, not sky"
           : std::string()) +
      (g.little_sky_dropped_pixels > 0
           ? "; " +
                 fmt("%.1f", 100.0 * double(g.little_sky_dropped_pixels) /
                                 double(g.distance_m.pixels().size())) +
                 " % of the frame, sky-like, is a little patch without a clear sky's colour or "
                 "an open top: not sky"
           : std::string()) +
      ", pitch " + fmt("%.2f", g.pose.pitch_deg) + " deg, roll " + fmt("%.2f", g.pose.roll_deg) +
      " deg, confidence " + fmt("%.2f", g.confidence));
  est.notes.push_back(std::string("camera height: ") + fmt("%.3f", g.pose.position_m.y) + " m (" +
                      (g.height_source == EstimateSource::annotations    ? "annotated"
                       : g.height_source == EstimateSource::known_length ? "from the known length"
                       : g.height_source == EstimateSource::interior_box
                           ? "from the interior box's ceiling height and ceiling point"
                       : g.scale_cue.empty() ? "default"
                                             : "default, scaled: " + g.scale_cue) +
                      ")");
  if (g.defocused_fraction > 0 || g.sharp_fraction > 0)
    est.notes.push_back("focus: " + fmt("%.0f", 100 * g.defocused_fraction) +
                        " % of the frame (sky left out) strongly out of focus, " +
                        fmt("%.0f", 100 * g.sharp_fraction) + " % sharp");
  const double n = double(photo.width()) * photo.height();
  est.notes.push_back(
      "depth: " + fmt("%.1f", 100.0 * g.ground_pixels / n) + " % ground, " +
      fmt("%.1f", 100.0 * g.plane_pixels / n) + " % planes, " +
      fmt("%.1f", 100.0 * g.hint_pixels / n) + " % hints, " +
      (g.room_pixels ? fmt("%.1f", 100.0 * g.room_pixels / n) + " % interior box" +
                           (g.room_ceiling_height_m
                                ? " (ceiling " + fmt("%.2f", *g.room_ceiling_height_m) + " m)"
                                : std::string(" (no ceiling)")) +
                           ", "
                     : std::string()) +
      fmt("%.1f", 100.0 * g.sky_pixels / n) + " % sky" +
      (g.sky_from_mask
           ? " (automatic sky mask), " + fmt("%.1f", 100.0 * g.contact_pixels / n) +
                 " % structures standing where they meet the ground, " +
                 (g.people_pixels ? fmt("%.1f", 100.0 * g.people_pixels / n) +
                                        " % people (by their faces or figures), "
                                  : std::string()) +
                 (g.frame_border_pixels ? fmt("%.1f", 100.0 * g.frame_border_pixels / n) +
                                              " % the frame's border (as the picture's edge), "
                                        : std::string()) +
                 fmt("%.1f", 100.0 * g.billboard_pixels / n) + " % far billboard at " +
                 fmt("%.0f",
                     g.pose.position_m.y / std::tan(options.billboard_depression_deg * kDeg)) +
                 " m"
           : std::string()));

  if (!annotations.shadow_pairs.empty()) {
    std::vector<photo::ShadowPair> pairs;
    for (const auto& p : annotations.shadow_pairs)
      pairs.push_back({p.caster_top, p.caster_foot, p.shadow_tip});
    photo::SunFit fit;
    try {
      fit = photo::fit_sun_direction(pairs, camera, g.pose);
    } catch (const Error& e) {
      throw Error(e.code(), std::string("/shadow_pairs: ") + e.what());
    }
    SunEstimate sun;
    sun.direction_to_sun = fit.direction_to_sun;
    sun.azimuth_deg = fit.azimuth_deg;
    sun.elevation_deg = fit.elevation_deg;
    sun.rms_residual_deg = fit.rms_residual_deg;
    sun.median_residual_px = fit.median_residual_px;
    est.sun = sun;
    Sun s;
    s.direction_to_sun = fit.direction_to_sun;
    est.notes.push_back("sun: from " + std::to_string(pairs.size()) + " shadow pair(s), azimuth " +
                        fmt("%.1f", fit.azimuth_deg) + " deg, elevation " +
                        fmt("%.1f", fit.elevation_deg) + " deg, residual " +
                        fmt("%.2f", fit.rms_residual_deg) + " deg RMS, " +
                        fmt("%.2f", fit.median_residual_px) + " px median");
    if (!annotations.sunlit_patch.empty()) {
      photo::SunSkyPatches patches;
      try {
        patches.lit = photo::PatchStats::from_pixels(pixels_in(photo, annotations.sunlit_patch));
      } catch (const Error& e) {
        throw Error(e.code(), std::string("/sunlit_patch: ") + e.what());
      }
      try {
        patches.shadowed =
            photo::PatchStats::from_pixels(pixels_in(photo, annotations.shadowed_patch));
      } catch (const Error& e) {
        throw Error(e.code(), std::string("/shadowed_patch: ") + e.what());
      }
      patches.direction_to_sun = fit.direction_to_sun;
      photo::SunSkyRatio ratio;
      try {
        ratio = photo::fit_sun_sky_ratio(patches);
      } catch (const Error& e) {
        throw Error(e.code(), std::string("/sunlit_patch, /shadowed_patch: ") + e.what());
      }
      const std::array<float, 3> sky = photo::estimate_airlight_dark_channel(photo.view());
      est.scene.lighting.sky_radiance = Rgb{sky[0], sky[1], sky[2]};
      for (int c = 0; c < 3; ++c)
        s.irradiance[c] = float(ratio.ratio_rgb[c] * std::numbers::pi * sky[c]);
      est.notes.push_back("sun/sky: E_sun / (pi L_sky) = " + fmt("%.2f", ratio.ratio) + " +- " +
                          fmt("%.2f", ratio.ratio_sigma) +
                          "; sky radiance from the photo (dark channel prior)");
    } else {
      // No patches: the sun's strength from the photo's exposure (issue 11 item 5) rather
      // than a fixed default that ignores it.
      const std::array<float, 3> sky = photo::estimate_airlight_dark_channel(photo.view());
      const photo::ExposureRelativeSun e =
          photo::exposure_relative_sun(photo.view(), g.distance_m.view(), sky);
      s.irradiance = Rgb{e.irradiance[0], e.irradiance[1], e.irradiance[2]};
      est.notes.push_back("sun: irradiance " + fmt("%.3g", e.irradiance[0]) +
                          " from the exposure (pi x the bright-surface luminance " +
                          fmt("%.3g", e.bright_surface_luminance) + ", sun/sky ratio " +
                          fmt("%.2g", e.sun_sky_ratio) + ")");
    }
    est.scene.lighting.sun = s;
  } else {
    est.notes.push_back("sun: no shadow pairs; sky light only (overcast)");
    // Overcast fall-back (issue 4 item 5): the sky light is what the sky pixels show.
    const std::size_t min_sky = std::max<std::size_t>(
        kMinOvercastSkyPixels, std::size_t(std::ceil(kMinOvercastSkyFraction * n)));
    if (g.sky_from_mask && g.sky_pixels >= min_sky) {
      const Rgb sky = median_sky_radiance(photo, g.distance_m);
      est.scene.lighting.sky_radiance = sky;
      est.notes.push_back("sky: radiance from " + std::to_string(g.sky_pixels) +
                          " sky pixels (overcast), median " + fmt("%.4g", sky[0]) + " " +
                          fmt("%.4g", sky[1]) + " " + fmt("%.4g", sky[2]));
    } else {
      est.notes.push_back(std::string("sky: ") +
                          (g.sky_from_mask
                               ? "only " + std::to_string(g.sky_pixels) +
                                     " sky pixels (fewer than " + std::to_string(min_sky) + ")"
                               : std::string("no automatic sky mask")) +
                          "; radiance left to mr fog (dark channel prior)");
    }
  }

  if (!annotations.lamps.empty()) {
    // Interior lamps (issue 4 item 5): lifted with the distance map, intensities fitted to the
    // shading of the lamp patches (photo/lamps.h states the model).
    std::vector<photo::LampMark> marks;
    for (const auto& l : annotations.lamps) marks.push_back({l.pixel, l.offset_m, l.color});
    std::vector<photo::LampPatch> patches;
    for (const auto& p : annotations.lamp_patches) {
      photo::LampPatch patch;
      patch.polygon = p.polygon;
      if (p.albedo) patch.albedo = *p.albedo;
      patches.push_back(std::move(patch));
    }
    photo::LampFit fit;
    try {
      fit = photo::fit_lamps(photo, g.distance_m, camera, g.pose, marks, patches);
    } catch (const Error& e) {
      throw Error(e.code(), std::string("/lamps, /lamp_patches: ") + e.what());
    }
    for (std::size_t i = 0; i < marks.size(); ++i) {
      Lamp lamp;
      lamp.position_m = fit.positions_m[i];
      const auto& I = fit.intensity_per_sr[i];
      lamp.intensity_per_sr = Rgb{float(I[0]), float(I[1]), float(I[2])};
      est.scene.lighting.lamps.push_back(lamp);
      const Vec3& q = fit.positions_m[i];
      est.notes.push_back("lamp " + std::to_string(i) + ": at (" + fmt("%.2f", q.x) + ", " +
                          fmt("%.2f", q.y) + ", " + fmt("%.2f", q.z) + ") m, intensity " +
                          fmt("%.4g", I[0]) + " " + fmt("%.4g", I[1]) + " " + fmt("%.4g", I[2]) +
                          " per sr");
    }
    est.notes.push_back(
        "lamps: " + std::to_string(marks.size()) + " lamp(s) fitted to " +
        std::to_string(fit.pixels_used) + " pixels of " + std::to_string(patches.size()) +
        " patch(es), residual " + fmt("%.1f", 100 * fit.rms_residual) + " % RMS, " +
        fmt("%.1f", 100 * fit.median_abs_residual) + " % median (of the median patch radiance)" +
        (fit.converged ? "" : "; Ceres did not report convergence"));
  }
  // What the annotations say the photo does not show (off-frame walls, a skyline, a canopy;
  // validated with the annotations) goes into the scene as stated.
  if (annotations.blockers) {
    const Blockers& b = *annotations.blockers;
    est.scene.blockers = b;
    std::string what;
    auto add = [&](const std::string& s) { what += (what.empty() ? "" : ", ") + s; };
    if (b.skyline) add("a skyline of " + std::to_string(b.skyline->samples.size()) + " points");
    if (!b.polygons.empty()) add(std::to_string(b.polygons.size()) + " polygon(s)");
    if (b.canopy) add("a canopy");
    add(std::string("completion of structures cut by the frame ") +
        (b.completion.enabled ? "on" : "off"));
    est.notes.push_back("blockers: annotated (" + what + ")");
  }
  steps.finish();
  return est;
}

double default_layer_top_m(const Medium& medium) {
  const double sigma =
      (double(medium.sigma_t_per_m[0]) + medium.sigma_t_per_m[1] + medium.sigma_t_per_m[2]) / 3;
  if (!(sigma > 0) || !std::isfinite(sigma))
    throw Error(ErrorCode::invalid_argument,
                "default_layer_top_m: medium.sigma_t_per_m must be positive, found a mean of " +
                    fmt("%g", sigma));
  const double visibility_m = visibility_from_extinction(sigma);
  return std::clamp(0.5 * visibility_m, 30.0, 2000.0);
}

PhotoCamera camera_for_photo(const Image& photo, double fallback_fov_deg) {
  if (photo.width() <= 0 || photo.height() <= 0)
    throw Error(ErrorCode::invalid_argument, "camera_for_photo: empty photo");
  PhotoCamera out;
  out.camera = Camera::from_horizontal_fov(photo.width(), photo.height(), fallback_fov_deg);
  out.source = "default";
  auto f35 = photo.metadata().get_number("Exif:FocalLengthIn35mmFilm");
  if (!f35) f35 = photo.metadata().get_number("Exif:FocalLengthIn35mmFormat");
  if (f35 && *f35 > 0) {
    out.camera =
        Camera::from_metadata(photo.width(), photo.height(), photo.metadata(), fallback_fov_deg);
    out.source = "exif";
    out.confidence = 1;
    return out;
  }
  if (const auto f = photo::estimate_focal_px(photo.view(), out.camera)) {
    out.camera = Camera::from_focal_px(photo.width(), photo.height(), f->focal_px);
    out.source = "vanishing points";
    out.confidence = f->confidence;
  }
  return out;
}

Image render_estimate_overlay(const Image& photo, const SceneEstimate& estimate,
                              const Annotations& annotations) {
  const GeometryEstimate& g = estimate.geometry;
  const int w = photo.width(), h = photo.height();
  if (photo.channels() < 3)
    throw Error(ErrorCode::invalid_argument, "overlay: the photo needs RGB channels");
  if (g.distance_m.width() != w || g.distance_m.height() != h)
    throw Error(ErrorCode::size_mismatch,
                "overlay: the estimate's distance map is " + std::to_string(g.distance_m.width()) +
                    "x" + std::to_string(g.distance_m.height()) + ", the photo " +
                    std::to_string(w) + "x" + std::to_string(h));
  Image out(w, h, 3);
  // Log-distance colour map over the finite range.
  float dmin = std::numeric_limits<float>::infinity(), dmax = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float d = g.distance_m.at(x, y, 0);
      if (std::isfinite(d) && d > 0) dmin = std::min(dmin, d), dmax = std::max(dmax, d);
    }
  const double l0 = std::log(std::max(1e-3f, dmin)), l1 = std::log(std::max(dmax, dmin * 1.001f));
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const float d = g.distance_m.at(x, y, 0);
      float c[3];
      float mix;
      if (!std::isfinite(d)) {
        c[0] = c[1] = c[2] = 1.25f, mix = 0.6f;  // sky: washed out white, unlike far blue
      } else {
        const double t = std::clamp((std::log(std::max(d, 1e-3f)) - l0) / (l1 - l0), 0.0, 1.0);
        // red -> yellow -> green -> cyan -> blue
        const double hue = 4 * t;
        const int seg = std::min(3, int(hue));
        const float f = float(hue - seg);
        const float ramps[5][3] = {{1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0, 1, 1}, {0, 0, 1}};
        for (int k = 0; k < 3; ++k) c[k] = ramps[seg][k] * (1 - f) + ramps[seg + 1][k] * f;
        mix = 0.5f;
      }
      for (int k = 0; k < 3; ++k) {
        const float p = std::max(0.0f, photo.at(x, y, k));
        out.at(x, y, k) = (1 - mix) * p + mix * c[k] * 0.8f;
      }
    }
  }
  cv::Mat m = detail::as_mat(out.view());
  const int thick = std::max(1, std::min(w, h) / 300);
  constexpr int kShift = 4;  // sub-pixel drawing: coordinates in 1/16 px
  auto pt = [](const PixelPoint& p) {
    return cv::Point(int(std::lround(p[0] * (1 << kShift))),
                     int(std::lround(p[1] * (1 << kShift))));
  };
  auto polygon = [&](const std::vector<PixelPoint>& poly, const cv::Scalar& colour) {
    std::vector<cv::Point> pts;
    for (const auto& p : poly) pts.push_back(pt(p));
    const cv::Point* data = pts.data();
    const int count = int(pts.size());
    cv::polylines(m, &data, &count, 1, true, colour, thick, cv::LINE_AA, kShift);
  };
  for (const auto& p : annotations.planes) polygon(p.polygon, cv::Scalar(1, 0.9, 0));
  for (const auto& p : annotations.distance_hints) polygon(p.polygon, cv::Scalar(0, 0.9, 1));
  if (!annotations.sunlit_patch.empty()) polygon(annotations.sunlit_patch, cv::Scalar(0.2, 1, 0.2));
  if (!annotations.shadowed_patch.empty())
    polygon(annotations.shadowed_patch, cv::Scalar(0, 0.35, 0));
  for (const auto& s : annotations.shadow_pairs) {
    cv::line(m, pt(s.caster_foot), pt(s.caster_top), cv::Scalar(1, 0, 1), thick, cv::LINE_AA,
             kShift);
    cv::line(m, pt(s.caster_top), pt(s.shadow_tip), cv::Scalar(1, 0, 1), thick, cv::LINE_AA,
             kShift);
  }
  for (const auto& p : annotations.lamp_patches) polygon(p.polygon, cv::Scalar(1, 0.5, 0));
  for (const auto& l : annotations.lamps) {
    const int r = std::max(3, std::min(w, h) / 80) << kShift;
    cv::circle(m, pt(l.pixel), r, cv::Scalar(1, 0.6, 0), thick + 1, cv::LINE_AA, kShift);
  }
  for (const auto& e : g.room_edges)
    cv::line(m, pt(e[0]), pt(e[1]), cv::Scalar(1, 1, 1), thick + 1, cv::LINE_AA, kShift);
  if (annotations.interior_box) {
    const int r = std::max(3, std::min(w, h) / 100) << kShift;
    for (const auto& p : annotations.interior_box->floor)
      cv::circle(m, pt(p), r, cv::Scalar(1, 1, 1), thick, cv::LINE_AA, kShift);
    if (annotations.interior_box->ceiling_point)
      cv::circle(m, pt(*annotations.interior_box->ceiling_point), r, cv::Scalar(1, 1, 1), thick,
                 cv::LINE_AA, kShift);
  }
  cv::line(m, pt(g.horizon[0]), pt(g.horizon[1]), cv::Scalar(1, 0, 0), thick + 1, cv::LINE_AA,
           kShift);
  if (estimate.sun) {
    // Compass at the top centre: up = the camera's horizontal forward, right = its right.
    const double az = (estimate.sun->azimuth_deg - g.pose.yaw_deg) * kDeg;
    const double len = std::min(w, h) / 10.0;
    const PixelPoint c{w / 2.0, len * 1.2};
    const PixelPoint tip{c[0] + len * std::sin(az), c[1] - len * std::cos(az)};
    cv::circle(m, pt(c), int(len * (1 << kShift)), cv::Scalar(1, 1, 1), thick, cv::LINE_AA, kShift);
    cv::arrowedLine(m, pt(c), pt(tip), cv::Scalar(1, 0.85, 0.2), thick + 1, cv::LINE_AA, kShift,
                    0.25);
  }
  return out;
}

}  // namespace mr
