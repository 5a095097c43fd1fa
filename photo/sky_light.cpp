#include "photo/sky_light.h"

#include "photo/airlight.h"

#include <tbb/parallel_for.h>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <vector>

#include "photo/sky_matte.h"
#include "render/physics/medium.h"
#include "render/physics/scattering.h"

namespace mr::photo {

namespace {

constexpr double kPi = std::numbers::pi;

double texel_elevation(int height, double row) {
  return 0.5 * kPi - row / height * kPi;
}

// Display luma (Rec.709 weights on the gamma-2.2 encoded values, as the gallery's measure and
// SkyMask take it) of scene-linear RGB. Scaling the colour by s scales it by s^(1 / 2.2).
constexpr double kDisplayGamma = 2.2;
double display_encode(double v) {
  return std::pow(std::max(0.0, v), 1 / kDisplayGamma);
}
double display_luma(double r, double g, double b) {
  return 0.2126 * display_encode(r) + 0.7152 * display_encode(g) + 0.0722 * display_encode(b);
}

// The domain transform's recursive filter (Gastal and Oliveira 2011, "Domain transform for
// edge-aware image and video processing", RF with three iterations) of the `n` interleaved
// channels of `data` (w x h, in place), guided by `guide` (w x h x 3): a pixel's neighbour
// across a step of the guide lies sigma_s / sigma_r times that step (summed over the channels)
// farther away, so the filter averages over sigma_s pixels inside a region and stops at its
// edges, soft ones included (their steps add up along the ramp).
void domain_transform_filter(std::vector<float>& data, int n, const std::vector<float>& guide,
                             int w, int h, double sigma_s, double sigma_r) {
  const std::size_t count = std::size_t(w) * h;
  // Distances in the transformed domain: dx[i] between (x - 1, y) and (x, y), dy[i] between
  // (x, y - 1) and (x, y).
  std::vector<float> dx(count, 1.0f), dy(count, 1.0f);
  const double ratio = sigma_s / sigma_r;
  tbb::parallel_for(0, h, [&](int y) {
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      double sx = 0, sy = 0;
      for (int c = 0; c < 3; ++c) {
        if (x > 0) sx += std::abs(guide[3 * i + c] - guide[3 * (i - 1) + c]);
        if (y > 0) sy += std::abs(guide[3 * i + c] - guide[3 * (i - w) + c]);
      }
      dx[i] = float(1 + ratio * sx);
      dy[i] = float(1 + ratio * sy);
    }
  });
  constexpr int kIterations = 3;
  constexpr int kColumnBlock = 64;
  for (int it = 0; it < kIterations; ++it) {
    // The paper's sigma_H for this iteration: the iterations' variances add up to sigma_s^2.
    const double sigma_h = sigma_s * std::sqrt(3.0) * std::pow(2.0, kIterations - it - 1) /
                           std::sqrt(std::pow(4.0, kIterations) - 1);
    const double log_a = -std::sqrt(2.0) / sigma_h;
    tbb::parallel_for(0, h, [&](int y) {
      float* row = data.data() + std::size_t(y) * w * n;
      const float* d = dx.data() + std::size_t(y) * w;
      for (int x = 1; x < w; ++x) {
        const float v = float(std::exp(log_a * d[x]));
        for (int c = 0; c < n; ++c) row[x * n + c] += v * (row[(x - 1) * n + c] - row[x * n + c]);
      }
      for (int x = w - 2; x >= 0; --x) {
        const float v = float(std::exp(log_a * d[x + 1]));
        for (int c = 0; c < n; ++c) row[x * n + c] += v * (row[(x + 1) * n + c] - row[x * n + c]);
      }
    });
    tbb::parallel_for(0, (w + kColumnBlock - 1) / kColumnBlock, [&](int block) {
      const int x0 = block * kColumnBlock, x1 = std::min(w, x0 + kColumnBlock);
      for (int y = 1; y < h; ++y)
        for (int x = x0; x < x1; ++x) {
          const std::size_t i = std::size_t(y) * w + x;
          const float v = float(std::exp(log_a * dy[i]));
          for (int c = 0; c < n; ++c)
            data[i * n + c] += v * (data[(i - w) * n + c] - data[i * n + c]);
        }
      for (int y = h - 2; y >= 0; --y)
        for (int x = x0; x < x1; ++x) {
          const std::size_t i = std::size_t(y) * w + x;
          const float v = float(std::exp(log_a * dy[i + w]));
          for (int c = 0; c < n; ++c)
            data[i * n + c] += v * (data[(i + w) * n + c] - data[i * n + c]);
        }
    });
  }
}

}  // namespace

