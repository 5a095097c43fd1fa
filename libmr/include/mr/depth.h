// Depth input: metric distance maps from depth or disparity files.
#pragma once

#include <cstddef>
#include <filesystem>

#include "mr/camera.h"
#include "mr/export.h"
#include "mr/image.h"

namespace mr {

/// What the values in a depth file mean.
enum class DepthKind {
  distance,   ///< Euclidean distance from the camera along the pixel's ray
  planar_z,   ///< z-depth (distance to the camera plane); converted using the camera
  disparity,  ///< stereo disparity in pixels: z = focal_px * baseline_m / (d + doffs)
};

/// Stored depth values (times DepthOptions::scale) at or above this many metres are sky by
/// default: the largest half float (65504, what a saturated half-float EXR holds), and with it
/// the larger sky conventions of common tools (Blender's Z pass writes 1e10 for the background;
/// others 1e6). A surface 65 km away lies behind more than 5 visibility lengths of even 50 km
/// haze, so reading it as sky changes nothing visible.
inline constexpr double kDefaultSkyDepthM = 65504.0;

/// The farthest surface the renderer traces, metres (10,000 km: beyond any terrestrial line of
/// sight, far inside the range Embree's rays are valid for). Finite distances beyond it are
/// clamped to it (read_depth, and render_scattering for maps that do not come from a file).
inline constexpr double kMaxSurfaceDistanceM = 1e7;

struct MR_API DepthOptions {
  DepthKind kind = DepthKind::distance;
  /// Multiplies the stored values first. Integer files (8/16-bit PNG/TIFF) are read as their
  /// raw integer values (0..65535), so e.g. 0.001 turns millimetres into metres; for
  /// disparity, the reciprocal of the file's disparity scale (Middlebury third size: 1/3).
  double scale = 1.0;
  double baseline_m = 0;  ///< disparity only: stereo baseline in metres (> 0)
  double doffs_px = 0;    ///< disparity only: x-difference of the principal points (Middlebury)
  /// distance and planar_z: stored values (times scale) >= this are sky (kDefaultSkyDepthM).
  /// +infinity: only 0, negative, NaN and infinite values are sky. Not used for disparity
  /// (there 0 is the sky).
  double sky_depth_m = kDefaultSkyDepthM;
};

/// A metric distance map: one channel ("Z"), metres along each pixel's ray.
/// Pixels with no surface (sky) hold +infinity.
struct MR_API DepthMap {
  Image distance_m;
  std::size_t no_surface_pixels = 0;  ///< pixels whose stored value was NaN, inf, 0 or < 0
  /// Of those, the pixels whose stored value was NaN or negative: not one of the sky encodings
  /// (0, +inf) but a sign of a broken or mis-scaled map (front ends warn about these).
  std::size_t invalid_pixels = 0;
  /// Of the no-surface pixels, those whose value was finite and >= DepthOptions::sky_depth_m.
  std::size_t sky_threshold_pixels = 0;
  /// Surface pixels whose distance was beyond kMaxSurfaceDistanceM, clamped to it.
  std::size_t clamped_pixels = 0;
};

/// Reads a depth file (float EXR/TIFF/PFM, 16-bit PNG/TIFF, ...; channel "Z", "depth.Z", "Y"
/// or the first) and converts it to distance along the ray with `camera` (whose focal length
/// is also the disparity focal length). A depth map must match the photo as displayed, i.e.
/// after read_image turned the photo by its EXIF Orientation: the photo's orientation is never
/// applied to the depth map; only the depth file's own Orientation tag is (files without one,
/// the usual case for EXR/PFM/PNG depth, are taken as stored). Throws mr::Error: io / corrupt_input naming the file;
/// size_mismatch naming both sizes if it differs from the camera's; invalid_argument for
/// absurd options (scale <= 0, disparity without baseline).
MR_API DepthMap read_depth(const std::filesystem::path& path, const Camera& camera,
                    const DepthOptions& options = {});

/// Converts stored values (already multiplied by scale) in place; exposed for tests and for
/// depth that does not come from a file.
MR_API DepthMap depth_to_distance(Image stored, const Camera& camera, const DepthOptions& options);

}  // namespace mr
