// The single-scattering physics of render/scattering_cpu.cpp and render/medium.cpp, in GLSL,
// for the Vulkan compute backend (render/vulkan/). Every function below mirrors the CPU function
// of the same name; keep them in step (the tests in tests/vulkan_scattering_test.cpp compare the
// two backends on the CPU core's test scenes).
//
// Differences from the CPU reference, all deliberate and measured in the tests / README:
// - float instead of double; expm1 / log1p / atan differences are evaluated in forms that keep
//   their relative precision (GPU exp/log are only accurate to ~2^-21 in absolute terms near 1);
// - shadows are looked up in shadow maps of the occluder mesh (sun: cascaded orthographic maps;
//   lamps: six cube faces) instead of traced with Embree; the sun is a point light for shadowing
//   (the CPU samples its 0.27 degree disk), so penumbrae are hard.
#extension GL_GOOGLE_include_directive : require

#include "scattering_params.h"

#define INF uintBitsToFloat(0x7F800000u)
const float kPi = 3.14159265358979323846;

layout(std430, set = 0, binding = 0) readonly buffer ParamsBuffer { ScatterParams P; };
layout(std430, set = 0, binding = 1) readonly buffer LampBuffer { GpuLamp lamps[]; };
layout(std430, set = 0, binding = 2) readonly buffer LayerBuffer { ShadowLayer layers[]; };
layout(std430, set = 0, binding = 3) readonly buffer DepthBuffer { float depth_m[]; };
layout(std430, set = 0, binding = 4) readonly buffer NormalBuffer { float normals[]; };
layout(std430, set = 0, binding = 5) buffer GridBuffer { vec4 grid_samples[]; };
layout(set = 0, binding = 11) uniform sampler2DArray shadow_atlas;

bool has_flag(int f) { return (P.flags.x & uint(f)) != 0u; }

// ---- numerics -------------------------------------------------------------------------------

float expm1_(float x) {
  if (abs(x) < 0.3)
    return x * (1.0 + x * (1.0 / 2.0 + x * (1.0 / 6.0 + x * (1.0 / 24.0 + x * (1.0 / 120.0 +
           x * (1.0 / 720.0 + x * (1.0 / 5040.0 + x * (1.0 / 40320.0))))))));
  return exp(x) - 1.0;
}
vec3 expm1_3(vec3 x) { return vec3(expm1_(x.x), expm1_(x.y), expm1_(x.z)); }

float log1p_(float x) {
  if (abs(x) < 0.3) {
    const float s = x / (2.0 + x), s2 = s * s;  // log1p = 2 atanh(s)
    return 2.0 * s * (1.0 + s2 * (1.0 / 3.0 + s2 * (1.0 / 5.0 + s2 * (1.0 / 7.0 + s2 * (1.0 / 9.0 +
           s2 * (1.0 / 11.0 + s2 * (1.0 / 13.0)))))));
  }
  return log(1.0 + x);
}

// atan(b) - atan(a), accurate when the two are close.
float atan_diff(float a, float b) {
  const float den = 1.0 + a * b;
  if (den > 0.5) return atan((b - a) / den);
  return atan(b) - atan(a);
}

bool is_sky(float d) { return isinf(d) || isnan(d) || d > 3.0e38; }

// ---- the medium (render/medium.cpp) ----------------------------------------------------------

struct RayDensity {
  float t_enter, t_exit, k, a;
  bool empty;
};

float exp_integral(float a, float len) {
  if (len <= 0.0) return 0.0;
  if (isinf(len)) return a > 0.0 ? 1.0 / a : INF;
  const float x = a * len;
  if (abs(x) < 1e-7) return len * (1.0 - 0.5 * x);
  return -expm1_(-x) / a;
}

