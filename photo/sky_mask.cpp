#include "photo/sky_mask.h"

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <vector>

#include "core/cv_bridge.h"
#include "photo/frame_border.h"
#include "photo/opencv_contrib.h"
#include "photo/sky_matte.h"

namespace mr::photo {

namespace {

// Display-referred RGB (CV_32FC3, [0, 1]) of a scene-linear photo with any channel count.
cv::Mat display_rgb(ConstImageView photo) {
  const cv::Mat src = detail::as_mat(photo);
  cv::Mat out(src.rows, src.cols, CV_32FC3);
  const int ch = photo.channels;
  for (int y = 0; y < src.rows; ++y) {
    const float* row = src.ptr<float>(y);
    cv::Vec3f* o = out.ptr<cv::Vec3f>(y);
    for (int x = 0; x < src.cols; ++x) {
      const float* p = row + std::ptrdiff_t(x) * ch;
      for (int c = 0; c < 3; ++c) {
        float v = p[ch >= 3 ? c : 0];
        if (!std::isfinite(v)) v = 0;
        o[x][c] = std::pow(std::clamp(v, 0.0f, 1.0f), 1 / 2.2f);
      }
    }
  }
  return out;
}

// The open sky's colour: mean and inverse covariance of the display-referred RGB of the sky
// pixels (`sky`, working size), and their median luma; not valid with too few of them.
struct SkyColour {
  bool valid = false;
  cv::Vec3d mean{0, 0, 0};
  cv::Matx33d inverse = cv::Matx33d::eye();
  double median_luma = 0;
  double low_luma = 0;  ///< 5th percentile: the sky's darkest part (a deep blue zenith)
};

SkyColour sky_colour(const cv::Mat& small, const cv::Mat& luma, const cv::Mat& sky) {
  SkyColour out;
  const int w = small.cols, h = small.rows;
  std::vector<cv::Vec3d> sky_rgb;
  std::vector<float> sky_luma;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (sky.at<std::uint8_t>(y, x)) {
        const cv::Vec3f& p = small.at<cv::Vec3f>(y, x);
        sky_rgb.emplace_back(p[0], p[1], p[2]);
        sky_luma.push_back(luma.at<float>(y, x));
      }
  if (sky_rgb.size() < std::max<std::size_t>(64, std::size_t(0.005 * w * h))) return out;
  for (const auto& v : sky_rgb) out.mean += v;
  out.mean *= 1.0 / double(sky_rgb.size());
  cv::Matx33d cov = cv::Matx33d::zeros();
  for (const auto& v : sky_rgb) {
    const cv::Vec3d d = v - out.mean;
    cov += d * d.t();
  }
  cov *= 1.0 / double(sky_rgb.size());
  for (int k = 0; k < 3; ++k) cov(k, k) += 0.03 * 0.03;  // a floor: a flat sky is not exact
  out.inverse = cov.inv(cv::DECOMP_CHOLESKY);
  std::nth_element(sky_luma.begin(), sky_luma.begin() + std::ptrdiff_t(sky_luma.size() / 2),
                   sky_luma.end());
  out.median_luma = sky_luma[sky_luma.size() / 2];
  const std::size_t low = std::size_t(0.05 * double(sky_luma.size() - 1));
  std::nth_element(sky_luma.begin(), sky_luma.begin() + std::ptrdiff_t(low), sky_luma.end());
  out.low_luma = sky_luma[low];
  out.valid = true;
  return out;
}

// Issue 11 (snow_birches): snow seen between a birch's branches has the sky's colour and thin
// structure all around it, but it is the ground seen between them and carries the ground's
// texture (snow's grain, its drifts' shading), where the sky seen through foliage or a lattice is
// as smooth as the open sky beside it. Which components (labels 1..m-1 of `labels`, those with
// `candidate`) are: their per-pixel gradient (`pixel_gradient`, working size), away from the
// structure around them (neither sky nor a component: the gradient's blur, sigma 1 px at full
// resolution, spreads a member's edge about 3 px, `s` the working scale), at most `ratio` x the
// open sky's median per-pixel gradient, clamped to [floor, ceiling] (the sky core's limit); the
// median of those pixels, or the smoothest tenth of a component too narrow to have any.
std::vector<std::uint8_t> as_smooth_as_the_sky(const cv::Mat& labels, int m,
                                               const std::vector<std::uint8_t>& candidate,
                                               const cv::Mat& sky, const cv::Mat& pixel_gradient,
                                               double s, double ratio, double floor,
                                               double ceiling) {
  const int w = labels.cols, h = labels.rows;
  std::vector<std::uint8_t> out(std::size_t(m), 0);
  std::vector<float> sky_gradient;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (sky.at<std::uint8_t>(y, x)) sky_gradient.push_back(pixel_gradient.at<float>(y, x));
  if (sky_gradient.empty()) return out;
  const std::size_t mid = sky_gradient.size() / 2;
  std::nth_element(sky_gradient.begin(), sky_gradient.begin() + std::ptrdiff_t(mid),
                   sky_gradient.end());
  const double limit = std::clamp(ratio * sky_gradient[mid], floor, ceiling);
  const int fringe = 1 + int(std::ceil(3.0 * s));
  cv::Mat structure(h, w, CV_8U), near_structure;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      structure.at<std::uint8_t>(y, x) = !sky.at<std::uint8_t>(y, x) && labels.at<int>(y, x) == 0;
  cv::dilate(
      structure, near_structure,
      cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * fringe + 1, 2 * fringe + 1)));
  std::vector<std::vector<float>> inner(static_cast<std::size_t>(m)),
      edge(static_cast<std::size_t>(m));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (const int l = labels.at<int>(y, x); l > 0 && candidate[std::size_t(l)])
        (near_structure.at<std::uint8_t>(y, x) ? edge : inner)[std::size_t(l)].push_back(
            pixel_gradient.at<float>(y, x));
  for (int i = 1; i < m; ++i) {
    const bool narrow = inner[std::size_t(i)].empty();
    std::vector<float>& v = narrow ? edge[std::size_t(i)] : inner[std::size_t(i)];
    if (v.empty()) continue;
    const std::size_t q = narrow ? v.size() / 10 : v.size() / 2;
    std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(q), v.end());
    out[std::size_t(i)] = v[q] <= limit;
  }
  return out;
}

}  // namespace