Vec3 latlong_direction(int width, int height, double col, double row) {
  const double az = col / width * 2 * kPi - kPi, el = texel_elevation(height, row);
  return {std::cos(el) * std::sin(az), std::sin(el), std::cos(el) * std::cos(az)};
}

double latlong_texel_solid_angle(int width, int height, int row) {
  return 2 * kPi / width *
         (std::sin(texel_elevation(height, row)) - std::sin(texel_elevation(height, row + 1)));
}

std::array<double, 3> sample_latlong(const Image& map, const Vec3& d) {
  const int w = map.width(), h = map.height();
  const double az = std::atan2(d.x, d.z);
  const double el = std::asin(std::clamp(d.y / std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z),
                                         -1.0, 1.0));
  const double u = (az + kPi) / (2 * kPi) * w - 0.5;
  const double v = std::clamp((0.5 * kPi - el) / kPi * h - 0.5, 0.0, double(h - 1));
  const double u0 = std::floor(u), v0 = std::floor(v);
  const double fu = u - u0, fv = v - v0;
  const int c0 = ((int(u0) % w) + w) % w, c1 = (c0 + 1) % w;
  const int r0 = int(v0), r1 = std::min(r0 + 1, h - 1);
  std::array<double, 3> out{};
  for (int c = 0; c < 3; ++c) {
    const double top = map.at(c0, r0, c) + (map.at(c1, r0, c) - map.at(c0, r0, c)) * fu;
    const double bottom = map.at(c0, r1, c) + (map.at(c1, r1, c) - map.at(c0, r1, c)) * fu;
    out[c] = top + (bottom - top) * fv;
  }
  return out;
}

Image convolve_henyey_greenstein(const Image& env, double g, int out_width, int out_height) {
  const int ew = env.width(), eh = env.height();
  std::vector<Vec3> dirs(std::size_t(ew) * eh);
  std::vector<double> solid(static_cast<std::size_t>(eh));
  for (int r = 0; r < eh; ++r) {
    solid[std::size_t(r)] = latlong_texel_solid_angle(ew, eh, r);
    for (int c = 0; c < ew; ++c) dirs[std::size_t(r) * ew + c] = latlong_direction(ew, eh, c + 0.5, r + 0.5);
  }
  Image out(out_width, out_height, 3);
  tbb::parallel_for(0, out_height, [&](int orow) {
    for (int ocol = 0; ocol < out_width; ++ocol) {
      const Vec3 w = latlong_direction(out_width, out_height, ocol + 0.5, orow + 0.5);
      double sum[3] = {0, 0, 0}, weight = 0;
      for (int r = 0; r < eh; ++r) {
        const float* row = env.pixel(0, r);
        for (int c = 0; c < ew; ++c) {
          const Vec3& wi = dirs[std::size_t(r) * ew + c];
          const double p = render::physics::henyey_greenstein(g, w.x * wi.x + w.y * wi.y +
                                                                     w.z * wi.z) *
                           solid[std::size_t(r)];
          weight += p;
          for (int k = 0; k < 3; ++k) sum[k] += p * row[3 * c + k];
        }
      }
      for (int k = 0; k < 3; ++k) out.at(ocol, orow, k) = float(sum[k] / weight);
    }
  });
  return out;
}

LatLongSizes latlong_sizes_for(double g) {
  // The lobe's half-width: p(theta) = p(0) / 2 where (1 + g^2 - 2 g cos) = (1 - g)^2 2^(2/3).
  double half_width = kPi / 2;  // back-scattering or isotropic phases: a wide lobe
  if (g > 0.05) {
    const double c = (1 + g * g - (1 - g) * (1 - g) * std::cbrt(4.0)) / (2 * g);
    half_width = std::acos(std::clamp(c, -1.0, 1.0));
  }
  // Eight texels across the half-width (2.8 degrees for haze's g = 0.6), 32..256 rows.
  int h = int(std::ceil(8 * kPi / half_width));
  h = std::clamp((h + 1) / 2 * 2, 32, 256);
  const int oh = std::max(16, h / 2);
  return {2 * h, h, 2 * oh, oh};
}