RayDensity ray_density(vec3 o, vec3 w) {
  RayDensity r;
  r.empty = true;
  r.t_enter = 0.0;
  r.t_exit = 0.0;
  r.k = 0.0;
  r.a = 0.0;
  float t0 = 0.0, t1 = INF;
  const float bottom = P.layer.x, top = P.layer.y;
  if (w.y == 0.0) {
    if (o.y < bottom || o.y > top) return r;
  } else {
    float ta = (bottom - o.y) / w.y, tb = (top - o.y) / w.y;
    if (ta > tb) {
      const float tmp = ta;
      ta = tb;
      tb = tmp;
    }
    t0 = max(t0, ta);
    t1 = min(t1, tb);
    if (!(t1 > t0)) return r;
  }
  r.empty = false;
  r.t_enter = t0;
  r.t_exit = t1;
  if (P.layer.w > 0.0) {
    const float h = P.layer.w;
    r.a = w.y / h;
    r.k = exp(-(o.y + t0 * w.y - P.layer.z) / h);
  } else {
    r.a = 0.0;
    r.k = 1.0;
  }
  return r;
}

float integral_from_enter(RayDensity r, float t) {
  return r.k * exp_integral(r.a, min(t, r.t_exit) - r.t_enter);
}

float optical_depth(RayDensity r, float t0, float t1) {
  if (r.empty || !(t1 > t0)) return 0.0;
  t0 = max(t0, r.t_enter);
  t1 = min(t1, r.t_exit);
  if (!(t1 > t0)) return 0.0;
  if (isinf(t1)) {
    const float tail = r.k * exp_integral(r.a, INF);
    if (isinf(tail)) return INF;
    return tail - integral_from_enter(r, t0);
  }
  if (r.a == 0.0) return r.k * (t1 - t0);
  return integral_from_enter(r, t1) - integral_from_enter(r, t0);
}

float distance_at_optical_depth(RayDensity r, float target) {
  if (r.empty) return INF;
  if (target <= 0.0) return 0.0;
  const float x = target / r.k;
  float s;
  if (abs(r.a) < 1e-12) {
    s = x;
  } else {
    const float ax = r.a * x;
    if (1.0 - ax <= 0.0) return INF;
    s = -log1p_(-ax) / r.a;
  }
  const float t = r.t_enter + s;
  return t > r.t_exit ? INF : t;
}

float density(RayDensity r, float t) {
  if (r.empty || t < r.t_enter || t > r.t_exit) return 0.0;
  return r.k * exp(-r.a * (t - r.t_enter));
}

uint hash3(int x, int y, int z, uint seed) {
  uint h = seed * 0x9E3779B9u;
  uint v[3] = uint[3](uint(x), uint(y), uint(z));
  for (int i = 0; i < 3; ++i) {
    h ^= v[i] + 0x7F4A7C15u + (h << 6) + (h >> 2);
    h *= 0x85EBCA6Bu;
    h ^= h >> 13;
  }
  return h;
}

float noise_grad(int cx, int cy, int cz, float rx, float ry, float rz, uint seed) {
  switch (hash3(cx, cy, cz, seed) % 12u) {
    case 0u: return rx + ry;
    case 1u: return -rx + ry;
    case 2u: return rx - ry;
    case 3u: return -rx - ry;
    case 4u: return rx + rz;
    case 5u: return -rx + rz;
    case 6u: return rx - rz;
    case 7u: return -rx - rz;
    case 8u: return ry + rz;
    case 9u: return -ry + rz;
    case 10u: return ry - rz;
    default: return -ry - rz;
  }
}

float fade(float t) { return t * t * t * (t * (t * 6.0 - 15.0) + 10.0); }

float gradient_noise(vec3 p, uint seed) {
  const vec3 f = floor(p);
  const ivec3 i = ivec3(f);
  const vec3 d = p - f;
  const float u = fade(d.x), v = fade(d.y), w = fade(d.z);
  float c[8];
  for (int k = 0; k < 2; ++k)
    for (int j = 0; j < 2; ++j)
      for (int l = 0; l < 2; ++l)
        c[k * 4 + j * 2 + l] =
            noise_grad(i.x + l, i.y + j, i.z + k, d.x - float(l), d.y - float(j), d.z - float(k), seed);
  const float x00 = mix(c[0], c[1], u), x10 = mix(c[2], c[3], u);
  const float x01 = mix(c[4], c[5], u), x11 = mix(c[6], c[7], u);
  return mix(mix(x00, x10, v), mix(x01, x11, v), w);
}