namespace {

// The mask of a picture without a frame border.
SkyMask sky_mask_of_picture(ConstImageView photo, const std::array<PixelPoint, 2>& horizon,
                            const SkyMaskOptions& o) {
  SkyMask out;
  out.width = photo.width;
  out.height = photo.height;
  out.sky.assign(std::size_t(photo.width) * photo.height, 0);
  out.alpha.assign(out.sky.size(), 0.0f);
  if (photo.width < 4 || photo.height < 4 || photo.channels < 1) return out;
  const double dx = horizon[1][0] - horizon[0][0];
  const double slope = std::abs(dx) > 1e-9 ? (horizon[1][1] - horizon[0][1]) / dx : 0.0;
  // Row of the horizon at column x (full-resolution pixel-centre coordinates).
  auto horizon_y = [&](double x) { return horizon[0][1] + (x - horizon[0][0]) * slope; };

  const cv::Mat full = display_rgb(photo);
  cv::Mat small = full;
  double s = 1;
  const double area = double(photo.width) * photo.height;
  if (area > o.working_pixels) {
    s = std::sqrt(o.working_pixels / area);
    cv::resize(full, small, cv::Size(), s, s, cv::INTER_AREA);
  }
  const int w = small.cols, h = small.rows;
  const double sx = double(w) / photo.width, sy = double(h) / photo.height;
  auto above = [&](int xw, int yw) {  // working pixel centre above the horizon
    const double x = (xw + 0.5) / sx - 0.5, y = (yw + 0.5) / sy - 0.5;
    return y < horizon_y(x);
  };

  cv::Mat luma(h, w, CV_32F);
  for (int y = 0; y < h; ++y) {
    const cv::Vec3f* p = small.ptr<cv::Vec3f>(y);
    float* l = luma.ptr<float>(y);
    for (int x = 0; x < w; ++x) l[x] = 0.2126f * p[x][0] + 0.7152f * p[x][1] + 0.0722f * p[x][2];
  }
  // Texture: mean gradient magnitude (Sobel / 8 = per-pixel difference) over a small window,
  // measured at full resolution (downscaling first would average fine texture such as foliage
  // or noise away) and then area-averaged to the working size.
  cv::Mat full_luma, blurred, gx, gy, texture;
  cv::cvtColor(full, full_luma, cv::COLOR_RGB2GRAY);
  cv::GaussianBlur(full_luma, blurred, cv::Size(0, 0), 1.0);
  cv::Sobel(blurred, gx, CV_32F, 1, 0, 3, 1.0 / 8);
  cv::Sobel(blurred, gy, CV_32F, 0, 1, 3, 1.0 / 8);
  cv::magnitude(gx, gy, texture);
  if (s < 1) cv::resize(texture, texture, cv::Size(w, h), 0, 0, cv::INTER_AREA);
  const int win = std::max(3, int(std::lround(0.006 * std::hypot(w, h))) | 1);
  // Roughness over three windows (for the sky's core, below): the mean gradient magnitude less
  // the magnitude of the mean gradient. A smooth ramp (a cloud's soft edge, the sky's own
  // gradient) has all its gradients in one direction and no roughness; a rock face's or a
  // concrete floor's fine texture points every way and is all roughness.
  cv::Mat roughness;
  {
    const cv::Size wide(3 * win, 3 * win);
    cv::Mat mx = gx, my = gy, mean_x, mean_y, coherent;
    if (s < 1) {
      cv::resize(gx, mx, cv::Size(w, h), 0, 0, cv::INTER_AREA);
      cv::resize(gy, my, cv::Size(w, h), 0, 0, cv::INTER_AREA);
    }
    cv::blur(mx, mean_x, wide);
    cv::blur(my, mean_y, wide);
    cv::magnitude(mean_x, mean_y, coherent);
    cv::blur(texture, roughness, wide);
    roughness = cv::max(roughness - coherent, 0.0);
  }
  // The full-resolution gradients are done with: four float images the rest of the mask (its
  // guided filter and edge tests at full resolution) would otherwise hold beside its own.
  full_luma.release(), blurred.release(), gx.release(), gy.release();
  const cv::Mat pixel_gradient = texture.clone();  // per working pixel, before the window
  cv::blur(texture, texture, cv::Size(win, win));

  // Bright reference: 95th percentile of the luma above the horizon.
  std::vector<float> lum_above;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (above(x, y)) lum_above.push_back(luma.at<float>(y, x));
  if (lum_above.empty()) return out;  // the horizon is above the frame: no sky
  const std::size_t k = std::size_t(0.95 * double(lum_above.size() - 1));
  std::nth_element(lum_above.begin(), lum_above.begin() + k, lum_above.end());
  const float bright_ref = lum_above[k];

  cv::Mat cand(h, w, CV_8U, cv::Scalar(0)), colour(h, w, CV_8U, cv::Scalar(0));
  cv::Mat blueish(h, w, CV_8U, cv::Scalar(0)), dark(h, w, CV_8U, cv::Scalar(0));
  cv::Mat saturation(h, w, CV_32F, cv::Scalar(1));
  for (int y = 0; y < h; ++y) {
    const cv::Vec3f* p = small.ptr<cv::Vec3f>(y);
    for (int x = 0; x < w; ++x) {
      if (!above(x, y)) continue;
      const float r = p[x][0], g = p[x][1], b = p[x][2], l = luma.at<float>(y, x);
      const float mx = std::max({r, g, b}), mn = std::min({r, g, b});
      const float sat = mx > 1e-4f ? (mx - mn) / mx : 0;
      saturation.at<float>(y, x) = sat;
      // A dim, barely bluish grey (shaded foliage, a wall in the shade: luma 0.3, saturation
      // 0.15) is not a blue sky: a clear sky that dim is deep blue (saturated), and one that
      // pale is bright.
      const bool blue = b > r + 0.03f && b >= g - 0.02f && l > 0.2f && (sat >= 0.2f || l >= 0.5f);
      // Twilight and dusk: a deep, strongly saturated blue darker than a day sky (kept only
      // in large components from the top border down, below; dark grey-blue glass is less
      // saturated).
      const bool dusk = !blue && b > r + 0.08f && b > g + 0.04f && sat > 0.45f && l > 0.05f;
      const bool grey_bright = sat < 0.2f && l > 0.35f && l >= o.bright_fraction * bright_ref;
      if (!blue && !dusk && !grey_bright) continue;
      colour.at<std::uint8_t>(y, x) = 1;
      blueish.at<std::uint8_t>(y, x) = blue || dusk;
      dark.at<std::uint8_t>(y, x) = dusk;
      if (texture.at<float>(y, x) <= o.max_texture) cand.at<std::uint8_t>(y, x) = 1;
    }
  }
  // Which candidate components are sky. Blue ones: touching the top border, or (below) a side
  // border or large (blue sky seen between branches) when blue sky touches the top; grey-bright
  // ones: touching the top border and, when the photo shows blue sky, touching it (clouds do; white
  // walls and panels mostly do not), or surrounded by it.
  cv::Mat labels, stats, centroids;
  const int n = cv::connectedComponentsWithStats(cand, labels, stats, centroids, 8, CV_32S);
  std::vector<int> blue_count(std::size_t(n), 0), dark_count(std::size_t(n), 0);
  std::vector<std::uint8_t> top(std::size_t(n), 0), side(std::size_t(n), 0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int lab = labels.at<int>(y, x);
      if (lab == 0) continue;
      blue_count[lab] += blueish.at<std::uint8_t>(y, x);
      dark_count[lab] += dark.at<std::uint8_t>(y, x);
      if (y == 0) top[lab] = 1;
      if (x == 0 || x == w - 1) side[lab] = 1;
    }
  std::vector<std::uint8_t> keep(std::size_t(n), 0), is_blue(std::size_t(n), 0);
  double blue_area = 0;
  for (int i = 1; i < n; ++i) {
    const int area = stats.at<int>(i, cv::CC_STAT_AREA);
    is_blue[i] = 2 * blue_count[i] > area;
    // Mostly dusk blue: only from the top border down (a dark blue wall or car rarely is).
    const bool dusk = 2 * dark_count[i] > area;
    if (is_blue[i] && top[i] && (!dusk || area > 0.01 * w * h)) keep[i] = 1, blue_area += area;
  }
  // Blue not reaching the top border (sky between branches, beside a tree) is sky only when
  // blue sky does reach it: a pale blue flower, sign, shirt or car in a close-up with no sky
  // above it is not. (Its colour is not compared with the top sky's: a clear sky pales by far
  // more than its own spread from the zenith to the horizon.) Nor is a piece of a bluish rock
  // face: its roughness (below), on average over the piece, is that of a textured surface.
  // For a piece at the frame's side, the median: such a piece is a sky cut off from the top by
  // branches or an eave at the frame's edge, and the roughness window reaches over them; their
  // fringe alone pushed a clear sky's mean over the limit (sample_photos/building.jpg: mean
  // 0.0039, median 0.0018; the facade's white panels were then its sky, and once the little-sky
  // rule dropped those, a street became an 8 m room). Inside the frame the mean stays: the gaps
  // and lattice openings there have their own tests after the sky's core (below), which keep an
  // opening whole where this one would then be trimmed by the core test.
  if (!o.detached_needs_top_sky || blue_area > 0) {
    std::vector<double> rough_sum(std::size_t(n), 0.0);
    std::vector<std::vector<float>> side_rough(static_cast<std::size_t>(n));
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        if (const int lab = labels.at<int>(y, x); lab > 0) {
          rough_sum[lab] += roughness.at<float>(y, x);
          if (side[lab] && is_blue[lab] && !keep[lab])
            side_rough[lab].push_back(roughness.at<float>(y, x));
        }
    for (int i = 1; i < n; ++i) {
      const int area = stats.at<int>(i, cv::CC_STAT_AREA);
      if (keep[i] || !is_blue[i] || 2 * dark_count[i] > area) continue;
      if (o.core_texture_factor > 0) {
        double typical = rough_sum[i] / area;
        if (auto& v = side_rough[i]; !v.empty()) {
          std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(v.size() / 2), v.end());
          typical = v[v.size() / 2];
        }
        if (typical > o.min_core_texture) continue;
      }
      if (side[i] || area > 0.002 * w * h) keep[i] = 1, blue_area += area;
    }
  }
  cv::Mat sky(h, w, CV_8U, cv::Scalar(0));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) sky.at<std::uint8_t>(y, x) = keep[labels.at<int>(y, x)];
  const bool blue_sky = blue_area > 0.01 * w * h;
  cv::Mat near_blue;
  cv::dilate(sky, near_blue, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(5, 5)));
  std::vector<std::uint8_t> touches_blue(std::size_t(n), 0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (near_blue.at<std::uint8_t>(y, x)) touches_blue[labels.at<int>(y, x)] = 1;
  // A cloud cut off from the top by its own edge (steeper than `max_texture`) in a blue sky:
  // grey-bright components whose surroundings are almost all blue sky, within two texture windows
  // (the edge band the texture test refused). A white wall or panel stands on something else.
  std::vector<int> ring(std::size_t(n), 0), ring_sky(std::size_t(n), 0);
  if (blue_sky) {
    cv::Mat near_sky;
    const int r = 2 * win + 2;
    cv::dilate(sky, near_sky,
               cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r + 1, 2 * r + 1)));
    std::vector<int> seen;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const int own = labels.at<int>(y, x);
        seen.clear();
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int yy = y + dy, xx = x + dx;
            if (yy < 0 || yy >= h || xx < 0 || xx >= w) continue;
            const int lab = labels.at<int>(yy, xx);
            if (lab == 0 || lab == own || is_blue[lab] || keep[lab]) continue;
            if (std::find(seen.begin(), seen.end(), lab) != seen.end()) continue;
            seen.push_back(lab);
            ++ring[lab];
            ring_sky[lab] += near_sky.at<std::uint8_t>(y, x) != 0;
          }
      }
  }
  for (int i = 1; i < n; ++i) {
    if (is_blue[i]) continue;
    if (top[i] && (!blue_sky || touches_blue[i])) keep[i] = 1;
    if (!top[i] && blue_sky && ring[i] > 0 && ring_sky[i] >= o.cloud_min_sky_ring * ring[i])
      keep[i] = 1;
  }
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) sky.at<std::uint8_t>(y, x) = keep[labels.at<int>(y, x)];
  // Issue 11: a grey or bluish rock face, a concrete floor or a hazy mountain is below
  // `max_texture` in most of its pixels, but much rougher than the sky, whose texture is the
  // camera's noise and smooth ramps (its gradient, the clouds' soft edges); touching the sky, it
  // joined its component. So the sky keeps only what lies within a bounded distance (`core_grow`
  // texture windows, through the sky) of its core: pixels whose roughness (above) is below a
  // few times the sky's own noise floor (its 5th percentile: a rough face that touches the sky may
  // be most of it), in patches at least two texture windows across (a rock face's smoothest patches
  // are not a core).
  if (o.core_texture_factor > 0 && o.core_grow > 0) {
    const cv::Mat& wide = roughness;
    std::vector<float> tex;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        if (sky.at<std::uint8_t>(y, x)) tex.push_back(wide.at<float>(y, x));
    if (!tex.empty()) {
      const std::size_t q = std::size_t(0.05 * double(tex.size() - 1));
      std::nth_element(tex.begin(), tex.begin() + std::ptrdiff_t(q), tex.end());
      const float limit = std::clamp(float(o.core_texture_factor) * tex[q],
                                     float(o.min_core_texture), float(o.max_texture));
      const cv::Mat patch =
          cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * win + 1, 2 * win + 1));
      cv::Mat core = sky & (wide <= limit);
      cv::morphologyEx(core, core, cv::MORPH_OPEN, patch);
      // Issue 11 (a snow field seen from above, a concrete slab): a sky is smooth down to the
      // camera's noise somewhere in every patch of its core, a textured surface nowhere (snow's
      // grain, however even, is several times rougher). Where such a surface is all the photo
      // offers as sky, its own 5th percentile set the floor above and its whole area passed; so
      // a core patch is kept only when it holds a patch (as wide) at most `max_core_floor`
      // rough. Where the sky's floor is lower the limit is already that low: no change.
      if (o.max_core_floor > 0 && limit > o.max_core_floor) {
        cv::Mat smooth = sky & (wide <= o.max_core_floor), cl;
        cv::morphologyEx(smooth, smooth, cv::MORPH_OPEN, patch);
        const int nc = cv::connectedComponents(core, cl, 8, CV_32S);
        std::vector<std::uint8_t> has_smooth(std::size_t(nc), 0);
        for (int y = 0; y < h; ++y)
          for (int x = 0; x < w; ++x)
            if (smooth.at<std::uint8_t>(y, x)) has_smooth[cl.at<int>(y, x)] = 1;
        for (int y = 0; y < h; ++y)
          for (int x = 0; x < w; ++x)
            if (!has_smooth[cl.at<int>(y, x)]) core.at<std::uint8_t>(y, x) = 0;
      }
      const cv::Mat step = cv::getStructuringElement(cv::MORPH_RECT, cv::Size(3, 3));
      const int steps = int(std::lround(o.core_grow * win));
      cv::Mat grown;
      for (int i = 0; i < steps; ++i) {
        cv::dilate(core, grown, step);
        grown &= sky;
        if (cv::countNonZero(grown != core) == 0) break;
        std::swap(core, grown);
      }
      sky = core;
    }
  }
  // The texture window widens every edge by about its radius: grow the sky back over pixels of
  // sky colour within that distance (the guided filter then places the edge).
  {
    cv::Mat grown;
    const int r = win / 2 + 2;
    cv::dilate(sky, grown,
               cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r + 1, 2 * r + 1)));
    sky |= grown & colour;
  }
  // Issue 11 item 4: clouds the colour test refused or the core test cut. A backlit cloud's
  // body is dark grey (neither blue nor bright), its sunlit rim textured (rougher than the
  // core); left out, the rim's cut-off part and the body became a surface a few tens of metres
  // away while the rest of the cloud was sky: in haze a flat patch of fog colour with a hard
  // edge cut into the cloud where the photo has none. What is above the horizon, not sky, and
  // does not stand on anything (no pixel of it reaches the horizon or the frame's bottom: a
  // tree, a mast, a building or a mountain does) is held up by nothing but the sky: a cloud
  // when it is grey (low saturation: a kite, a balloon or foliage is not) or mostly of the sky's
  // colours (blue seen through a hole in a cloud) and not textured like
  // foliage or a lattice (mean per-pixel gradient below `max_texture`; a bright white one may
  // be: a cumulus' sunlit detail) and mostly ringed by sky (not by the frame: a bridge deck or
  // an eave seen from below spans it).
  if (o.floating_max_saturation > 0 && cv::countNonZero(sky) > 0) {
    cv::Mat rest(h, w, CV_8U, cv::Scalar(0));
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        rest.at<std::uint8_t>(y, x) = above(x, y) && !sky.at<std::uint8_t>(y, x);
    cv::Mat fl, fs, fc;
    const int m = cv::connectedComponentsWithStats(rest, fl, fs, fc, 8, CV_32S);
    std::vector<std::uint8_t> grounded(std::size_t(m), 0);
    std::vector<double> sat_sum(std::size_t(m), 0.0), grad_sum(std::size_t(m), 0.0),
        rough_sum(std::size_t(m), 0.0), luma_sum(std::size_t(m), 0.0),
        sky_coloured(std::size_t(m), 0.0);
    std::vector<int> ring_sky(std::size_t(m), 0), ring_frame(std::size_t(m), 0);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const int l = fl.at<int>(y, x);
        if (l == 0) continue;
        if (y + 1 >= h || !above(x, y + 1)) grounded[l] = 1;
        sat_sum[l] += saturation.at<float>(y, x);
        grad_sum[l] += pixel_gradient.at<float>(y, x);
        rough_sum[l] += roughness.at<float>(y, x);
        luma_sum[l] += luma.at<float>(y, x);
        sky_coloured[l] += colour.at<std::uint8_t>(y, x);
        const bool frame = x == 0 || y == 0 || x == w - 1;
        bool next_to_sky = false;
        for (int dy = -1; dy <= 1 && !next_to_sky; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int yy = y + dy, xx = x + dx;
            if (yy >= 0 && yy < h && xx >= 0 && xx < w && sky.at<std::uint8_t>(yy, xx)) {
              next_to_sky = true;
              break;
            }
          }
        ring_sky[l] += next_to_sky;
        ring_frame[l] += frame;
      }
    std::vector<std::uint8_t> cloud(std::size_t(m), 0);
    bool any_cloud = false;
    for (int i = 1; i < m; ++i) {
      const double area = fs.at<int>(i, cv::CC_STAT_AREA);
      // A bright white one may be textured: a cumulus' sunlit cauliflower detail.
      const bool white =
          luma_sum[i] >= std::max(0.6, double(o.bright_fraction * bright_ref)) * area;
      // Grey, or mostly of the sky's colours (blue seen through a gap in the cloud).
      const bool grey =
          sat_sum[i] <= o.floating_max_saturation * area || 2 * sky_coloured[i] > area;
      // Not textured like foliage or a lattice: a low mean gradient, or gradients that are
      // smooth ramps (a dark cloud's soft edge against a bright sky near the sun, or its sunlit
      // rim, is steep but coherent: its roughness is the sky core's, below min_core_texture).
      const bool smooth =
          grad_sum[i] <= o.max_texture * area || rough_sum[i] <= o.min_core_texture * area;
      cloud[i] = !grounded[i] && grey && (white || smooth) &&
                 ring_sky[i] >= o.floating_min_sky_ring * (ring_sky[i] + ring_frame[i]);
      any_cloud |= cloud[i] != 0;
    }
    if (any_cloud)
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
          if (cloud[fl.at<int>(y, x)]) sky.at<std::uint8_t>(y, x) = 1;
  }
  // Fill small enclosed holes (non-sky components not touching the border).
  {
    cv::Mat not_sky = 1 - sky, hl, stats, centroids;
    const int m = cv::connectedComponentsWithStats(not_sky, hl, stats, centroids, 4, CV_32S);
    const double max_hole = o.max_hole_fraction * w * h;
    std::vector<std::uint8_t> fill(std::size_t(m), 0);
    for (int i = 1; i < m; ++i) {
      const int x0 = stats.at<int>(i, cv::CC_STAT_LEFT), y0 = stats.at<int>(i, cv::CC_STAT_TOP);
      const int x1 = x0 + stats.at<int>(i, cv::CC_STAT_WIDTH),
                y1 = y0 + stats.at<int>(i, cv::CC_STAT_HEIGHT);
      const bool border = x0 == 0 || y0 == 0 || x1 == w || y1 == h;
      if (!border && stats.at<int>(i, cv::CC_STAT_AREA) <= max_hole) fill[i] = 1;
    }
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        if (fill[hl.at<int>(y, x)]) sky.at<std::uint8_t>(y, x) = 1;
  }

  // Sky seen through foliage: small sky-coloured components the texture test refused (a gap's
  // edge pixels are mixtures, so the window sees texture), enclosed in textured structure, whose
  // colour is the open sky's. Without this, a billboard fills every gap: no sky through the
  // canopy, no sunlight between the branches.
  // Only under a blue sky: a pale grey "sky" may be a studio backdrop or a white wall, whose
  // colour a highlight on a cheek or a sleeve matches (and sunlight through a canopy, what
  // the gaps are for, comes with a blue sky).
  std::size_t gap_pixels_working = 0;
  if (o.max_gap_fraction > 0 && blue_sky) {
    const SkyColour model = sky_colour(small, luma, sky);
    if (model.valid) {
      const cv::Vec3d& mean = model.mean;
      const cv::Matx33d& inverse = model.inverse;
      const double median_luma = model.median_luma;
      cv::Mat gap_cand = colour & (1 - sky);
      cv::Mat gl, gs, gc;
      const int m = cv::connectedComponentsWithStats(gap_cand, gl, gs, gc, 8, CV_32S);
      std::vector<cv::Vec3d> sum(std::size_t(m), cv::Vec3d(0, 0, 0));
      std::vector<double> luma_sum(std::size_t(m), 0.0);
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
          if (const int l = gl.at<int>(y, x); l > 0) {
            const cv::Vec3f& p = small.at<cv::Vec3f>(y, x);
            sum[l] += cv::Vec3d(p[0], p[1], p[2]);
            luma_sum[l] += luma.at<float>(y, x);
          }
      std::vector<std::uint8_t> gap(std::size_t(m), 0);
      const double max_area = o.max_gap_fraction * w * h;
      for (int i = 1; i < m; ++i) {
        const int area = gs.at<int>(i, cv::CC_STAT_AREA);
        if (area > max_area) continue;
        const cv::Vec3d d = sum[i] * (1.0 / area) - mean;
        if (!((d.t() * inverse * d)(0) <= o.gap_max_sigma * o.gap_max_sigma)) continue;
        if (!(luma_sum[i] / area >= o.gap_min_luma * median_luma)) continue;
        // Enclosed in texture (foliage): most of the pixels around it are textured, which a
        // white boat on a smooth sea or a pale patch of a plain wall are not.
        const int x0 = std::max(0, gs.at<int>(i, cv::CC_STAT_LEFT) - 3),
                  y0 = std::max(0, gs.at<int>(i, cv::CC_STAT_TOP) - 3);
        const int x1 = std::min(
                      w, gs.at<int>(i, cv::CC_STAT_LEFT) + gs.at<int>(i, cv::CC_STAT_WIDTH) + 3),
                  y1 = std::min(
                      h, gs.at<int>(i, cv::CC_STAT_TOP) + gs.at<int>(i, cv::CC_STAT_HEIGHT) + 3);
        int around = 0, textured = 0;
        for (int y = y0; y < y1; ++y)
          for (int x = x0; x < x1; ++x) {
            if (gl.at<int>(y, x) == i || sky.at<std::uint8_t>(y, x)) continue;
            ++around;
            textured += texture.at<float>(y, x) > o.max_texture;
          }
        if (around > 0 && 2 * textured >= around) gap[i] = 1;
      }
      // ... and as smooth as the open sky (snow seen between twigs is not).
      if (o.opening_max_texture_ratio > 0) {
        const std::vector<std::uint8_t> smooth =
            as_smooth_as_the_sky(gl, m, gap, sky, pixel_gradient, s, o.opening_max_texture_ratio,
                                 o.min_core_texture, o.max_texture);
        for (int i = 1; i < m; ++i) gap[i] = gap[i] && smooth[i];
      }
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
          if (gap[gl.at<int>(y, x)] && above(x, y)) {
            sky.at<std::uint8_t>(y, x) = 1;
            ++gap_pixels_working;
          }
    }
  }
  // Issue 11: sky seen through a lattice or between cables (a launch tower, a suspension
  // bridge's hangers, a pylon). Each opening is a patch of the sky's own colour, but the
  // texture window around it takes in the thin members, so the sky's core never reaches it, and
  // the openings run into one another (a member one pixel wide does not cut an 8-connected
  // component), too large for the gaps above. Left out, the whole lattice was one surface:
  // in haze its sky stayed blue inside a hard outline while the open sky around it turned the
  // fog's grey. Such a component is sky when it has the open sky's colour and what separates
  // it from the sky (the structure within about a member's width of it) is thin: narrower than
  // `thin_member_width` (a morphological opening removes it) in all but `thin_max_thick` of its
  // pixels, and bounds it along at least `thin_min_bounded` of its ring (sky-coloured rock or a
  // bluish wall meeting the sky has mostly open sky or thick structure around it), and it is
  // as smooth as the open sky (as_smooth_as_the_sky: snow seen between a birch's twigs is
  // bounded just so, but grainy). Openings reached only through other openings follow once
  // those are sky.
  if (o.thin_member_width > 0 && blue_sky) {
    const SkyColour model = sky_colour(small, luma, sky);
    if (model.valid) {
      const int member = std::max(3, int(std::lround(o.thin_member_width * std::hypot(w, h))) | 1);
      const int reach = member;  // across a member (and its mixed fringe) to the sky beyond
      cv::Mat open_cand = colour & (1 - sky), structure(h, w, CV_8U, cv::Scalar(0)), thick;
      // Each pixel of the sky's colour (a component's mean would mix the sky in a lattice's
      // openings with the pale haze along the horizon they run into), no darker than the
      // sky's darkest part (a tower's top stands against the deep blue zenith).
      auto sky_coloured_at = [&](int x, int y) {
        const cv::Vec3f& p = small.at<cv::Vec3f>(y, x);
        const cv::Vec3d d = cv::Vec3d(p[0], p[1], p[2]) - model.mean;
        return (d.t() * model.inverse * d)(0) <= o.gap_max_sigma * o.gap_max_sigma &&
               luma.at<float>(y, x) >= o.gap_min_luma * model.low_luma;
      };
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
          if (open_cand.at<std::uint8_t>(y, x))
            open_cand.at<std::uint8_t>(y, x) = sky_coloured_at(x, y);
      // Below the horizon, the pixels of the sky's colour.
      cv::Mat sky_like_ground(h, w, CV_8U, cv::Scalar(0));
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
          if (!above(x, y)) sky_like_ground.at<std::uint8_t>(y, x) = sky_coloured_at(x, y);
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
          structure.at<std::uint8_t>(y, x) =
              !sky.at<std::uint8_t>(y, x) && !open_cand.at<std::uint8_t>(y, x);
      cv::morphologyEx(structure, thick, cv::MORPH_OPEN,
                       cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(member, member)));
      // Below the horizon is the ground, never a member. The sky mask ends at the horizon, so
      // an opening that reaches it is sky only where the photo's opening ends there too: where
      // most of the ground around it has the sky's colour (the opening goes on below a horizon
      // drawn a few pixels high, rocket's left tower), its sky would end in a line across the
      // lattice; where the ground around it does not (the tower's foot on a dark cloud bank,
      // rocket's middle tower), the whole of it as a surface left the lattice's blue inside a
      // hard outline while the sky around it took the haze's grey (issue 11, helper haze16).
      // Only where members go on below it too, or the sky's colour goes on far below it: a thin
      // band of the sky's colour alone below it is the band a guessed horizon was drawn in,
      // which the open sky beside it shares, and refused, an opening as large as bridge's
      // triangle between its cable stays stood as a wall at the far billboard (a grey triangle
      // in the night look); a pale wall taken for sky goes on far below (friends' siding).
      cv::Mat ground(h, w, CV_8U, cv::Scalar(0));
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
          if (!above(x, y)) ground.at<std::uint8_t>(y, x) = 1;
      cv::Mat ol, os, oc;
      const int m = cv::connectedComponentsWithStats(open_cand, ol, os, oc, 8, CV_32S);
      std::vector<cv::Vec3d> sum(std::size_t(m), cv::Vec3d(0, 0, 0));
      std::vector<double> luma_sum(std::size_t(m), 0.0);
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
          if (const int l = ol.at<int>(y, x); l > 0) {
            const cv::Vec3f& p = small.at<cv::Vec3f>(y, x);
            sum[l] += cv::Vec3d(p[0], p[1], p[2]);
            luma_sum[l] += luma.at<float>(y, x);
          }
      std::vector<std::uint8_t> sky_coloured(std::size_t(m), 0), made(std::size_t(m), 0);
      for (int i = 1; i < m; ++i) {
        const double area = os.at<int>(i, cv::CC_STAT_AREA);
        const cv::Vec3d d = sum[i] * (1.0 / area) - model.mean;
        sky_coloured[i] = (d.t() * model.inverse * d)(0) <= o.gap_max_sigma * o.gap_max_sigma &&
                          luma_sum[i] / area >= o.gap_min_luma * model.low_luma;
      }
      if (o.opening_max_texture_ratio > 0) {
        const std::vector<std::uint8_t> smooth =
            as_smooth_as_the_sky(ol, m, sky_coloured, sky, pixel_gradient, s,
                                 o.opening_max_texture_ratio, o.min_core_texture, o.max_texture);
        for (int i = 1; i < m; ++i) sky_coloured[i] = sky_coloured[i] && smooth[i];
      }
      // The ring: every pixel within `reach` of a component's pixels, weighted by how many of
      // them it is near (cheap, and it weights the ring by closeness).
      std::vector<cv::Point> disk;
      for (int dy = -reach; dy <= reach; ++dy)
        for (int dx = -reach; dx <= reach; ++dx)
          if (dx * dx + dy * dy <= reach * reach && (dx || dy)) disk.emplace_back(dx, dy);
      std::vector<double> ring_sky(std::size_t(m), 0.0), ring_thin(std::size_t(m), 0.0),
          ring_thick(std::size_t(m), 0.0), ring_all(std::size_t(m), 0.0);
      std::vector<std::uint8_t> reaches_ground(std::size_t(m), 0);
      std::vector<double> ring_ground(std::size_t(m), 0.0), ring_ground_sky(std::size_t(m), 0.0);
      // How far below the horizon the sky's colour goes on under opening i: the median, over
      // the columns where it meets the horizon, of the rows of the sky's colour from there.
      auto band_below = [&](int i) {
        std::vector<int> rows;
        const int x0 = os.at<int>(i, cv::CC_STAT_LEFT), y0 = os.at<int>(i, cv::CC_STAT_TOP);
        const int x1 = x0 + os.at<int>(i, cv::CC_STAT_WIDTH),
                  y1 = y0 + os.at<int>(i, cv::CC_STAT_HEIGHT);
        for (int x = x0; x < x1; ++x)
          for (int y = y1 - 1; y >= y0; --y) {
            if (ol.at<int>(y, x) != i) continue;
            if (y + 1 < h && !above(x, y + 1)) {
              int run = 0;
              while (y + 1 + run < h && sky_like_ground.at<std::uint8_t>(y + 1 + run, x)) ++run;
              rows.push_back(run);
            }
            break;
          }
        if (rows.empty()) return 0;
        std::nth_element(rows.begin(), rows.begin() + std::ptrdiff_t(rows.size() / 2), rows.end());
        return rows[rows.size() / 2];
      };
      for (int round = 0; round < 16; ++round) {
        std::fill(ring_sky.begin(), ring_sky.end(), 0.0);
        std::fill(ring_thin.begin(), ring_thin.end(), 0.0);
        std::fill(ring_thick.begin(), ring_thick.end(), 0.0);
        std::fill(ring_all.begin(), ring_all.end(), 0.0);
        std::fill(ring_ground.begin(), ring_ground.end(), 0.0);
        std::fill(ring_ground_sky.begin(), ring_ground_sky.end(), 0.0);
        for (int y = 0; y < h; ++y)
          for (int x = 0; x < w; ++x) {
            const int l = ol.at<int>(y, x);
            if (l == 0 || made[l] || !sky_coloured[l]) continue;
            for (const cv::Point& d : disk) {
              const int xx = x + d.x, yy = y + d.y;
              if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
              const int k = ol.at<int>(yy, xx);
              if (k == l) continue;
              ring_all[l] += 1;
              if (sky.at<std::uint8_t>(yy, xx) || (k > 0 && made[k]))
                ring_sky[l] += 1;
              else if (ground.at<std::uint8_t>(yy, xx)) {
                reaches_ground[l] = 1;
                ring_ground[l] += 1;
                ring_ground_sky[l] += sky_like_ground.at<std::uint8_t>(yy, xx);
              } else if (thick.at<std::uint8_t>(yy, xx))
                ring_thick[l] += 1;
              else if (structure.at<std::uint8_t>(yy, xx))
                ring_thin[l] += 1;
            }
          }
        bool changed = false;
        for (int i = 1; i < m; ++i) {
          if (made[i] || !sky_coloured[i] || !(ring_sky[i] > 0)) continue;
          if (reaches_ground[i] && ring_ground_sky[i] > o.thin_max_ground_sky * ring_ground[i] &&
              (ring_ground[i] - ring_ground_sky[i] >= o.thin_min_ground_members * ring_ground[i] ||
               band_below(i) > o.thin_max_band_fraction * h))
            continue;
          const double members = ring_thin[i] + ring_thick[i];
          if (members >= o.thin_min_bounded * ring_all[i] &&
              ring_thick[i] <= o.thin_max_thick * members)
            made[i] = 1, changed = true;
        }
        if (!changed) break;
      }
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
          if (made[ol.at<int>(y, x)]) {
            sky.at<std::uint8_t>(y, x) = 1;
            ++gap_pixels_working;
          }
    }
  }

  // Full resolution: upsample, refine the edges with a guided filter, clip to the horizon.
  cv::Mat soft;
  sky.convertTo(soft, CV_32F);
  if (s < 1) cv::resize(soft, soft, cv::Size(photo.width, photo.height), 0, 0, cv::INTER_LINEAR);
  const int radius = std::max(2, int(std::lround(0.004 * std::hypot(photo.width, photo.height))));
  cv::Mat binary, grown, shrunk;
  // Only within `radius` of the mask's edges does the filter decide; elsewhere the mask stands.
  binary = soft >= 0.5f;
  const cv::Mat disk =
      cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * radius + 1, 2 * radius + 1));
  cv::dilate(binary, grown, disk);
  cv::erode(binary, shrunk, disk);
  // The filter in strips of rows, only where they hold some of that band: its value at a pixel
  // depends on the rows within 2 radius of it (a box of radius r over coefficients that are
  // boxes of radius r), so each strip is filtered with that margin and its own rows kept. With
  // a 3-channel guide the whole-frame filter held about 20 float images of the photo's size
  // (2 GB at 24 MP, the estimate's peak); a strip's are of its size.
  cv::Mat refined(soft.size(), CV_32F, cv::Scalar(0));
  const int margin = 2 * radius + 2, strip = std::max(256, 8 * radius);
  for (int y0 = 0; y0 < photo.height; y0 += strip) {
    const int y1 = std::min(photo.height, y0 + strip);
    if (cv::countNonZero(grown.rowRange(y0, y1) != shrunk.rowRange(y0, y1)) == 0) continue;
    const int a = std::max(0, y0 - margin), b = std::min(photo.height, y1 + margin);
    cv::Mat part;
    contrib::guided_filter(full.rowRange(a, b), soft.rowRange(a, b), part, radius, 1e-3);
    part.rowRange(y0 - a, y1 - a).copyTo(refined.rowRange(y0, y1));
  }
  // Issue 11 item 4: in that band the matte is how much of the sky each pixel shows. The mask
  // stops short of the sky's edge or overshoots it by a pixel or two (its texture test looks
  // at a window), and the guided filter can only blur such a misplaced edge: a ramp several
  // pixels wide, off the photo's edge, whose fog mix (photo/sky_matte.h) then lays a band of
  // sky fog over a surface the photo shows plainly. So where the two sides differ in colour,
  // each band pixel is unmixed against the colours on both sides of it (the two-colour model
  // of matting: I = (1 - a) F + a B in scene-linear light, F the nearest surface pixel's colour
  // beyond the band, B the nearest sky pixel's, both 3x3 means; a = the projection of I - F on
  // B - F), which puts the matte where the photo's edge is and as wide as it is; where they do
  // not (a hill fading into haze: the photo has no edge there), the guided filter's smooth
  // ramp stands, and in between the two are blended by the contrast.
  const std::size_t npx = std::size_t(photo.width) * photo.height;
  std::vector<std::uint8_t> pure_sky(npx), pure_surface(npx);
  for (int y = 0; y < photo.height; ++y)
    for (int x = 0; x < photo.width; ++x) {
      const std::size_t i = std::size_t(y) * photo.width + x;
      pure_sky[i] = shrunk.at<std::uint8_t>(y, x) != 0;
      pure_surface[i] = grown.at<std::uint8_t>(y, x) == 0;
    }
  const std::vector<std::int32_t> near_sky = nearest_source(photo.width, photo.height, pure_sky);
  const std::vector<std::int32_t> near_surface =
      nearest_source(photo.width, photo.height, pure_surface);
  cv::Mat linear(photo.height, photo.width, CV_32FC3), linear_mean;
  for (int y = 0; y < photo.height; ++y)
    for (int x = 0; x < photo.width; ++x) {
      const cv::Vec3f d = full.at<cv::Vec3f>(y, x);
      linear.at<cv::Vec3f>(y, x) = {std::pow(d[0], 2.2f), std::pow(d[1], 2.2f),
                                    std::pow(d[2], 2.2f)};
    }
  cv::blur(linear, linear_mean, cv::Size(3, 3));
  // Display-referred distance between the two sides below which the photo shows no edge (about
  // 8 codes of 255), and above which the unmixed matte is used alone (about 20).
  constexpr float kNoEdge = 0.03f, kEdge = 0.08f;
  auto unmixed = [&](int x, int y, float guided) {
    if (!o.unmix_edges || near_sky.empty() || near_surface.empty()) return guided;
    const std::size_t i = std::size_t(y) * photo.width + x;
    const std::int32_t k = near_sky[i], f = near_surface[i];
    if (k < 0 || f < 0) return guided;
    const cv::Vec3f B = linear_mean.at<cv::Vec3f>(k / photo.width, k % photo.width);
    const cv::Vec3f F = linear_mean.at<cv::Vec3f>(f / photo.width, f % photo.width);
    const cv::Vec3f I = linear.at<cv::Vec3f>(y, x);
    const cv::Vec3f BF = B - F;
    const float norm2 = BF.dot(BF);
    float contrast = 0;
    for (int c = 0; c < 3; ++c)
      contrast = std::max(contrast, std::abs(std::pow(std::max(B[c], 0.0f), 1 / 2.2f) -
                                             std::pow(std::max(F[c], 0.0f), 1 / 2.2f)));
    const float t = std::clamp((contrast - kNoEdge) / (kEdge - kNoEdge), 0.0f, 1.0f);
    if (!(t > 0) || !(norm2 > 0)) return guided;
    const float a = std::clamp((I - F).dot(BF) / norm2, 0.0f, 1.0f);
    // Trust in the two-colour model: the pixel lies near the line from F to B (the residual,
    // fading out at half their distance); a pixel off it (a leaf of another colour, a
    // dark crack beside a pale wall) keeps the guided filter's value.
    const float norm = std::sqrt(norm2);
    const cv::Vec3f off = I - F - a * BF;
    const float residual = std::sqrt(off.dot(off)) / norm;
    const float model = std::clamp(1.0f - residual / 0.5f, 0.0f, 1.0f);
    const float wt = t * t * (3 - 2 * t) * model;
    return wt * a + (1 - wt) * guided;
  };
  for (int y = 0; y < photo.height; ++y) {
    const float* r = refined.ptr<float>(y);
    const float* so = soft.ptr<float>(y);
    const std::uint8_t* gr = grown.ptr<std::uint8_t>(y);
    const std::uint8_t* sh = shrunk.ptr<std::uint8_t>(y);
    for (int x = 0; x < photo.width; ++x) {
      const float v = gr[x] != sh[x] ? unmixed(x, y, std::clamp(r[x], 0.0f, 1.0f)) : so[x];
      const bool above_horizon = y < horizon_y(x);
      const bool is_sky = v >= 0.5f && above_horizon;
      out.sky[std::size_t(y) * photo.width + x] = is_sky;
      out.alpha[std::size_t(y) * photo.width + x] =
          above_horizon && std::isfinite(v) ? std::clamp(v, 0.0f, 1.0f) : 0.0f;
      out.pixels += is_sky;
    }
  }
  out.gap_pixels = std::size_t(std::lround(double(gap_pixels_working) / (sx * sy)));
  return out;
}

}  // namespace

