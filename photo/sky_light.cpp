#include "photo/sky_light.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <vector>

#include "render/physics/medium.h"
#include "render/physics/scattering.h"

namespace mr::photo {

namespace {

constexpr double kPi = std::numbers::pi;

double texel_elevation(int height, double row) {
  return 0.5 * kPi - row / height * kPi;
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

bool all_zero(const Image& map) {
  for (float v : map.pixels())
    if (v != 0) return false;
  return true;
}

}  // namespace mr::photo