float noise_modulation(vec3 x) {
  if (P.noise.x <= 0.0) return 1.0;
  float sum = 0.0, amp = 1.0, norm = 0.0, freq = P.noise.y;
  const int octaves = int(P.flags.w);
  for (int o = 0; o < octaves; ++o) {
    sum += amp * gradient_noise(x * freq, P.flags.z + 101u * uint(o));
    norm += amp;
    amp *= 0.5;
    freq *= 2.0;
  }
  return max(0.0, 1.0 + P.noise.x * clamp(sum / norm, -1.0, 1.0));
}

float henyey_greenstein(float g, float cos_theta) {
  const float denom = 1.0 + g * g - 2.0 * g * cos_theta;
  return (1.0 - g * g) / (4.0 * kPi * denom * sqrt(denom));
}

// ---- camera, jitter, lamps (render/scattering_cpu.cpp) ---------------------------------------

vec3 ray_dir(int x, int y) {
  const float u = (float(x) + 0.5 - P.camera.y) / P.camera.x;
  const float v = (float(y) + 0.5 - P.camera.z) / P.camera.x;
  return normalize(u * P.right.xyz - v * P.up.xyz + P.forward.xyz);
}

// Interleaved gradient noise, as pixel_jitter on the CPU. fract(a x + b y) is formed in 32-bit
// fixed point (exact for integer pixels), so it keeps the CPU's double precision.
float pixel_jitter(int x, int y, uint seed) {
  const uint a = 288240406u;  // round(0.06711056 * 2^32)
  const uint b = 25070697u;   // round(0.00583715 * 2^32)
  const uint frac32 = a * uint(x) + b * uint(y);
  const float f = float(frac32 >> 8) * (1.0 / 16777216.0);
  const float ign = fract(52.9829189 * f);
  const float rot = float((seed * 2654435761u) >> 8) / 16777216.0;
  return fract(ign + rot);
}

float spot_factor(GpuLamp lamp, vec3 from_lamp_unit) {
  if (lamp.spot.w == 0.0) return 1.0;
  const float cos_a = dot(lamp.spot.xyz, from_lamp_unit);
  const float cos_in = lamp.cone.x, cos_out = lamp.cone.y;
  if (cos_a >= cos_in) return 1.0;
  if (cos_a <= cos_out) return 0.0;
  const float t = (cos_a - cos_out) / (cos_in - cos_out);
  return t * t * (3.0 - 2.0 * t);
}

// ---- shadow maps ------------------------------------------------------------------------------

// The depth stored in shadow-map `layer` where x projects, or +inf when x is outside the layer.
float shadow_lookup(int layer, vec3 x, out bool inside) {
  inside = false;
  const vec4 clip = layers[layer].view_proj * vec4(x, 1.0);
  if (!(clip.w > 0.0)) return INF;
  const vec2 ndc = clip.xy / clip.w;
  if (!(abs(ndc.x) <= 1.0 && abs(ndc.y) <= 1.0)) return INF;
  inside = true;
  const int size = int(P.misc.y);
  const ivec2 texel = clamp(ivec2((ndc * 0.5 + 0.5) * float(size)), ivec2(0), ivec2(size - 1));
  return texelFetch(shadow_atlas, ivec3(texel, layer), 0).r;
}

// Whether the sun reaches x (view distance t_view picks the cascade). `bias`: the CPU's shadow
// ray starts this far from x. Surface points pass their normal n (else 0): they are looked up
// `offset` off the surface, at least 1.5 texels (normal-offset shadow mapping).
bool sun_lit(vec3 x, vec3 n, float t_view, float offset, float bias) {
  const int count = P.grid_count.z;
  int c = 0;
  while (c + 1 < count && t_view > P.cascade_end[c]) ++c;
  for (; c < count; ++c) {
    const vec3 xo = x + n * max(offset, 1.5 * layers[c].axis.w);
    bool inside;
    const float stored = shadow_lookup(c, xo, inside);
    if (!inside) continue;  // past this cascade's edge: a wider one holds x
    return !(stored < dot(xo, layers[c].axis.xyz) - bias);
  }
  return true;  // outside every cascade: no occluder between x and the sun
}