SkyMask estimate_sky_mask(ConstImageView photo, const std::array<PixelPoint, 2>& horizon,
                          const SkyMaskOptions& o) {
  // Issue 11: a scanned print's border is not sky, and the sky's tests (touching the frame's
  // top) read the picture's own edges: the mask is found inside it.
  const FrameBorder border = o.inside_frame_border ? find_frame_border(photo) : FrameBorder{};
  if (!border.any()) return sky_mask_of_picture(photo, horizon, o);
  const Rect r = border.inside(photo.width, photo.height);
  const std::array<PixelPoint, 2> shifted{PixelPoint{horizon[0][0] - r.x, horizon[0][1] - r.y},
                                          PixelPoint{horizon[1][0] - r.x, horizon[1][1] - r.y}};
  const SkyMask inner = sky_mask_of_picture(photo.sub(r), shifted, o);
  SkyMask out;
  out.width = photo.width;
  out.height = photo.height;
  out.sky.assign(std::size_t(photo.width) * photo.height, 0);
  out.alpha.assign(out.sky.size(), 0.0f);
  for (int y = 0; y < r.height && !inner.sky.empty(); ++y)
    for (int x = 0; x < r.width; ++x) {
      const std::size_t from = std::size_t(y) * r.width + x;
      const std::size_t to = std::size_t(y + r.y) * photo.width + x + r.x;
      out.sky[to] = inner.sky[from];
      out.alpha[to] = inner.alpha[from];
    }
  out.pixels = inner.pixels;
  out.gap_pixels = inner.gap_pixels;
  return out;
}

