// Private to libmr: the small vector algebra on the public mr::Vec3 (metres, world axes: +Y up)
// that the API layer, photo/ and core/ use; render/ has its own (render/math.h), in the shared
// physics' Float3, because the same code compiles as GLSL.
#pragma once

#include <cmath>

#include "mr/scene.h"

namespace mr::vec3 {

inline Vec3 add(const Vec3& a, const Vec3& b) {
  return {a.x + b.x, a.y + b.y, a.z + b.z};
}
inline Vec3 sub(const Vec3& a, const Vec3& b) {
  return {a.x - b.x, a.y - b.y, a.z - b.z};
}
inline Vec3 scale(const Vec3& a, double s) {
  return {a.x * s, a.y * s, a.z * s};
}
inline double dot(const Vec3& a, const Vec3& b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
inline Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline double norm(const Vec3& a) {
  return std::sqrt(dot(a, a));
}
/// a / |a| (not finite for a zero vector: callers check).
inline Vec3 normalized(const Vec3& a) {
  return scale(a, 1.0 / norm(a));
}

}  // namespace mr::vec3
