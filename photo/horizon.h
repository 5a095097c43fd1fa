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
// confidence. A fit whose roll exceeds HorizonOptions::max_roll_deg is not used at all (the
// lines were not verticals or level ones: brush handles, a bridge's cable stays, a leaning
// trunk), and the result is the level fall-back.
// Pixel coordinates as in CameraPose::ray_direction: (0, 0) is the centre of the top-left pixel.
#pragma once

#include <array>
#include <cstdint>
#include <limits>
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
  /// The roll (degrees) of the lines' fit when it was rejected for exceeding max_roll_deg
  /// (the result is then the fall-back); NaN otherwise.
  double rejected_roll_deg = std::numeric_limits<double>::quiet_NaN();
};

struct HorizonOptions {
  double working_pixels = 1.0e6;        ///< downscale to about this many pixels first
  double min_segment_fraction = 0.025;  ///< shortest segment used, as a fraction of the diagonal
  double inlier_angle_deg = 1.5;        ///< segment-to-vanishing-point angle of an inlier
  double min_support = 0.6;             ///< inlier length / diagonal for a vanishing point to count
  int max_vanishing_points = 4;
  int ransac_iterations = 600;
  unsigned seed = 1;  ///< the RANSAC draws (equal seeds, equal results)
  /// Largest roll (degrees) a fit may have. Photos are held level to within a few degrees; on
  /// the tuning half of the gallery every fit beyond 8 degrees was wrong (10.5-21 degrees, from
  /// lines that were not verticals: brush handles, a railing, a leaning trunk, a bridge's cable
  /// stays) and every one within it was right (at most 4.9 degrees). Not 8: at 10.5-14 degrees
  /// (kleiber, canyon_couple, brushes) the wrong horizon, pitched up, happens to serve the
  /// close-up and far-billboard rules that decide those photos' looks, and the level
  /// fall-back lost them (kleiber's bird veiled in dense fog; README, issue 11).
  double max_roll_deg = 15;
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

/// Issue 11: the dark land of a backlit photo (a sunset or dusk silhouette).
struct SilhouetteOptions {
  /// Land: display-referred luma (scene-linear luma ^ (1 / 2.2)) of at most `max_land_luma`
  /// and at most `max_land_to_sky` times the sky's median display luma.
  double max_land_luma = 0.08;
  double max_land_to_sky = 0.25;
  /// No silhouette when that bound is below this (a night sky), nor when the frame's top row's
  /// median is within it (a letterboxed frame's black bars).
  double min_land_luma = 0.02;
  /// A column's land is its run of land pixels up from the frame's bottom row, through gaps of
  /// at most `max_gap_px` other pixels (a lit window, a lamp, noise); at least this fraction of
  /// the columns must have land at the bottom row.
  int max_gap_px = 2;
  double min_land_columns = 0.9;
  /// The median skyline (the top of each column's land) at least this fraction of the height
  /// above the bottom (a dark foreground strip is not a landscape's land).
  double min_land_height = 0.03;
  /// A silhouette: over the `edge_band` of the height above each column's skyline, the median
  /// display luma is at least `min_contrast` times the land's and at least `min_above_luma`.
  double edge_band = 0.03;
  double min_contrast = 4.0;
  double min_above_luma = 0.1;
};

struct Silhouette {
  /// Row (pixel centres, top = 0) of the median skyline, the top of the land; NaN: no silhouette.
  double skyline_row = std::numeric_limits<double>::quiet_NaN();
  double land_columns = 0;  ///< fraction of the columns with land at the bottom row
  double contrast = 0;      ///< median display luma above the skyline over the land's
  /// Row-major, the photo's size, 1 on the land and what stands on it: the dark pixels (as
  /// the land's) 8-connected to the frame's bottom row; empty when there is no silhouette.
  std::vector<std::uint8_t> land;
  /// Per column: the top row of its land (the topmost `land` pixel), -1 where it has none;
  /// empty when there is no silhouette.
  std::vector<int> column_skyline;
  /// Row-major, the photo's size, in [0, 1]: the sky's matte over what is not land and is
  /// 8-connected (through what is not land) to a pixel above the skyline row: clouds, the
  /// glow down to the land where it dips below the median skyline. It ramps from 0 at the
  /// land's luma to 1 at twice it (a branch's mixed pixels); 0 elsewhere. Empty when there is
  /// no silhouette.
  std::vector<float> sky_alpha;
};

/// The land of a backlit photo, seen as a dark silhouette under a brighter sky: every column's
/// dark run up from the bottom row (see SilhouetteOptions). `photo`: scene-linear, >= 3
/// channels; `sky`: row-major, the photo's size, non-zero on sky (the sky's median luma is the
/// reference; with no sky pixel the frame's top row's). Never throws for any image content.
Silhouette find_silhouette(ConstImageView photo, const std::vector<std::uint8_t>& sky,
                           const SilhouetteOptions& options = {});

/// A backlit land's skyline for its distances: Silhouette::column_skyline with columns without
/// land filled from their neighbours, its running median over `reach_fraction` of the width to
/// either side (a lamp or a lit window breaking a column's land, a post), then its running
/// mean over the same (no step from one column to the next). Empty for an empty input or no
/// column with land.
std::vector<double> receding_skyline(const std::vector<int>& column_skyline,
                                     double reach_fraction = 0.02);

}  // namespace mr::photo