Image environment_deviation(ConstImageView photo, ConstImageView distance_m, const Camera& camera,
                            const CameraPose& pose, const std::array<float, 3>& sky_radiance,
                            int width, int height) {
  const int half = height / 2;  // rows [0, half) above the horizon
  std::vector<double> sum(std::size_t(width) * half * 3, 0.0), count(std::size_t(width) * half, 0);
  std::vector<double> row_sum(std::size_t(half) * 3, 0.0), row_count(std::size_t(half), 0.0);
  double ground_sum[3] = {0, 0, 0}, ground_count = 0;
  double surface_sum[3] = {0, 0, 0}, surface_count = 0;
  for (int y = 0; y < photo.height; ++y)
    for (int x = 0; x < photo.width; ++x) {
      const float* p = photo.pixel(x, y);
      if (!(std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]))) continue;
      const double v[3] = {std::max(0.0f, p[0]), std::max(0.0f, p[1]), std::max(0.0f, p[2])};
      const Vec3 d = pose.ray_direction(camera, x, y);
      const bool sky = render::physics::is_sky(distance_m.at(x, y, 0));
      if (!sky) {
        for (int c = 0; c < 3; ++c) surface_sum[c] += v[c];
        ++surface_count;
        if (d.y < 0) {
          for (int c = 0; c < 3; ++c) ground_sum[c] += v[c];
          ++ground_count;
        }
        continue;
      }
      if (d.y < 0) continue;  // below the horizon the environment is the ground
      const double az = std::atan2(d.x, d.z), el = std::asin(std::clamp(d.y, 0.0, 1.0));
      const int col = std::clamp(int((az + kPi) / (2 * kPi) * width), 0, width - 1);
      const int row = std::clamp(int((0.5 * kPi - el) / kPi * height), 0, half - 1);
      const std::size_t t = std::size_t(row) * width + col;
      for (int c = 0; c < 3; ++c) {
        sum[3 * t + c] += v[c];
        row_sum[3 * std::size_t(row) + c] += v[c];
      }
      ++count[t];
      ++row_count[std::size_t(row)];
    }
  // The ground's upward radiance: the surfaces below the horizon (any surface, else L_sky).
  double ground[3];
  for (int c = 0; c < 3; ++c)
    ground[c] = ground_count > 0    ? ground_sum[c] / ground_count
                : surface_count > 0 ? surface_sum[c] / surface_count
                                    : double(sky_radiance[c]);
  // Each sky row's mean; rows without sky: interpolated between the nearest rows with sky
  // (a + (b - a) t: equal neighbours give exactly their value), held beyond them, L_sky with
  // no sky at all.
  std::vector<double> row_mean(std::size_t(half) * 3);
  std::vector<int> with_sky;
  for (int r = 0; r < half; ++r)
    if (row_count[std::size_t(r)] > 0) with_sky.push_back(r);
  for (int r = 0; r < half; ++r) {
    double* m = &row_mean[3 * std::size_t(r)];
    if (with_sky.empty()) {
      for (int c = 0; c < 3; ++c) m[c] = sky_radiance[c];
      continue;
    }
    const auto above = std::upper_bound(with_sky.begin(), with_sky.end(), r);
    const int b = above == with_sky.end() ? with_sky.back() : *above;
    const int a = above == with_sky.begin() ? with_sky.front() : *(above - 1);
    const double t = b == a ? 0.0 : double(r - a) / double(b - a);
    for (int c = 0; c < 3; ++c) {
      const double va = row_sum[3 * std::size_t(a) + c] / row_count[std::size_t(a)];
      const double vb = row_sum[3 * std::size_t(b) + c] / row_count[std::size_t(b)];
      m[c] = va + (vb - va) * t;
    }
  }
  Image out(width, height, 3);
  for (int r = 0; r < half; ++r)
    for (int col = 0; col < width; ++col)
      for (int c = 0; c < 3; ++c) {
        const std::size_t t = std::size_t(r) * width + col;
        const double v = count[t] > 0 ? sum[3 * t + c] / count[t] : row_mean[3 * std::size_t(r) + c];
        out.at(col, r, c) = float(v - double(sky_radiance[c]));
      }
  // Below the horizon: the ground seen from inside the fog. The light scattered toward the
  // camera comes from points spread along the view ray, about one optical depth in; seen from
  // such a point (for a ray at 30 degrees: half an optical depth above the camera), the ground
  // lies behind optical depth kGroundOpticalHeight / sin(depression) of fog, and what the fog in
  // between sends is the horizon sky's light (a deep path through the same fog). So the
  // environment goes from the horizon sky's colour (in its column) at the horizon to mostly the
  // ground's colour straight down, with no step at the horizon.
  constexpr double kGroundOpticalHeight = 0.5;
  for (int r = half; r < height; ++r) {
    const double depression = std::sin(-texel_elevation(height, r + 0.5));
    const double to_ground = std::exp(-kGroundOpticalHeight / depression);
    for (int col = 0; col < width; ++col)
      for (int c = 0; c < 3; ++c) {
        const double horizon = double(out.at(col, half - 1, c)) + double(sky_radiance[c]);
        const double v = horizon + (ground[c] - horizon) * to_ground;
        out.at(col, r, c) = float(v - double(sky_radiance[c]));
      }
  }
  return out;
}

