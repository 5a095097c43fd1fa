#include "mr/scene.h"
#include "core/vec3.h"

#include <bit>
#include <cmath>
#include <cstdint>
#include <numbers>

namespace mr {

namespace {

using vec3::cross;  // core/vec3.h
constexpr double kDeg = std::numbers::pi / 180.0;
}  // namespace

std::array<Vec3, 3> CameraPose::axes() const {
  // ray_direction asks for the axes once a pixel, and the photo's stages ask for millions of
  // pixels of one pose: the last pose's axes are kept per thread (six trig calls a ray were
  // 10 % of an automatic 12 MP fog). The same arithmetic either way: bit-identical rays.
  // (Compared bit for bit: -0 and 0 give different signed zeros.)
  using Bits = std::array<std::uint64_t, 3>;
  const Bits angles{std::bit_cast<std::uint64_t>(yaw_deg), std::bit_cast<std::uint64_t>(pitch_deg),
                    std::bit_cast<std::uint64_t>(roll_deg)};
  thread_local bool known = false;
  thread_local Bits last_angles{};
  thread_local std::array<Vec3, 3> last_axes{};
  if (known && angles == last_angles) return last_axes;
  const double cy = std::cos(yaw_deg * kDeg), sy = std::sin(yaw_deg * kDeg);
  const double cp = std::cos(pitch_deg * kDeg), sp = std::sin(pitch_deg * kDeg);
  const double cr = std::cos(roll_deg * kDeg), sr = std::sin(roll_deg * kDeg);
  const Vec3 forward{sy * cp, sp, cy * cp};
  const Vec3 right0{cy, 0, -sy};
  const Vec3 up0 = cross(forward, right0);
  const Vec3 right{cr * right0.x - sr * up0.x, cr * right0.y - sr * up0.y, cr * right0.z - sr * up0.z};
  const Vec3 up{sr * right0.x + cr * up0.x, sr * right0.y + cr * up0.y, sr * right0.z + cr * up0.z};
  known = true;
  last_angles = angles;
  last_axes = {forward, right, up};
  return last_axes;
}

Vec3 CameraPose::ray_direction(const Camera& camera, double x, double y) const {
  const auto [f, r, u] = axes();
  const double a = (x + 0.5 - camera.cx) / camera.focal_px;
  const double b = (y + 0.5 - camera.cy) / camera.focal_px;
  Vec3 d{a * r.x - b * u.x + f.x, a * r.y - b * u.y + f.y, a * r.z - b * u.z + f.z};
  const double n = std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
  return {d.x / n, d.y / n, d.z / n};
}

Vec3 direction_from_azimuth_elevation(double azimuth_deg, double elevation_deg) {
  const double ce = std::cos(elevation_deg * kDeg);
  return {ce * std::sin(azimuth_deg * kDeg), std::sin(elevation_deg * kDeg),
          ce * std::cos(azimuth_deg * kDeg)};
}

}  // namespace mr