// Whether `lamp` reaches x at distance r from it (n, offset: as for sun_lit).
bool lamp_lit(GpuLamp lamp, vec3 x, vec3 n, float r, float offset, float bias) {
  const int base = int(lamp.position.w);
  if (base < 0) return true;
  const vec3 d = x - lamp.position.xyz;
  int face = 0;
  float best = -INF;
  for (int f = 0; f < 6; ++f) {
    const float v = dot(d, layers[base + f].axis.xyz);
    if (v > best) {
      best = v;
      face = f;
    }
  }
  const vec3 xo = x + n * max(offset, 1.5 * r * layers[base + face].axis.w);
  bool inside;
  const float stored = shadow_lookup(base + face, xo, inside);
  return !(stored < length(xo - lamp.position.xyz) - bias);
}

// ---- pixels -----------------------------------------------------------------------------------

float depth_at(int x, int y) {
  return depth_m[(y - P.region.y) * P.region.z + (x - P.region.x)];
}
vec3 normal_at(int x, int y) {
  const int i = 3 * ((y - P.region.y) * P.region.z + (x - P.region.x));
  return vec3(normals[i], normals[i + 1], normals[i + 2]);
}

float march_length(RayDensity rd, float distance) {
  if (!is_sky(distance)) return distance;
  if (P.misc.x > 0.0) return P.misc.x;
  const float kMax = 100e3;
  const float sigma_min = P.sky.w;
  if (sigma_min <= 0.0) return kMax;
  const float od_inf = optical_depth(rd, 0.0, INF);
  const float target = isinf(od_inf) ? 9.21 / sigma_min : od_inf - 1e-4 / sigma_min;
  if (target <= 0.0) return 0.0;
  return min(kMax, distance_at_optical_depth(rd, target));
}

struct PixelSample {
  vec3 inscatter;
  vec3 camera_od;
  float shaft;  // the sun-lit fraction of the march's length, averaged over segments (1: no sun)
  float ao;
};

// Lamps the march handles (each brings an equiangular boundary sequence).
const int kMaxLamps = 16;

struct MarchSetup {
  RayDensity rd;
  float len;
  float od_mean_total;
  float one_minus_tau_end;
  int steps;  // segments uniform in transmittance (the preset's, or more at a shaft's edge)
};

float uniform_boundary(MarchSetup m, int i) {
  if (m.od_mean_total > 1e-6) {
    const float frac = float(i) / float(m.steps);
    const float neg_log_tau = -log1p_(-m.one_minus_tau_end * frac);
    return distance_at_optical_depth(m.rd, neg_log_tau / P.sigma.w);
  }
  return m.len * float(i) / float(m.steps);
}

float lamp_boundary(float tc, float h, float th_a, float th_b, int i) {
  return tc + h * tan(th_a + (th_b - th_a) * float(i) / float(P.plan.y));
}

// The segment boundaries in order: the sorted, de-duplicated union of the uniform sequence and
// every lamp's equiangular one (the CPU sorts them all; here they are merged as they go).
struct Boundaries {
  int n_lamps;
  float l_tc[kMaxLamps], l_h[kMaxLamps], l_tha[kMaxLamps], l_thb[kMaxLamps];
  int l_next[kMaxLamps];
  float l_val[kMaxLamps];
  int u_next;
  float u_val;
};

// The next boundary after ta (the march's end m.len; ta itself once ta has reached the end).
float next_boundary(MarchSetup m, inout Boundaries b, float ta) {
  // Advance every sequence past ta, then take the smallest next value (or the end).
  while (b.u_val <= ta && b.u_next < m.steps) {
    ++b.u_next;
    if (b.u_next >= m.steps) {
      b.u_val = INF;
      break;
    }
    const float t = uniform_boundary(m, b.u_next);
    b.u_val = (t > 0.0 && t < m.len) ? t : (t >= m.len ? INF : -INF);
    if (b.u_val == INF) b.u_next = m.steps;
  }
  if (b.u_next >= m.steps && b.u_val <= ta) b.u_val = INF;
  float tb = min(b.u_val, m.len);
  for (int l = 0; l < b.n_lamps; ++l) {
    while (b.l_val[l] <= ta && b.l_next[l] < P.plan.y) {
      ++b.l_next[l];
      if (b.l_next[l] >= P.plan.y) {
        b.l_val[l] = INF;
        break;
      }
      const float t = lamp_boundary(b.l_tc[l], b.l_h[l], b.l_tha[l], b.l_thb[l], b.l_next[l]);
      b.l_val[l] = (t > 0.0 && t < m.len) ? t : (t >= m.len ? INF : -INF);
      if (b.l_val[l] == INF) b.l_next[l] = P.plan.y;
    }
    if (b.l_next[l] >= P.plan.y && b.l_val[l] <= ta) b.l_val[l] = INF;
    tb = min(tb, b.l_val[l]);
  }
  return tb;
}

