// Private to libmr: user-assisted single-photo geometry (DESIGN.md section 4, issue 4 item 3).
// The camera's pitch and roll from the horizon line, its height from the annotations (or one
// known length on the ground), and a metric distance map from the ground plane y = 0, vertical
// planes standing on it, and distance hints. Pixel coordinates as in CameraPose::ray_direction:
// (0, 0) is the centre of the top-left pixel.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include "mr/annotations.h"
#include "mr/camera.h"
#include "mr/image.h"
#include "mr/scene.h"

namespace mr::photo {

/// Pitch and roll (degrees, CameraPose conventions) of a camera whose horizon passes through
/// both points. With normalised image coordinates a = (x + 0.5 - cx) / f, b = (y + 0.5 - cy) / f,
/// the horizon of a camera at yaw 0 is the line a sin(roll) + b cos(roll) = tan(pitch), so the
/// line's unit normal (oriented down the image) gives roll and its offset gives pitch. Exact.
/// Throws mr::Error(invalid_argument) naming "/horizon" (or a point of it): a non-finite point,
/// points less than 1 px apart, a point farther outside the image than one image size, or a
/// line more than 45 degrees from level (a vertical horizon included).
struct PitchRoll {
  double pitch_deg = 0, roll_deg = 0;
};
PitchRoll pitch_roll_from_horizon(const Camera& camera, const std::array<PixelPoint, 2>& horizon);

/// Where the horizon of `pose` crosses the columns x = 0 and x = width - 1 (pixel-centre
/// coordinates). Throws mr::Error(invalid_argument) when |roll| >= 90 degrees (the horizon is
/// then not a function of x).
std::array<PixelPoint, 2> horizon_of_pose(const Camera& camera, const CameraPose& pose);

/// Where the ray through pixel `p` meets the ground y = 0; nullopt on or above the horizon.
std::optional<Vec3> ground_point(const Camera& camera, const CameraPose& pose, const PixelPoint& p);

/// The camera height that puts two ground pixels `length_m` apart (the ground points scale
/// linearly with the height). Throws mr::Error(invalid_argument) naming "/known_length/a" or
/// "/b" when a point is on or above the horizon of `pose` (whose height is ignored).
double camera_height_from_known_length(const Camera& camera, const CameraPose& pose,
                                       const Annotations::KnownLength& known);

/// A vertical plane n . X = offset (n horizontal, unit).
struct VerticalPlane {
  Vec3 normal;
  double offset = 0;
};
/// The plane of an annotated polygon: through the ground points of its `base` if given, else
/// perpendicular to the camera's horizontal viewing direction through the ground point of the
/// polygon's lowest vertex (the one farthest below the horizon line). Throws
/// mr::Error(invalid_argument) naming `pointer` (e.g. "/planes/2") when that point is on or above
/// the horizon, or the base's ground points coincide.
VerticalPlane plane_of_polygon(const Camera& camera, const CameraPose& pose,
                               const Annotations::Plane& plane, const std::string& pointer);

/// The convex room of an interior_box annotation: vertical walls standing on the floor y = 0
/// through consecutive floor points, and the ceiling y = ceiling_height_m when known.
struct Room {
  std::vector<Vec3> floor_m;  ///< the floor points on y = 0 (world, metres)
  /// Wall i through floor_m[i] and floor_m[i + 1]; its normal points into the room (towards
  /// the camera), so the room is where normal . X > offset for every wall.
  std::vector<VerticalPlane> walls;
  std::optional<double> ceiling_height_m;
  /// Metres along the unit ray `d` from `origin` (inside the room) to the first surface of the
  /// room it meets: the floor, the ceiling or a wall; +inf when it meets none (a horizontal ray
  /// leaving through the open side of the walls, without a ceiling above).
  double distance(const Vec3& origin, const Vec3& d) const;
};

/// The room seen by the camera at `pose` (its height is pose.position_m.y): the floor points'
/// ground points, the walls through them and the ceiling (box.ceiling_height_m, else from
/// box.ceiling_point at this camera height, else none). Throws mr::Error(invalid_argument)
/// naming "/interior_box/...": a floor point on or above the horizon, two consecutive points
/// meeting the floor at the same place, three consecutive points on one line (collinear),
/// points that do not bound a convex room around the camera, a ceiling point on or below the
/// horizon or meeting no wall, a ceiling not above the camera.
Room room_of_box(const Camera& camera, const CameraPose& pose, const Annotations::InteriorBox& box);

/// The height of the box's ceiling_point over the camera height (> 1: the point's ray meets the
/// nearest wall above the camera). Independent of pose.position_m.y. Throws as room_of_box.
double ceiling_over_camera_height(const Camera& camera, const CameraPose& pose,
                                  const Annotations::InteriorBox& box);

/// Pixel-centre coordinates of a world point; nullopt behind (or within 1 mm of) the camera.
std::optional<PixelPoint> project(const Camera& camera, const CameraPose& pose, const Vec3& p);

/// What covers each pixel of a distance map.
enum class Coverage : unsigned char { sky = 0, ground = 1, plane = 2, hint = 3, room = 4 };

struct DistanceMap {
  Image distance_m;                         ///< 1 channel "Z": metres along each ray, +inf = sky
  std::vector<Coverage> coverage;           ///< per pixel, row-major
  std::size_t counts[5] = {0, 0, 0, 0, 0};  ///< pixels per Coverage
  std::optional<Room> room;                 ///< with an interior_box annotation
};

/// The distance map of the annotated scene seen by `camera` at `pose` (pose.position_m.y is the
/// camera height, > 0): per pixel centre, the ground where the ray meets y = 0 (with an
/// interior box: the room's floor, walls or ceiling, room_of_box); inside a plane
/// polygon the nearest such plane where the ray meets it at or above the ground (below the
/// plane's base the ground is nearer); inside a distance hint its distance (hints are applied
/// in order, a later one over an earlier one); +inf for rays above the horizon that nothing
/// covers. Polygons are tested at pixel centres with the even-odd rule.
DistanceMap distance_map(const Camera& camera, const CameraPose& pose,
                         const Annotations& annotations);

/// Even-odd point-in-polygon test.
bool inside_polygon(const std::vector<PixelPoint>& polygon, double x, double y);

/// Edge-aware refinement of an estimated depth (issue 11 item 3: depth that does no harm). Fog
/// turns every jump of the depth into a jump of the transmittance, so a jump where the photo has
/// no edge becomes a seam the photo never had. The inverse distance q = 1 / d (0 = sky, so the
/// sky joins in without infinities) is smoothed with a confidence-normalised fast global
/// smoother (cv::ximgproc::fastGlobalSmootherFilter, Min et al. 2014, on c q and on c, then
/// divided; guide = the display-referred photo) on a working copy of about `working_pixels`:
/// neighbours are tied by exp(-|photo difference| / sigma_color), so values spread freely
/// along smooth colour ramps (a sunset band into the sky, the sea into the haze) and stop at the
/// photo's edges, over about sqrt(lambda) working pixels. The result is
/// w q + (1 - w) smoothed, w = smoothstep(0.5, 1, confidence): confidence 1 (the ground plane,
/// annotations, the sky) keeps its value exactly, confidence <= 0.5 takes the smoothed one, and
/// w varies continuously with the confidence.
struct DepthRefineOptions {
  double working_pixels = 0.5e6;
  double lambda = 1500;    ///< smoothness (working pixels^2)
  double sigma_color = 4;  ///< of 255, display-referred
  /// Texture smaller than about this many working pixels is taken out of the guide first
  /// (rolling guidance filter, sigma_space = texture_px, sigma_color 25 of 255, 4 rounds), so
  /// that the smoother spreads across grain and stops only at outlines. 0: off.
  double texture_px = 3;
};
/// `inverse_distance` and `confidence` ([0, 1]) are row-major at the photo's size (photo:
/// scene-linear, >= 1 channel); returns the refined inverse distance (>= 0), same layout.
/// Throws mr::Error(size_mismatch) when the sizes differ.
std::vector<float> refine_inverse_distance(ConstImageView photo,
                                           const std::vector<float>& inverse_distance,
                                           const std::vector<float>& confidence,
                                           const DepthRefineOptions& options = {});
/// The weight refine_inverse_distance gives a pixel's own value: smoothstep(0.5, 1, confidence).
float refine_keep_weight(float confidence);

/// How much of the sky a pixel "sees" through the photo (issue 11 item 4: no discontinuity
/// between the sky and what meets it with no edge). The binary sky mask smoothed with the same
/// confidence-free fast global smoother as refine_inverse_distance (guide: the display-referred
/// photo): 1 inside the sky, about 0.5 on a surface pixel next to the sky where the photo shows
/// no edge (a calm sea meeting a hazy sky, a hill fading into it), falling over about
/// sqrt(lambda) working pixels away from it, and near 0 across an edge of the photo (a roof
/// line, a dark ridge). Only the open sky (the mask's components that reach the frame's border)
/// spreads: enclosed pieces (sky through foliage, a pale patch misjudged as sky) do not pull
/// the surface around them away. Row-major at the photo's size; sky pixels exactly 1. Throws
/// mr::Error(size_mismatch) when `sky` is not the photo's size.
struct SkyProximityOptions {
  double working_pixels = 0.5e6;
  double lambda = 1500;    ///< smoothness (working pixels^2)
  double sigma_color = 4;  ///< of 255, display-referred
};
std::vector<float> sky_proximity(ConstImageView photo, const std::vector<std::uint8_t>& sky,
                                 const SkyProximityOptions& options = {});

/// The factor on a surface pixel's inverse distance at sky proximity `p` (sky_proximity):
/// (1 - 2 p)^2 clamped to [0, 1]: 1 where the pixel is apart from the sky (p = 0), 0 where it
/// meets the sky with no edge (p >= 0.5), so that there its distance reaches the sky's (+inf)
/// and the fog on both sides of the boundary is the same, and rising smoothly in between (the
/// square makes the distance's return from infinity gentle: the fog's transmittance
/// exp(-sigma d) ramps over many pixels rather than a few, for thin haze too).
float sky_fold(float proximity);

/// The smooth maximum max(a, b) + softness ln(1 + exp(-|a - b| / softness)) (softplus):
/// at least max(a, b), at most max(a, b) + softness ln 2 (where a = b), within
/// softness exp(-|a - b| / softness) of it, smooth, and increasing in a and in b. softness <= 0
/// (or not finite): max(a, b) exactly.
double smooth_max(double a, double b, double softness);

/// The inverse distance of a bounded scene's pixel (issue 11 item 3: a photo with no sky, whose
/// horizon is a guess and in which nothing is known to be far): the ground plane's and the far
/// billboard's, joined by smooth_max. `ray_up` is the unit ray's upward component (world y,
/// negative below the horizon), `ray_forward` its horizontal part along the camera's viewing
/// direction, `camera_height_m` (> 0), `far_forward_m` the far billboard's forward distance.
/// The ground's inverse distance -ray_up / camera_height_m is extended above the horizon as a
/// negative number (linear in the image rows near the principal point), so the join is smooth
/// across it. `soft_rows` (>= 0) is the join's width in image rows at focal length `focal_px`:
/// softness = soft_rows / (focal_px camera_height_m), the ground's inverse distance per row at
/// the principal point of a level camera. The result is >= both, so no distance is farther than
/// the far billboard; 0 soft rows gives the plain nearer-of-the-two (the unrefined estimate).
double bounded_inverse_distance(double ray_up, double ray_forward, double camera_height_m,
                                double far_forward_m, double focal_px, double soft_rows);

/// A smooth forward distance for a structure's columns (issue 11 item 3: no seam between
/// columns). `forward[k]`, k < count: the structure's forward distance measured in column k
/// (> 0), or <= 0 (or not finite) where none was measured. Fits a line q = a + b k to the
/// inverse distances q = 1 / forward[k] of the measured columns, robustly (iteratively
/// reweighted least squares with Huber weights at 1.345 x the residuals' scaled median absolute
/// deviation, 20 rounds), so a few columns reaching a foreground object do not pull it; for one
/// vertical plane seen by a level camera q is exactly linear in the column. With `reach` > 0
/// (and at least 3 measured columns) each column takes a local line instead (weighted least
/// squares over the measured columns within `reach`, tricube kernel times the global fit's
/// robust weights: a box's two faces keep their own slopes, rounded over `reach` at the
/// corner), mixed with the global line by the kernel's mass (m / (1 + m), m = the weights'
/// sum over 0.3 reach + 1), so the result is continuous in the column also where measured
/// columns thin out. Returns 1 / q for every column (+inf where q <= 0); with fewer than two
/// distinct measured columns, their median everywhere; all +inf without any.
std::vector<double> robust_inverse_line(const double* forward, int count, int reach = 0);
inline std::vector<double> robust_inverse_line(const std::vector<double>& forward, int count,
                                               int reach = 0) {
  return robust_inverse_line(forward.data(), count, reach);
}

/// How much of a photo is strongly out of focus (issue 11 item 3: a close-up's cue). A
/// background blurred well beyond the sharp subject's edges means a shallow depth of field,
/// which at any ordinary aperture means a subject centimetres to a few metres away (a 50 mm
/// lens at f/2.8 focused at 2 m keeps about +-0.2 m sharp; a subject tens of metres away has
/// its background nearly as sharp as itself). Measured on the display-referred luma at about
/// `working_long_side` pixels across, in blocks of `block_px` working pixels: the blur is
/// estimated from the drop of the block's gradient energy after a Gaussian re-blur of sigma s0
/// (after Zhuo and Sim 2011: an edge blurred by sigma has its gradient energy divided by
/// R = sqrt(sigma^2 + s0^2) / sigma, so sigma = s0 / sqrt(R^2 - 1)); sharp (<= sharp_px),
/// blurred (>= blurred_px), or neither; a block whose re-blurred RMS gradient is below
/// `min_structure` (luma per working pixel: a plain wall, noise) is neither. Blocks that are
/// mostly `sky` (row-major at the photo's size, or empty) are left out.
struct DefocusOptions {
  int working_long_side = 640;
  int block_px = 32;
  double reblur_sigma_px = 2.0;
  double sharp_px = 0.8, blurred_px = 1.8;
  double min_structure = 0.004;
};
struct Defocus {
  std::size_t blocks = 0;          ///< blocks not mostly sky
  std::size_t sharp_blocks = 0;    ///< of them, with sharp edges
  std::size_t blurred_blocks = 0;  ///< of them, with strongly blurred edges
  double blurred_fraction() const { return blocks ? double(blurred_blocks) / blocks : 0.0; }
  double sharp_fraction() const { return blocks ? double(sharp_blocks) / blocks : 0.0; }
};
Defocus estimate_defocus(ConstImageView photo, const std::vector<std::uint8_t>& sky,
                         const DefocusOptions& options = {});

}  // namespace mr::photo
