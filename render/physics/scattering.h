// Single scattering of sun, sky and lamps along a view ray, and the surface term, shared by the
// CPU core (render/scattering_cpu.cpp) and the Vulkan shaders (shaders/scattering_common.glsl)
// in the common subset of C++ and GLSL (render/physics/types.h). What is here is every formula
// both backends evaluate; what they keep is how they find visibility (Embree rays vs shadow
// maps) and how they schedule the work (the CPU takes a ray's sun samples first, in 8-wide
// packets; the GPU marches one segment ahead).
//
// The view ray is cut into segments (uniform in transmittance, plus equiangular ones around each
// lamp's closest approach); within a segment the transmittance-weighted scattering is integrated
// exactly, lamps' 1/r^2 exactly, the sun's visibility is sampled at a stratified jittered point
// and its crossings bisected, the sun's light-path transmittance averaged over the segment where
// it changes (DESIGN.md section 3, README "Integration").
#ifndef MR_RENDER_PHYSICS_SCATTERING_H
#define MR_RENDER_PHYSICS_SCATTERING_H

#include "render/physics/medium.h"

MR_PHYSICS_BEGIN

// ---- per-channel exponentials -----------------------------------------------------------------
// Grey fog (equal channels, the usual case) needs one exp: a channel equal to the one before
// reuses its value, which is bit for bit what it would compute.

MR_FN Float3 exp3(Float3 v) {
  const Float x = exp(v.x);
  const Float y = v.y == v.x ? x : exp(v.y);
  return Float3(x, y, v.z == v.y ? y : exp(v.z));
}
MR_FN Float3 expm1_3(Float3 v) {
  const Float x = expm1_(v.x);
  const Float y = v.y == v.x ? x : expm1_(v.y);
  return Float3(x, y, v.z == v.y ? y : expm1_(v.z));
}

/// exp(-sigma od) per channel, 1 in a channel without extinction even where od = inf (the sun's
/// path through an unbounded medium; 0 inf would be NaN: clear air transmits everything).
MR_FN Float3 transmittance(Float3 sigma_t_per_m, Float unit_optical_depth_m) {
  return exp3(-scaled_optical_depth(sigma_t_per_m, unit_optical_depth_m));
}

// ---- phase function, lamps, camera, jitter ----------------------------------------------------

/// Henyey-Greenstein phase function; cos_theta = dot(view direction, direction to the light).
MR_FN Float henyey_greenstein(Float g, Float cos_theta) {
  const Float denom = 1.0 + g * g - 2.0 * g * cos_theta;
  return (1.0 - g * g) / (4.0 * kPi * denom * sqrt(denom));
}

/// A spot lamp's smooth cone falloff at cos_a = dot(axis, direction from the lamp): 1 inside the
/// inner cone, 0 outside the outer, smoothstep between.
MR_FN Float spot_cone(Float cos_a, Float cos_inner, Float cos_outer) {
  if (cos_a >= cos_inner) return 1.0;
  if (cos_a <= cos_outer) return 0.0;
  const Float t = (cos_a - cos_outer) / (cos_inner - cos_outer);
  return t * t * (3.0 - 2.0 * t);
}

/// The unit view ray through pixel (x, y)'s centre (camera axes in the world, focal length and
/// principal point in pixels).
MR_FN Float3 camera_ray(Float3 forward, Float3 right, Float3 up, Float focal_px, Float cx, Float cy,
                        int x, int y) {
  const Float a = (Float(x) + 0.5 - cx) / focal_px;
  const Float b = (Float(y) + 0.5 - cy) / focal_px;
  return normalize(forward + a * right + (-b) * up);
}

/// Interleaved gradient noise (Jimenez 2014), rotated by the render seed: a per-pixel offset in
/// [0, 1) whose neighbours differ, so stratified jitter turns into fine noise that the
/// interpolation and the eye average out. fract(a x + b y) is formed in 32-bit fixed point
/// (exact for integer pixels), so float keeps what double would.
MR_FN Float pixel_jitter(int x, int y, uint seed) {
  const uint a = 288240406u;  // round(0.06711056 * 2^32)
  const uint b = 25070697u;   // round(0.00583715 * 2^32)
  const uint frac32 = a * uint(x) + b * uint(y);
  const Float f = Float(frac32 >> 8) * (1.0 / 16777216.0);
  const Float ign = fract(52.9829189 * f);
  const Float rot = Float((seed * 2654435761u) >> 8) * (1.0 / 16777216.0);
  return fract(ign + rot);
}

// ---- segment boundaries ------------------------------------------------------------------------