// Whether the sun reaches the view ray's point at t (a march sample's shadow query).
bool sun_lit_on_ray(vec3 origin, vec3 w, float t) {
  return sun_lit(origin + w * t, vec3(0.0), t, 0.0, 1e-3 + 1e-4 * t);
}

// `steps`: view-ray segments uniform in transmittance (the preset's, or more where a pixel
// straddles a shaft edge), as the CPU's march(x, y, steps).
PixelSample march(int x, int y, int steps) {
  PixelSample s;
  s.inscatter = vec3(0.0);
  s.camera_od = vec3(0.0);
  s.shaft = 1.0;
  s.ao = 1.0;
  const float distance = depth_at(x, y);
  const vec3 w = ray_dir(x, y);
  const vec3 origin = P.origin.xyz;
  MarchSetup m;
  m.rd = ray_density(origin, w);
  m.len = march_length(m.rd, distance);
  m.steps = steps;
  const float od_unit_total = optical_depth(m.rd, 0.0, m.len);
  const vec3 sigma = P.sigma.xyz, albedo = P.albedo.xyz;
  const bool noise = has_flag(kFlagNoise);

  if (has_flag(kFlagConstantSource) || m.len <= 0.0) {
    const float od_exact = optical_depth(m.rd, 0.0, distance);
    s.camera_od = sigma * od_exact;
    s.inscatter = albedo * P.sky.xyz * -expm1_3(-s.camera_od);
    return s;
  }

  m.od_mean_total = P.sigma.w * od_unit_total;
  m.one_minus_tau_end = -expm1_(-m.od_mean_total);
  Boundaries b;
  b.n_lamps = min(P.image.w, kMaxLamps);
  // Lamps' closest approach to the ray and their equiangular sequences.
  for (int l = 0; l < b.n_lamps; ++l) {
    const vec3 rel = lamps[l].position.xyz - origin;
    const float tc = dot(rel, w);
    const float h = max(1e-6, length(rel - tc * w));  // = sqrt(|rel|^2 - tc^2), without cancellation
    b.l_tc[l] = tc;
    b.l_h[l] = h;
    b.l_tha[l] = atan(-tc, h);
    b.l_thb[l] = atan(m.len - tc, h);
    b.l_next[l] = 0;
    b.l_val[l] = -INF;
  }
  b.u_next = 0;
  b.u_val = -INF;

  const float jitter = pixel_jitter(x, y, P.flags.y);
  vec3 od = vec3(0.0), tau_a = vec3(1.0);
  int sun_samples = 0;
  float sun_seen_fraction = 0.0;
  const bool sun = has_flag(kFlagSun), shadows = has_flag(kFlagShadows);
  const bool sun_shadows = sun && shadows;
  const bool lpa = has_flag(kFlagLightPathAttenuation);
  const float g = P.albedo.w;
  const int n_lamps = b.n_lamps;

  // Segment i = [ta, tb] with its sample ts and the sun's visibility there; a segment's lit part
  // needs its neighbours' samples too (the CPU first takes every sample, then sums), so the
  // march runs one segment ahead: segment i + 1 (tn, ts_n, vis_n) and the crossing between
  // samples i and i + 1 are known when segment i is summed.
  float ta = 0.0;
  float tb = next_boundary(m, b, ta);
  if (!(tb > ta)) return s;  // an empty march
  // Stratified jitter: each segment's own offset (a golden-ratio sequence from the pixel's).
  float ts = ta + (tb - ta) * fract(jitter);
  bool vis = !sun_shadows || sun_lit_on_ray(origin, w, ts);
  bool vis_prev = vis;
  float crossing_prev = ta;  // visibility change between samples i - 1 and i (where vis_prev != vis)
  for (int i = 0;; ++i) {
    const float tn = next_boundary(m, b, tb);
    const bool has_next = tn > tb;
    float ts_n = tb;
    bool vis_n = vis;
    float crossing = tb;
    if (has_next) {
      ts_n = tb + (tn - tb) * fract(jitter + 0.6180339887498949 * float(i + 1));
      vis_n = !sun_shadows || sun_lit_on_ray(origin, w, ts_n);
      if (vis_n != vis) {
        // Shaft edge: bisect between the two samples for the crossing (to 1/64 of the gap).
        float lo = ts, hi = ts_n;
        for (int k = 0; k < kEdgeBisections; ++k) {
          const float mid = 0.5 * (lo + hi);
          if (sun_lit_on_ray(origin, w, mid) == vis)
            lo = mid;
          else
            hi = mid;
        }
        crossing = 0.5 * (lo + hi);
      }
    }

    const vec3 xs = origin + w * ts;
    const float modulation = noise ? noise_modulation(xs) : 1.0;
    const float seg_od_unit = optical_depth(m.rd, ta, tb) * modulation;
    const vec3 tau_before = tau_a;
    od += sigma * seg_od_unit;
    const vec3 tau_b = exp(-od);
    const vec3 weight = albedo * tau_a * -expm1_3(-sigma * seg_od_unit);
    tau_a = tau_b;
    if (!(weight.x + weight.y + weight.z <= 0.0 && tau_before.x + tau_before.y + tau_before.z <= 0.0)) {
      if (sun) {
        // The segment's lit weight: [ta, tl] is lit as sample i - 1, [tl, tr] as sample i,
        // [tr, tb] as sample i + 1 (tl, tr: the bisected crossings that fall inside it).
        const float tl = vis_prev != vis ? max(ta, crossing_prev) : ta;
        const float tr = vis_n != vis ? min(tb, crossing) : tb;
        vec3 lit_weight = vec3(0.0);
        if (tl == ta && tr == tb) {
          if (vis) lit_weight = weight;
        } else {
          const float piece_t[4] = float[4](ta, tl, tr, tb);
          const bool piece_lit[3] = bool[3](vis_prev, vis, vis_n);
          for (int k = 0; k < 3; ++k) {
            const float p = piece_t[k], q = piece_t[k + 1];
            if (!piece_lit[k] || !(q > p)) continue;
            // exp(-sigma od(ta, p)) - exp(-sigma od(ta, q)), without the cancellation.
            const float od_p = optical_depth(m.rd, ta, p) * modulation;
            const float od_pq = optical_depth(m.rd, p, q) * modulation;
            lit_weight += albedo * tau_before * exp(-sigma * od_p) * -expm1_3(-sigma * od_pq);
          }
        }
        const float length_ab = tb - ta;
        sun_seen_fraction += length_ab > 0.0
                                 ? ((vis_prev ? tl - ta : 0.0) + (vis ? tr - tl : 0.0) +
                                    (vis_n ? tb - tr : 0.0)) / length_ab
                                 : (vis ? 1.0 : 0.0);
        ++sun_samples;
        if (lit_weight.x + lit_weight.y + lit_weight.z > 0.0) {
          const float phase = henyey_greenstein(g, dot(w, P.sun_dir.xyz));
          const float od_sun = lpa ? optical_depth(ray_density(xs, P.sun_dir.xyz), 0.0, INF) : 0.0;
          s.inscatter += lit_weight * phase * P.sun_irradiance.xyz * exp(-sigma * od_sun);
        }
      }
      for (int l = 0; l < n_lamps; ++l) {
        const GpuLamp lamp = lamps[l];
        const float h = b.l_h[l], tc = b.l_tc[l];
        const float A = (ta - tc) / h, B = (tb - tc) / h;
        const float th_a = atan(A), th_b = atan(B);
        const float tm = clamp(tc + h * tan(0.5 * (th_a + th_b)), ta, tb);
        const vec3 xm = origin + w * tm;
        const vec3 to_lamp = lamp.position.xyz - xm;
        const float r = length(to_lamp);
        if (r < 1e-9) continue;
        const vec3 lv = to_lamp / r;
        const float spot = spot_factor(lamp, -lv);
        if (spot <= 0.0) continue;
        if (shadows && !lamp_lit(lamp, xm, vec3(0.0), r, 0.0, 1e-3 + 1e-4 * tm)) continue;
        const float lamp_modulation = noise ? noise_modulation(xm) : 1.0;
        const float rho = density(m.rd, tm) * lamp_modulation;
        const float od_to_m = optical_depth(m.rd, ta, tm) * lamp_modulation;
        const float phase = henyey_greenstein(g, dot(w, lv));
        const float od_lamp = lpa ? optical_depth(ray_density(xm, lv), 0.0, r) : 0.0;
        const float common_ = atan_diff(A, B) / h * phase * spot * rho;
        s.inscatter += albedo * sigma * tau_before * exp(-sigma * (od_to_m + od_lamp)) * common_ *
                       lamp.intensity.xyz;
      }
      s.inscatter += weight * P.sky.xyz;
    }
    if (!has_next) break;
    vis_prev = vis;
    crossing_prev = crossing;
    ta = tb;
    tb = tn;
    ts = ts_n;
    vis = vis_n;
  }
  s.camera_od = od;
  s.shaft = sun_samples > 0 ? sun_seen_fraction / float(sun_samples) : 1.0;
  return s;
}