int count_lamps_in_sky(ConstImageView photo, const std::vector<std::uint8_t>& sky,
                       const LampsInSkyOptions& o) {
  const int w = photo.width, h = photo.height;
  const std::size_t n = std::size_t(w) * h;
  if (w < 1 || h < 1 || photo.channels < 1 || sky.size() != n) return 0;
  cv::Mat clipped(h, w, CV_8U);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float* p = photo.pixel(x, y);
      bool all = sky[std::size_t(y) * w + x] != 0;
      for (int c = 0; c < std::min(3, photo.channels) && all; ++c) all = p[c] >= o.min_clipped;
      clipped.at<std::uint8_t>(y, x) = all;
    }
  cv::Mat labels, stats, centroids;
  const int m = cv::connectedComponentsWithStats(clipped, labels, stats, centroids, 8, CV_32S);
  int lamps = 0;
  for (int l = 1; l < m; ++l) {
    const int area = stats.at<int>(l, cv::CC_STAT_AREA);
    if (double(area) < o.min_area_fraction * double(n)) continue;
    const cv::Rect box(stats.at<int>(l, cv::CC_STAT_LEFT), stats.at<int>(l, cv::CC_STAT_TOP),
                       stats.at<int>(l, cv::CC_STAT_WIDTH), stats.at<int>(l, cv::CC_STAT_HEIGHT));
    std::vector<std::vector<cv::Point>> contours;
    cv::findContours(cv::Mat(labels(box) == l), contours, cv::RETR_EXTERNAL,
                     cv::CHAIN_APPROX_SIMPLE);
    std::vector<cv::Point> points;
    for (const auto& c : contours) points.insert(points.end(), c.begin(), c.end());
    std::vector<cv::Point> hull;
    cv::convexHull(points, hull);
    // The hull runs through the outline pixels' centres: half a pixel of rim is outside it.
    const double hull_area = cv::contourArea(hull) + 0.5 * cv::arcLength(hull, true) + 1.0;
    lamps += double(area) >= o.min_solidity * hull_area;
  }
  return lamps;
}

