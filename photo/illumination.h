// Private to libmr: the light of an outdoor photo from a few user marks (DESIGN.md section 4,
// issue 4 item 5): the sun direction from shadow pairs, and the sun/sky ratio from a sunlit and
// a shadowed patch of one material. Ceres is used in illumination.cpp only.
#pragma once

#include <array>
#include <cstddef>
#include <vector>

#include "mr/camera.h"
#include "mr/image.h"
#include "mr/scene.h"

namespace mr::photo {

/// One shadow mark, in pixel coordinates of the photo (the convention of
/// CameraPose::ray_direction: (x, y) = (0, 0) is the centre of the top-left pixel).
/// The caster is a vertical object standing on the ground (the plane y = 0 of mr/scene.h) at
/// `caster_foot_px`; its top, at `caster_top_px`, casts the shadow whose tip on the ground is at
/// `shadow_tip_px`.
struct ShadowPair {
  std::array<double, 2> caster_top_px{}, caster_foot_px{}, shadow_tip_px{};
};

struct SunFitOptions {
  /// Where the solver starts; without it, at the normalised mean of the pairs' directions.
  bool use_initial_guess = false;
  double initial_azimuth_deg = 0, initial_elevation_deg = 45;
  /// Scale of the Cauchy loss: pairs whose residual is well above this many degrees are
  /// down-weighted (a mis-click among good pairs barely moves the fit).
  double robust_scale_deg = 5;
  /// Scale of the Cauchy loss on a pair's reprojection error (pixels) in the final stage.
  double robust_scale_px = 3;
  /// The pairs are called contradictory, and the fit fails with mr::Error(invalid_argument),
  /// when the median per-pair reprojection error (SunFit::residuals_px) exceeds this many
  /// pixels. Clicks a pixel or two off give about that; shadows pointing different ways give
  /// tens to hundreds of pixels.
  double max_median_residual_px = 5;
};

/// The sun direction that best explains the marked shadows.
struct SunFit {
  Vec3 direction_to_sun;  ///< unit, world frame (mr/scene.h), y > 0
  double azimuth_deg = 0;    ///< in [0, 360); 0 = +Z, 90 = +X (direction_from_azimuth_elevation)
  double elevation_deg = 0;  ///< above the horizon, in (0, 90]
  /// Per pair, in the order given: the angle at the fitted top of the caster between the ray
  /// toward the sun and the ray toward the marked tip (lifted to the ground), i.e. how far
  /// from the marked tip the fitted sun would put the shadow, as seen from the top.
  std::vector<double> residuals_deg;
  double rms_residual_deg = 0;  ///< of residuals_deg
  /// Per pair: RMS over top, foot and tip of the distance between each mark and where the
  /// fitted caster and sun put it in the image (pixels).
  std::vector<double> residuals_px;
  double median_residual_px = 0;  ///< what max_median_residual_px is compared with
  bool converged = false;  ///< Ceres reported convergence (else: best point after its iterations)
  int iterations = 0;      ///< Ceres iterations, all three stages together
};

/// Fits the sun direction to shadow pairs seen by `camera` at `pose` (pose.position_m.y is the
/// camera's height above the ground, > 0).
///
/// Each pair is lifted to 3D: foot F and tip P are where their pixel rays meet the ground; the
/// top T is the point of the vertical line above F closest to the top pixel's ray. The pair's
/// observed sun direction is then d = (T - P) / |T - P|: light from the sun grazes the top and
/// lands at the tip. The residual of a pair for a candidate sun direction l is the angle between
/// l and d, which is also the angle, seen from the top, between where the shadow of T would
/// land under l and the marked tip (the seed's argmin_l sum_j arccos(l . d_j), DESIGN.md
/// section 4). Ceres minimises the sum over pairs of Cauchy(|l - d_j|^2) (chord length: 2
/// sin(angle / 2), smooth at zero, unlike arccos) with l on the unit sphere (SphereManifold, no
/// azimuth singularity at the zenith): first with a plain squared loss from the start point
/// (it converges from anywhere but the antipode of the pairs' mean), then robustly from there.
/// That angular fit weighs every pair alike, but a distant caster's ground position is poorly
/// pinned down by its pixels (ground depth error grows with distance squared), so a third
/// stage refines the sun together with every caster's foot (X, Z) and height h, minimising the
/// pixel reprojection error of top, foot and tip (Cauchy loss, scale robust_scale_px): the
/// maximum-likelihood estimate under pixel noise on the marks.
///
/// Throws mr::Error(invalid_argument), naming the pair index and the problem, when: there are
/// no pairs; a coordinate is NaN or infinite; the camera is not above the ground; a foot or tip
/// is on or above the horizon (its ray does not meet the ground in front of the camera); a top
/// is not above its foot (or its ray is parallel to the caster); the options are out of range;
/// or the pairs are contradictory (median reprojection error above
/// options.max_median_residual_px; the message gives every pair's residuals).
SunFit fit_sun_direction(const std::vector<ShadowPair>& pairs, const Camera& camera,
                         const CameraPose& pose, const SunFitOptions& options = {});

/// Linear RGB statistics of one marked patch.
struct PatchStats {
  std::array<double, 3> mean{};    ///< mean linear RGB
  std::array<double, 3> stddev{};  ///< per-pixel standard deviation (0: not known)
  std::size_t pixel_count = 1;

