// An independent, brute-force Monte Carlo reference for the single-scattering core
// (DESIGN.md sections 3 and 7). It shares nothing with render/ beyond the public scene structs
// (mr::FogScene, mr::Camera, mr::CameraPose::ray_direction, mr::Image): its own analytic scene
// geometry and ray intersection, its own optical depths by numerical quadrature (never the
// closed forms), its own light sampling.
//
// What it computes, per pixel (the pixel-centre ray only, as the core does): with o the camera
// position, w = pose.ray_direction(camera, x, y), D the distance to the surface (the distance map)
// or, for sky (+inf), the distance where the ray leaves the medium or its transmittance (in the
// least attenuated channel) drops below Settings::sky_cutoff_transmittance,
//
//   R = integral_0^D tau(o, x_t) sigma_s(x_t) [ sum_k p(w . l_k) E_k(x_t) V_k(x_t) + L_sky ] dt
//
//   sigma_t(x) = medium.sigma_t_per_m * rho(x),  rho = 1 or exp(-(y - base) / scale),
//                rho = 0 outside [layer_bottom_m, layer_top_m];  sigma_s = albedo * sigma_t;
//   tau(a, b)  = exp(-sigma_t_per_m * integral of rho along a -> b)   (Gauss-Legendre quadrature);
//   p          = Henyey-Greenstein, cosine between w and the direction from x toward the light;
//   sun:  E = irradiance * tau(x -> out of the medium toward the sun), V = fraction of the
//         sun's disk (angular_radius_deg) not blocked by the geometry (one uniformly sampled
//         direction in the disk's cone per sample);
//   lamp: E = intensity * spot(x) * tau(x, p) / |p - x|^2, V = segment x -> p unblocked;
//         spot = smoothstep in cos(alpha) between outer and inner angle, 1 for outer >= 180;
//   the light paths' tau is 1 when render.light_path_attenuation is false, V is 1 when
//   render.volumetric_shadows is false; the sky term is never attenuated or blocked.
// Noise (medium.noise.amplitude > 0) is not supported (std::invalid_argument).
//
// Sampling scheme (unbiased), per pixel and per batch:
//  * the sun and sky terms: transmittance sampling of the view ray. Its density integral Rho(t)
//    is tabulated exactly (quadrature) at the edges of `pdf_bins` equal bins of [0, D'] (D' =
//    where the least attenuated channel's optical depth reaches 16; one more bin covers
//    [D', D]); with Rho~ its linear interpolation, one technique per distinct channel
//    extinction sigma samples t with the pdf sigma Rho~'(t) exp(-sigma Rho~(t)) / (1 - e^{-sigma
//    Rho(D)}) (exact transmittance sampling for homogeneous fog), and the techniques are combined
//    with the balance heuristic (multi-sample MIS, Veach 1997) when the channels differ;
//  * each lamp's term: equiangular sampling toward that lamp (Kulla and Fajardo 2012), which
//    cancels its 1 / r^2 peak; a lamp's term is estimated by its own technique alone (combining
//    it with the others through MIS only added the noise of their samples near its peak);
//  * every technique draws stratified samples (one jittered sample per stratum of [0, 1));
//    every sample costs one sun-disk direction or one lamp segment, traced exactly, and
//    quadrature optical depths for the view ray (from the nearest tabulated edge), the sun's
//    path out of the medium and the lamp segment.
// The pixel's estimate is the mean of `batches` independent such estimates (independent jitter
// and sun-disk samples); its standard error is the standard deviation of the batch estimates
// over sqrt(batches) (batch means: honest also for stratified samples, whose per-sample variance
// would overstate the error). Deterministic for Settings::seed and the pixel, whatever the
// thread count.
//
// Its own error: no bias beyond the sky cut-off (R beyond it is < 1e-6 of the sky term) and the
// quadrature (< 1e-12); the noise is reported per pixel. In the comparison scene of
// mc_reference_test.cpp (ground, two boxes, low sun with shafts, a lamp, sky; 96 x 64 pixels) the
// defaults (16 batches of 256 medium and 128 lamp samples) give a relative standard error of
// 2e-4 per pixel (median; 7e-4 at worst, 1e-5 on sky-lit-only rays) in 4 s on 2 cores.
//
// Optical depths: the density is integrated with 8-point Gauss-Legendre on panels in which the
// height changes by at most scale_height / 4 (one panel for a homogeneous medium), only over
// the part of a path inside the layer (so the layer's jumps never fall inside a panel); a path
// that never leaves a medium whose density does not vanish has infinite optical depth
// (transmittance 0), one going up through height fog is cut where the density has fallen by
// e^-45. Relative error < 1e-12 in double precision.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include "mr/camera.h"
#include "mr/image.h"
#include "mr/scene.h"

namespace mr::mcref {

inline constexpr double kInfinity = std::numeric_limits<double>::infinity();

/// Axis-aligned box [min, max] (a solid: rays are blocked by any of its faces).
struct Box {
  Vec3 min, max;
};

/// A parallelogram: corner + s * edge_u + t * edge_v for s, t in [0, 1] (two-sided).
/// A half-plane is a very large one.
struct Quad {
  Vec3 corner, edge_u, edge_v;
};

/// A solid sphere (issue 16: an inserted object).
struct Sphere {
  Vec3 centre;
  double radius = 1;
};

/// The estimator's own analytic scene: an optional ground plane y = 0, boxes, quads, spheres.
struct Geometry {
  bool ground = false;
  std::vector<Box> boxes;
  std::vector<Quad> quads;
  std::vector<Sphere> spheres;

