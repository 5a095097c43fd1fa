// Private to libmr: inverse rendering of one segment's BRDF (mr::Material) from the radiance a
// photo shows, with the geometry and lighting of render/surface_shading.h, by Ceres.
#pragma once
#include <cstdint>
#include <span>
#include "mr/image.h"
#include "mr/material_model.h"
#include "render/surface_shading.h"

namespace mr::photo {

struct BrdfFitOptions {
  int max_pixels = 4000;  ///< pixels sampled from the segment (deterministic stride)
  /// Cauchy loss (scale 0.1 of the mean radiance) against texture and outliers.
  bool robust = true;
  /// Weight of a prior pulling F0 toward 0.04 (dielectrics: most real surfaces). Under soft or
  /// guessed light a bright, rough specular lobe and a brighter diffuse albedo explain a real
  /// photo about equally well, and the unregularised fit drifts to F0 = 1 (seen on
  /// sample_photos/building.jpg: a "rough mirror" facade). With weight w the prior costs
  /// w * n * (F0 - 0.04)^2 next to the n pixels' squared relative residuals, so a highlight the
  /// data shows still wins (F0 0.85 recovered within 0.05 in the tests). 0 disables it.
  double dielectric_prior_weight = 1e-3;
};

struct BrdfFit {
  Material material;
  /// sqrt(mean over the used pixels and R, G, B of (model - radiance)^2) / the mean of the
  /// used pixels' radiance over R, G, B (unweighted, whatever the robust loss).
  double relative_rms = 0;
  int pixels_used = 0;
  bool converged = false;  ///< Ceres reported convergence for the kept start
  int iterations = 0;      ///< Ceres iterations over all starts and stages
};

/// Fits diffuse albedo (RGB), specular albedo and roughness so that shade_pixel(material, ...)
/// matches `radiance` (scene-linear RGB, the geometry's size) over `pixels` (indices y * width +
/// x; sky pixels are skipped). Starts from several roughness values and keeps the best.
/// Parameters are bounded to the ranges of mr::Material. Throws mr::Error(invalid_argument) when
/// fewer than 16 usable pixels remain.
BrdfFit fit_brdf(const Image& radiance, const render::SurfaceGeometry& geometry,
                 const Lighting& lighting, std::span<const std::int32_t> pixels,
                 const BrdfFitOptions& options = {});

}  // namespace mr::photo
