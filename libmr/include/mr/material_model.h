// mr::Material: the reflectance model of a surface, a core type shared by material style transfer
// (mr/material.h, photo/material/) and the renderer's surface shading (render/surface_shading.h).
#pragma once

#include <string>

#include "mr/export.h"
#include "mr/vec3.h"

namespace mr {

/// A surface's reflectance: Lambert diffuse plus a GGX microfacet specular lobe with Smith
/// (height-correlated) masking-shadowing and Schlick's Fresnel,
///   f_r(l, v) = diffuse_albedo / pi + D(h) G2(l, v) F(v.h) / (4 |n.l| |n.v|),
///   F(u) = F0 + (1 - F0) (1 - u)^5, F0 = specular_albedo, GGX alpha = roughness^2.
struct MR_API Material {
  Rgb diffuse_albedo{0.5f, 0.5f, 0.5f};  ///< in [0, 1] per channel
  float specular_albedo = 0.04f;          ///< F0: reflectance at normal incidence, in [0, 1]
  float roughness = 0.5f;                 ///< perceptual roughness in [0.02, 1]
};

/// Throws mr::Error(invalid_argument) naming `what` and the field for values outside the ranges
/// above or not finite.
MR_API void validate_material(const Material& material, const std::string& what = "material");

}  // namespace mr
