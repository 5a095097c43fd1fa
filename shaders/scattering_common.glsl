// The Vulkan compute backend's side of the scattering core (render/vulkan/): its buffers, and
// the march, surface term and ambient occlusion put together from the shared physics
// (render/physics/*.h, the same source the CPU core compiles; kept in step by construction, the
// tests in tests/vulkan_scattering_test.cpp compare the two backends on the CPU core's scenes).
//
// What differs from the CPU reference, deliberately (measured in the tests / README):
// - float instead of double (render/physics/types.h evaluates expm1 / log1p in forms that keep
//   their relative precision);
// - shadows are looked up in shadow maps of the occluder mesh (sun: cascaded orthographic maps;
//   lamps: six cube faces) instead of traced with Embree; the sun is a point light for shadowing
//   (the CPU samples its 0.27 degree disk), so penumbrae are hard;
// - the march runs one segment ahead instead of taking a ray's sun samples first; ambient
//   occlusion rays are marched in screen space.
#extension GL_GOOGLE_include_directive : require

#include "scattering_params.h"
#include "render/physics/medium.h"
#include "render/physics/occlusion.h"
#include "render/physics/scattering.h"

#define INF MR_INF

layout(std430, set = 0, binding = 0) readonly buffer ParamsBuffer { ScatterParams P; };
layout(std430, set = 0, binding = 1) readonly buffer LampBuffer { GpuLamp lamps[]; };
layout(std430, set = 0, binding = 2) readonly buffer LayerBuffer { ShadowLayer layers[]; };
layout(std430, set = 0, binding = 3) readonly buffer DepthBuffer { float depth_m[]; };
layout(std430, set = 0, binding = 4) readonly buffer NormalBuffer { float normals[]; };
layout(std430, set = 0, binding = 5) buffer GridBuffer { vec4 grid_samples[]; };
layout(set = 0, binding = 11) uniform sampler2DArray shadow_atlas;

bool has_flag(int f) { return (P.flags.x & uint(f)) != 0u; }

MediumShape medium_shape() { return MediumShape(P.layer.x, P.layer.y, P.layer.z, P.layer.w); }
RayDensity ray_density(vec3 o, vec3 w) { return ray_density(medium_shape(), o, w); }

float noise_modulation(vec3 x) {
  return noise_modulation(x, P.noise.x, P.noise.y, int(P.flags.w), P.flags.z);
}

// ---- camera, lamps ----------------------------------------------------------------------------

vec3 ray_dir(int x, int y) {
  return camera_ray(P.forward.xyz, P.right.xyz, P.up.xyz, P.camera.x, P.camera.y, P.camera.z, x, y);
}

float spot_factor(GpuLamp lamp, vec3 from_lamp_unit) {
  if (lamp.spot.w == 0.0) return 1.0;
  return spot_cone(dot(lamp.spot.xyz, from_lamp_unit), lamp.cone.x, lamp.cone.y);
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
  return march_length(rd, distance, P.misc.x, P.sky.w);
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
  return uniform_boundary(m.rd, i, m.steps, P.sigma.w, m.od_mean_total, m.one_minus_tau_end, m.len);
}