  /// What the unit ray o + t d first meets (t > 0): distance, unit normal facing the ray's
  /// origin, and which primitive (kind and index into its list).
  struct Hit {
    enum class Kind { none, ground, box, quad, sphere } kind = Kind::none;
    std::size_t index = 0;
    double t = kInfinity;
    Vec3 normal{0, 0, 0};
  };
  Hit first_hit_info(const Vec3& o, const Vec3& d) const;

  /// Distance to the nearest surface along the unit ray o + t d, t in (0, t_max); +inf if none.
  double first_hit(const Vec3& o, const Vec3& d, double t_max = kInfinity) const;
  /// Whether anything lies on the unit ray o + t d for t in (0, t_max).
  bool occluded(const Vec3& o, const Vec3& d, double t_max = kInfinity) const;
  /// The unit normal of the surface the unit ray o + t d first meets (facing the ray's origin),
  /// or (0, 0, 0) if it meets none.
  Vec3 first_hit_normal(const Vec3& o, const Vec3& d) const;
};

/// The distance map the core gets: each pixel-centre ray cast against `geometry`; sky = +inf.
/// 1 channel ("Z"), metres along the ray.
Image distance_map(const Camera& camera, const CameraPose& pose, const Geometry& geometry);

/// Density rho(x) (dimensionless, multiplies sigma_t_per_m), layer limits included.
double density(const Medium& medium, const Vec3& x);

/// integral_t0^t1 rho(o + t d) dt by Gauss-Legendre quadrature (d unit; t1 may be +inf).
/// `panel_scale` multiplies the number of panels (for convergence checks). May return +inf.
double density_integral(const Medium& medium, const Vec3& o, const Vec3& d, double t0, double t1,
                        int panel_scale = 1);

/// The first t >= 0 where integral_0^t rho = `target` along o + t d, or, if the ray leaves the
/// medium (or its density vanishes) before, that exit distance (capped at 1e7 m).
double distance_to_density_integral(const Medium& medium, const Vec3& o, const Vec3& d,
                                    double target);

/// Henyey-Greenstein phase function.
double henyey_greenstein(double g, double cos_theta);

struct Settings {
  int batches = 16;          ///< independent estimates per pixel (>= 2, for the error)
  int medium_samples = 256;  ///< stratified samples per batch for the sun and sky terms (split
                             ///< evenly between the channels' techniques when they differ)
  int lamp_samples = 128;    ///< stratified equiangular samples per batch, per lamp
  int pdf_bins = 128;        ///< bins of the view ray's density table
  double sky_cutoff_transmittance = 1e-6;
  std::uint32_t seed = 1;
};

struct RayEstimate {
  std::array<double, 3> inscatter{};       ///< R per channel
  std::array<double, 3> standard_error{};  ///< of R, per channel
  std::array<double, 3> transmittance{};   ///< tau(o, surface); for sky tau(o, out of medium)
  double distance = 0;                     ///< D integrated to
};

/// R along one ray (unit w) from scene.pose.position_m to `distance` (+inf = sky).
/// `stream` picks the ray's random numbers (e.g. the pixel index).
RayEstimate estimate_ray(const Vec3& w, double distance, const FogScene& scene,
                         const Geometry& geometry, const Settings& settings,
                         std::uint64_t stream = 0);

struct Result {
  Image inscatter;       ///< R (R,G,B)
  Image standard_error;  ///< its standard error (R,G,B)
  Image transmittance;   ///< tau(camera, surface) (R,G,B); 0 for sky in unbounded fog
  /// Mean over pixels and channels of standard_error / inscatter, where inscatter > 1e-4.
  double mean_relative_standard_error = 0;
  double max_relative_standard_error = 0;
};

/// The whole image (pixel-centre rays, in parallel over rows with TBB).
/// `distance_m`: 1 channel, +inf = sky (e.g. from distance_map). The sky radiance must be given
/// (scene.lighting.sky_radiance), else std::invalid_argument.
Result render(const Image& distance_m, const Camera& camera, const FogScene& scene,
              const Geometry& geometry, const Settings& settings = {});

/// The surface term of the transmittance map (DESIGN.md section 3, T = tau(o, x0) S) from the
/// exact geometry, per surface pixel (pixel-centre ray, surface point x0 at the map's distance,
/// normal n from the geometry):
///   direct  = E_sun (n . l)+ V tau_sun-free,  V = fraction of `rays` directions uniform in the sun's
///             disk (angular_radius_deg) not blocked;
///   ambient = pi L_sky A,  A = fraction of `rays` cosine-weighted directions about n that travel
///             max(1, d / 4) metres without meeting the geometry (the core's ambient occlusion);
///   S       = (direct tau_sun(x0) + ambient) / (direct + ambient), tau_sun by quadrature (1 with
///             no light-path attenuation); 1 where direct + ambient is 0;
///   T       = tau(o, x0) S.
/// Lamps are not supported (std::invalid_argument). Sky pixels: T = tau to the end of the
/// march (as render()), direct = ambient = 0. Stratified (jittered) directions, deterministic.
struct SurfaceResult {
  Image transmittance;   ///< T (R,G,B)
  Image direct;          ///< E_sun (n . l)+ V (R,G,B): the sun's share of the surface's light
  Image ambient;         ///< pi L_sky A (R,G,B)
  Image sun_visibility;  ///< V (1 channel; 0 facing away from the sun)
};
SurfaceResult surface_reference(const Image& distance_m, const Camera& camera,
                                const FogScene& scene, const Geometry& geometry, int rays = 256);

}  // namespace mr::mcref
