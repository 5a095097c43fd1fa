// The brute-force Monte Carlo single-scattering reference; see mc_reference.h for what it
// computes and how. Shares no code with render/.
#include "mc_reference.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

namespace mr::mcref {

namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;
constexpr double kRayEpsilon = 1e-9;  // metres; shadow rays start in open air
constexpr double kMaxDistance = 1e7;  // metres; no path is marched further

Vec3 operator+(const Vec3& a, const Vec3& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
Vec3 operator-(const Vec3& a, const Vec3& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
Vec3 operator*(double s, const Vec3& a) { return {s * a.x, s * a.y, s * a.z}; }
double dot(const Vec3& a, const Vec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
double length(const Vec3& a) { return std::sqrt(dot(a, a)); }
Vec3 normalized(const Vec3& a) { return (1.0 / length(a)) * a; }
Vec3 at(const Vec3& o, const Vec3& d, double t) { return {o.x + t * d.x, o.y + t * d.y, o.z + t * d.z}; }

// SplitMix64: small, fast, statistically fine for this, and fully under our control.
class Rng {
 public:
  explicit Rng(std::uint64_t seed) : state_(seed) {}
  std::uint64_t next() {
    std::uint64_t z = (state_ += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  double uniform() { return double(next() >> 11) * 0x1.0p-53; }  // [0, 1)

 private:
  std::uint64_t state_;
};

std::uint64_t mix_seed(std::uint64_t a, std::uint64_t b, std::uint64_t c) {
  Rng r(a * 0x100000001B3ull ^ (b + 0x9E3779B97F4A7C15ull));
  Rng s(r.next() ^ (c * 0xD6E8FEB86659FD93ull));
  return s.next();
}

// 8-point Gauss-Legendre on [-1, 1].
constexpr std::array<double, 4> kGlNode{0.1834346424956498, 0.5255324099163290,
                                        0.7966664774136267, 0.9602898564975363};
constexpr std::array<double, 4> kGlWeight{0.3626837833783620, 0.3137066458778873,
                                          0.2223810344533745, 0.1012285362903763};

// The part [lo, hi] of [t0, t1] where o + t d lies inside the layer; false if empty.
bool layer_interval(const Medium& m, const Vec3& o, const Vec3& d, double t0, double t1,
                    double& lo, double& hi) {
  lo = t0;
  hi = t1;
  if (d.y == 0) {
    if (!(o.y >= m.layer_bottom_m && o.y <= m.layer_top_m)) return false;
  } else {
    double s1 = (m.layer_bottom_m - o.y) / d.y, s2 = (m.layer_top_m - o.y) / d.y;
    if (s1 > s2) std::swap(s1, s2);
    lo = std::max(lo, s1);
    hi = std::min(hi, s2);
  }
  return lo < hi;
}

// Where a path going up through height fog may be cut: the density there has fallen by e^-45
// below its value at the path's start (or the fog's base), so the rest is negligible.
double height_fog_cut(const Medium& m, const Vec3& o, const Vec3& d, double t_start) {
  const auto& hf = *m.height_fog;
  const double y_cut = std::max(o.y + t_start * d.y, hf.base_height_m) + 45.0 * hf.scale_height_m;
  return (y_cut - o.y) / d.y;
}

// Gauss-Legendre over [a, b] (finite, inside the layer) with `panels` equal panels.
double gauss_legendre(const Medium& m, const Vec3& o, const Vec3& d, double a, double b,
                      int panels) {
  const double h = (b - a) / panels;
  double sum = 0;
  for (int p = 0; p < panels; ++p) {
    const double mid = a + (p + 0.5) * h, half = 0.5 * h;
    double s = 0;
    for (int i = 0; i < 4; ++i) {
      s += kGlWeight[i] * (density(m, at(o, d, mid - half * kGlNode[i])) +
                           density(m, at(o, d, mid + half * kGlNode[i])));
    }
    sum += s * half;
  }
  return sum;
}

int panel_count(const Medium& m, const Vec3& d, double a, double b) {
  if (!m.height_fog) return 1;  // constant density inside the layer: exact with one panel
  const double dy = std::fabs(d.y) * (b - a);
  return std::max(1, int(std::ceil(dy / (0.25 * m.height_fog->scale_height_m))));
}

double exp_neg(double sigma, double density_integral) {
  if (sigma == 0) return 1.0;  // avoids 0 * inf
  return std::exp(-sigma * density_integral);
}

double henyey_greenstein_impl(double g, double c) {
  const double denom = 1.0 + g * g - 2.0 * g * c;
  return (1.0 - g * g) / (4.0 * kPi * denom * std::sqrt(denom));
}

double spot_factor(const Lamp& lamp, const Vec3& lamp_to_x_unit) {
  if (lamp.outer_angle_deg >= 180.0) return 1.0;
  const double cos_alpha = dot(normalized(lamp.spot_direction), lamp_to_x_unit);
  const double cos_in = std::cos(lamp.inner_angle_deg * kDeg);
  const double cos_out = std::cos(lamp.outer_angle_deg * kDeg);
  if (cos_alpha >= cos_in) return 1.0;
  if (cos_alpha <= cos_out) return 0.0;
  const double t = (cos_alpha - cos_out) / (cos_in - cos_out);
  return t * t * (3.0 - 2.0 * t);
}

// A direction uniformly distributed (in solid angle) in the cone of half-angle `radius` about l.
Vec3 sample_cone(const Vec3& l, double radius_rad, double u1, double u2) {
  if (radius_rad <= 0) return l;
  const double cos_t = 1.0 - u1 * (1.0 - std::cos(radius_rad));
  const double sin_t = std::sqrt(std::max(0.0, 1.0 - cos_t * cos_t));
  const double phi = 2.0 * kPi * u2;
  const Vec3 helper = std::fabs(l.x) < 0.9 ? Vec3{1, 0, 0} : Vec3{0, 1, 0};
  const Vec3 a = normalized(cross(l, helper));
  const Vec3 b = cross(l, a);
  return normalized(cos_t * l + (sin_t * std::cos(phi)) * a + (sin_t * std::sin(phi)) * b);
}

// Slab test; [t_enter, t_exit] of the ray in the closed box, false if it misses.
bool box_span(const Box& box, const Vec3& o, const Vec3& d, double& t_enter, double& t_exit) {
  t_enter = -kInfinity;
  t_exit = kInfinity;
  const double os[3] = {o.x, o.y, o.z}, ds[3] = {d.x, d.y, d.z};
  const double mins[3] = {box.min.x, box.min.y, box.min.z};
  const double maxs[3] = {box.max.x, box.max.y, box.max.z};
  for (int a = 0; a < 3; ++a) {
    if (ds[a] == 0) {
      if (os[a] < mins[a] || os[a] > maxs[a]) return false;
      continue;
    }
    double t1 = (mins[a] - os[a]) / ds[a], t2 = (maxs[a] - os[a]) / ds[a];
    if (t1 > t2) std::swap(t1, t2);
    t_enter = std::max(t_enter, t1);
    t_exit = std::min(t_exit, t2);
  }
  return t_enter <= t_exit;
}

double quad_hit(const Quad& q, const Vec3& o, const Vec3& d) {
  const Vec3 n = cross(q.edge_u, q.edge_v);
  const double denom = dot(n, d);
  if (denom == 0) return kInfinity;
  const double t = dot(n, q.corner - o) / denom;
  const Vec3 p = at(o, d, t) - q.corner;
  const double nn = dot(n, n);
  const double s = dot(cross(p, q.edge_v), n) / nn, r = dot(cross(q.edge_u, p), n) / nn;
  if (s < 0 || s > 1 || r < 0 || r > 1) return kInfinity;
  return t;
}

// The nearest t > kRayEpsilon where the unit ray meets the sphere, or +inf.
double sphere_hit(const Sphere& s, const Vec3& o, const Vec3& d) {
  const Vec3 q = o - s.centre;
  const double b = dot(q, d), c = dot(q, q) - s.radius * s.radius;
  const double disc = b * b - c;
  if (disc < 0) return kInfinity;
  const double root = std::sqrt(disc);
  const double t0 = -b - root, t1 = -b + root;
  if (t0 > kRayEpsilon) return t0;
  if (t1 > kRayEpsilon) return t1;
  return kInfinity;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Geometry

double Geometry::first_hit(const Vec3& o, const Vec3& d, double t_max) const {
  double best = t_max;
  if (ground && d.y != 0) {
    const double t = -o.y / d.y;
    if (t > kRayEpsilon && t < best) best = t;
  }
  for (const Box& b : boxes) {
    double t0, t1;
    if (!box_span(b, o, d, t0, t1)) continue;
    const double t = t0 > kRayEpsilon ? t0 : t1;  // from inside: the exit face
    if (t > kRayEpsilon && t < best) best = t;
  }
  for (const Quad& q : quads) {
    const double t = quad_hit(q, o, d);
    if (t > kRayEpsilon && t < best) best = t;
  }
  for (const Sphere& sp : spheres) {
    const double t = sphere_hit(sp, o, d);
    if (t < best) best = t;
  }
  return best < t_max ? best : kInfinity;
}

bool Geometry::occluded(const Vec3& o, const Vec3& d, double t_max) const {
  if (ground && d.y != 0) {
    const double t = -o.y / d.y;
    if (t > kRayEpsilon && t < t_max) return true;
  }
  for (const Box& b : boxes) {
    double t0, t1;
    // Boxes are solids: blocked if the open segment meets the closed box.
    if (box_span(b, o, d, t0, t1) && t1 > kRayEpsilon && t0 < t_max) return true;
  }
  for (const Quad& q : quads) {
    const double t = quad_hit(q, o, d);
    if (t > kRayEpsilon && t < t_max) return true;
  }
  for (const Sphere& sp : spheres)
    if (sphere_hit(sp, o, d) < t_max) return true;
  return false;
}

Vec3 Geometry::first_hit_normal(const Vec3& o, const Vec3& d) const {
  double best = kInfinity;
  Vec3 n{0, 0, 0};
  if (ground && d.y != 0) {
    const double t = -o.y / d.y;
    if (t > kRayEpsilon && t < best) best = t, n = {0, o.y >= 0 ? 1.0 : -1.0, 0};
  }
  for (const Box& b : boxes) {
    double t0, t1;
    if (!box_span(b, o, d, t0, t1)) continue;
    const double t = t0 > kRayEpsilon ? t0 : t1;
    if (!(t > kRayEpsilon && t < best)) continue;
    best = t;
    // The face the hit lies on: the coordinate closest to one of the box's bounds.
    const Vec3 p = at(o, d, t);
    const double ps[3] = {p.x, p.y, p.z};
    const double mins[3] = {b.min.x, b.min.y, b.min.z}, maxs[3] = {b.max.x, b.max.y, b.max.z};
    double closest = kInfinity;
    for (int a = 0; a < 3; ++a)
      for (int side = 0; side < 2; ++side) {
        const double gap = std::fabs(ps[a] - (side ? maxs[a] : mins[a]));
        if (gap < closest) {
          closest = gap;
          double v[3] = {0, 0, 0};
          v[a] = side ? 1 : -1;
          n = {v[0], v[1], v[2]};
        }
      }
  }
  for (const Quad& q : quads) {
    const double t = quad_hit(q, o, d);
    if (t > kRayEpsilon && t < best) best = t, n = normalized(cross(q.edge_u, q.edge_v));
  }
  for (const Sphere& sp : spheres) {
    const double t = sphere_hit(sp, o, d);
    if (t < best) best = t, n = normalized(at(o, d, t) - sp.centre);
  }
  if (dot(n, d) > 0) n = -1.0 * n;
  return n;
}

Geometry::Hit Geometry::first_hit_info(const Vec3& o, const Vec3& d) const {
  Hit h;
  // The nearest primitive: each kind tested alone, with the same tests as first_hit.
  auto consider = [&](Hit::Kind kind, std::size_t index, double t) {
    if (t > kRayEpsilon && t < h.t) h.t = t, h.kind = kind, h.index = index;
  };
  if (ground && d.y != 0) consider(Hit::Kind::ground, 0, -o.y / d.y);
  for (std::size_t i = 0; i < boxes.size(); ++i) {
    double t0, t1;
    if (box_span(boxes[i], o, d, t0, t1)) consider(Hit::Kind::box, i, t0 > kRayEpsilon ? t0 : t1);
  }
  for (std::size_t i = 0; i < quads.size(); ++i) consider(Hit::Kind::quad, i, quad_hit(quads[i], o, d));
  for (std::size_t i = 0; i < spheres.size(); ++i) consider(Hit::Kind::sphere, i, sphere_hit(spheres[i], o, d));
  if (h.kind == Hit::Kind::none) return h;
  Geometry one;  // the hit primitive alone gives its normal
  switch (h.kind) {
    case Hit::Kind::ground: one.ground = true; break;
    case Hit::Kind::box: one.boxes.push_back(boxes[h.index]); break;
    case Hit::Kind::quad: one.quads.push_back(quads[h.index]); break;
    case Hit::Kind::sphere: one.spheres.push_back(spheres[h.index]); break;
    case Hit::Kind::none: break;
  }
  h.normal = one.first_hit_normal(o, d);
  return h;
}

Image distance_map(const Camera& camera, const CameraPose& pose, const Geometry& geometry) {
  Image out(camera.width, camera.height, 1, {"Z"});
  for (int y = 0; y < camera.height; ++y)
    for (int x = 0; x < camera.width; ++x) {
      const Vec3 w = pose.ray_direction(camera, x, y);
      out.at(x, y, 0) = float(geometry.first_hit(pose.position_m, w));
    }
  return out;
}

// ---------------------------------------------------------------------------------------------
// Medium

double density(const Medium& m, const Vec3& x) {
  if (!(x.y >= m.layer_bottom_m && x.y <= m.layer_top_m)) return 0.0;
  if (!m.height_fog) return 1.0;
  return std::exp(-(x.y - m.height_fog->base_height_m) / m.height_fog->scale_height_m);
}

double henyey_greenstein(double g, double cos_theta) { return henyey_greenstein_impl(g, cos_theta); }

double density_integral(const Medium& m, const Vec3& o, const Vec3& d, double t0, double t1,
                        int panel_scale) {
  double a, b;
  if (!(t1 > t0) || !layer_interval(m, o, d, t0, t1, a, b)) return 0.0;
  if (!std::isfinite(b)) {
    if (m.height_fog && d.y > 0) {
      b = height_fog_cut(m, o, d, a);
      if (!(b > a)) return 0.0;
    } else {
      // The density does not vanish along the rest of the path (homogeneous, level, or
      // going down into ever denser height fog): infinite optical depth.
      return density(m, at(o, d, a + 1.0)) > 0 ? kInfinity : 0.0;
    }
  }
  return gauss_legendre(m, o, d, a, b, panel_count(m, d, a, b) * std::max(1, panel_scale));
}

double distance_to_density_integral(const Medium& m, const Vec3& o, const Vec3& d,
                                    double target) {
  double a, b;
  if (!(target > 0) || !layer_interval(m, o, d, 0.0, kInfinity, a, b)) return 0.0;
  if (!std::isfinite(b) && m.height_fog && d.y > 0) b = height_fog_cut(m, o, d, a);
  b = std::min(b, kMaxDistance);
  if (a >= b) return std::min(a, kMaxDistance);

  // March panels until the integral passes the target, then bisect inside the panel.
  double lo = a, acc = 0;
  while (lo < b) {
    double step;
    const double rho = std::max(density(m, at(o, d, lo)), 1e-300);
    step = (target - acc) / rho;  // exact for constant density
    if (m.height_fog && d.y != 0)
      step = std::min(step, 0.25 * m.height_fog->scale_height_m / std::fabs(d.y));
    step = std::max(step, 1e-9 * (1.0 + lo));
    const double hi = std::min(lo + step, b);
    const double inc = density_integral(m, o, d, lo, hi);
    if (acc + inc < target) {
      acc += inc;
      lo = hi;
      continue;
    }
    double l = lo, h = hi, acc_l = acc;
    for (int it = 0; it < 200 && h - l > 1e-13 * h; ++it) {
      const double mid = 0.5 * (l + h);
      const double part = density_integral(m, o, d, l, mid);
      if (acc_l + part < target) {
        acc_l += part;
        l = mid;
      } else {
        h = mid;
      }
    }
    return 0.5 * (l + h);
  }
  return b;
}

// ---------------------------------------------------------------------------------------------
// The estimator

namespace {

struct RayContext {
  RayContext(const FogScene& s, const Geometry& g, const Vec3& origin, const Vec3& direction)
      : scene(s), geometry(g), o(origin), w(direction) {}
  const FogScene& scene;
  const Geometry& geometry;
  Vec3 o, w;
  double D = 0;
  std::array<double, 3> sigma{}, albedo{}, sky{};
  // The view ray's density integral: bins [edge_j, edge_j+1] and its exact value cum_j at
  // the edges; Rho~(t) interpolates it linearly inside a bin.
  std::vector<double> edge, cum;
  // One "medium" technique per distinct sigma_t of the channels: transmittance sampling with
  // the pdf sigma Rho~'(t) exp(-sigma Rho~(t)) / (1 - exp(-sigma Rho(D))).
  struct MediumSampler {
    double sigma = 0, total = 0;
  };
  std::vector<MediumSampler> medium_sampler;
  struct LampSampler {
    double delta = 0, b = 0, theta_a = 0, theta_b = 0;
  };
  std::vector<LampSampler> lamp_sampler;
  int n_medium = 0, n_lamp = 0;  // samples per batch, per technique
  Vec3 sun_dir{};
  double sun_radius = 0;

  std::size_t bin_of(double t) const {
    const auto it = std::upper_bound(edge.begin(), edge.end(), t);
    const std::ptrdiff_t j = (it - edge.begin()) - 1;
    return std::size_t(std::clamp<std::ptrdiff_t>(j, 0, std::ptrdiff_t(edge.size()) - 2));
  }

  double medium_pdf(const MediumSampler& s, double t) const {
    const std::size_t j = bin_of(t);
    const double width = edge[j + 1] - edge[j];
    if (!(width > 0)) return 0.0;
    const double slope = (cum[j + 1] - cum[j]) / width;
    const double rho_approx = cum[j] + slope * (t - edge[j]);
    return s.sigma * slope * std::exp(-s.sigma * rho_approx) / s.total;
  }

  double sample_medium(const MediumSampler& s, double u) const {
    const double target = -std::log1p(-u * s.total) / s.sigma;  // Rho~(t) = target
    const auto it = std::upper_bound(cum.begin(), cum.end(), target);
    std::ptrdiff_t j = (it - cum.begin()) - 1;
    j = std::clamp<std::ptrdiff_t>(j, 0, std::ptrdiff_t(cum.size()) - 2);
    const double inc = cum[j + 1] - cum[j];
    const double f = inc > 0 ? std::clamp((target - cum[j]) / inc, 0.0, 1.0) : 0.5;
    return edge[j] + f * (edge[j + 1] - edge[j]);
  }

  double lamp_pdf(const LampSampler& s, double t) const {
    const double x = t - s.delta;
    return s.b / ((s.theta_b - s.theta_a) * (s.b * s.b + x * x));
  }

  double sample_lamp(const LampSampler& s, double u) const {
    const double th = s.theta_a + u * (s.theta_b - s.theta_a);
    return std::clamp(s.delta + s.b * std::tan(th), 0.0, D);
  }

  double medium_pdf_sum(double t) const {  // sum over the medium techniques of N p
    double q = 0;
    for (const auto& s : medium_sampler) q += n_medium * medium_pdf(s, t);
    return q;
  }

  // A term of the integrand at t (per channel): term < 0 the sun and sky, term = k lamp k.
  // rng: the sun-disk direction.
  std::array<double, 3> integrand(double t, int term, Rng& rng) const {
    std::array<double, 3> f{};
    const Medium& m = scene.medium;
    const Vec3 x = at(o, w, t);
    const double rho = density(m, x);
    if (!(rho > 0)) return f;
    const bool attenuate = scene.render.light_path_attenuation;
    const bool shadows = scene.render.volumetric_shadows;
    std::array<double, 3> source{};
    if (term < 0) {
      source = sky;
      if (const auto& sun = scene.lighting.sun) {
        const double u1 = rng.uniform(), u2 = rng.uniform();
        const bool visible =
            !shadows || !geometry.occluded(x, sample_cone(sun_dir, sun_radius, u1, u2));
        if (visible) {
          const double ph = henyey_greenstein_impl(m.g, dot(w, sun_dir));
          const double sun_rho =
              attenuate ? density_integral(m, x, sun_dir, 0.0, kInfinity) : 0.0;
          for (int c = 0; c < 3; ++c)
            source[c] += ph * sun->irradiance[c] * (attenuate ? exp_neg(sigma[c], sun_rho) : 1.0);
        }
      }
    } else {
      const Lamp& lamp = scene.lighting.lamps[std::size_t(term)];
      const Vec3 to_lamp = lamp.position_m - x;
      const double r2 = dot(to_lamp, to_lamp);
      if (!(r2 > 0)) return f;
      const double r = std::sqrt(r2);
      const Vec3 dir = (1.0 / r) * to_lamp;
      const double spot = spot_factor(lamp, -1.0 * dir);
      if (spot <= 0) return f;
      if (shadows && geometry.occluded(x, dir, r)) return f;
      const double ph = henyey_greenstein_impl(m.g, dot(w, dir));
      const double lamp_rho = attenuate ? density_integral(m, x, dir, 0.0, r) : 0.0;
      for (int c = 0; c < 3; ++c)
        source[c] = ph * lamp.intensity_per_sr[c] * spot / r2 *
                    (attenuate ? exp_neg(sigma[c], lamp_rho) : 1.0);
    }
    const std::size_t j = bin_of(t);
    const double view_rho = cum[j] + density_integral(m, o, w, edge[j], t);
    for (int c = 0; c < 3; ++c)
      f[c] = exp_neg(sigma[c], view_rho) * albedo[c] * sigma[c] * rho * source[c];
    return f;
  }
};

}  // namespace

RayEstimate estimate_ray(const Vec3& w_in, double distance, const FogScene& scene,
                         const Geometry& geometry, const Settings& settings,
                         std::uint64_t stream) {
  const Medium& m = scene.medium;
  if (m.noise.amplitude != 0)
    throw std::invalid_argument("mc reference: medium.noise is not supported");
  if (!scene.lighting.sky_radiance)
    throw std::invalid_argument("mc reference: lighting.sky_radiance must be given");
  if (settings.batches < 2 || settings.medium_samples < 1 || settings.pdf_bins < 1 ||
      (!scene.lighting.lamps.empty() && settings.lamp_samples < 1))
    throw std::invalid_argument("mc reference: bad settings");
  if (std::isnan(distance)) throw std::invalid_argument("mc reference: NaN distance");

  RayContext ctx(scene, geometry, scene.pose.position_m, normalized(w_in));
  for (int c = 0; c < 3; ++c) {
    ctx.sigma[c] = m.sigma_t_per_m[c];
    ctx.albedo[c] = m.albedo[c];
    ctx.sky[c] = (*scene.lighting.sky_radiance)[c];
  }
  RayEstimate out;
  const Vec3& o = ctx.o;
  const Vec3& w = ctx.w;

  // The distance integrated to.
  const bool sky = !std::isfinite(distance);
  double sigma_min = kInfinity;
  for (double s : ctx.sigma)
    if (s > 0) sigma_min = std::min(sigma_min, s);
  double D = distance;
  if (sky) {
    D = std::isfinite(sigma_min)
            ? distance_to_density_integral(m, o, w,
                                           -std::log(settings.sky_cutoff_transmittance) / sigma_min)
            : 0.0;
    if (scene.render.max_distance_m > 0) D = std::min(D, scene.render.max_distance_m);
  }
  ctx.D = D = std::max(D, 0.0);
  out.distance = D;
  const double surface_rho = density_integral(m, o, w, 0.0, sky ? kInfinity : D);
  for (int c = 0; c < 3; ++c) out.transmittance[c] = exp_neg(ctx.sigma[c], surface_rho);

  if (!std::isfinite(sigma_min) || !(D > 0)) return out;  // no extinction, or nothing to march

  // Bins for the medium techniques: equal bins over [0, D'], D' where the optical depth of
  // the least attenuated channel reaches 16, and one more bin for the rest, if any.
  const double d_prime = std::min(D, distance_to_density_integral(m, o, w, 16.0 / sigma_min));
  const int bins = settings.pdf_bins;
  for (int j = 0; j <= bins; ++j) ctx.edge.push_back(d_prime * j / bins);
  ctx.edge.back() = d_prime;
  if (D > d_prime) ctx.edge.push_back(D);
  if (ctx.edge.back() <= 0) return out;
  const std::size_t nbins = ctx.edge.size() - 1;
  ctx.cum.assign(ctx.edge.size(), 0.0);
  for (std::size_t j = 0; j < nbins; ++j)
    ctx.cum[j + 1] = ctx.cum[j] + density_integral(m, o, w, ctx.edge[j], ctx.edge[j + 1]);
  for (int c = 0; c < 3; ++c) {
    const double sc = ctx.sigma[c];
    if (!(sc > 0)) continue;
    bool seen = false;
    for (const auto& ms : ctx.medium_sampler) seen = seen || ms.sigma == sc;
    const double total = -std::expm1(-sc * ctx.cum.back());  // 1 - tau(0, D)
    if (!seen && total > 0) ctx.medium_sampler.push_back({sc, total});
  }
  if (ctx.medium_sampler.empty()) return out;  // the ray never meets the medium

  // Equiangular samplers toward the lamps.
  for (const Lamp& lamp : scene.lighting.lamps) {
    RayContext::LampSampler s;
    const Vec3 op = lamp.position_m - o;
    s.delta = dot(op, w);
    s.b = std::max(length(op - s.delta * w), 1e-9);
    s.theta_a = std::atan2(-s.delta, s.b);
    s.theta_b = std::atan2(D - s.delta, s.b);
    ctx.lamp_sampler.push_back(s);
  }
  ctx.n_medium = (settings.medium_samples + int(ctx.medium_sampler.size()) - 1) /
                 int(ctx.medium_sampler.size());
  ctx.n_lamp = scene.lighting.lamps.empty() ? 0 : settings.lamp_samples;
  if (const auto& sun = scene.lighting.sun) {
    ctx.sun_dir = normalized(sun->direction_to_sun);
    ctx.sun_radius = sun->angular_radius_deg * kDeg;
  }

  // Batches of stratified multi-sample MIS estimates.
  const int B = settings.batches;
  std::vector<std::array<double, 3>> batch(B);
  for (int bi = 0; bi < B; ++bi) {
    Rng rng(mix_seed(settings.seed, stream, std::uint64_t(bi)));
    std::array<double, 3> sum{};
    // Sun and sky: the medium techniques, combined with the balance heuristic.
    for (const auto& ms : ctx.medium_sampler)
      for (int i = 0; i < ctx.n_medium; ++i) {
        const double t = ctx.sample_medium(ms, (i + rng.uniform()) / ctx.n_medium);
        const double q = ctx.medium_pdf_sum(t);
        if (!(q > 0)) continue;
        const auto f = ctx.integrand(t, -1, rng);
        for (int c = 0; c < 3; ++c) sum[c] += f[c] / q;
      }
    // Lamp k: its equiangular technique alone.
    for (std::size_t k = 0; k < ctx.lamp_sampler.size(); ++k) {
      const auto& ls = ctx.lamp_sampler[k];
      for (int i = 0; i < ctx.n_lamp; ++i) {
        const double t = ctx.sample_lamp(ls, (i + rng.uniform()) / ctx.n_lamp);
        const double q = ctx.n_lamp * ctx.lamp_pdf(ls, t);
        if (!(q > 0)) continue;
        const auto f = ctx.integrand(t, int(k), rng);
        for (int c = 0; c < 3; ++c) sum[c] += f[c] / q;
      }
    }
    batch[bi] = sum;
  }
  for (int c = 0; c < 3; ++c) {
    double mean = 0;
    for (const auto& b : batch) mean += b[c];
    mean /= B;
    double var = 0;
    for (const auto& b : batch) var += (b[c] - mean) * (b[c] - mean);
    out.inscatter[c] = mean;
    out.standard_error[c] = std::sqrt(var / (double(B) * (B - 1)));
  }
  return out;
}

SurfaceResult surface_reference(const Image& distance_m, const Camera& camera,
                                const FogScene& scene, const Geometry& geometry, int rays) {
  if (!scene.lighting.lamps.empty())
    throw std::invalid_argument("mc surface reference: lamps are not supported");
  if (!scene.lighting.sky_radiance)
    throw std::invalid_argument("mc surface reference: lighting.sky_radiance must be given");
  const int W = camera.width, H = camera.height;
  SurfaceResult res{Image(W, H, 3), Image(W, H, 3), Image(W, H, 3), Image(W, H, 1)};
  const Medium& m = scene.medium;
  const Rgb& sky = *scene.lighting.sky_radiance;
  tbb::parallel_for(tbb::blocked_range<int>(0, H), [&](const tbb::blocked_range<int>& range) {
    for (int y = range.begin(); y < range.end(); ++y)
      for (int x = 0; x < W; ++x) {
        const Vec3 o = scene.pose.position_m;
        const Vec3 w = scene.pose.ray_direction(camera, x, y);
        const double d = distance_m.at(x, y, 0);
        if (!std::isfinite(d)) {
          const RayEstimate e = estimate_ray(w, d, scene, geometry, Settings{2, 1, 1}, 0);
          for (int c = 0; c < 3; ++c) res.transmittance.at(x, y, c) = float(e.transmittance[c]);
          continue;
        }
        const Vec3 x0 = at(o, w, d);
        const Vec3 n = geometry.first_hit_normal(o, w);
        // Off the surface by a hair, so the point's own surface does not block its rays.
        const Vec3 xo = x0 + (1e-6 * (1 + d)) * n;
        Rng rng(mix_seed(0x5eed, std::uint64_t(y) * W + x, 17));
        auto u = [&rng] { return rng.uniform(); };
        double visible = 0, cos_i = 0;
        if (scene.lighting.sun) {
          const Vec3 l = normalized(scene.lighting.sun->direction_to_sun);
          cos_i = dot(n, l);
          if (cos_i > 0) {
            const double radius = scene.lighting.sun->angular_radius_deg * kPi / 180;
            int seen = 0;
            for (int i = 0; i < rays; ++i) {
              const Vec3 dir = sample_cone(l, radius, (i + u()) / rays, u());
              seen += dot(dir, n) > 0 && !geometry.occluded(xo, dir);
            }
            visible = double(seen) / rays;
          }
        }
        // Ambient occlusion: cosine-weighted directions about n, up to max(1, d / 4).
        const Vec3 helper = std::fabs(n.x) < 0.9 ? Vec3{1, 0, 0} : Vec3{0, 1, 0};
        const Vec3 t1 = normalized(cross(n, helper)), t2 = cross(n, t1);
        int open = 0;
        for (int i = 0; i < rays; ++i) {
          const double u1 = (i + u()) / rays, phi = 2 * kPi * u();
          const double r = std::sqrt(u1), cz = std::sqrt(std::max(0.0, 1 - u1));
          const Vec3 dir =
              normalized((r * std::cos(phi)) * t1 + (r * std::sin(phi)) * t2 + cz * n);
          open += !geometry.occluded(xo, dir, std::max(1.0, 0.25 * d));
        }
        const double ao = double(open) / rays;
        const double view_od = density_integral(m, o, w, 0, d);
        double sun_od = 0;
        if (scene.lighting.sun && scene.render.light_path_attenuation)
          sun_od = density_integral(m, x0, normalized(scene.lighting.sun->direction_to_sun), 0,
                                    kInfinity);
        res.sun_visibility.at(x, y, 0) = float(visible);
        for (int c = 0; c < 3; ++c) {
          const double direct =
              scene.lighting.sun ? scene.lighting.sun->irradiance[c] * std::max(0.0, cos_i) * visible
                                 : 0.0;
          const double ambient = kPi * sky[c] * ao;
          const double total = direct + ambient;
          const double S =
              total > 0 ? (direct * exp_neg(m.sigma_t_per_m[c], sun_od) + ambient) / total : 1.0;
          res.transmittance.at(x, y, c) = float(exp_neg(m.sigma_t_per_m[c], view_od) * S);
          res.direct.at(x, y, c) = float(direct);
          res.ambient.at(x, y, c) = float(ambient);
        }
      }
  });
  return res;
}

Result render(const Image& distance_m, const Camera& camera, const FogScene& scene,
              const Geometry& geometry, const Settings& settings) {
  if (distance_m.width() != camera.width || distance_m.height() != camera.height ||
      distance_m.channels() != 1)
    throw std::invalid_argument("mc reference: distance map must be 1 channel, camera-sized");
  if (!scene.lighting.sky_radiance)
    throw std::invalid_argument("mc reference: lighting.sky_radiance must be given");
  const int W = camera.width, H = camera.height;
  Result res{Image(W, H, 3), Image(W, H, 3), Image(W, H, 3)};
  tbb::parallel_for(tbb::blocked_range<int>(0, H), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y < rows.end(); ++y)
      for (int x = 0; x < W; ++x) {
        const Vec3 w = scene.pose.ray_direction(camera, x, y);
        const RayEstimate e = estimate_ray(w, distance_m.at(x, y, 0), scene, geometry, settings,
                                           std::uint64_t(y) * std::uint64_t(W) + std::uint64_t(x));
        for (int c = 0; c < 3; ++c) {
          res.inscatter.at(x, y, c) = float(e.inscatter[c]);
          res.standard_error.at(x, y, c) = float(e.standard_error[c]);
          res.transmittance.at(x, y, c) = float(e.transmittance[c]);
        }
      }
  });
  double sum = 0, worst = 0;
  std::size_t n = 0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      for (int c = 0; c < 3; ++c) {
        const double r = res.inscatter.at(x, y, c);
        if (!(r > 1e-4)) continue;
        const double rel = res.standard_error.at(x, y, c) / r;
        sum += rel;
        worst = std::max(worst, rel);
        ++n;
      }
  res.mean_relative_standard_error = n ? sum / double(n) : 0.0;
  res.max_relative_standard_error = worst;
  return res;
}

}  // namespace mr::mcref
