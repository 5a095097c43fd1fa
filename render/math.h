// Private to libmr: render/'s one small-vector header. Vec3d is the shared physics' 3-vector
// (render/physics/types.h: double on the CPU, with GLSL's operators and names, indexable like
// the std::array it replaced); Vec3f (std::array<float, 3>, render/surface_shading.h) gets the
// few float helpers the BRDF code needs. The one hash is physics::hash32
// (render/physics/medium.h).
#pragma once

#include <array>
#include <cmath>
#include <cstdint>

#include "mr/scene.h"
#include "render/physics/types.h"

namespace mr::render {

using Vec3d = physics::Float3;
using physics::cross;
using physics::dot;
using physics::length;

inline Vec3d vec(const Vec3& v) {
  return {v.x, v.y, v.z};
}
/// a + s b (componentwise, in that order).
inline Vec3d add(const Vec3d& a, const Vec3d& b, double s = 1) {
  return {a.x + s * b.x, a.y + s * b.y, a.z + s * b.z};
}
inline Vec3d sub(const Vec3d& a, const Vec3d& b) {
  return a - b;
}
/// a / |a| (NaN for a zero vector; unit() where that can happen).
inline Vec3d normalized(const Vec3d& a) {
  return physics::normalize(a);
}
/// a / |a|, or 0 for a zero vector.
inline Vec3d unit(const Vec3d& a) {
  const double n = length(a);
  return n > 0 ? Vec3d{a.x / n, a.y / n, a.z / n} : Vec3d{0, 0, 0};
}
inline std::array<float, 3> f3(const Vec3d& v) {
  return {float(v.x), float(v.y), float(v.z)};
}

using Vec3f = std::array<float, 3>;
inline float dot(const Vec3f& a, const Vec3f& b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
inline Vec3f cross(const Vec3f& a, const Vec3f& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
/// a / |a|, or 0 for a zero vector.
inline Vec3f unit(const Vec3f& a) {
  const float n = std::sqrt(dot(a, a));
  return n > 0 ? Vec3f{a[0] / n, a[1] / n, a[2] / n} : Vec3f{0, 0, 0};
}
inline Vec3f to_f(const Vec3& v) {
  return {float(v.x), float(v.y), float(v.z)};
}

// Van der Corput radical inverse in base 2 (the second Hammersley coordinate): i's bits
// mirrored about the binary point, in [0, 1).
inline double radical_inverse_base2(std::uint32_t i) {
  i = (i << 16u) | (i >> 16u);
  i = ((i & 0x55555555u) << 1u) | ((i & 0xAAAAAAAAu) >> 1u);
  i = ((i & 0x33333333u) << 2u) | ((i & 0xCCCCCCCCu) >> 2u);
  i = ((i & 0x0F0F0F0Fu) << 4u) | ((i & 0xF0F0F0F0u) >> 4u);
  i = ((i & 0x00FF00FFu) << 8u) | ((i & 0xFF00FF00u) >> 8u);
  return double(i) * 2.3283064365386963e-10;
}

}  // namespace mr::render
