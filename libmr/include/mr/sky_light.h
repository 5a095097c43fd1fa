// Sky light by direction (issue 11): the fog lit by the sky the photo shows, not one colour.
//
// The scattering core lights the fog with one isotropic sky radiance L_sky, so every view ray's
// sky in-scatter is albedo L_sky (1 - tau): in haze, where the sky is seen through an almost
// opaque layer, a sunset, a sky gradient or a cloud's colour becomes one flat colour, and so do
// hillsides and the sea. Single scattering of the whole environment along a view direction w is
// L_in(w) = integral over the sphere of L_env(w') p_HG(w . w') dw'; the sky term then becomes
// albedo L_in(w) (1 - tau) exactly (the source is still constant along the ray), i.e. R gains
// albedo (L_in(w) - L_sky) (1 - tau(0, D)), computed from the pixel's optical depth with the
// core's own closed form. The environment is built from the photo (its sky where it shows the
// sky, a smooth fill elsewhere above the horizon, the mean ground colour below it), held as a
// low-resolution latitude-longitude map and convolved with the medium's Henyey-Greenstein phase.
// The surface term S keeps the uniform L_sky (its ambient pi L_sky AO stands in for multiple
// scattering at the surface, and without sun or lamps S = 1 whatever it is).
#pragma once

#include "mr/camera.h"
#include "mr/export.h"
#include "mr/fog.h"
#include "mr/image.h"
#include "mr/scene.h"

namespace mr {

/// The sky light of one photo: L_in(w) - L_sky as a latitude-longitude map in world directions
/// (column c: azimuth (c + 0.5) / W 360 - 180 degrees, 0 = +Z, 90 = +X; row r: elevation
/// 90 - (r + 0.5) / H 180 degrees; 3 channels, scene-linear), for one phase asymmetry g.
struct MR_API SkyLight {
  Rgb sky_radiance{};  ///< the uniform L_sky the map is relative to
  double g = 0;        ///< the Henyey-Greenstein asymmetry it was convolved with
  /// The deviation map; empty: a uniform sky (the correction is exactly zero).
  Image deviation;
  /// L_in(w) - L_sky at a world direction (bilinear in the map; 0 for an empty map).
  Rgb deviation_at(const Vec3& direction) const;
  /// Issue 11 (haze14): the factor on the sky light along each pixel's ray that brings it to
  /// the luminance of the photo's own sky around the pixel (photo/sky_light.h,
  /// sky_brightness_scale), 1 channel at the camera's size; empty: 1 everywhere.
  Image scale;
  /// The factor per channel on the scaled light that gives it part of the hue of the photo's
  /// own sky around the pixel at the same display luma (photo/sky_light.h), 3 channels at the
  /// camera's size; empty: 1 everywhere.
  Image tint;
  /// The light's deviation for pixel (x, y) seen along `direction`: s t_c (L_sky + deviation) -
  /// L_sky with s = scale(x, y) and t = tint(x, y), exactly deviation_at(direction) where both
  /// are 1 or empty.
  Rgb deviation_at(const Vec3& direction, int x, int y) const;
};

/// The sky light of `photo` (scene-linear RGB, the camera's size) with its distance map
/// (1 channel, +inf = sky) seen by `camera` from `scene.pose`, convolved with scene.medium.g,
/// relative to `sky_radiance` (the L_sky the render uses). A photo whose sky and ground are both
/// exactly sky_radiance gives an empty map. `brightness_from_photo` (issue 11, helpers haze14
/// and haze15): also the scale that brings the light along each pixel's ray to the display luma
/// of the photo's own sky around the pixel (SkyLight::scale, photo/sky_light.h: only darker near
/// a surface; deep in the sky it follows the sky's own luma, clouds included), and the tint
/// that gives the light half of that sky's hue at the same luma (SkyLight::tint; the colour
/// bounded as every automatic fog colour, C*ab <= 33.6). On by default
/// since haze15 (render_scattering and the streamed `mr fog` use the default): on the gallery's
/// tuning half it lowered the haze misses with dense fog still within the target everywhere
/// (gallery/results/haze15_tune.md). Throws mr::Error(size_mismatch / invalid_argument) for
/// inputs of another size or channel count.
MR_API SkyLight sky_light_from_photo(const Image& photo, const Image& distance_m,
                                     const Camera& camera, const FogScene& scene,
                                     const Rgb& sky_radiance, bool brightness_from_photo = true);

/// How much of the photo's sky brightness (SkyLight::scale) the light in `medium` takes: the
/// scale used is scale^w. Fog (meteorological visibility under 1 km, WMO) is optically thick
/// over the frame, so the light in it has scattered from the whole dome and carries no pattern
/// of the sky behind one pixel: w = 0 at 500 m and below, 1 from 1 km (mist and haze, where the
/// sky is seen through the layer), log-linear between so a visibility slider has no step.
/// Visibility from the mean of sigma_t_per_m at density 1; w = 1 for a medium without extinction.
MR_API double sky_brightness_scale_weight(const Medium& medium);

/// Adds the sky light's correction albedo (L_in(w) - L_sky) (1 - exp(-optical_depth)) to
/// `inscatter` (3 channels) at every pixel, w the pixel's view ray from `pose`, optical_depth
/// per channel (3 channels, ScatteringLayers::optical_depth: +inf gives 1 - tau = 1). Nothing
/// changes for an empty map. Throws mr::Error(size_mismatch) for layers of another size.
MR_API void add_sky_light(const SkyLight& sky_light, const Medium& medium, const Camera& camera,
                          const CameraPose& pose, const Image& optical_depth, Image& inscatter);

}  // namespace mr
