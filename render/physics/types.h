// The language layer of the shared physics (render/physics/*.h): the headers there are written
// once in the common subset of C++20 and GLSL 4.50 and compiled by both, the CPU scattering core
// (render/scattering_cpu.cpp, in double: the reference path) and the Vulkan shaders
// (shaders/*.comp, in float; included through glslc's -I <source root>). This header maps the
// few things that differ between the two languages; nothing physical is written here.
//
// Shared code uses only:
//  - `Float` and `Float3` (double / a small vector struct in C++; float / vec3 in GLSL), int,
//    uint, bool; Float3 members .x .y .z and [i]; construction as Float3(x, y, z);
//  - the GLSL built-ins that this header also defines for C++: abs min max clamp floor fract exp
//    log sqrt tan atan (one and two arguments) dot cross length normalize isinf isnan, plus expm1_
//    and log1p_ (GLSL has neither: evaluated there in forms that keep their relative precision),
//    lerp_ (a + (b - a) t, the same operations in both) and copysign_one;
//  - MR_FN before every function (C++: inline; MR_HOT_FN: always inlined in C++, for the few
//    closed forms a march evaluates per segment), MR_OUT(T) / MR_INOUT(T) for out-parameters,
//    MR_INF, MR_CONSTANT for constants, and MR_PHYSICS_BEGIN / MR_PHYSICS_END around the code (C++:
//    namespace mr::render::physics).
// No references, pointers, templates, member functions, brace initialisers, or GLSL keywords
// as names (sample, common, input, output, filter, ...).
#ifndef MR_RENDER_PHYSICS_TYPES_H
#define MR_RENDER_PHYSICS_TYPES_H

#ifdef __cplusplus

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