// min(ratio, 1) with its corner rounded below 1 by the cubic that leaves the line with slope 1
// at 1 - knee and arrives at 1 with slope 0 (C1): exactly 1 from 1 on (a sky as bright as the
// light or brighter keeps it), the ratio itself below 1 - knee, and never above 1; on the
// knee it is up to 4/27 knee above the ratio.
double soft_limit_to_one(double ratio, double knee) {
  if (ratio >= 1) return 1;
  if (ratio <= 1 - knee) return ratio;
  const double t = (ratio - (1 - knee)) / knee;
  return 1 - knee + knee * (t + t * t - t * t * t);
}

// The rise above 1 of the light's ratio to a brighter sky, 0 at 1 and C1 there (slope 0, as
// soft_limit_to_one arrives at 1 from below: no kink in the fogged sky where the photo's sky
// crosses the light's luma), then the ratio's own slope, reaching at most max_rise over a knee.
double soft_rise_above_one(double ratio, double knee, double max_rise) {
  const double t = ratio - 1;
  if (!(t > 0)) return 0;
  const double rise = t < knee ? t * t / (2 * knee) : t - knee / 2;
  return max_rise * soft_limit_to_one(rise / max_rise, knee);
}

bool all_zero(const Image& map) {
  for (float v : map.pixels())
    if (v != 0) return false;
  return true;
}

void wide_gaussian_blur(cv::Mat& image, double sigma_px) {
  constexpr double kDirectBelowPx = 4;
  if (sigma_px < kDirectBelowPx) {
    cv::GaussianBlur(image, image, cv::Size(0, 0), sigma_px, sigma_px, cv::BORDER_REPLICATE);
    return;
  }
  constexpr int kPasses = 3;
  const double variance = sigma_px * sigma_px;
  int lower = int(std::floor(std::sqrt(12 * variance / kPasses + 1)));
  if (lower % 2 == 0) --lower;  // odd widths, centred
  const int upper = lower + 2;
  // The fewest passes at the lower width whose variance (a box of width b: (b^2 - 1) / 12) does
  // not exceed the Gaussian's; an exact Gaussian of the small remainder makes it up.
  auto box_variance = [&](int lower_passes) {
    return (lower_passes * (lower * lower - 1) + (kPasses - lower_passes) * (upper * upper - 1)) /
           12.0;
  };
  int lower_passes = 0;
  while (box_variance(lower_passes) > variance) ++lower_passes;
  for (int pass = 0; pass < kPasses; ++pass) {
    const int width = pass < lower_passes ? lower : upper;
    cv::blur(image, image, cv::Size(width, width), cv::Point(-1, -1), cv::BORDER_REPLICATE);
  }
  if (const double rest = std::sqrt(variance - box_variance(lower_passes)); rest > 0.05)
    cv::GaussianBlur(image, image, cv::Size(0, 0), rest, rest, cv::BORDER_REPLICATE);
}