// The fraction of the sun's disk a surface pixel sees past the occluders (-1 where that does not
// apply: no sun, no surface or normal, or the surface faces away from the sun). Hard: 0 or 1.
float sun_disk_visibility(int x, int y) {
  if (!has_flag(kFlagSun) || !has_flag(kFlagNormals)) return -1.0;
  const float distance = depth_at(x, y);
  if (is_sky(distance)) return -1.0;
  const vec3 n = normal_at(x, y);
  if (dot(n, n) < 0.5 || dot(n, P.sun_dir.xyz) <= 0.0) return -1.0;
  if (!has_flag(kFlagShadows)) return 1.0;
  const vec3 x0 = P.origin.xyz + ray_dir(x, y) * distance;
  return sun_lit(x0, n, distance, 1e-3 + 1e-3 * distance, 0.0) ? 1.0 : 0.0;
}

// Camera optical depth in closed form (exact unless noise modulates the view ray).
vec3 camera_optical_depth(int x, int y) {
  const vec3 w = ray_dir(x, y);
  const RayDensity rd = ray_density(P.origin.xyz, w);
  const float d = depth_at(x, y);
  const float len = march_length(rd, d);
  return P.sigma.xyz * optical_depth(rd, 0.0, is_sky(d) ? INF : len);
}

