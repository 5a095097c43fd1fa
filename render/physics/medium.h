// The participating medium, shared by the CPU core and the Vulkan shaders (render/physics/
// types.h): the smooth density (homogeneous or exponential height fog, optionally inside a
// layer), its closed-form optical depth along a ray (DESIGN.md section 3), the inverse map from
// optical depth back to distance, and fBm noise that modulates the density.
#ifndef MR_RENDER_PHYSICS_MEDIUM_H
#define MR_RENDER_PHYSICS_MEDIUM_H

#include "render/physics/types.h"

MR_PHYSICS_BEGIN

MR_CONSTANT Float kPi = 3.14159265358979323846;

/// A pixel's distance that means "no surface": inf, NaN, or beyond float's range.
MR_FN bool is_sky(Float distance_m) {
  return isinf(distance_m) || isnan(distance_m) || distance_m > 3.0e38;
}

/// The smooth density: 0 outside [bottom_m, top_m]; inside 1, or exp(-(y - base_m) / scale_m)
/// when scale_m > 0 (height fog).
struct MediumShape {
  Float bottom_m;
  Float top_m;
  Float base_m;
  Float scale_m;
};

/// A ray o + t w inside the medium: in [t_enter, t_exit] the density is k exp(-a (t - t_enter))
/// (a = w_y / H; a = 0 and k = 1 for homogeneous fog). Optical depths are of the smooth density
/// for a unit extinction: times sigma_t per channel.
struct RayDensity {
  Float t_enter;
  Float t_exit;
  Float k;
  Float a;
  bool empty;
};

/// integral_0^L exp(-a s) ds = (1 - exp(-a L)) / a, stable for a -> 0 and L = inf.
MR_HOT_FN Float exp_integral(Float a, Float len) {
  if (len <= 0.0) return 0.0;
  if (isinf(len)) return a > 0.0 ? 1.0 / a : MR_INF;
  const Float x = a * len;
  if (abs(x) < MR_EXP_SERIES_BELOW) return len * (1.0 - 0.5 * x);
  return -expm1_(-x) / a;
}

MR_HOT_FN RayDensity ray_density(MediumShape m, Float3 o, Float3 w) {
  RayDensity r;
  r.t_enter = 0.0;
  r.t_exit = 0.0;
  r.k = 0.0;
  r.a = 0.0;
  r.empty = true;
  // Where the ray is inside the layer bottom <= y <= top.
  Float t0 = 0.0;
  Float t1 = MR_INF;
  if (w.y == 0.0) {
    if (o.y < m.bottom_m || o.y > m.top_m) return r;
  } else {
    Float ta = (m.bottom_m - o.y) / w.y;
    Float tb = (m.top_m - o.y) / w.y;
    if (ta > tb) {
      const Float swap_ = ta;
      ta = tb;
      tb = swap_;
    }
    t0 = max(t0, ta);
    t1 = min(t1, tb);
    if (!(t1 > t0)) return r;  // also catches NaN from inf - inf
  }
  r.empty = false;
  r.t_enter = t0;
  r.t_exit = t1;
  if (m.scale_m > 0.0) {
    r.a = w.y / m.scale_m;
    r.k = exp(-(o.y + t0 * w.y - m.base_m) / m.scale_m);  // rho(t_enter + s) = k exp(-a s)
  } else {
    r.a = 0.0;
    r.k = 1.0;
  }
  return r;
}

// Of k exp(-a s) ds over [t_enter, t].
MR_HOT_FN Float integral_from_enter(RayDensity r, Float t) {
  return r.k * exp_integral(r.a, min(t, r.t_exit) - r.t_enter);
}

/// Unit-extinction optical depth from t0 to t1 (t1 may be +inf), >= 0; +inf if the ray runs
/// forever through density bounded away from 0.
MR_HOT_FN Float optical_depth(RayDensity r, Float t0, Float t1) {
  if (r.empty || !(t1 > t0)) return 0.0;
  t0 = max(t0, r.t_enter);
  t1 = min(t1, r.t_exit);
  if (!(t1 > t0)) return 0.0;
  if (isinf(t1)) {
    const Float tail = r.k * exp_integral(r.a, MR_INF);  // from t_enter
    if (isinf(tail)) return MR_INF;
    return tail - integral_from_enter(r, t0);
  }
  // Homogeneous: one difference (the general form's two cancel to it less exactly).
  if (r.a == 0.0) return r.k * (t1 - t0);
  return integral_from_enter(r, t1) - integral_from_enter(r, t0);
}