CloseUpSky keep_evident_sky(ConstImageView photo, SkyMask& mask, const CloseUpSkyOptions& o) {
  CloseUpSky out;
  const int w = photo.width, h = photo.height;
  const std::size_t n = std::size_t(w) * h;
  if (w < 1 || h < 1 || photo.channels < 1 || mask.width != w || mask.height != h ||
      mask.sky.size() != n || mask.alpha.size() != n)
    return out;
  cv::Mat support(h, w, CV_8U);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      support.at<std::uint8_t>(y, x) = mask.sky[i] != 0 || mask.alpha[i] > 0;
    }
  cv::Mat labels;
  const int m = cv::connectedComponents(support, labels, 8, CV_32S);
  if (m <= 1) return out;
  const cv::Mat display = display_rgb(photo);
  std::vector<cv::Vec3d> sum(std::size_t(m), cv::Vec3d(0, 0, 0));
  std::vector<std::size_t> sky_count(std::size_t(m), 0), top_run(std::size_t(m), 0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int l = labels.at<int>(y, x);
      const std::size_t i = std::size_t(y) * w + x;
      if (l == 0 || !mask.sky[i]) continue;
      const cv::Vec3f& p = display.at<cv::Vec3f>(y, x);
      sum[std::size_t(l)] += cv::Vec3d(p[0], p[1], p[2]);
      ++sky_count[std::size_t(l)];
      if (y == 0) ++top_run[std::size_t(l)];
    }
  std::vector<std::uint8_t> keep(std::size_t(m), 0);
  for (int l = 1; l < m; ++l) {
    const std::size_t k = std::size_t(l);
    if (sky_count[k] == 0 || double(top_run[k]) < o.min_top_fraction * w) continue;
    if (double(top_run[k]) >= o.keep_open_top_fraction * w) {
      keep[k] = 1;
      continue;
    }
    const cv::Vec3d c = sum[k] * (1.0 / double(sky_count[k]));
    const double mx = std::max({c[0], c[1], c[2]}), mn = std::min({c[0], c[1], c[2]});
    if (!(mx > 1e-6) || !((mx - mn) / mx >= o.min_saturation)) continue;
    // Hue in degrees (the hexcone's), from the mean colour.
    const double d = mx - mn;
    double hue = mx == c[0]   ? 60 * std::fmod((c[1] - c[2]) / d, 6.0)
                 : mx == c[1] ? 60 * ((c[2] - c[0]) / d + 2)
                              : 60 * ((c[0] - c[1]) / d + 4);
    if (hue < 0) hue += 360;
    keep[k] = hue >= o.min_hue_deg && hue <= o.max_hue_deg;
  }
  std::size_t kept = 0, dropped = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int l = labels.at<int>(y, x);
      if (l == 0) continue;
      const std::size_t i = std::size_t(y) * w + x;
      if (keep[std::size_t(l)]) {
        kept += mask.sky[i] != 0;
        continue;
      }
      dropped += mask.sky[i] != 0;
      mask.sky[i] = 0;
      mask.alpha[i] = 0.0f;
    }
  if (mask.pixels > 0)
    mask.gap_pixels =
        std::size_t(std::lround(double(mask.gap_pixels) * double(kept) / double(mask.pixels)));
  mask.pixels = kept;
  out.kept_pixels = kept;
  out.dropped_pixels = dropped;
  return out;
}