Image sky_brightness_scale(ConstImageView photo, ConstImageView distance_m, const Camera& camera,
                           const CameraPose& pose, const Image& deviation,
                           const std::array<float, 3>& sky_radiance, Image* tint) {
  if (tint) *tint = Image{};
  const int w = photo.width, h = photo.height;
  if (w < 1 || h < 1 || photo.channels < 3 || deviation.empty()) return {};
  const std::size_t count = std::size_t(w) * h;
  // The sky mask and the display-referred guide.
  std::vector<float> guide(3 * count), luma(count);
  // The display-encoded colour (as display_luma encodes it), for the sky's local hue (tint).
  std::vector<float> colour(tint ? 3 * count : 0);
  cv::Mat sky(h, w, CV_8U, cv::Scalar(0));
  tbb::parallel_for(0, h, [&](int y) {
    for (int x = 0; x < w; ++x) {
      const float* p = photo.pixel(x, y);
      const std::size_t i = std::size_t(y) * w + x;
      const bool finite = std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]);
      // The display encoding once: display_luma's sum, the tint's colour and (clamped to 1)
      // the guide.
      const double e[3] = {display_encode(p[0]), display_encode(p[1]), display_encode(p[2])};
      for (int c = 0; c < 3; ++c) guide[3 * i + c] = finite ? float(std::min(1.0, e[c])) : 0.0f;
      luma[i] = finite ? float(0.2126 * e[0] + 0.7152 * e[1] + 0.0722 * e[2]) : 0.0f;
      for (int c = 0; tint && c < 3; ++c) colour[3 * i + c] = finite ? float(e[c]) : 0.0f;
      if (finite && render::physics::is_sky(distance_m.at(x, y, 0))) sky.at<std::uint8_t>(y, x) = 1;
    }
  });
  if (cv::countNonZero(sky) == 0) return {};
  // Thin structures the sky mask took for sky (cables, a ladder's rails, a lattice's struts:
  // rocket, bridge, coldripple) would keep part of their contrast in the average, fading in
  // and out along their length: a median over kMedianFraction of the frame removes them from
  // the guide (anything wider, a cloud's body, keeps its edges), and the pixels that stand off
  // the median by more than kStructureLuma do not feed the average (its luma stays the photo's
  // own, unquantized and unclamped: a uniform sky gives exactly the light's luma back).
  constexpr double kMedianFraction = 0.012;
  constexpr float kStructureLuma = 0.03f;
  const int median_px =
      std::clamp(int(std::lround(kMedianFraction * std::max(w, h))) / 2 * 2 + 1, 5, 31);
  cv::Mat structure(h, w, CV_8U, cv::Scalar(0));
  {
    cv::Mat g8(h, w, CV_8UC3);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        for (int c = 0; c < 3; ++c)
          g8.at<cv::Vec3b>(y, x)[c] =
              cv::saturate_cast<std::uint8_t>(255 * guide[3 * (std::size_t(y) * w + x) + c]);
    cv::Mat m8;
    cv::medianBlur(g8, m8, median_px);
    auto luma8 = [](const cv::Vec3b& v) {
      return (0.2126f * v[0] + 0.7152f * v[1] + 0.0722f * v[2]) / 255.0f;
    };
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const std::size_t i = std::size_t(y) * w + x;
        const cv::Vec3b& v = m8.at<cv::Vec3b>(y, x);
        for (int c = 0; c < 3; ++c) guide[3 * i + c] = v[c] / 255.0f;
        structure.at<std::uint8_t>(y, x) =
            std::abs(luma8(g8.at<cv::Vec3b>(y, x)) - luma8(v)) > kStructureLuma;
      }
  }
  // The core of the sky: sky pixels whose whole median window is sky (the binary sky's outer
  // pixels are mixed with the surface along its edge, and a window reaching past it judges
  // structure against the surface) that are not structure.
  const cv::Mat window = cv::getStructuringElement(cv::MORPH_RECT, cv::Size(median_px, median_px));
  cv::Mat core;
  cv::erode(sky, core, window);
  core.setTo(0, structure);
  // A lattice dense enough that its steel outweighs its openings in the median window (rocket's
  // launch towers) passes the structure test (the median is steel, and the openings are what
  // stands off it), and against a dark dusk sky its steel is not much darker than the sky: it
  // fed the average and darkened the fog into ghostly columns (haze14's v5/v6). Dark things
  // narrower than kClosingFraction of the frame in some direction (struts, cables, a facade's
  // windows) are not the sky's brightness: a grey closing of the sky's luma (the maximum over a
  // square window, then the minimum; surfaces left out of both) lifts them to the brightness
  // of the sky around them, while a dark cloud wider than the window keeps its own. A pixel
  // darker than kDarkShare below its closing does not feed the average (the closing itself is
  // not the data: its flat-topped plateaus would show as blocks in a sky of wisps). kDarkShare
  // 0.2: at 0.1 the dark gaps between backlit clouds next to their glow were kept out too, and
  // the fog there took the glow's brightness (SkyLight.BacklitCloudsUnderAWeakHorizonLowerIt:
  // 0.0212 % created edges; 0.0085 % at 0.2, as without the closing).
  constexpr double kClosingFraction = 0.03;
  constexpr float kDarkShare = 0.2f, kBrightShare = 0.1f;
  {
    const int closing_px = std::max(3, int(std::lround(kClosingFraction * std::max(w, h))) | 1);
    const cv::Mat square =
        cv::getStructuringElement(cv::MORPH_RECT, cv::Size(closing_px, closing_px));
    cv::Mat l(h, w, CV_32F), high, closed;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        l.at<float>(y, x) = sky.at<std::uint8_t>(y, x) ? luma[std::size_t(y) * w + x] : 0.0f;
    cv::dilate(l, high, square, cv::Point(-1, -1), 1, cv::BORDER_REPLICATE);
    high.setTo(std::numeric_limits<float>::max(), sky == 0);
    cv::erode(high, closed, square, cv::Point(-1, -1), 1, cv::BORDER_REPLICATE);
    core.setTo(0, l < (1 - kDarkShare) * closed);
    // The same for bright structures (a lit lattice against a dusk sky, a pale tower): a grey
    // opening (the minimum, then the maximum; surfaces left out) brings them down to the sky
    // around them, and a pixel brighter than kBrightShare above it does not feed the average.
    cv::Mat low, opened;
    l.setTo(std::numeric_limits<float>::max(), sky == 0);
    cv::erode(l, low, square, cv::Point(-1, -1), 1, cv::BORDER_REPLICATE);
    low.setTo(0, sky == 0);
    cv::dilate(low, opened, square, cv::Point(-1, -1), 1, cv::BORDER_REPLICATE);
    core.setTo(0, l > (1 + kBrightShare) * opened);
  }
  // Normalized convolution: the filter of (core Y', core) and, for the tint, of the core's
  // display colour; their ratios.
  const int n = tint ? 5 : 2;
  std::vector<float> data(std::size_t(n) * count);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      const float m = core.at<std::uint8_t>(y, x) ? 1.0f : 0.0f;
      data[n * i] = m * luma[i];
      data[n * i + 1] = m;
      for (int c = 0; c < n - 2; ++c) data[n * i + 2 + c] = m * colour[3 * i + c];
    }
  // Smoothing over about 3 % of the frame (the haze hides the sky's fine texture), stopped by
  // steps of the guide's channels summing to about kEdgeSigma.
  constexpr double kSmoothingFraction = 0.03, kEdgeSigma = 0.2;
  domain_transform_filter(data, n, guide, w, h, kSmoothingFraction * std::max(w, h), kEdgeSigma);
  // The scale on the sky: the local luma against the sky light's along the pixel's ray.
  // The average's own weight (the share of core sky that reached the pixel) says how much it
  // holds: below kFullWeight the scale fades into the plain average below (a sky pocket
  // narrower than the core's window, far along the filter from any core), with no step.
  constexpr float kMinWeight = 1e-6f, kFullWeight = 0.1f;
  // Only ever darker: where the photo's sky is brighter than the light (a glow, white clouds,
  // a pale tower taken for sky) the haze keeps its flat light, as before; brightening it
  // brought back structures the sky mask took in and made the matte's spill at a bright
  // horizon stand out (a mixed pixel given the sky's fog).
  // The limit is reached over a knee of kKnee in the luma ratio: a hard one cut
  // the fogged sky's gradient along the contour where the photo's sky meets the light, a Mach
  // band drawn as a bright arc through a sunset's haze (sunset_aitzol).
  constexpr double kMinScale = 0.1, kKnee = 0.3;
  // Deep in the sky, away from every surface, the light follows the sky's own luma (photo/
  // sky_light.h): darker as it is, brighter by kRiseShare of its excess over the flat light,
  // up to kMaxRise above it. In full from kDeepFarFraction of the frame away from the nearest
  // surface pixel, not at all within kDeepNearFraction (a smoothstep between).
  constexpr double kDeepNearFraction = 0.05, kDeepFarFraction = 0.25, kMaxRise = 1.5,
                   kRiseShare = 0.7;
  const double kMaxScale = std::pow(1 + kMaxRise, kDisplayGamma);
  cv::Mat from_surface;  // each sky pixel's distance to the nearest surface pixel
  cv::distanceTransform(sky, from_surface, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  const double deep_near_px = kDeepNearFraction * std::max(w, h),
               deep_far_px = kDeepFarFraction * std::max(w, h);
  // The tint: the light's colour moved kSkyHueShare of the way toward the hue of the photo's
  // own sky around the pixel (its display colour normalised to unit luma), at the scaled
  // light's display luma, which the blend leaves unchanged (luma is linear in display values),
  // so the created-edge balance of the scale above holds. The neutral prior alone turned a
  // deep blue sky seen through haze into slate grey at the blue's luma (palace, kite):
  // haze lit by a blue sky and no sun takes some of that sky's colour, and the chroma bound
  // of the fog colour (the gallery's C*) still holds the blend to a muted blue.
  constexpr double kSkyHueShare = 0.5;
  // The blend's colour is bounded as every automatic fog colour is (photo/airlight.h), but with
  // the cool end of the daylight locus moved out to a clear sky's light (blue skylight without
  // the sun reaches 15000-25000 K and beyond, against the prior's 10000 K for daylight); the
  // chroma bound (33.6, under the gallery's 36.1) binds first on a deep blue sky.
  NeutralPrior skylight_prior;
  skylight_prior.cool_limit = 0.06;
  skylight_prior.knee_fraction = 1;
  // The sky light along pixel (x, y)'s ray (scene-linear), for the scale and again for the tint.
  auto light_at = [&](int x, int y) {
    const auto d = sample_latlong(deviation, pose.ray_direction(camera, x, y));
    return std::array<double, 3>{sky_radiance[0] + d[0], sky_radiance[1] + d[1],
                                 sky_radiance[2] + d[2]};
  };
  std::vector<float> scale(count, 1.0f);
  // The scale without the sky's own luma, for the surfaces (a surface under the sky takes the
  // sky's average, not the single pixel's luma nearest to it).
  std::vector<float> near_scale(count, 1.0f);
  std::vector<float> hue(tint ? 3 * count : 0, 1.0f);  // the tint's factor on the scaled light
  cv::Mat sky_weight(h, w, CV_32F, cv::Scalar(0));
  cv::Mat deep_weight(h, w, CV_32F, cv::Scalar(0));
  tbb::parallel_for(0, h, [&](int y) {
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      const float* a = &data[std::size_t(n) * i];
      if (!sky.at<std::uint8_t>(y, x)) continue;
      const double t0 = std::clamp(
          (from_surface.at<float>(y, x) - deep_near_px) / (deep_far_px - deep_near_px), 0.0, 1.0);
      const double t = t0 * t0 * (3 - 2 * t0);
      const bool averaged = a[1] > kMinWeight;
      if (!averaged && !(t > 0)) continue;
      const double local = averaged ? double(a[0]) / double(a[1]) : 0.0;
      const std::array<double, 3> lin = light_at(x, y);
      const double light = display_luma(lin[0], lin[1], lin[2]);
      if (!(light > 0) || !(local >= 0)) continue;
      // Near a surface: the edge-aware average, only ever darker. Deep in the sky: the sky's
      // own luma, darker as it is and brighter by kRiseShare of its excess.
      const double own_ratio = luma[i] / light;
      const double deep = soft_limit_to_one(own_ratio, kKnee) +
                          kRiseShare * soft_rise_above_one(own_ratio, kKnee, kMaxRise);
      const double near = averaged ? soft_limit_to_one(local / light, kKnee) : deep;
      const float s = float(
          std::clamp(std::pow(near + t * (deep - near), kDisplayGamma), kMinScale, kMaxScale));
      scale[i] = s;
      deep_weight.at<float>(y, x) = float(t);
      if (!averaged) continue;  // never a sound source for the surfaces: no near_scale
      near_scale[i] = float(std::clamp(std::pow(near, kDisplayGamma), kMinScale, 1.0));
      sky_weight.at<float>(y, x) = std::min(1.0f, a[1] / kFullWeight);
      // The local sky's display colour at unit luma (its hue), for the tint below.
      for (int c = 0; tint && local > 0 && c < 3; ++c)
        hue[3 * i + c] = float(double(a[2 + c]) / double(a[1]) / local);
    }
  });
  // The tint. The sky's hue is blurred over kHueBlurFraction of the frame first (not
  // edge-aware): the edge-aware average stops at a cloud's rim, and a white cloud kept at the
  // light's luma turned into a grey cut-out with a sharp hue edge inside the blue (kite). Then,
  // per pixel: the unit-luma display colours of the light (scaling leaves them as they are) and
  // of the sky, blended, at the scaled light's luma, back to scene-linear, bounded; the factor
  // on the scaled light. (Blurring the bounded factors instead mixed lights of different rows
  // and made a sunset's warmth step back and forth down the sky.)
  constexpr double kHueBlurFraction = 0.015;
  if (tint) {
    cv::Mat weighted(h, w, CV_32FC3), weight(h, w, CV_32F);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const std::size_t i = std::size_t(y) * w + x;
        const float m = sky.at<std::uint8_t>(y, x) ? sky_weight.at<float>(y, x) : 0.0f;
        weight.at<float>(y, x) = m;
        for (int c = 0; c < 3; ++c) weighted.at<cv::Vec3f>(y, x)[c] = m * hue[3 * i + c];
      }
    const double blur_px = std::max(1.0, kHueBlurFraction * std::max(w, h));
    wide_gaussian_blur(weighted, blur_px);
    wide_gaussian_blur(weight, blur_px);
    tbb::parallel_for(0, h, [&](int y) {
      for (int x = 0; x < w; ++x) {
        const std::size_t i = std::size_t(y) * w + x;
        const float m = weight.at<float>(y, x);
        const float s = scale[i];
        float* factor = &hue[3 * i];
        if (!sky.at<std::uint8_t>(y, x) || !(m > 1e-4f) || !(sky_weight.at<float>(y, x) > 0)) {
          factor[0] = factor[1] = factor[2] = 1.0f;
          continue;
        }
        const std::array<double, 3> lin = light_at(x, y);
        const double light = display_luma(lin[0], lin[1], lin[2]);
        const double light_scaled = light * std::pow(double(s), 1 / kDisplayGamma);
        std::array<float, 3> target;
        for (int c = 0; c < 3; ++c) {
          const double own = display_encode(lin[c]) / light;
          const double sky_hue = double(weighted.at<cv::Vec3f>(y, x)[c]) / m;
          target[c] = float(std::pow(
              std::max(0.0, light_scaled * ((1 - kSkyHueShare) * own + kSkyHueShare * sky_hue)),
              kDisplayGamma));
        }
        // (The bound keeps the luminance; the display luma is the scale's, so it is put back.)
        std::array<float, 3> bounded = neutral_fog_colour(target, skylight_prior);
        const double luma_target = display_luma(target[0], target[1], target[2]),
                     luma_bounded = display_luma(bounded[0], bounded[1], bounded[2]);
        if (luma_bounded > 0)
          for (float& v : bounded)
            v = float(v * std::pow(luma_target / luma_bounded, kDisplayGamma));
        for (int c = 0; c < 3; ++c) {
          const double scaled = double(s) * std::max(0.0, lin[c]);
          factor[c] = scaled > 0 ? float(std::clamp(bounded[c] / scaled, 0.0, 4.0)) : 1.0f;
        }
      }
    });
  }
  // Elsewhere, and where the average holds little: the scale of the nearest sky pixel whose
  // average is sound (a far hill under the sky, at T ~ 0, shows the same fog as the sky just
  // above it, not a broad average that takes in a darker zenith), smoothed over kSpreadFraction
  // of the frame so the nearest pixels' cells leave no seams, and fading to 1 with the distance
  // from the sky (kFadeFraction of the frame; near surfaces are nearly clear anyway). The fade
  // counts from any sky pixel, sound or not: the steel of a lattice taken partly for surface
  // lies between its sky-coloured openings, far from sound sky, and faded to the flat light it
  // stood out as a lighter ghost of the tower where the fog hides it (rocket in dense fog); a
  // surface seen right beside the sky is seen in the sky's direction, through the same fog.
  // The tint spreads and fades as the scale does.
  constexpr double kSpreadFraction = 0.01, kFadeFraction = 0.05;
  std::vector<std::uint8_t> sound(count, 0);
  bool any_sound = false;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      sound[std::size_t(y) * w + x] = sky_weight.at<float>(y, x) >= 1.0f;
      any_sound |= sky_weight.at<float>(y, x) >= 1.0f;
    }
  if (!any_sound) return {};
  const std::vector<std::int32_t> nearest = nearest_source(w, h, sound);
  const int k_channels = tint ? 4 : 1;  // the scale, then the tint's three factors
  cv::Mat spread(h, w, CV_32FC(k_channels));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::int32_t k = nearest[std::size_t(y) * w + x];
      float* f = spread.ptr<float>(y) + std::size_t(k_channels) * x;
      f[0] = k >= 0 ? near_scale[std::size_t(k)] : 1.0f;
      for (int c = 1; c < k_channels; ++c) f[c] = k >= 0 ? hue[3 * std::size_t(k) + c - 1] : 1.0f;
    }
  const double spread_px = std::max(1.0, kSpreadFraction * std::max(w, h));
  wide_gaussian_blur(spread, spread_px);
  const double fade_px = kFadeFraction * std::max(w, h);
  cv::Mat from_sky;  // each pixel's distance to the nearest sky pixel (0 on the sky)
  cv::distanceTransform(sky == 0, from_sky, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  bool any = false, any_tint = false;
  Image out(w, h, 1);
  Image tinted(tint ? w : 0, tint ? h : 0, 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      // The sky's own luma deep in the sky holds whatever the average's weight (the scale's;
      // the tint comes from the average alone).
      const float b_tint = sky_weight.at<float>(y, x);
      const float b_scale = b_tint + deep_weight.at<float>(y, x) * (1 - b_tint);
      const float* f = spread.ptr<float>(y) + std::size_t(k_channels) * x;
      const bool on_sky = sky.at<std::uint8_t>(y, x);
      const float fade = on_sky ? 0.0f : float(std::exp(-from_sky.at<float>(y, x) / fade_px));
      for (int c = 0; c < k_channels; ++c) {
        const float own = c == 0 ? scale[i] : hue[3 * i + c - 1];
        const float b = c == 0 ? b_scale : b_tint;
        const float v = on_sky ? f[c] + b * (own - f[c]) : 1.0f + fade * (f[c] - 1.0f);
        if (c == 0) {
          out.at(x, y, 0) = v;
          any |= v != 1.0f;
        } else {
          tinted.at(x, y, c - 1) = v;
          any_tint |= v != 1.0f;
        }
      }
    }
  if (tint && any_tint) *tint = std::move(tinted);
  if (!any) return {};
  return out;
}

}  // namespace mr::photo
