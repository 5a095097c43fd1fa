// Private to libmr: interior lamps of a photo from a few user marks (DESIGN.md section 4, issue 4
// item 5): each marked lamp pixel is lifted to 3D with the distance map, and the lamps' radiant
// intensities are fitted with Ceres to the photo's shading on marked surfaces ("lamp patches").
// Ceres is used in lamps.cpp only.
//
// Model (per colour channel c), the direct light evaluated with the project's shared shading
// code (render/surface_shading.h: the Lambert term of shading_terms, one lamp at a time at unit
// intensity, i.e. a unit-albedo Lambertian surface), times the lamp's visibility:
//
//   L_p,c = rho_k,c * sum_i I_i,c * V_i,p * D_i,p + A_k,c,
//   D_i,p = max(0, n_p . (P_i - X_p)) / (pi |P_i - X_p|^3)   (what shading_terms returns)
//
//   L_p      the photo's scene-linear radiance at pixel p of lamp patch k
//   X_p, n_p the surface point seen at p (camera + ray * distance) and its normal, from the
//            distance map (one-sided differences with the neighbour of smaller depth change on
//            each axis, so creases and depth edges are not smeared), turned toward the camera
//   P_i      lamp i's position (lift_lamp); I_i,c its radiant intensity per steradian (unknown,
//            >= 0); irradiance I cos / r^2 as mr::Lamp defines it
//   V_i,p    1 where the segment from X_p to lamp i is free, 0 where the scene hides the lamp:
//            a shadow ray against the occluder mesh of the distance map
//            (render::reconstruct_occluder_mesh in an Embree OccluderScene, reduced to at most
//            1 MP for larger maps), leaving the surface 1 mm + 1e-3 of its distance along n_p
//            (times the reduction factor) and ending 1 cm + 2e-3 of the lamp's distance (times
//            the factor) in front of the surface the lamp was marked on, along that surface's
//            normal, so a lamp marked on a wall (offset_m = 0) is not hidden by the wall itself.
//            LampFitOptions::shadows = false takes V = 1 (the model before shadows were added)
//   rho_k,c  the patch's Lambertian albedo: GIVEN (LampPatch::albedo, default 0.5). The albedo
//            and the intensities only appear as their product, so the intensities scale with
//            1 / albedo; a wrong albedo guess scales every lamp alike
//   A_k,c    per patch, unknown, >= 0: everything else that lights it (ambient / sky /
//            interreflections), i.e. the patch's albedo times its ambient irradiance / pi,
//            taken as constant over the patch
//
// Only the Lambert lobe of the shared BRDF is used: the patches are taken as matte, and the
// model stays linear in (I, A) with one albedo per patch (a specular lobe would add a roughness
// and F0 per patch that a few marked patches cannot pin down).
//
// The fit is linear in the unknowns (I, A). It runs in three Ceres stages: a plain squared loss
// from the start point (converges from any start), then a Cauchy loss from there with no bounds
// (to see whether the data need a negative intensity: contradictory marks), then the Cauchy loss
// with I >= 0, A >= 0. Residuals are relative: (model - L) / m_c, m_c the median patch radiance
// of channel c.
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <optional>
#include <vector>

#include "mr/annotations.h"
#include "mr/camera.h"
#include "mr/image.h"
#include "mr/scene.h"

