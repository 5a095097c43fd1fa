#include "render/medium.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

namespace mr::render {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// integral_0^L exp(-a s) ds = (1 - exp(-a L)) / a, stable for a -> 0 and L = inf.
double exp_integral(double a, double length) {
  if (length <= 0) return 0;
  if (std::isinf(length)) return a > 0 ? 1.0 / a : kInf;
  const double x = a * length;
  if (std::fabs(x) < 1e-9) return length * (1.0 - 0.5 * x);
  return -std::expm1(-x) / a;
}

}  // namespace

RayDensity::RayDensity(const Medium& m, const Vec3d& o, const Vec3d& w) {
  // Where the ray is inside the layer bottom <= y <= top.
  double t0 = 0, t1 = kInf;
  const double oy = o[1], wy = w[1];
  if (wy == 0) {
    if (oy < m.layer_bottom_m || oy > m.layer_top_m) return;
  } else {
    double ta = (m.layer_bottom_m - oy) / wy, tb = (m.layer_top_m - oy) / wy;
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
    if (!(t1 > t0)) return;  // also catches NaN from inf - inf
  }
  empty_ = false;
  t_enter_ = t0;
  t_exit_ = t1;
  if (m.height_fog) {
    const double h = m.height_fog->scale_height_m;
    a_ = wy / h;
    // rho(t_enter + s) = k exp(-a s)
    k_ = std::exp(-(oy + t0 * wy - m.height_fog->base_height_m) / h);
  } else {
    a_ = 0;
    k_ = 1;
  }
}

double RayDensity::integral_from_enter(double t) const {
  return k_ * exp_integral(a_, std::min(t, t_exit_) - t_enter_);
}

double RayDensity::optical_depth(double t0, double t1) const {
  if (empty_ || !(t1 > t0)) return 0;
  t0 = std::max(t0, t_enter_);
  t1 = std::min(t1, t_exit_);
  if (!(t1 > t0)) return 0;
  if (std::isinf(t1)) {
    const double tail = k_ * exp_integral(a_, kInf);  // from t_enter
    if (std::isinf(tail)) return kInf;
    return tail - integral_from_enter(t0);
  }
  return integral_from_enter(t1) - integral_from_enter(t0);
}

double RayDensity::distance_at_optical_depth(double target) const {
  if (empty_) return kInf;
  if (target <= 0) return 0;
  // Solve k * (1 - exp(-a s)) / a = target for s (homogeneous: k s = target).
  const double x = target / k_;
  double s;
  if (std::fabs(a_) < 1e-12) {
    s = x;
  } else {
    const double inner = 1.0 - a_ * x;  // exp(-a s)
    if (inner <= 0) return kInf;         // beyond the optical depth to infinity
    s = -std::log(inner) / a_;
  }
  const double t = t_enter_ + s;
  return t > t_exit_ ? kInf : t;
}

double RayDensity::density(double t) const {
  if (empty_ || t < t_enter_ || t > t_exit_) return 0;
  return k_ * std::exp(-a_ * (t - t_enter_));
}

double density_at(const Medium& m, const Vec3d& x) {
  if (x[1] < m.layer_bottom_m || x[1] > m.layer_top_m) return 0;
  if (!m.height_fog) return 1;
  return std::exp(-(x[1] - m.height_fog->base_height_m) / m.height_fog->scale_height_m);
}

namespace {

std::uint32_t hash3(std::int32_t x, std::int32_t y, std::int32_t z, std::uint32_t seed) {
  std::uint32_t h = seed * 0x9E3779B9u;
  for (std::uint32_t v : {std::uint32_t(x), std::uint32_t(y), std::uint32_t(z)}) {
    h ^= v + 0x7F4A7C15u + (h << 6) + (h >> 2);
    h *= 0x85EBCA6Bu;
    h ^= h >> 13;
  }
  return h;
}

// Perlin-style gradient noise in [-1, 1] (approximately), deterministic for a seed.
double gradient_noise(double px, double py, double pz, std::uint32_t seed) {
  const double fx = std::floor(px), fy = std::floor(py), fz = std::floor(pz);
  const int ix = int(fx), iy = int(fy), iz = int(fz);
  const double dx = px - fx, dy = py - fy, dz = pz - fz;
  auto fade = [](double t) { return t * t * t * (t * (t * 6 - 15) + 10); };
  auto grad = [&](int cx, int cy, int cz, double rx, double ry, double rz) {
    // 12 edge directions of a cube, as in improved Perlin noise.
    switch (hash3(cx, cy, cz, seed) % 12) {
      case 0: return rx + ry;
      case 1: return -rx + ry;
      case 2: return rx - ry;
      case 3: return -rx - ry;
      case 4: return rx + rz;
      case 5: return -rx + rz;
      case 6: return rx - rz;
      case 7: return -rx - rz;
      case 8: return ry + rz;
      case 9: return -ry + rz;
      case 10: return ry - rz;
      default: return -ry - rz;
    }
  };
  const double u = fade(dx), v = fade(dy), w = fade(dz);
  double c[2][2][2];
  for (int k = 0; k < 2; ++k)
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i < 2; ++i) c[k][j][i] = grad(ix + i, iy + j, iz + k, dx - i, dy - j, dz - k);
  auto lerp = [](double a, double b, double t) { return a + (b - a) * t; };
  const double x00 = lerp(c[0][0][0], c[0][0][1], u), x10 = lerp(c[0][1][0], c[0][1][1], u);
  const double x01 = lerp(c[1][0][0], c[1][0][1], u), x11 = lerp(c[1][1][0], c[1][1][1], u);
  return lerp(lerp(x00, x10, v), lerp(x01, x11, v), w);
}

}  // namespace

double noise_modulation(const Medium::Noise& noise, const Vec3d& x) {
  if (noise.amplitude <= 0) return 1;
  double sum = 0, amp = 1, norm = 0, freq = 1.0 / noise.scale_m;
  for (int o = 0; o < noise.octaves; ++o) {
    sum += amp * gradient_noise(x[0] * freq, x[1] * freq, x[2] * freq, noise.seed + 101u * o);
    norm += amp;
    amp *= 0.5;
    freq *= 2.0;
  }
  return std::max(0.0, 1.0 + noise.amplitude * std::clamp(sum / norm, -1.0, 1.0));
}

}  // namespace mr::render
