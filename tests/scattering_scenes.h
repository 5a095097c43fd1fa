// Scenes and small helpers shared by the scattering core's tests (tests/scattering_test.cpp,
// compiled once per backend) and the GPU-vs-CPU comparisons (tests/vulkan_scattering_test.cpp).
#pragma once

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

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

/// A birch forest seen from 1.6 m: 300 trunks (radius 6-20 cm, 6-25 m tall, so most are cut by
/// the frame's top) standing on the ground 4-70 m ahead over 50 m of width, each with three
/// thin branches (radius 3-5 cm, 1.5-3 m long, rising 30 degrees), sky between them. Under
/// low_sun_height_fog_scene's sun (in front of the camera) every view ray crosses shafts: the
/// scene where nearly every grid cell has a shadow edge (render/scattering_cpu.cpp, pass 2).
/// Depth of each pixel's centre ray, exact (ray-cylinder intersections). Deterministic.
inline Image forest_depth(const Camera& cam, const CameraPose& pose) {
  struct Cylinder {
    Vec3 base, axis;  // axis: unit direction
    double length, radius;
  };
  std::vector<Cylinder> cylinders;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0, 1);
  for (int i = 0; i < 300; ++i) {
    const double x = -25 + 50 * u(rng), z = 4 + 66 * u(rng);
    const double radius = 0.06 + 0.14 * u(rng), height = 6 + 19 * u(rng);
    cylinders.push_back({{x, 0, z}, {0, 1, 0}, height, radius});
    for (int b = 0; b < 3; ++b) {
      const double y = 2 + 6 * u(rng), a = 2 * kPi * u(rng), rise = kPi / 6;
      cylinders.push_back(
          {{x, y, z},
           {std::cos(a) * std::cos(rise), std::sin(rise), std::sin(a) * std::cos(rise)},
           1.5 + 1.5 * u(rng),
           0.03 + 0.02 * u(rng)});
    }
  }
  Image depth = ground_depth(cam, pose);
  const Vec3 o = pose.position_m;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const Vec3 w = pose.ray_direction(cam, x, y);
      float& d = depth.at(x, y, 0);
      for (const Cylinder& c : cylinders) {
        // |(p - base) - ((p - base).axis) axis| = radius, with p = o + t w, t > 0, and the
        // point's position along the axis within [0, length]: the nearer root.
        const Vec3 m{o.x - c.base.x, o.y - c.base.y, o.z - c.base.z};
        const double wa = dot(w, c.axis), ma = dot(m, c.axis);
        const Vec3 wp{w.x - wa * c.axis.x, w.y - wa * c.axis.y, w.z - wa * c.axis.z};
        const Vec3 mp{m.x - ma * c.axis.x, m.y - ma * c.axis.y, m.z - ma * c.axis.z};
        const double qa = dot(wp, wp), qb = 2 * dot(wp, mp), qc = dot(mp, mp) - c.radius * c.radius;
        const double disc = qb * qb - 4 * qa * qc;
        if (qa < 1e-12 || disc < 0) continue;
        const double t = (-qb - std::sqrt(disc)) / (2 * qa);
        const double along = ma + t * wa;
        if (t > 0.1 && t < d && along >= 0 && along <= c.length) d = float(t);
      }
    }
  return depth;
}

}  // namespace mr::test