// ---- ambient occlusion ------------------------------------------------------------------------
// The CPU traces AO rays against the occluder mesh with Embree. The mesh is the depth map's
// surface: every pixel a planar patch through its 3D point with its normal. Without ray queries
// the GPU marches the same rays (same directions, same seed) in screen space against that
// per-pixel plane model: a ray is blocked where it crosses, from the front, the planar patch of
// the pixel it passes over; passing behind a silhouette is not a hit (the mesh breaks at depth
// discontinuities). Rays that leave the image or the
// uploaded region, or pass behind the camera, meet no geometry (the mesh lies inside the view).

uint hash32(uint x) {
  x ^= x >> 16;
  x *= 0x7feb352du;
  x ^= x >> 15;
  x *= 0x846ca68bu;
  x ^= x >> 16;
  return x;
}
float unit_float(uint bits) { return float(bits >> 8) * (1.0 / 16777216.0); }

const int kAoMaxSteps = 96;

// Projects a world point to continuous pixel coordinates; false behind the camera.
bool project(vec3 q, out vec2 pixel) {
  const vec3 rel = q - P.origin.xyz;
  const float z = dot(rel, P.forward.xyz);
  pixel = vec2(0.0);
  if (z <= 1e-6) return false;
  pixel = vec2(P.camera.y + P.camera.x * dot(rel, P.right.xyz) / z,
               P.camera.z - P.camera.x * dot(rel, P.up.xyz) / z);
  return true;
}

