// The brute-force Monte Carlo reference for inserted objects (issue 16): the radiance the
// camera sees of an analytic scene (tests/mc_reference.h's Geometry: ground, boxes, quads,
// spheres) under a sun with its disk and a uniform sky, with NO fog. Like mc_reference.* it
// shares nothing with render/ (its own ray casting, its own GGX, its own sampling).
//
// Per pixel: the mean over N x N stratified, jittered sub-pixel camera rays of
//   sky (no hit):   L_sky
//   a surface x:    L(x, v) = E_sun / Omega_sun * integral over the sun's cone of f_r (n.l)+ V dl
//                           + L_sky * integral over {n.l > 0, l.y > 0} of f_r (n.l)+ V dl
// with f_r = albedo / pi (+ GGX specular: D with alpha = roughness^2, Smith height-correlated
// G2, Schlick F with F0 per channel, for materials that have one), V = 1 where the ray to the
// light leaves the scene. The sun term samples the cone uniformly in solid angle (stratified),
// the sky term cosine-weighted directions about n (stratified), so the sky estimate is
// pi L_sky mean(f_r V [l.y > 0]). Only direct light: the scene's surfaces reflect nothing onto
// each other (the product's differential renderer models the same light).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "mc_reference.h"
#include "mr/camera.h"
#include "mr/image.h"
#include "mr/scene.h"

namespace mr::mcref {

struct SurfaceMaterial {
  std::array<double, 3> diffuse_albedo{0.5, 0.5, 0.5};
  bool specular = false;  ///< false: Lambertian only
  std::array<double, 3> f0{0.04, 0.04, 0.04};
  double roughness = 0.5;  ///< perceptual; alpha = roughness^2
};

/// One material per primitive of a Geometry (lists parallel to its boxes, quads, spheres).
struct MaterialTable {
  SurfaceMaterial ground;
  std::vector<SurfaceMaterial> boxes, quads, spheres;
};

struct RadianceSettings {
  int pixel_samples_per_axis = 4;
  int sun_samples = 16;   ///< per camera ray
  int sky_samples = 256;  ///< per camera ray
  std::uint64_t seed = 1;
};

/// Lighting: the sun (direction, irradiance, angular radius) and sky_radiance (required);
/// lamps are not supported (std::invalid_argument). 3 channels, deterministic.
Image surface_radiance(const Camera& camera, const CameraPose& pose, const Lighting& lighting,
                       const Geometry& geometry, const MaterialTable& materials,
                       const RadianceSettings& settings = {});

/// The reference's own f_r(l, v) (n.l)+ per channel (exposed for its closed-form test).
std::array<double, 3> brdf_cosine(const SurfaceMaterial& m, const Vec3& n, const Vec3& l, const Vec3& v);

}  // namespace mr::mcref