namespace mr::photo {

/// A lamp marked in the photo: its pixel (CameraPose::ray_direction convention) and how far in
/// front of the surface seen there it hangs (metres along the pixel's ray, >= 0).
struct LampMark {
  std::array<double, 2> pixel{};
  double offset_m = 0;
  /// Optional colour (linear RGB, >= 0, not all 0): the lamp's intensity is then s * colour /
  /// luminance(colour) with one unknown s >= 0, instead of three free channels.
  std::optional<std::array<double, 3>> color;
};

/// A surface lit by the lamps (floor, wall, table top), over one material.
struct LampPatch {
  std::vector<PixelPoint> polygon;  ///< >= 3 points; pixel centres inside (even-odd rule) count
  std::array<double, 3> albedo{0.5, 0.5, 0.5};  ///< in (0, 1] per channel (see the model)
};

struct LampFitOptions {
  /// Scale of the Cauchy loss on the relative residual (0.1: pixels more than ~10 % off the
  /// model, e.g. a mis-marked patch corner over another material, are down-weighted).
  double robust_scale = 0.1;
  /// The marks are contradictory when the unconstrained robust fit needs an intensity below
  /// -max_negative_fraction * (the largest |intensity| of that channel), or a patch's ambient
  /// term below -max_negative_fraction * (the median patch radiance of that channel).
  double max_negative_fraction = 0.05;
  /// Lamp visibility by shadow rays against the occluder mesh (see the model). false: every
  /// patch pixel facing a lamp is lit by it (biased where the scene shadows a patch).
  bool shadows = true;
  /// At most this many pixels per patch are used (an even stride over the patch).
  std::size_t max_pixels_per_patch = 4000;
  /// Start point of the intensities, per lamp (RGB; a coloured lamp uses their luminance).
  /// Empty: every lamp alike, explaining half the patches' mean radiance.
  std::vector<std::array<double, 3>> initial_intensity;
};

struct LampFit {
  std::vector<Vec3> positions_m;                        ///< per lamp, world frame
  std::vector<std::array<double, 3>> intensity_per_sr;  ///< per lamp, RGB, >= 0
  std::vector<std::array<double, 3>> ambient;           ///< per patch: A_k (radiance units)
  /// Relative residual (model - photo) / median patch radiance, over the used pixels and the
  /// three channels: RMS and median of the absolute value; and the RMS per patch.
  double rms_residual = 0, median_abs_residual = 0;
  std::vector<double> patch_rms_residual;
  std::size_t pixels_used = 0;
  /// Per lamp: the share of the used patch pixels facing it that the scene hides from it.
  std::vector<double> shadowed_fraction;
  bool converged = false;  ///< the last Ceres stage reported convergence
  int iterations = 0;      ///< all stages together
};

/// The 3D position of a marked lamp: camera + ray(pixel) * (distance - offset), the distance
/// bilinear in the map where the four nearest pixels are finite and within 10 % of each other,
/// else the nearest pixel's. Throws mr::Error(invalid_argument) "lamp <index>: ..." when the
/// pixel or offset is not finite, the pixel lies outside the image, the map shows sky (+inf)
/// or no valid depth there, the offset is negative, or offset >= distance (the lamp would be
/// at or behind the camera).
Vec3 lift_lamp(const Image& distance_m, const Camera& camera, const CameraPose& pose,
               const LampMark& lamp, std::size_t index);

/// The surface point and normal the fit uses at pixel (x, y) (see the model); false where the
/// depth is not finite or no neighbour gives a normal.
bool surface_point(const Image& distance_m, const Camera& camera, const CameraPose& pose, int x,
                   int y, Vec3& position, Vec3& normal);

/// Lifts the lamps and fits their intensities (model above). `photo`: scene-linear RGB of the
/// camera's size; `distance_m`: metres along each ray (+inf = sky), the same size.
/// Throws mr::Error(invalid_argument) naming the lamp or patch index when: a lamp cannot be
/// lifted (lift_lamp); there are no lamps or no patches; a patch has an albedo outside (0, 1],
/// fewer than 3 points or no pixel with a finite depth, normal and photo value; a lamp lights
/// none of the patch pixels (faces away from all of them or is hidden from them: its intensity
/// is then undetermined); the patches are black; or the
/// data are contradictory (a lamp needs a negative intensity or a patch a negative ambient term,
/// see LampFitOptions::max_negative_fraction). size_mismatch for images of the wrong size.
LampFit fit_lamps(const Image& photo, const Image& distance_m, const Camera& camera,
                  const CameraPose& pose, const std::vector<LampMark>& lamps,
                  const std::vector<LampPatch>& patches, const LampFitOptions& options = {});

/// A lamp's intensity relative to the photo's exposure (issue 11 item 5), for a lamp placed
/// without a given strength (Lamp::intensity_auto), so that a night look's lamps neither blow
/// the frame to white nor vanish, whatever the photo's exposure.
///
/// Rule: the lamp is as strong as would light a white (albedo 1) Lambertian surface facing it,
/// at the distance of the nearest surface the photo shows, exactly as bright as the photo's
/// bright surfaces:
///   I = pi L_bright d_near^2   (then (1 / pi) I / d_near^2 = L_bright),
/// L_bright: the 99th percentile of the surface pixels' Rec. 709 luminance (as for the sun,
/// exposure_relative_sun; all pixels when under 1 % are surfaces), d_near: the distance from the
/// lamp to the nearest surface point of the distance map (pixels sampled on a grid of at most
/// about 250,000), at least 0.25 m; without any surface pixel, the lamp's distance from the
/// camera. A lamp over a ground of photo luminance L_0 at height h (the ground below it in
/// view) gets I = pi L_0 h^2. The colour is `colour`'s chromaticity (scaled to luminance 1; a
/// colour without positive luminance: grey).
struct ExposureRelativeLamp {
  std::array<float, 3> intensity_per_sr{};
  double bright_surface_luminance = 0;  ///< L_bright
  double nearest_surface_m = 0;         ///< d_near
  /// The glow bound's luminance intensity (per sr; +inf without a medium or without fog at the
  /// lamp), and whether it, not the surface rule, set the intensity.
  double glow_bound_intensity = INFINITY;
  bool glow_limited = false;
};

/// `photo`: scene-linear RGB; `distance_m`: its distance map (1 channel, +inf = sky), of the
/// camera's size. Throws mr::Error(invalid_argument) for a non-RGB photo, size_mismatch for
/// images not of the camera's size.
ExposureRelativeLamp exposure_relative_lamp(const Image& photo, const Image& distance_m,
                                            const Camera& camera, const CameraPose& pose,
                                            const Vec3& lamp_position_m,
                                            const std::array<float, 3>& colour);

/// The same, with the glow bound of the fog the lamp shines in (issue 11 item 5; what
/// render_scattering uses). In fog the surface rule alone does not bound what the camera sees:
/// the single-scattered glow of a point lamp on a view ray that passes it at the distance
/// b = D sin(alpha) (D the lamp's distance from the camera, alpha the ray's angle from the
/// lamp's direction) is, neglecting the extinction between lamp and fog,
///   R(alpha) = T_cam sigma_s rho I J(alpha) / (D sin alpha),  J(alpha) = int_alpha^pi p(cos phi)
///   dphi
/// (p the Henyey-Greenstein phase of the medium's g; T_cam the camera-lamp transmittance, which
/// bounds the extinction camera -> fog -> lamp in homogeneous fog as t + r >= D; rho
/// the largest density within b of the lamp, sigma_s = albedo sigma_t), i.e. it grows with
/// sigma_s d_near^2 under the surface rule: a lamp 20 m from the nearest surface in 70 m fog
/// lit a glow brighter than the photo's bright surfaces over 5 degrees around it, and three of
/// them washed a dusk photo out to yellow-white. Bound: the glow's core, where R exceeds
/// L_bright, has an angular radius of at most kGlowCoreFraction of the frame's diagonal (as
/// the camera's focal length turns pixels into angles): I is the smaller of the surface rule
/// and the I for which R(alpha_core) = L_bright in luminance (a lamp outside the frame: at the
/// angle of the frame's view ray nearest to it, when larger). Outside the core the glow falls
/// as about alpha_core / alpha times L_bright; pure white (all channels past the highlight
/// roll-off's 250/255, 1.49 linear) needs R >= 1.49 / L_bright times that in the colour's
/// weakest channel, so at most a few core areas per lamp.
inline constexpr double kGlowCoreFraction = 0.01;
ExposureRelativeLamp exposure_relative_lamp(const Image& photo, const Image& distance_m,
                                            const Camera& camera, const CameraPose& pose,
                                            const Vec3& lamp_position_m,
                                            const std::array<float, 3>& colour,
                                            const Medium& medium);

/// J(alpha) = int_alpha^pi p_HG(g, cos phi) dphi of the glow bound (numerical, relative error
/// below 1e-6 for |g| <= 0.95 and alpha >= 1e-4 rad). Isotropic: (pi - alpha) / (4 pi).
double lamp_glow_phase_integral(double g, double alpha_rad);

}  // namespace mr::photo
