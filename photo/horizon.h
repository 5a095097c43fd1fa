// Private to libmr: the horizon found automatically from the photo's straight lines (issue 4
// item 2). Line segments (OpenCV's LSD on a grey copy of at most about 1 MP) are grouped into
// vanishing points by sequential RANSAC over segment pairs (support = inlier length); each
// vanishing point is a direction in the camera frame, so points at infinity need no special
// case. The horizon is the image of the plane through the camera perpendicular to the vertical,
// a great circle of view directions with normal n: the least-squares n with n . d_i = 0 for the
// horizontal vanishing points d_i and n = z for the vertical (zenith) one, weighted by support.
// The cue named is what went into it:
//
//   horizontal_vps            two (or more) horizontal vanishing points >= 20 degrees apart
//   horizontal_vp_and_zenith  one horizontal vanishing point and the zenith
//   zenith                    the zenith alone (right only with the right focal length)
//   horizontal_vp_level       one horizontal vanishing point, level through it (roll 0 assumed)
//   none                      level through the principal point (the fall-back)
//
// Weak echoes (support < 0.3 x the strongest, or within 10 degrees of a stronger one) are left
// out; a fit more than 2 (5) degrees from one of its cues loses a quarter (half) of its
// confidence.
// Pixel coordinates as in CameraPose::ray_direction: (0, 0) is the centre of the top-left pixel.
#pragma once

#include <array>
#include <optional>
#include <vector>

#include "mr/annotations.h"
#include "mr/camera.h"
#include "mr/image.h"

namespace mr::photo {

enum class HorizonCue {
  none,                      ///< no usable lines: level through the principal point
  horizontal_vps,            ///< two (or more) horizontal vanishing points
  horizontal_vp_and_zenith,  ///< one horizontal vanishing point + the vertical one
  zenith,                    ///< the vertical vanishing point alone
  horizontal_vp_level,       ///< one horizontal vanishing point, roll assumed 0
};
const char* to_string(HorizonCue cue) noexcept;

struct VanishingPoint {
  std::array<double, 3> direction{};  ///< unit view direction (a, b, 1)-space: a right, b down
  double support = 0;                 ///< inlier segment length over the working image's diagonal
  int inliers = 0;
};

struct AutoHorizon {
  /// Two points of the horizon: where it crosses the first and the last pixel column.
  std::array<PixelPoint, 2> points{};
  /// In [0, 1]; 0.1 for the fall-back, at most 0.9 (two horizontal vanishing points agreeing
  /// with the vertical one).
  double confidence = 0.1;
  HorizonCue cue = HorizonCue::none;
  std::vector<VanishingPoint> vanishing_points;  ///< all found, strongest first
  int segments = 0;                              ///< line segments used (after the length filter)
};

struct HorizonOptions {
  double working_pixels = 1.0e6;        ///< downscale to about this many pixels first
  double min_segment_fraction = 0.025;  ///< shortest segment used, as a fraction of the diagonal
  double inlier_angle_deg = 1.5;        ///< segment-to-vanishing-point angle of an inlier
  double min_support = 0.6;             ///< inlier length / diagonal for a vanishing point to count
  int max_vanishing_points = 4;
  int ransac_iterations = 600;
  unsigned seed = 1;  ///< the RANSAC draws (equal seeds, equal results)
};

/// The horizon of `photo` (scene-linear, >= 1 channel; the camera's size). Never throws for any
/// image content: with too few or inconsistent lines the result is the level fall-back. Throws
/// mr::Error(size_mismatch) when the photo and the camera differ in size.
AutoHorizon estimate_horizon(ConstImageView photo, const Camera& camera,
                             const HorizonOptions& options = {});

/// The focal length from orthogonal vanishing points (issue 4 item 1, when EXIF has none): for
/// two vanishing points v1, v2 of orthogonal directions and the principal point c,
/// f = sqrt(-(v1 - c) . (v2 - c)). The vanishing points are found as for the horizon (the
/// camera's focal length only parametrises them; the result does not depend on it). Accepted:
///   three vanishing points whose three pairs give focal lengths within `max_spread` of their
///   geometric mean (a Manhattan scene): that mean, confidence 0.9 x strength;
///   else the two strongest finite vanishing points, when their pair gives a focal length:
///   confidence 0.5 x strength (orthogonality assumed).
/// strength = 1 - exp(-s / 1.5) for s the weaker point's support. nullopt when no pair gives a
/// real focal length, when the horizontal field of view it implies is outside
/// [min_fov_deg, max_fov_deg], or the confidence is below min_confidence.
struct FocalOptions {
  double min_fov_deg = 20, max_fov_deg = 120;
  double max_spread = 0.1;
  double min_confidence = 0.3;
};
struct FocalFromVanishingPoints {
  double focal_px = 0;
  double confidence = 0;
  int vanishing_points = 0;  ///< 3: a consistent orthogonal triple; 2: one pair
};
std::optional<FocalFromVanishingPoints> estimate_focal_px(ConstImageView photo,
                                                          const Camera& camera,
                                                          const FocalOptions& options = {},
                                                          const HorizonOptions& lines = {});

}  // namespace mr::photo
