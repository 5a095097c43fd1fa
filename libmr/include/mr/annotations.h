// User annotations of one photo: the few clicks that give single-photo estimation its geometry
// and light (DESIGN.md section 4): the horizon, the camera height (or one known length), vertical
// planes, "this region is at distance X", shadow pairs and a sunlit / shadowed patch.
// The JSON document (every key, unit and rule) is documented in docs/annotations.md:
//
//   {"format": "libmr-annotations", "version": 1, "horizon": [[x0, y0], [x1, y1]],
//    "camera_height_m": 1.6, "planes": [{"polygon": [[x, y], ...]}], ...}
//
// Pixel coordinates follow CameraPose::ray_direction: (0, 0) is the centre of the top-left pixel,
// x to the right, y down; a click at continuous position (u, v) (pixel edges at integers) is
// (u - 0.5, v - 0.5).
#pragma once

#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "mr/export.h"
#include "mr/scene.h"

namespace mr {

/// A point in the photo, in pixels (x right, y down; (0, 0) = centre of the top-left pixel).
using PixelPoint = std::array<double, 2>;

struct MR_API Annotations {
  /// Two points on the horizon line (the image of the plane through the camera parallel to the
  /// ground). Gives the camera's pitch and roll. nullopt: estimated automatically.
  std::optional<std::array<PixelPoint, 2>> horizon;
  /// Height of the camera above the ground, metres (> 0). At most one of camera_height_m and
  /// known_length is given; with neither, estimation assumes 1.6 m.
  std::optional<double> camera_height_m;
  /// Two points on the ground a known distance apart: fixes the camera height instead.
  struct KnownLength {
    PixelPoint a{}, b{};
    double length_m = 0;  ///< > 0
  };
  std::optional<KnownLength> known_length;
  /// A vertical plane standing on the ground, covering the polygon's pixels.
  struct Plane {
    std::vector<PixelPoint> polygon;  ///< >= 3 points
    /// Optional: two image points where the plane meets the ground (its orientation). Without
    /// it the plane faces the camera (perpendicular to its horizontal viewing direction) and
    /// stands where the polygon's lowest point (measured across the horizon) meets the ground.
    std::optional<std::array<PixelPoint, 2>> base;
  };
  std::vector<Plane> planes;
  /// "The pixels of this polygon are `distance_m` metres away (along their rays)".
  struct DistanceHint {
    std::vector<PixelPoint> polygon;  ///< >= 3 points
    double distance_m = 0;            ///< > 0
  };
  std::vector<DistanceHint> distance_hints;
  /// A vertical caster standing on the ground at caster_foot, whose top at caster_top casts the
  /// shadow whose tip on the ground is at shadow_tip.
  struct ShadowPair {
    PixelPoint caster_top{}, caster_foot{}, shadow_tip{};
  };
  std::vector<ShadowPair> shadow_pairs;
  /// Polygons over one material in sun and in shadow (empty: not marked). Both or neither.
  std::vector<PixelPoint> sunlit_patch, shadowed_patch;
  /// An interior lamp: the pixel it is seen at, lifted to 3D with the distance map, `offset_m`
  /// metres (>= 0) in front of the surface seen there (along the pixel's ray).
  struct Lamp {
    PixelPoint pixel{};
    double offset_m = 0;
    /// Optional linear RGB colour (>= 0, not all 0): the fit then keeps this chromaticity and
    /// fits one intensity; without it the three channels are fitted freely.
    std::optional<std::array<double, 3>> color;
  };
  std::vector<Lamp> lamps;
  /// A surface the lamps light (one material; shadows cast by the scene of the distance map are
  /// traced): their intensities are fitted to its shading. `albedo` per channel in (0, 1];
  /// unset: 0.5 (intensities scale with 1 / albedo).
  struct LampPatch {
    std::vector<PixelPoint> polygon;  ///< >= 3 points
    std::optional<std::array<double, 3>> albedo;
  };
  std::vector<LampPatch> lamp_patches;  ///< both lamps and lamp_patches, or neither
  /// An interior: the camera stands in a convex room whose walls are vertical planes on the
  /// floor (the ground y = 0) and whose ceiling, when known, is the plane y = ceiling height.
  /// Every pixel is then on the floor, a wall or the ceiling (no sky); planes and distance hints
  /// still override it.
  struct InteriorBox {
    /// >= 3 points where walls meet the floor, in order along the floor's edge (e.g. a point
    /// on the left wall's base, the back-left corner, the back-right corner, a point on the
    /// right wall's base): each two consecutive points span one wall. All below the horizon.
    std::vector<PixelPoint> floor;
    /// Ceiling height above the floor, metres (> 0).
    std::optional<double> ceiling_height_m;
    /// A point where the ceiling meets a wall (above the horizon): gives the ceiling height
    /// relative to the camera height; with ceiling_height_m too it fixes the camera height
    /// (then neither camera_height_m nor known_length may be given).
    std::optional<PixelPoint> ceiling_point;
  };
  std::optional<InteriorBox> interior_box;
  /// What the photo does not show but shadows the scene: a skyline above the frame, off-frame
  /// walls or tree lines, a canopy, and how structures cut by the frame are continued; the
  /// scene document's "blockers" (same JSON schema and rules, docs/scene.md). In world
  /// coordinates of the estimated pose (the camera above x = z = 0 at yaw 0, looking along +Z).
  /// estimate_scene copies it into the scene it estimates. nullopt: the scene's defaults.
  std::optional<Blockers> blockers;
};

/// The value of the document's "format" key.
inline constexpr const char* kAnnotationsFormatName = "libmr-annotations";
/// The newest document version this libmr reads and the one it writes.
inline constexpr int kAnnotationsFormatVersion = 1;

/// Checks what can be checked without the photo: every coordinate and number finite, heights,
/// lengths and distances > 0, not both camera_height_m and known_length, polygons with >= 3
/// points, horizon points and known-length points >= 1 px apart, both patches or neither,
/// lamp offsets >= 0, lamp colours >= 0 and not black, lamp-patch albedos in (0, 1], both lamps
/// and lamp_patches or neither; an interior box with >= 3 floor points, consecutive ones >= 1 px
/// apart, and not ceiling_height_m and ceiling_point together with camera_height_m or
/// known_length; blockers by validate_scene's rules (mr/scattering.h), the message then naming
/// the field both ways ("/blockers/skyline/samples/0/1: blockers.skyline.samples[0].height_m =
/// -5: must be in [0, 10000]").
/// Throws mr::Error(invalid_argument) "source: /json/pointer: problem", e.g.
///   "a.json: /planes/2/polygon: expected at least 3 points, found 2".
MR_API void validate_annotations(const Annotations& annotations,
                          const std::string& source_name = "<annotations>");

/// Parses and validates a document. Unknown and duplicate keys are errors; so is a missing or
/// wrong "format" / "version". Throws mr::Error(invalid_argument) naming the source and the JSON
/// pointer of the offending value ("a.json: /horizon/1/0: expected a number, found null").
MR_API Annotations annotations_from_json(const std::string& text,
                                  const std::string& source_name = "<annotations>");

/// Writes a document of kAnnotationsFormatVersion (pretty-printed, only the keys that are set;
/// doubles with enough digits to read back bit for bit). Validates first (invalid_argument).
MR_API std::string annotations_to_json(const Annotations& annotations);

/// Reads and parses a file. Throws mr::Error: io (cannot read), invalid_argument (content).
MR_API Annotations load_annotations(const std::filesystem::path& path);

/// Writes annotations_to_json atomically (temporary file + rename). Throws mr::Error:
/// invalid_argument (nothing written), io.
MR_API void save_annotations(const std::filesystem::path& path, const Annotations& annotations);

}  // namespace mr