/// The t >= 0 where optical_depth(0, t) == target (+inf beyond the optical depth to infinity).
MR_FN Float distance_at_optical_depth(RayDensity r, Float target) {
  if (r.empty) return MR_INF;
  if (target <= 0.0) return 0.0;
  // Solve k (1 - exp(-a s)) / a = target for s (homogeneous: k s = target).
  const Float x = target / r.k;
  Float s = x;
  if (!(abs(r.a) < 1e-12)) {
    const Float ax = r.a * x;
    if (1.0 - ax <= 0.0) return MR_INF;
    s = -log1p_(-ax) / r.a;
  }
  const Float t = r.t_enter + s;
  return t > r.t_exit ? MR_INF : t;
}

/// Density rho at distance t (smooth part; 0 outside the layer).
MR_HOT_FN Float density(RayDensity r, Float t) {
  if (r.empty || t < r.t_enter || t > r.t_exit) return 0.0;
  // Homogeneous fog: exp(-0 (t - t_enter)) is exactly 1 for a finite t (the quadrature's nodes
  // and a lamp's sample point), so k itself, without an exp per call.
  if (r.a == 0.0 && !isinf(t)) return r.k;
  return r.k * exp(-r.a * (t - r.t_enter));
}

/// Smooth density at a world point (0 outside the layer).
MR_FN Float density_at(MediumShape m, Float3 x) {
  if (x.y < m.bottom_m || x.y > m.top_m) return 0.0;
  if (!(m.scale_m > 0.0)) return 1.0;
  return exp(-(x.y - m.base_m) / m.scale_m);
}

/// sigma_t (1/m) times a unit-density optical depth (m): 0 where there is no medium, also along
/// an infinite ray (0 * inf would be NaN: clear air transmits everything).
MR_FN Float scaled_optical_depth(Float sigma_t_per_m, Float unit_optical_depth_m) {
  return sigma_t_per_m > 0.0 ? sigma_t_per_m * unit_optical_depth_m : 0.0;
}
MR_FN Float3 scaled_optical_depth(Float3 sigma_t_per_m, Float unit_optical_depth_m) {
  return Float3(scaled_optical_depth(sigma_t_per_m.x, unit_optical_depth_m),
                scaled_optical_depth(sigma_t_per_m.y, unit_optical_depth_m),
                scaled_optical_depth(sigma_t_per_m.z, unit_optical_depth_m));
}
/// The march's far end: the surface, or for the sky (distance inf) where the fog has (almost)
/// ended: max_distance_m when > 0, else transmittance 1e-4 in the clearest channel (extinction
/// sigma_min), or, fog thinning upward, all but 1e-4 of the remaining optical depth; at most
/// 100 km.
MR_FN Float march_length(RayDensity rd, Float distance, Float max_distance_m, Float sigma_min) {
  if (!is_sky(distance)) return distance;
  if (max_distance_m > 0.0) return max_distance_m;
  const Float kMax = 100e3;
  if (sigma_min <= 0.0) return kMax;
  const Float od_inf = optical_depth(rd, 0.0, MR_INF);
  const Float target = isinf(od_inf) ? 9.21 / sigma_min : od_inf - 1e-4 / sigma_min;
  if (target <= 0.0) return 0.0;
  return min(kMax, distance_at_optical_depth(rd, target));
}

/// Sky light only (no sun, no lamps, no noise; DESIGN.md section 3): the in-scatter R of a pixel
/// whose camera optical depths are `od` (per channel); albedo_sky = albedo L_sky. The source is
/// constant along the ray, so the march's sum telescopes to R = albedo L_sky (1 - tau) exactly;
/// expm1 keeps thin fog's 1 - tau precise. T is exp(-od) (S = 1: ambient light only).
MR_FN Float3 sky_only_inscatter(Float3 od, Float3 albedo_sky) {
  Float3 scattered = Float3(0.0, 0.0, 0.0);  // 1 - tau; grey fog needs one expm1
  scattered.x = -expm1_(-od.x);
  scattered.y = od.y == od.x ? scattered.x : -expm1_(-od.y);
  scattered.z = od.z == od.y ? scattered.y : -expm1_(-od.z);
  return albedo_sky * scattered;
}