// The segment boundaries in order: the sorted, de-duplicated union of the uniform sequence and
// every lamp's equiangular one (the CPU sorts them all; here they are merged as they go).
struct Boundaries {
  int n_lamps;
  LampOnRay l_ray[kMaxLamps];
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
      const float t = lamp_boundary(b.l_ray[l], b.l_next[l], P.plan.y);
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
    s.camera_od = scaled_optical_depth(sigma, optical_depth(m.rd, 0.0, distance));
    s.inscatter = sky_only_inscatter(s.camera_od, albedo * P.sky.xyz);
    return s;
  }

  m.od_mean_total = P.sigma.w * od_unit_total;
  m.one_minus_tau_end = -expm1_(-m.od_mean_total);
  Boundaries b;
  b.n_lamps = min(P.image.w, kMaxLamps);
  // Lamps' closest approach to the ray and their equiangular sequences.
  for (int l = 0; l < b.n_lamps; ++l) {
    b.l_ray[l] = lamp_on_ray(lamps[l].position.xyz, origin, w, m.len);
    b.l_next[l] = 0;
    b.l_val[l] = -INF;
  }
  b.u_next = 0;
  b.u_val = -INF;

  const float jitter = pixel_jitter(x, y, P.flags.y);
  vec3 od = vec3(0.0), tau = vec3(1.0);
  int sun_samples = 0;
  float sun_seen = 0.0;
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
  float ts = segment_sample_t(ta, tb, jitter, 0);
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
      ts_n = segment_sample_t(tb, tn, jitter, i + 1);
      vis_n = !sun_shadows || sun_lit_on_ray(origin, w, ts_n);
      if (vis_n != vis) {
        // Shaft edge: bisect between the two samples for the crossing (to 1/64 of the gap).
        float lo = ts, hi = ts_n;
        // Fewer in a refined march (a shaft-edge cell's pixel): its samples are closer.
        const int bisections = steps > P.plan.x ? kShaftRefinementBisections : kEdgeBisections;
        for (int k = 0; k < bisections; ++k) {
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
    const vec3 tau_before = tau;
    const vec3 weight = advance_segment(od, tau, sigma, albedo, seg_od_unit);
    if (!segment_dark(weight, tau_before)) {
      if (sun) {
        const float tl = vis_prev != vis ? max(ta, crossing_prev) : ta;
        const float tr = vis_n != vis ? min(tb, crossing) : tb;
        const vec3 lit_weight = sun_lit_weight(m.rd, ta, tb, tl, tr, vis_prev, vis, vis_n,
                                               modulation, weight, albedo, tau_before, sigma);
        sun_seen += sun_seen_fraction(ta, tb, tl, tr, vis_prev, vis, vis_n);
        ++sun_samples;
        if (lit_weight.x + lit_weight.y + lit_weight.z > 0.0) {
          const vec3 tau_sun = lpa ? sun_path_transmittance(medium_shape(), m.rd, origin, w,
                                                            P.sun_dir.xyz, ta, tb, xs, modulation,
                                                            sigma)
                                   : vec3(1.0);
          s.inscatter += sun_inscatter(lit_weight, g, w, P.sun_dir.xyz, P.sun_irradiance.xyz,
                                       tau_sun);
        }
      }
      for (int l = 0; l < n_lamps; ++l) {
        const GpuLamp lamp = lamps[l];
        const float tm = lamp_segment_t(b.l_ray[l], ta, tb);
        const vec3 xm = origin + w * tm;
        const TowardLamp to_lamp = toward_lamp(xm, lamp.position.xyz);
        const float r = to_lamp.r;
        if (r < 1e-9) continue;
        const vec3 lv = to_lamp.l;
        const float spot = spot_factor(lamp, -lv);
        if (spot <= 0.0) continue;
        if (shadows && !lamp_lit(lamp, xm, vec3(0.0), r, 0.0, 1e-3 + 1e-4 * tm)) continue;
        const float lamp_modulation = noise ? noise_modulation(xm) : 1.0;
        const float phase = henyey_greenstein(g, dot(w, lv));
        const float od_lamp = lpa ? optical_depth(ray_density(xm, lv), 0.0, r) : 0.0;
        s.inscatter += lamp_inscatter(b.l_ray[l], m.rd, ta, tb, tm, lamp_modulation, phase, spot,
                                      od_lamp, albedo, sigma, tau_before, lamp.intensity.xyz);
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
  s.shaft = sun_samples > 0 ? sun_seen / float(sun_samples) : 1.0;
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
  return scaled_optical_depth(P.sigma.xyz, optical_depth(rd, 0.0, is_sky(d) ? INF : len));
}

// ---- ambient occlusion ------------------------------------------------------------------------
// The CPU traces AO rays against the occluder mesh with Embree. The mesh is the depth map's
// surface: every pixel a planar patch through its 3D point with its normal. Without ray queries
// the GPU marches the same rays (same directions, same seed) in screen space against that
// per-pixel plane model: a ray is blocked where it crosses, from the front, the planar patch of
// the pixel it passes over; passing behind a silhouette is not a hit (the mesh breaks at depth
// discontinuities). Rays that leave the image or the
// uploaded region, or pass behind the camera, meet no geometry (the mesh lies inside the view).

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
  const uint seed = P.flags.y;  // one ray set for the render (render/physics/occlusion.h)
  n = normalize(n);
  vec3 t1, t2;
  ao_frame(n, -P.forward.xyz, t1, t2);
  const vec3 origin = x0 + n * max(1e-4, 1e-4 * length(x0));
  const uint stream = ao_stream(seed);
  // Every stride-th ray of a set of ao_partial_rays first; where they disagree, the rest (as
  // ambient_occlusion on the CPU).
  const int total = max(ray_count, int(P.misc.z));
  const int stride = total / ray_count;
  int open = 0;
  for (int k = 0; k < ray_count; ++k)
    if (!screen_space_occluded(origin, ao_direction(stream, k * stride, total, stride, n, t1, t2), t_far)) ++open;
  if (stride == 1 || open == 0 || open == ray_count) return float(open) / float(ray_count);
  for (int index = 0; index < total; ++index)
    if (index % stride != 0 &&
        !screen_space_occluded(origin, ao_direction(stream, index, total, stride, n, t1, t2), t_far))
      ++open;
  return float(open) / float(ray_count * stride);
}
