// mr::fog: put fog into a photo with its depth map.
#pragma once

#include <array>
#include <optional>

#include "mr/export.h"
#include "mr/image.h"

namespace mr {

using Rgb = std::array<float, 3>;

/// Koschmieder: extinction coefficient (1/m) for a meteorological visibility (m), the distance
/// at which a black object's contrast against the horizon sky falls to 2 %: 3.912 / V.
/// Throws mr::Error(invalid_argument) unless V is finite and > 0.
MR_API double extinction_from_visibility(double visibility_m);

/// The inverse: the meteorological visibility (m) of an extinction coefficient (1/m),
/// 3.912 / sigma_t. Throws mr::Error(invalid_argument) unless sigma_t is finite and > 0.
MR_API double visibility_from_extinction(double sigma_t_per_m);

/// Parameters of homogeneous fog lit only by the sky (the Koschmieder model).
struct MR_API FogParams {
  Rgb sigma_t_per_m{0.01f, 0.01f, 0.01f};  ///< extinction coefficient, 1/m, per channel, >= 0
  /// Airlight (fog colour, the radiance of an infinitely deep fog), scene-linear.
  /// nullopt: estimated from the photo (estimate_airlight).
  std::optional<Rgb> airlight;
};

/// The layers of a fogged photo, all the photo's size, scene-linear float.
struct MR_API FogLayers {
  Image composite;      ///< C = I * T + R (R,G,B)
  Image transmittance;  ///< T (R,G,B), in [0, 1]
  Image inscatter;      ///< R (R,G,B): light scattered into the view ray by the fog
  Rgb airlight{};       ///< the airlight used (given or estimated)
};

/// Homogeneous fog under sky light: T = exp(-sigma_t d), R = A (1 - T), C = I T + R.
/// `photo`: scene-linear, >= 3 channels (the first three are used; alpha is carried).
/// `distance_m`: one channel, metres along the ray; +inf (sky) gives T = 0, C = A.
/// Throws mr::Error: size_mismatch (naming both sizes), invalid_argument (negative or
/// non-finite sigma or airlight, NaN distance).
MR_API FogLayers fog(const Image& photo, const Image& distance_m, const FogParams& params);

/// Airlight estimated from a scene-linear photo with the dark channel prior (He et al. 2009,
/// as used for Foggy Cityscapes): the dark channel is the per-pixel minimum of R,G,B, min-filtered
/// over a 15x15 window (scaled with the image size); the airlight is the mean colour of the
/// brightest 0.1 % of dark-channel pixels, then bounded: real fog takes the colour of the
/// daylight that lights it, so the colour's CIE u'v' offset from D65 is kept within the daylight
/// locus from 4000 K (0.043) to 10000 K (0.029) and 0.01 across it, compressed smoothly above half
/// those limits (a neutral prior), and its CIELAB chroma (at Y = 1) at most 33.6, the Planckian
/// 4000 K's; its luminance unchanged (photo/airlight.h gives the sources). Throws
/// mr::Error(invalid_argument) on an empty image.
MR_API Rgb estimate_airlight(const Image& photo);

/// A sun irradiance that matches the photo's exposure, for a sun placed without a given
/// strength: E_sun = pi x the 99th percentile luminance of the surface pixels (a white surface
/// facing the sun would be as bright as the photo's bright surfaces), kept within
/// 1 <= E_sun / (pi L_sky) <= 10 of the sky's luminance when `sky_radiance` is positive; grey.
/// `distance_m`: the photo's distance map (+inf = sky) or an empty image (all pixels count).
/// Throws mr::Error(invalid_argument) for a non-RGB photo or a distance map of another size.
MR_API Rgb exposure_relative_sun_irradiance(const Image& photo, const Image& distance_m,
                                     const Rgb& sky_radiance);

}  // namespace mr
