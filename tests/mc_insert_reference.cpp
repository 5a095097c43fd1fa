// The Monte Carlo reference for inserted objects (tests/mc_insert_reference.h).
#include "mc_insert_reference.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

namespace mr::mcref {

namespace {

constexpr double kPi = std::numbers::pi;

Vec3 operator+(const Vec3& a, const Vec3& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
Vec3 operator*(double s, const Vec3& a) { return {s * a.x, s * a.y, s * a.z}; }
double dot(const Vec3& a, const Vec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
Vec3 normalized(const Vec3& a) { return (1.0 / std::sqrt(dot(a, a))) * a; }

class Rng {  // SplitMix64
 public:
  explicit Rng(std::uint64_t seed) : state_(seed) {}
  double uniform() {
    std::uint64_t z = (state_ += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    z ^= z >> 31;
    return double(z >> 11) * 0x1.0p-53;
  }

 private:
  std::uint64_t state_;
};

void basis(const Vec3& n, Vec3& a, Vec3& b) {
  const Vec3 helper = std::fabs(n.x) < 0.9 ? Vec3{1, 0, 0} : Vec3{0, 1, 0};
  a = normalized(cross(n, helper));
  b = cross(n, a);
}

const SurfaceMaterial& material_of(const MaterialTable& m, const Geometry::Hit& h) {
  switch (h.kind) {
    case Geometry::Hit::Kind::box: return m.boxes.at(h.index);
    case Geometry::Hit::Kind::quad: return m.quads.at(h.index);
    case Geometry::Hit::Kind::sphere: return m.spheres.at(h.index);
    default: return m.ground;
  }
}

}  // namespace

std::array<double, 3> brdf_cosine(const SurfaceMaterial& m, const Vec3& n, const Vec3& l, const Vec3& v) {
  const double nl = dot(n, l), nv = dot(n, v);
  std::array<double, 3> out{};
  if (nl <= 0 || nv <= 0) return out;
  for (int c = 0; c < 3; ++c) out[c] = m.diffuse_albedo[c] / kPi * nl;
  if (!m.specular) return out;
  const Vec3 h = normalized(l + v);
  const double nh = dot(n, h), vh = std::clamp(dot(v, h), 0.0, 1.0);
  const double alpha = std::max(m.roughness, 0.02) * std::max(m.roughness, 0.02), a2 = alpha * alpha;
  const double denom = nh * nh * (a2 - 1) + 1;
  const double D = nh > 0 ? a2 / (kPi * denom * denom) : 0.0;
  // Smith height-correlated: G2 / (4 nl nv) = 0.5 / (nv sqrt(a2 + (1-a2) nl^2) + nl sqrt(a2 + (1-a2) nv^2))
  const double vis = 0.5 / (nv * std::sqrt(a2 + (1 - a2) * nl * nl) + nl * std::sqrt(a2 + (1 - a2) * nv * nv));
  const double w = std::pow(1 - vh, 5);
  for (int c = 0; c < 3; ++c) out[c] += D * vis * (m.f0[c] + (1 - m.f0[c]) * w) * nl;
  return out;
}

Image surface_radiance(const Camera& camera, const CameraPose& pose, const Lighting& lighting,
                       const Geometry& geometry, const MaterialTable& materials,
                       const RadianceSettings& settings) {
  if (!lighting.sky_radiance) throw std::invalid_argument("surface_radiance: no sky radiance");
  if (!lighting.lamps.empty()) throw std::invalid_argument("surface_radiance: lamps are not supported");
  const int w = camera.width, h = camera.height, N = settings.pixel_samples_per_axis;
  const Rgb sky = *lighting.sky_radiance;
  Image out(w, h, 3);
  Vec3 sun_dir{0, 1, 0}, sun_a, sun_b;
  double cos_max = 1;
  if (lighting.sun) {
    sun_dir = normalized(lighting.sun->direction_to_sun);
    basis(sun_dir, sun_a, sun_b);
    cos_max = std::cos(lighting.sun->angular_radius_deg * kPi / 180);
  }
  tbb::parallel_for(tbb::blocked_range<int>(0, h), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y != rows.end(); ++y)
      for (int x = 0; x < w; ++x) {
        Rng rng(settings.seed * 0x9E3779B97F4A7C15ull + std::uint64_t(y) * 100003ull + std::uint64_t(x) + 1);
        std::array<double, 3> sum{};
        for (int j = 0; j < N; ++j)
          for (int i = 0; i < N; ++i) {
            const double sx = x + (i + rng.uniform()) / N, sy = y + (j + rng.uniform()) / N;
            const Vec3 d = pose.ray_direction(camera, sx - 0.5, sy - 0.5);
            const Geometry::Hit hit = geometry.first_hit_info(pose.position_m, d);
            if (hit.kind == Geometry::Hit::Kind::none) {
              for (int c = 0; c < 3; ++c) sum[c] += sky[c];
              continue;
            }
            const SurfaceMaterial& m = material_of(materials, hit);
            const Vec3 n = hit.normal, v = -1.0 * d;
            const Vec3 p = pose.position_m + hit.t * d;
            const Vec3 o = p + 1e-7 * (1 + hit.t) * n;
            if (lighting.sun) {
              const int K = settings.sun_samples;
              for (int k = 0; k < K; ++k) {
                // Stratified in cos(theta) within the cone, uniform in azimuth.
                const double ct = 1 - (k + rng.uniform()) / K * (1 - cos_max);
                const double st = std::sqrt(std::max(0.0, 1 - ct * ct)), phi = 2 * kPi * rng.uniform();
                const Vec3 l = normalized(ct * sun_dir + (st * std::cos(phi)) * sun_a + (st * std::sin(phi)) * sun_b);
                if (dot(n, l) <= 0 || geometry.occluded(o, l)) continue;
                const auto f = brdf_cosine(m, n, l, v);
                for (int c = 0; c < 3; ++c) sum[c] += lighting.sun->irradiance[c] * f[c] / K;
              }
            }
            Vec3 ta, tb;
            basis(n, ta, tb);
            const int M = settings.sky_samples;
            const int side = std::max(1, int(std::sqrt(double(M))));
            const int count = side * side;
            for (int k = 0; k < count; ++k) {
              const double u1 = ((k % side) + rng.uniform()) / side, u2 = ((k / side) + rng.uniform()) / side;
              const double r = std::sqrt(u1), phi = 2 * kPi * u2;
              const Vec3 l = (r * std::cos(phi)) * ta + (r * std::sin(phi)) * tb + std::sqrt(std::max(0.0, 1 - u1)) * n;
              if (l.y <= 0 || geometry.occluded(o, l)) continue;
              const double nl = dot(n, l);
              if (nl <= 0) continue;
              const auto f = brdf_cosine(m, n, l, v);
              // pdf = nl / pi: f cos / pdf = pi f.
              for (int c = 0; c < 3; ++c) sum[c] += sky[c] * kPi * f[c] / nl / count;
            }
          }
        for (int c = 0; c < 3; ++c) out.view().at(x, y, c) = float(sum[c] / (N * N));
      }
  });
  return out;
}

}  // namespace mr::mcref