namespace mr::render::physics {

using Float = double;
using uint = std::uint32_t;

/// The 3-vector of the shared physics on the CPU, and render/'s one small vector type
/// (render/math.h): double, with GLSL's operators and names. Indexable like the std::array it
/// replaces.
struct Float3 {
  double x = 0, y = 0, z = 0;
  constexpr Float3() = default;
  constexpr Float3(double x_, double y_, double z_) : x(x_), y(y_), z(z_) {}
  constexpr double& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
  constexpr double operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
  friend constexpr bool operator==(const Float3&, const Float3&) = default;
};

constexpr Float3 operator+(const Float3& a, const Float3& b) {
  return {a.x + b.x, a.y + b.y, a.z + b.z};
}
constexpr Float3 operator-(const Float3& a, const Float3& b) {
  return {a.x - b.x, a.y - b.y, a.z - b.z};
}
constexpr Float3 operator-(const Float3& a) {
  return {-a.x, -a.y, -a.z};
}
constexpr Float3 operator*(const Float3& a, const Float3& b) {
  return {a.x * b.x, a.y * b.y, a.z * b.z};
}
constexpr Float3 operator*(const Float3& a, double s) {
  return {a.x * s, a.y * s, a.z * s};
}
constexpr Float3 operator*(double s, const Float3& a) {
  return {s * a.x, s * a.y, s * a.z};
}
constexpr Float3 operator/(const Float3& a, double s) {
  return {a.x / s, a.y / s, a.z / s};
}
constexpr Float3 operator/(const Float3& a, const Float3& b) {
  return {a.x / b.x, a.y / b.y, a.z / b.z};
}
constexpr Float3& operator+=(Float3& a, const Float3& b) {
  return a = a + b;
}
constexpr Float3& operator-=(Float3& a, const Float3& b) {
  return a = a - b;
}
constexpr Float3& operator*=(Float3& a, const Float3& b) {
  return a = a * b;
}
constexpr Float3& operator*=(Float3& a, double s) {
  return a = a * s;
}

using std::abs;
using std::atan;
using std::clamp;
using std::cos;
using std::exp;
using std::floor;
using std::isinf;
using std::isnan;
using std::log;
using std::max;
using std::min;
using std::sin;
using std::sqrt;
using std::tan;

inline double atan(double y, double x) {
  return std::atan2(y, x);
}
inline double fract(double v) {
  return v - std::floor(v);
}
inline double expm1_(double x) {
  return std::expm1(x);
}
inline double log1p_(double x) {
  return std::log1p(x);
}
inline double lerp_(double a, double b, double t) {
  return a + (b - a) * t;
}
/// +1 or -1 with the sign of x, -0 included (std::copysign(1, x)).
inline double copysign_one(double x) {
  return std::copysign(1.0, x);
}
constexpr double dot(const Float3& a, const Float3& b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
constexpr Float3 cross(const Float3& a, const Float3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline double length(const Float3& a) {
  return std::sqrt(dot(a, a));
}
/// a / |a| (each component divided, as the CPU core always did).
inline Float3 normalize(const Float3& a) {
  const double n = length(a);
  return {a.x / n, a.y / n, a.z / n};
}
inline Float3 exp(const Float3& a) {
  return {std::exp(a.x), std::exp(a.y), std::exp(a.z)};
}
inline Float3 expm1_(const Float3& a) {
  return {std::expm1(a.x), std::expm1(a.y), std::expm1(a.z)};
}
inline Float3 max(const Float3& a, const Float3& b) {
  return {std::max(a.x, b.x), std::max(a.y, b.y), std::max(a.z, b.z)};
}
inline Float3 min(const Float3& a, const Float3& b) {
  return {std::min(a.x, b.x), std::min(a.y, b.y), std::min(a.z, b.z)};
}

}  // namespace mr::render::physics

#define MR_PHYSICS_BEGIN namespace mr::render::physics {
#define MR_PHYSICS_END }
#define MR_FN inline
// The closed forms every march segment evaluates several times (optical depths along the view
// ray and the sun's path): inlined into their callers, where GCC kept them out of line (~4 % of
// a 1080p render's CPU in the calls); the same arithmetic either way.
#define MR_HOT_FN [[gnu::always_inline]] inline
#define MR_OUT(T) T&
#define MR_INOUT(T) T&
#define MR_CONSTANT inline constexpr
#define MR_INF (std::numeric_limits<double>::infinity())
// Below this |a L| the closed form's (1 - exp(-a L)) / a is taken from its series.
#define MR_EXP_SERIES_BELOW 1e-9
#define MR_DOUBLE_PRECISION 1

#else  // GLSL

#define Float float
#define Float3 vec3
#define MR_PHYSICS_BEGIN
#define MR_PHYSICS_END
#define MR_FN
#define MR_HOT_FN
#define MR_OUT(T) out T
#define MR_INOUT(T) inout T
#define MR_CONSTANT const
#define MR_INF uintBitsToFloat(0x7F800000u)
#define MR_EXP_SERIES_BELOW 1e-7

// expm1 and log1p: GPU exp / log are accurate only to ~2^-21 in absolute terms near 1, so small
// arguments take their series (7 and 8 terms: below float's epsilon at |x| < 0.3).
float expm1_(float x) {
  if (abs(x) < 0.3)
    return x * (1.0 + x * (1.0 / 2.0 + x * (1.0 / 6.0 + x * (1.0 / 24.0 + x * (1.0 / 120.0 +
           x * (1.0 / 720.0 + x * (1.0 / 5040.0 + x * (1.0 / 40320.0))))))));
  return exp(x) - 1.0;
}
vec3 expm1_(vec3 x) { return vec3(expm1_(x.x), expm1_(x.y), expm1_(x.z)); }

float log1p_(float x) {
  if (abs(x) < 0.3) {
    const float s = x / (2.0 + x), s2 = s * s;  // log1p = 2 atanh(s)
    return 2.0 * s * (1.0 + s2 * (1.0 / 3.0 + s2 * (1.0 / 5.0 + s2 * (1.0 / 7.0 + s2 * (1.0 / 9.0 +
           s2 * (1.0 / 11.0 + s2 * (1.0 / 13.0)))))));
  }
  return log(1.0 + x);
}
float lerp_(float a, float b, float t) { return a + (b - a) * t; }
float copysign_one(float x) { return (floatBitsToUint(x) & 0x80000000u) != 0u ? -1.0 : 1.0; }

#endif

#endif  // MR_RENDER_PHYSICS_TYPES_H