// Whether the ray p + t dir, 0 < t <= t_far, meets the depth map's surface: marched in steps of
// about one pixel; a hit is a step that crosses the plane of the pixel it lands on, from its
// front, at a point that projects into that pixel (or a neighbour).
bool screen_space_occluded(vec3 p, vec3 dir, float t_far) {
  // Clip the ray to the camera's front half-space, then size the steps to ~1 pixel.
  const float z0 = dot(p - P.origin.xyz, P.forward.xyz), dz = dot(dir, P.forward.xyz);
  float t_end = t_far;
  if (dz < 0.0) t_end = min(t_end, 0.999 * (z0 - 1e-3) / -dz);
  if (t_end <= 0.0) return false;
  vec2 a, b;
  project(p, a);
  project(p + t_end * dir, b);
  const int steps = clamp(int(ceil(length(b - a))), 2, kAoMaxSteps);
  vec3 q_prev = p;
  for (int k = 1; k <= steps; ++k) {
    const vec3 q = p + (t_end * float(k) / float(steps)) * dir;
    vec2 px;
    if (!project(q, px)) return false;  // behind the camera: no geometry there
    const int ix = int(floor(px.x)), iy = int(floor(px.y));
    if (ix < P.region.x || iy < P.region.y || ix >= P.region.x + P.region.z || iy >= P.region.y + P.region.w)
      return false;  // left the image (or the uploaded region)
    const float d = depth_at(ix, iy);
    if (!is_sky(d)) {
      const vec3 n = normal_at(ix, iy);
      const vec3 xp = P.origin.xyz + ray_dir(ix, iy) * d;
      const float s_prev = dot(q_prev - xp, n), s = dot(q - xp, n);
      if (s_prev > 0.0 && s <= 0.0) {
        const vec3 hit = mix(q_prev, q, s_prev / (s_prev - s));
        vec2 hp;
        if (project(hit, hp) && abs(floor(hp.x) - float(ix)) <= 1.0 && abs(floor(hp.y) - float(iy)) <= 1.0)
          return true;
      }
    }
    q_prev = q;
  }
  return false;
}

// ambient_occlusion_at on the CPU: fraction of cosine-weighted rays over the hemisphere
// that travel max(1, d / 4) metres without meeting the scene.
float ambient_occlusion_at(int x, int y) {
  const int ray_count = P.plan.w;
  if (!has_flag(kFlagNeedsAo) || ray_count <= 0 || !has_flag(kFlagNormals)) return 1.0;
  const float distance = depth_at(x, y);
  if (is_sky(distance)) return 1.0;
  vec3 n = normal_at(x, y);
  if (dot(n, n) < 0.5) return 1.0;
  const vec3 x0 = P.origin.xyz + ray_dir(x, y) * distance + n * (1e-3 + 1e-3 * distance);
  const float t_far = max(1.0, 0.25 * distance);
  const uint seed = P.flags.y ^ uint(x * 7919 + y * 104729);
  n = normalize(n);
  const float sign_ = n.z >= 0.0 ? 1.0 : -1.0;
  const float a = -1.0 / (sign_ + n.z), b = n.x * n.y * a;
  const vec3 t1 = vec3(1.0 + sign_ * n.x * n.x * a, sign_ * b, -sign_ * n.x);
  const vec3 t2 = vec3(b, sign_ + n.y * n.y * a, -n.y);
  const vec3 origin = x0 + n * max(1e-4, 1e-4 * length(x0));
  const uint stream = hash32(seed ^ 0x5bd1e995u);
  int open = 0;
  for (int index = 0; index < ray_count; ++index) {
    const uint h1 = hash32(stream + 2u * uint(index));
    const uint h2 = hash32(h1 ^ 0x68e31da4u);
    const float u1 = (float(index) + unit_float(h1)) / float(ray_count);
    const float phi = 2.0 * kPi * unit_float(h2);
    const float r = sqrt(u1), cos_theta = sqrt(max(0.0, 1.0 - u1));
    const vec3 dir = r * cos(phi) * t1 + r * sin(phi) * t2 + cos_theta * n;
    if (!screen_space_occluded(origin, dir, t_far)) ++open;
  }
  return float(open) / float(ray_count);
}