GroundMask estimate_ground_mask(ConstImageView photo, const std::array<PixelPoint, 2>& horizon,
                                const std::vector<std::uint8_t>& sky, const GroundMaskOptions& o) {
  GroundMask out;
  out.width = photo.width;
  out.height = photo.height;
  const int w = photo.width, h = photo.height;
  out.ground.assign(std::size_t(w) * h, 0);
  if (w < 8 || h < 8 || photo.channels < 1) return out;
  const bool have_sky = sky.size() == std::size_t(w) * h;
  const double dx = horizon[1][0] - horizon[0][0];
  const double slope = std::abs(dx) > 1e-9 ? (horizon[1][1] - horizon[0][1]) / dx : 0.0;
  auto horizon_y = [&](double x) { return horizon[0][1] + (x - horizon[0][0]) * slope; };

  cv::Mat rgb = display_rgb(photo);
  cv::medianBlur(rgb, rgb, 5);  // texture averaged out, edges kept where they are
  // Samples: the bottom band, well below the horizon, not sky (an even stride: <= ~200k).
  const int band_top = h - std::max(2, int(std::lround(o.band_fraction * h)));
  const double min_below = o.min_depression_fraction * h;
  std::vector<cv::Vec3d> samples;
  const std::size_t band_pixels = std::size_t(h - band_top) * w;
  const int stride = int(std::max<std::size_t>(1, band_pixels / 200000));
  const int x_begin = int(std::lround(0.5 * (1 - o.band_width_fraction) * w));
  const int x_end = w - x_begin;
  for (int y = band_top; y < h; ++y)
    for (int x = x_begin + (y * 7) % stride; x < x_end; x += stride) {
      if (y < horizon_y(x) + min_below) continue;
      if (have_sky && sky[std::size_t(y) * w + x]) continue;
      const cv::Vec3f& p = rgb.at<cv::Vec3f>(y, x);
      samples.emplace_back(p[0], p[1], p[2]);
    }
  if (int(samples.size()) < o.min_samples) return out;
  cv::Vec3d mean;
  cv::Matx33d inverse;
  const double limit = o.max_sigma * o.max_sigma;
  auto fit = [&](const std::vector<cv::Vec3d>& all) {
    std::vector<cv::Vec3d> kept = all;
    for (int pass = 0; pass < 4; ++pass) {
      mean = cv::Vec3d(0, 0, 0);
      for (const auto& v : kept) mean += v;
      mean *= 1.0 / double(kept.size());
      cv::Matx33d cov = cv::Matx33d::zeros();
      for (const auto& v : kept) {
        const cv::Vec3d d = v - mean;
        cov += d * d.t();
      }
      cov *= 1.0 / double(kept.size());
      for (int k = 0; k < 3; ++k) cov(k, k) += o.min_sigma * o.min_sigma;
      inverse = cov.inv(cv::DECOMP_CHOLESKY);
      if (pass == 3) break;
      std::vector<cv::Vec3d> inliers;
      for (const auto& v : all) {
        const cv::Vec3d d = v - mean;
        if ((d.t() * inverse * d)(0) < 2.5 * 2.5) inliers.push_back(v);
      }
      if (int(inliers.size()) < o.min_samples) break;
      kept = std::move(inliers);
    }
  };
  fit(samples);
  auto ground_coloured = [&](int x, int y) {
    const cv::Vec3f& p = rgb.at<cv::Vec3f>(y, x);
    const cv::Vec3d d = cv::Vec3d(p[0], p[1], p[2]) - mean;
    return (d.t() * inverse * d)(0) < limit;
  };
  // Issue 11 (a portrait: a person filling the middle of the bottom band): the ground is a
  // plane below the horizon; it never rises above it. Where the modelled colour runs up a
  // column from the frame's bottom, without a break, to well above the horizon, it is the
  // colour of something standing in front of the camera (a coat, a trunk), not of the ground.
  // When such columns are most of the band the model was taken from, the model is refit from
  // the bottom band across the whole width, in the columns where the colour does not rise and
  // without the subject's colour (the ground beside the subject), if there are enough such
  // samples; otherwise it is kept.
  if (o.max_subject_fraction < 1) {
    const double rise_px = o.subject_min_rise_fraction * h;
    std::vector<std::uint8_t> rises(std::size_t(w), 0);
    for (int x = 0; x < w; ++x) {
      int y = h - 1;
      while (y >= 0 && !(have_sky && sky[std::size_t(y) * w + x]) && ground_coloured(x, y)) --y;
      rises[std::size_t(x)] = double(y) < horizon_y(x) - rise_px;
    }
    int middle_rising = 0, free_columns = 0;
    for (int x = x_begin; x < x_end; ++x) middle_rising += rises[std::size_t(x)];
    for (int x = 0; x < w; ++x) free_columns += !rises[std::size_t(x)];
    if (middle_rising > o.max_subject_fraction * (x_end - x_begin) &&
        free_columns >= o.min_ground_width_fraction * w) {
      std::vector<cv::Vec3d> beside;
      for (int y = band_top; y < h; ++y)
        for (int x = (y * 7) % stride; x < w; x += stride) {
          if (rises[std::size_t(x)] || y < horizon_y(x) + min_below) continue;
          if ((have_sky && sky[std::size_t(y) * w + x]) || ground_coloured(x, y)) continue;
          const cv::Vec3f& p = rgb.at<cv::Vec3f>(y, x);
          beside.emplace_back(p[0], p[1], p[2]);
        }
      if (int(beside.size()) >= o.min_samples) {
        fit(beside);
        out.standing_subject = true;
      }
    }
  }
  // The model is read below the horizon; for a standing subject above it too (its search,
  // photo/subject.h, follows the subject up past the horizon).
  if (out.standing_subject) out.coloured.assign(std::size_t(w) * h, 0);
  cv::Mat not_ground(h, w, CV_8U, cv::Scalar(0));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const bool below = y > horizon_y(x);
      if (!below && !out.standing_subject) continue;
      const bool within = ground_coloured(x, y);
      if (below && !within) not_ground.at<std::uint8_t>(y, x) = 1;
      if (out.standing_subject)
        out.coloured[std::size_t(y) * w + x] = within && !(have_sky && sky[std::size_t(y) * w + x]);
    }
  cv::morphologyEx(not_ground, not_ground, cv::MORPH_OPEN,
                   cv::getStructuringElement(cv::MORPH_RECT, cv::Size(3, 3)));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      out.ground[std::size_t(y) * w + x] = y > horizon_y(x) && !not_ground.at<std::uint8_t>(y, x);
  out.valid = true;
  return out;
}

}  // namespace mr::photo