// ---- noise ----------------------------------------------------------------------------------

/// A 32-bit integer hash with good avalanche (Wellons' "lowbias32"): the one hash of render/
/// (ambient occlusion's and the surface shading's rays).
MR_FN uint hash32(uint x) {
  x ^= x >> 16;
  x *= 0x7feb352du;
  x ^= x >> 15;
  x *= 0x846ca68bu;
  x ^= x >> 16;
  return x;
}
/// The top 24 bits of a hash as a number in [0, 1) (exact in float and double).
MR_FN Float unit_float(uint bits) {
  return Float(bits >> 8) * (1.0 / 16777216.0);
}

MR_FN uint hash_combine_(uint h, uint v) {
  h ^= v + 0x7F4A7C15u + (h << 6) + (h >> 2);
  h *= 0x85EBCA6Bu;
  h ^= h >> 13;
  return h;
}
/// The noise lattice's hash of a cell.
MR_FN uint hash3(int x, int y, int z, uint seed) {
  uint h = seed * 0x9E3779B9u;
  h = hash_combine_(h, uint(x));
  h = hash_combine_(h, uint(y));
  h = hash_combine_(h, uint(z));
  return h;
}

// The gradient of a lattice corner dotted with the offset: 12 edge directions of a cube, as in
// improved Perlin noise.
MR_FN Float noise_grad(int cx, int cy, int cz, Float rx, Float ry, Float rz, uint seed) {
  // h = 0..3: (+-rx) + (+-ry); 4..7: (+-rx) + (+-rz); 8..11: (+-ry) + (+-rz).
  const uint h = hash3(cx, cy, cz, seed) % 12u;
  const Float u = h < 8u ? rx : ry;
  const Float v = h < 4u ? ry : rz;
  return ((h & 1u) == 0u ? u : -u) + ((h & 2u) == 0u ? v : -v);
}

MR_FN Float noise_fade(Float t) {
  return t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
}

/// Perlin-style gradient noise in [-1, 1] (approximately), deterministic for a seed.
MR_FN Float gradient_noise(Float3 p, uint seed) {
  const Float fx = floor(p.x);
  const Float fy = floor(p.y);
  const Float fz = floor(p.z);
  const int ix = int(fx);
  const int iy = int(fy);
  const int iz = int(fz);
  const Float dx = p.x - fx;
  const Float dy = p.y - fy;
  const Float dz = p.z - fz;
  const Float u = noise_fade(dx);
  const Float v = noise_fade(dy);
  const Float w = noise_fade(dz);
  Float c[8];
  for (int k = 0; k < 2; ++k)
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i < 2; ++i)
        c[k * 4 + j * 2 + i] =
            noise_grad(ix + i, iy + j, iz + k, dx - Float(i), dy - Float(j), dz - Float(k), seed);
  const Float x00 = lerp_(c[0], c[1], u);
  const Float x10 = lerp_(c[2], c[3], u);
  const Float x01 = lerp_(c[4], c[5], u);
  const Float x11 = lerp_(c[6], c[7], u);
  return lerp_(lerp_(x00, x10, v), lerp_(x01, x11, v), w);
}

/// The density's noise modulation max(0, 1 + amplitude fbm(x frequency)) (1 when amplitude <=
/// 0): `octaves` octaves of gradient noise, each twice the frequency and half the weight.
MR_FN Float noise_modulation(Float3 x, Float amplitude, Float frequency, int octaves, uint seed) {
  if (amplitude <= 0.0) return 1.0;
  Float sum = 0.0;
  Float amp = 1.0;
  Float norm = 0.0;
  Float freq = frequency;
  for (int o = 0; o < octaves; ++o) {
    sum += amp * gradient_noise(x * freq, seed + 101u * uint(o));
    norm += amp;
    amp *= 0.5;
    freq *= 2.0;
  }
  return max(0.0, 1.0 + amplitude * clamp(sum / norm, -1.0, 1.0));
}

MR_PHYSICS_END

#endif  // MR_RENDER_PHYSICS_MEDIUM_H