  /// Mean and standard deviation of a patch's pixels. Throws mr::Error(invalid_argument) when
  /// there are none or one is NaN or infinite.
  static PatchStats from_pixels(const std::vector<std::array<float, 3>>& pixels);
};

/// A sunlit and a shadowed patch of one (Lambertian) material, and what is known about them.
struct SunSkyPatches {
  PatchStats lit, shadowed;
  Vec3 normal{0, 1, 0};  ///< surface normal of both patches (need not be unit); the ground: +Y
  Vec3 direction_to_sun{0, 1, 0};  ///< e.g. SunFit::direction_to_sun
  /// Fraction of the sky each patch sees (ambient occlusion, in (0, 1]). The default assumes
  /// both see the same, whole sky. A shadowed patch next to its caster usually sees less
  /// (the caster hides part of the sky); assuming 1 there then overestimates the ratio.
  double sky_visibility_lit = 1, sky_visibility_shadowed = 1;
};

/// The sun/sky ratio of a photo, per channel.
///
/// Model (DESIGN.md section 4), per channel c, Lambertian albedo rho_c, sky radiance L_sky
/// (isotropic), sun irradiance E_sun (on a surface facing it), cos(theta) = n . l:
///   lit      = rho (E_sun cos(theta) + pi L_sky A_lit)
///   shadowed = rho (pi L_sky A_shadowed)
/// so the albedo cancels and
///   E_sun cos(theta) / (pi L_sky) = A_shadowed lit / shadowed - A_lit
/// (= lit / shadowed - 1 when both see the whole sky). `ratio_rgb` is E_sun / (pi L_sky), the
/// above divided by cos(theta): the quantity a scene needs, independent of the patch.
struct SunSkyRatio {
  std::array<double, 3> patch_ratio_rgb{};  ///< E_sun cos(theta) / (pi L_sky) per channel
  std::array<double, 3> ratio_rgb{};        ///< E_sun / (pi L_sky) per channel
  /// One standard deviation of ratio_rgb from the patches' pixel noise (standard error of each
  /// mean, propagated to first order); 0 when the patches carry no stddev.
  std::array<double, 3> ratio_sigma_rgb{};
  double ratio = 0;  ///< Rec. 709 luminance-weighted mean of ratio_rgb
  double ratio_sigma = 0;  ///< its standard deviation (channels' errors independent)
  /// Spread between channels: (max - min) / ratio of ratio_rgb. Sun and sky differ in colour, so
  /// this is a property of the light, not an error; it is large when the sun is much warmer.
  double channel_spread = 0;
  double cos_theta = 0;  ///< n . l of the patches
};

/// Estimates the sun/sky ratio from the patches (model above). Throws
/// mr::Error(invalid_argument) when a value is NaN or infinite, a sky visibility is outside
/// (0, 1], the normal or sun direction is zero, the sun is behind the surface (cos(theta) <=
/// 0.02: the "lit" patch cannot be sunlit), a shadowed mean is not positive, or the lit patch is
/// not brighter than the shadowed one in some channel (the marks are swapped or not one
/// material; the message names the channel).
SunSkyRatio fit_sun_sky_ratio(const SunSkyPatches& patches);

/// The sun's strength relative to the photo's exposure (issue 11 item 5), for a sun the user
/// placed without saying how bright it is.
///
/// A photo's exposure puts its brightest diffuse surfaces, in a sunny scene the sunlit ones,
/// near the top of its range. Rule: the sun is as strong as would make a white (albedo 1)
/// Lambertian surface facing it exactly as bright as the photo's bright surfaces,
///   E_sun = pi L_bright,  L_bright = the 99th percentile of the Rec. 709 luminance of the
///   surface pixels (distance finite; all pixels when there is no distance map or fewer than
///   1 % surface),
/// then kept within the sun/sky ratios of real daylight, 1 <= E_sun / (pi L_sky) <= 10 (L_sky
/// the luminance of the sky radiance; clear skies give 3-10, hazy ones less), when L_sky > 0.
/// Neutral in colour: a photo white-balanced for daylight shows sunlit white as white.
/// What this bounds: sunlit fog of albedo a seen at scattering angle theta has at most the
/// single-scattered radiance a p(theta) E_sun = a pi p(theta) L_bright (the optically thick,
/// unshadowed limit), i.e. a quarter of L_bright for isotropic scattering and pi p_HG(theta)
/// times it in general, so the in-scatter of a sunlit look is a bounded multiple of the photo's
/// own bright-surface radiance, whatever its exposure.
struct ExposureRelativeSun {
  std::array<float, 3> irradiance{};  ///< E_sun, grey
  double bright_surface_luminance = 0;  ///< L_bright
  double sky_luminance = 0;             ///< luminance of the sky radiance given
  double sun_sky_ratio = 0;             ///< E_sun / (pi L_sky); 0 without sky light
  std::size_t surface_pixels = 0;       ///< pixels L_bright was taken from (sampled)
};

/// `photo`: scene-linear RGB (>= 3 channels); `distance_m`: its distance map (1 channel, +inf
/// or non-finite = sky) or an empty view; `sky_radiance`: the scene's L_sky (e.g. the airlight).
/// Non-finite photo values are skipped. Throws mr::Error(invalid_argument) for a photo with
/// fewer than 3 channels or a distance map of another size.
ExposureRelativeSun exposure_relative_sun(ConstImageView photo, ConstImageView distance_m,
                                          const std::array<float, 3>& sky_radiance);

}  // namespace mr::photo
