// Private to libmr: transmittance and in-scatter of a homogeneous medium lit only by an
// isotropic sky (the Koschmieder model). The scattering core with sun, lamps and height fog
// (issue 3) generalises this; this closed form is its ambient-only, homogeneous special case.
#pragma once

#include <array>

#include "mr/image.h"

namespace mr::render {

struct HomogeneousSkyMedium {
  std::array<float, 3> sigma_t_per_m;  ///< extinction, 1/m
  std::array<float, 3> albedo;         ///< sigma_s / sigma_t
  std::array<float, 3> sky_radiance;   ///< isotropic L_sky lighting the medium
};

/// For each pixel with distance d (metres; +inf = no surface):
///   T = exp(-sigma_t d)
///   R = integral_0^d T(t) sigma_s L_sky dt = albedo L_sky (1 - T)
/// `transmittance` and `inscatter` must be 3-channel images of the distance map's size.
void render_homogeneous_sky(ConstImageView distance_m, const HomogeneousSkyMedium& medium,
                            ImageView transmittance, ImageView inscatter);

}  // namespace mr::render