/// Boundary i of `steps` segments uniform in transmittance at the mean extinction sigma_mean
/// (od_mean_total = sigma_mean times the march's unit optical depth, one_minus_tau_end =
/// -expm1(-od_mean_total)); uniform in distance over len in (almost) clear air.
MR_FN Float uniform_boundary(RayDensity rd, int i, int steps, Float sigma_mean, Float od_mean_total,
                             Float one_minus_tau_end, Float len) {
  if (od_mean_total > 1e-6) {
    const Float frac = Float(i) / Float(steps);
    return distance_at_optical_depth(rd, -log1p_(-one_minus_tau_end * frac) / sigma_mean);
  }
  return len * Float(i) / Float(steps);
}

/// A lamp's closest approach to the view ray o + t w: at distance tc along it, h away from it;
/// th_a, th_b the angles (seen from the lamp) of the march's ends 0 and len.
struct LampOnRay {
  Float tc;
  Float h;
  Float th_a;
  Float th_b;
};

MR_FN LampOnRay lamp_on_ray(Float3 lamp_position, Float3 o, Float3 w, Float len) {
  LampOnRay l;
  const Float3 rel = lamp_position - o;
  l.tc = dot(rel, w);
  l.h = max(1e-6, length(rel - l.tc * w));  // = sqrt(|rel|^2 - tc^2), without cancellation
  l.th_a = atan(-l.tc, l.h);
  l.th_b = atan(len - l.tc, l.h);
  return l;
}

/// Boundary i of the lamp's `lamp_steps` equiangular segments (denser where 1/r^2 peaks).
MR_FN Float lamp_boundary(LampOnRay l, int i, int lamp_steps) {
  return l.tc + l.h * tan(l.th_a + (l.th_b - l.th_a) * Float(i) / Float(lamp_steps));
}

/// Segment i = [ta, tb]'s sample point: stratified jitter, each segment's own offset (a
/// golden-ratio sequence from the pixel's), so the offsets' biases cancel along the ray.
MR_FN Float segment_sample_t(Float ta, Float tb, Float jitter, int i) {
  return ta + (tb - ta) * fract(jitter + 0.6180339887498949 * Float(i));
}

// ---- one segment's integral ---------------------------------------------------------------------

/// Advances the camera's optical depth `od` and transmittance `tau` over a segment of unit optical
/// depth seg_od_unit (noise included) and returns its scattering weight, the exact integral of
/// tau sigma_s over it: albedo tau_before (1 - exp(-sigma od_segment)). One expm1 per channel
/// gives both (thin segments keep their precision; grey fog needs one): tau is carried as the
/// product of the segments' transmittances, within a few ulps of exp(-od) per segment.
MR_FN Float3 advance_segment(MR_INOUT(Float3) od, MR_INOUT(Float3) tau, Float3 sigma, Float3 albedo,
                             Float seg_od_unit) {
  const Float3 od_segment = sigma * seg_od_unit;
  const Float3 e = expm1_3(-od_segment);  // exp(-od_segment) - 1
  const Float3 weight = albedo * tau * -e;
  od += od_segment;
  tau = tau + tau * e;
  return weight;
}

/// Whether a segment contributes nothing: no weight and no light left in front of it.
MR_FN bool segment_dark(Float3 weight, Float3 tau_before) {
  return weight.x + weight.y + weight.z <= 0.0 && tau_before.x + tau_before.y + tau_before.z <= 0.0;
}

/// The sun-lit part of segment [ta, tb]'s weight. Its visibility is that of the previous sample
/// on [ta, tl], of its own on [tl, tr], of the next on [tr, tb] (tl, tr: the bisected crossings
/// that fall inside it; ta, tb where there are none). `modulation`: the segment's noise factor.
MR_FN Float3 sun_lit_weight(RayDensity rd, Float ta, Float tb, Float tl, Float tr, bool vis_prev,
                            bool vis, bool vis_next, Float modulation, Float3 weight, Float3 albedo,
                            Float3 tau_before, Float3 sigma) {
  Float3 lit = Float3(0.0, 0.0, 0.0);
  if (tl == ta && tr == tb) return vis ? weight : lit;
  for (int k = 0; k < 3; ++k) {
    const Float p = k == 0 ? ta : (k == 1 ? tl : tr);
    const Float q = k == 0 ? tl : (k == 1 ? tr : tb);
    const bool lit_k = k == 0 ? vis_prev : (k == 1 ? vis : vis_next);
    if (!lit_k || !(q > p)) continue;
    // exp(-sigma od(ta, p)) - exp(-sigma od(ta, q)), without the cancellation.
    const Float od_p = optical_depth(rd, ta, p) * modulation;
    const Float od_pq = optical_depth(rd, p, q) * modulation;
    lit += albedo * tau_before * exp3(-sigma * od_p) * -expm1_3(-sigma * od_pq);
  }
  return lit;
}

