// Scenes and small helpers shared by the scattering core's tests (tests/scattering_test.cpp,
// compiled once per backend) and the GPU-vs-CPU comparisons (tests/vulkan_scattering_test.cpp).
#pragma once

#include <cmath>
#include <functional>
#include <limits>
#include <numbers>

#include "mr/image.h"
#include "mr/scene.h"

namespace mr::test {

constexpr double kPi = std::numbers::pi;
constexpr float kInf = std::numeric_limits<float>::infinity();

/// Henyey-Greenstein phase function, written out independently of render/medium.h.
inline double hg(double g, double c) {
  return (1 - g * g) / (4 * kPi * std::pow(1 + g * g - 2 * g * c, 1.5));
}
inline double dot(const Vec3& a, const Vec3& b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
inline Vec3 normalize(const Vec3& v) {
  const double n = std::sqrt(dot(v, v));
  return {v.x / n, v.y / n, v.z / n};
}

/// Composite Simpson on [a, b] with n (even) intervals.
inline double simpson(const std::function<double(double)>& f, double a, double b, int n) {
  const double h = (b - a) / n;
  double s = f(a) + f(b);
  for (int i = 1; i < n; ++i) s += f(a + i * h) * (i % 2 ? 4 : 2);
  return s * h / 3;
}

/// A depth map where every pixel sees a surface at distance `d`.
inline Image constant_depth(const Camera& cam, float d) {
  Image im(cam.width, cam.height, 1, {"Z"});
  for (float& v : im.pixels()) v = d;
  return im;
}

/// Ground plane y = 0 seen from the pose; sky (+inf) above the horizon.
inline Image ground_depth(const Camera& cam, const CameraPose& pose) {
  Image im(cam.width, cam.height, 1, {"Z"});
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const Vec3 w = pose.ray_direction(cam, x, y);
      im.at(x, y, 0) = w.y < -1e-6 ? float(-pose.position_m.y / w.y) : kInf;
    }
  return im;
}

/// A street: the ground, a wall on the left (x = -3, 6 m high), a pillar 1 m wide at x in [1, 2],
/// z = 12, 8 m high, a far wall (z = 60, 14 m high); sky above.
inline Image street_depth(const Camera& cam, const CameraPose& pose) {
  Image depth = ground_depth(cam, pose);
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const Vec3 w = pose.ray_direction(cam, x, y);
      float& d = depth.at(x, y, 0);
      if (w.x < 0) {
        const double t = -3.0 / w.x;
        if (pose.position_m.y + t * w.y < 6 && t < d) d = float(t);
      }
      if (w.z > 0) {
        const double t = (60 - pose.position_m.z) / w.z;
        if (pose.position_m.y + t * w.y < 14 && t < d) d = float(t);
        const double tp = (12 - pose.position_m.z) / w.z;
        const double px = pose.position_m.x + tp * w.x, py = pose.position_m.y + tp * w.y;
        if (px > 1 && px < 2 && py < 8 && tp < d) d = float(tp);
      }
    }
  return depth;
}

/// Coloured fog with g 0.4, no sky light, final quality (the closed-form tests' start).
inline FogScene base_scene() {
  FogScene s;
  s.medium.sigma_t_per_m = {0.02f, 0.02f, 0.02f};
  s.medium.albedo = {0.9f, 0.8f, 0.7f};
  s.medium.g = 0.4;
  s.lighting.sky_radiance = Rgb{0, 0, 0};
  s.render.quality = Quality::final;
  return s;
}

/// Issue 11's sun bank look: height fog (90 m visibility at the ground, scale height 12 m, top
/// 40 m, g 0.6) under a low sun (elevation 8 deg, azimuth 20), sky light, a level camera 1.6 m
/// above the ground (ground_depth), normal quality.
inline FogScene low_sun_height_fog_scene() {
  FogScene s = base_scene();
  s.pose.position_m = {0, 1.6, 0};
  const float sigma = float(3.912 / 90);
  s.medium.sigma_t_per_m = {sigma, sigma, sigma};
  s.medium.albedo = {1, 1, 1};
  s.medium.g = 0.6;
  s.medium.height_fog = Medium::HeightFog{0.0, 12.0};
  s.medium.layer_top_m = 40;
  s.lighting.sky_radiance = Rgb{0.3f, 0.32f, 0.36f};
  s.lighting.sun = Sun{direction_from_azimuth_elevation(20, 8), {3, 3, 3}, 0.27};
  s.render.quality = Quality::normal;
  return s;
}

}  // namespace mr::test