/// The sun-lit fraction of segment [ta, tb]'s length (pieces as sun_lit_weight).
MR_FN Float sun_seen_fraction(Float ta, Float tb, Float tl, Float tr, bool vis_prev, bool vis,
                              bool vis_next) {
  const Float length_ab = tb - ta;
  if (!(length_ab > 0.0)) return vis ? 1.0 : 0.0;
  return ((vis_prev ? tl - ta : 0.0) + (vis ? tr - tl : 0.0) + (vis_next ? tb - tr : 0.0)) /
         length_ab;
}

/// The sun's in-scatter of a segment: its lit weight times the phase function, the irradiance
/// above the fog and the transmittance of the sun's path to the sample point.
/// Here with the phase function henyey_greenstein(g, dot(w, sun_dir)) given (the same for every
/// segment of a view ray).
MR_FN Float3 sun_inscatter_phase(Float3 lit_weight, Float phase, Float3 irradiance,
                                 Float3 tau_sun) {
  return lit_weight * phase * irradiance * tau_sun;
}
MR_FN Float3 sun_inscatter(Float3 lit_weight, Float g, Float3 w, Float3 sun_dir, Float3 irradiance,
                           Float3 tau_sun) {
  return sun_inscatter_phase(lit_weight, henyey_greenstein(g, dot(w, sun_dir)), irradiance,
                             tau_sun);
}

/// Unit optical depth from x up the sun's path out of the medium (closed form; inf where it never
/// leaves a medium that does not thin out).
MR_HOT_FN Float sun_path_optical_depth(MediumShape shape, Float3 x, Float3 sun_dir) {
  return optical_depth(ray_density(shape, x, sun_dir), 0.0, MR_INF);
}

/// The transmittance of the sun's path to segment [ta, tb] of the view ray o + t w (rd), as the
/// segment's in-scatter sees it: averaged with its weight rho(t) tau_camera(t) by 4-point
/// Gauss-Legendre quadrature (closed-form optical depths, no rays). One value at the jittered
/// sample xs is exact in expectation but, in height fog under a low sun, varies by orders of
/// magnitude across a long sky segment (od_sun = sigma H e^(-y/H) / sin(elevation)), which the
/// per-pixel jitter turned into a grainy sky (issue 11, sun bank). Where the sun's optical depth
/// changes by at most 0.01 (times the largest sigma_t) over the segment, its transmittance varies
/// by under 1 % there: the value at xs is as good and four times cheaper (homogeneous fog under a
/// layer top, short segments). `modulation`: the segment's noise factor (scales the camera's
/// optical depth within it, as in advance_segment).
/// Here with the sun's optical depths at the segment's ends given (sun_path_optical_depth at
/// o + w ta and o + w tb: a march shares each boundary's between the two segments that meet
/// there); the one at xs is computed only where it is used. sun_path_transmittance below
/// computes the ends itself.
MR_FN Float3 sun_path_transmittance_ends(MediumShape shape, RayDensity rd, Float3 o, Float3 w,
                                         Float3 sun_dir, Float ta, Float tb, Float3 xs,
                                         Float modulation, Float3 sigma, Float od_a, Float od_b) {
  const Float sigma_max = max(max(sigma.x, sigma.y), sigma.z);
  if (!(sigma_max * abs(od_a - od_b) > 0.01))
    return transmittance(sigma, sun_path_optical_depth(shape, xs, sun_dir));
  const Float mid = 0.5 * (ta + tb);
  const Float half_length = 0.5 * (tb - ta);
  Float3 num = Float3(0.0, 0.0, 0.0);
  Float3 den = Float3(0.0, 0.0, 0.0);
  for (int k = 0; k < 4; ++k) {
    // Nodes -n1 -n0 n0 n1 and their weights.
    const bool outer = k == 0 || k == 3;
    const Float node = outer ? 0.8611363115940526 : 0.3399810435848563;
    const Float node_weight = outer ? 0.3478548451374538 : 0.6521451548625461;
    const Float t = mid + half_length * (k < 2 ? -node : node);
    const Float rho = density(rd, t);
    if (!(rho > 0.0)) continue;
    const Float3 camera_tau = transmittance(sigma, optical_depth(rd, ta, t) * modulation);
    const Float3 sun_tau = transmittance(sigma, sun_path_optical_depth(shape, o + w * t, sun_dir));
    const Float3 weight = camera_tau * (node_weight * rho);
    num += weight * sun_tau;
    den += weight;
  }
  if (!(den.x > 0.0 && den.y > 0.0 && den.z > 0.0))
    return transmittance(sigma, sun_path_optical_depth(shape, xs, sun_dir));
  return num / den;
}

MR_FN Float3 sun_path_transmittance(MediumShape shape, RayDensity rd, Float3 o, Float3 w,
                                    Float3 sun_dir, Float ta, Float tb, Float3 xs, Float modulation,
                                    Float3 sigma) {
  return sun_path_transmittance_ends(shape, rd, o, w, sun_dir, ta, tb, xs, modulation, sigma,
                                     sun_path_optical_depth(shape, o + w * ta, sun_dir),
                                     sun_path_optical_depth(shape, o + w * tb, sun_dir));
}

/// From a point toward a lamp: the unit direction l, the distance r and its square r2 (l is
/// not finite where r = 0: callers skip r below their threshold first).
struct TowardLamp {
  Float3 l;
  Float r;
  Float r2;
};
MR_FN TowardLamp toward_lamp(Float3 point, Float3 lamp_position) {
  TowardLamp t;
  const Float3 d = lamp_position - point;
  t.r2 = dot(d, d);
  t.r = sqrt(t.r2);
  t.l = d / t.r;
  return t;
}

/// atan(b) - atan(a), accurate also when the two are close.
MR_FN Float atan_diff(Float a, Float b) {
  const Float den = 1.0 + a * b;
  if (den > 0.5) return atan((b - a) / den);
  return atan(b) - atan(a);
}

/// Where a lamp's light is taken within segment [ta, tb]: the midpoint in angle seen from the
/// lamp (no jitter: lamps light the fog smoothly, and jitter would only add noise).
MR_FN Float lamp_segment_t(LampOnRay l, Float ta, Float tb) {
  const Float th_a = atan((ta - l.tc) / l.h);
  const Float th_b = atan((tb - l.tc) / l.h);
  return clamp(l.tc + l.h * tan(0.5 * (th_a + th_b)), ta, tb);
}

/// A lamp's in-scatter over segment [ta, tb]: 1/r^2 integrated exactly (t = tc + h tan(th):
/// dt / r^2 = d(th) / h), the rest of the integrand at tm = lamp_segment_t. `modulation`: the
/// noise at tm; phase, spot at tm; od_lamp: unit optical depth from tm to the lamp.
MR_FN Float3 lamp_inscatter(LampOnRay l, RayDensity rd, Float ta, Float tb, Float tm,
                            Float modulation, Float phase, Float spot, Float od_lamp, Float3 albedo,
                            Float3 sigma, Float3 tau_before, Float3 intensity) {
  const Float rho = density(rd, tm) * modulation;
  const Float od_to_m = optical_depth(rd, ta, tm) * modulation;
  const Float angle = atan_diff((ta - l.tc) / l.h, (tb - l.tc) / l.h);
  const Float common_ = angle / l.h * phase * spot * rho;
  return albedo * sigma * tau_before * exp3(-sigma * (od_to_m + od_lamp)) * common_ * intensity;
}

// ---- the surface term S of T (DESIGN.md section 3) -------------------------------------------

/// Light arriving at a surface: `e` (its irradiance without fog) adds to `direct`, e times its
/// path's transmittance to `direct_fogged`.
MR_FN void add_surface_light(MR_INOUT(Float3) direct, MR_INOUT(Float3) direct_fogged, Float3 e,
                             Float3 tau_path) {
  direct += e;
  direct_fogged += e * tau_path;
}

/// S per channel: (fogged direct light + ambient) / (direct light + ambient), the ambient
/// pi L_sky AO not attenuated (it stands in for multiple scattering); 1 without any light.
MR_FN Float3 surface_factor(Float3 direct, Float3 direct_fogged, Float3 sky_radiance, Float ao) {
  const Float3 ambient = kPi * sky_radiance * ao;
  Float3 s = Float3(1.0, 1.0, 1.0);
  for (int c = 0; c < 3; ++c) {
    const Float total = direct[c] + ambient[c];
    s[c] = total > 0.0 ? (direct_fogged[c] + ambient[c]) / total : 1.0;
  }
  return s;
}

MR_PHYSICS_END

#endif  // MR_RENDER_PHYSICS_SCATTERING_H
