// Single-photo estimation (DESIGN.md section 4, issue 4): from one photo and its annotations
// (mr/annotations.h), the camera pose, a metric distance map and the light, as a FogScene that
// mr::fog renders and mr::save_scene writes.
//
//   mr::Image photo = mr::read_image("street.jpg");
//   mr::Camera camera = mr::Camera::from_metadata(photo.width(), photo.height(), photo.metadata());
//   mr::SceneEstimate est = mr::estimate_scene(photo, camera, mr::load_annotations("street.json"));
//   mr::save_scene("street.scene.json", est.scene);       // est.geometry.distance_m: the depth
#pragma once

#include <array>
#include <cstddef>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "mr/annotations.h"
#include "mr/camera.h"
#include "mr/cancel.h"
#include "mr/export.h"
#include "mr/image.h"
#include "mr/scene.h"

namespace mr {

struct MR_API EstimateOptions {
  /// Camera height when the annotations give neither camera_height_m nor known_length.
  double default_camera_height_m = 1.6;
  /// With a photo: find the horizon (when not annotated) and the sky automatically.
  bool automatic = true;
  /// Pixels above the horizon that are neither sky nor annotated become a billboard facing the
  /// camera, standing on the ground where it is this many degrees below the horizon
  /// (forward distance h / tan(angle): 46 m for 1.6 m and 2 degrees). Far, so that fog errs
  /// towards too much on unknown structures rather than none.
  double billboard_depression_deg = 2.0;
  /// Structures standing on the ground (issue 4 item 2): a non-sky structure above the horizon
  /// is followed down to where it meets ground-coloured pixels (photo/sky_mask.h's ground
  /// model); in each column where that contact lies below the horizon, the structure is a
  /// billboard facing the camera at the ground's forward distance there (median over nearby
  /// columns of the structure, at most the far billboard's; its columns without a contact take
  /// the nearest contact's). A structure with contacts in fewer than 30 % of its columns, or
  /// a photo whose ground colour cannot be modelled, keeps the far billboard. false: the far
  /// billboard everywhere.
  bool ground_contact = true;
  /// A structure column counts as standing on the ground only where its part above the horizon
  /// is at least this fraction of its part below (a building 3 m tall seen from 1.6 m: about 0.9;
  /// the sea reaching up to a boat on the horizon, a person, a low wall: far less). Elsewhere
  /// its pixels below the horizon stay on the ground plane.
  double min_rise_ratio = 0.4;
  /// Depth that does no harm (issue 11 item 3): with the automatic sky mask, the estimated
  /// depth is refined against the photo (photo/geometry.h, refine_inverse_distance) so that it
  /// jumps only where the photo has an edge; the ground plane (more than 4 degrees below the
  /// horizon), the annotations and the sky are kept exactly (confidence 1), the far billboard
  /// (0.05), structures standing on the ground (0.3) and the ground near the horizon (rising
  /// from 0 at the horizon to 1 at 4 degrees below it) follow the photo, and the far billboard
  /// no longer cuts the ground behind it. The sky's soft matte blends into the depth (see
  /// GeometryEstimate::sky_alpha). false: the depth as before (binary sky, hard billboards),
  /// except for the matte's blend.
  bool refine_depth = true;
  /// With refine_depth: a surface that meets the sky where the photo shows no edge (a calm sea
  /// under a hazy sky, a hill fading into it) goes to the sky's distance at the boundary and
  /// returns to its own over the refinement's reach (photo/geometry.h, sky_proximity and
  /// sky_fold), so that the fog, opaque in the sky for haze, is continuous there. false: off.
  bool sky_fold = true;
  /// Under a guessed horizon (the level fall-back, or a line cue of confidence below 0.2): sky
  /// the guess cut off (a dark cloud deck reaching the guess "stands" on it; a pale sky under
  /// the deck is cut off from the top border) is sky when the sky mask run without the horizon
  /// finds it joined to the open sky, in at least 25 % of the columns reaching the guess where
  /// the mask's sky does not; the horizon's lowering then judges the sky below the guess in the
  /// columns that sky reaches the guess in (issue 11, valendas; libmr/src/estimate.cpp,
  /// join_sky_cut_by_a_guess). false: the mask clipped at the guess as it is.
  bool sky_cut_by_a_guess = true;
  /// With refine_depth: open water (or flat ground) meeting the sky at the horizon, where the
  /// photo's water mirrors the sky above it, is no nearer than its ground plane's distance over
  /// the ground's confidence (that is, farther than the plane near the horizon), so its fog
  /// ramps into the sky's over tens of pixels instead of stepping at the horizon; only under a
  /// horizon annotated or found with confidence >= 0.2 that open sky meets (issue 11, helper
  /// sea11; libmr/src/estimate.cpp). false: the refinement's distance as it is.
  bool sea_horizon = true;
  /// With sea_horizon: a thin band of far shore, land or skyline resting on that horizon (what
  /// stands between the horizon and the open sky above it rises less than the far billboard's
  /// depression, and nothing in it stands on a contact nearer than the far billboard) is as far
  /// as the horizon, no nearer than the sea's geometric horizon from the camera's height
  /// (sqrt(2 R h): 4.5 km from 1.6 m), and the water in front of it that mirrors it or the sky
  /// gets the sea_horizon bound like open water, so haze veils the band as it veils the sky
  /// behind it, and the water's fog ramps up to it (issue 11, helpers shore14, shore15). Only
  /// where the water below mirrors the band: the photo under the waterline correlates with the
  /// band and the sky over it flipped (>= 0.8, colour and outline, no more contrast than the
  /// original: a dark field under a ridge does not), the waterline snapped within two lines'
  /// widths of the horizon to the row where the mirror is best, the reflection as far down as
  /// the band's top mirrored about it (gallery/results/shore15_tune.md). false: the band keeps
  /// the refinement's distance (the far billboard's, 46 m from 1.6 m) and bounds no water.
  bool far_shore = true;
  /// Issue 11: when a weak automatic horizon is lowered because the sky goes on below it, calm
  /// water mirroring the sky goes on as smoothly: the horizon is lowered only to the row about
  /// which the photo below mirrors the photo above (the median over the columns of their
  /// correlation at least 0.8; the waterline), not out of the frame with the lake taken for sky
  /// (GeometryEstimate::lowered_to_water). false: lowered as far as the sky-like pixels go.
  bool water_mirror = true;
  /// Issue 11: a frame whose weak automatic horizon was lowered under its "sky", the sky (with
  /// a cloud bank) covering at least 90 % of it, but which holds two or more lamps (compact
  /// clipped blobs of at least 1 % of the frame; photo/sky_mask.h, count_lamps_in_sky) is a
  /// ceiling seen from below: it has no sky, and is a bounded scene
  /// (GeometryEstimate::lamps_not_sky). false: all sky, as the mask says.
  bool lamps_not_sky = true;
  /// Issue 11: a pale, smooth surface that a horizon measured from the photo's lines (not the
  /// level fall-back, not a weak cue) cuts across, going on below it with no edge, is a wall
  /// (an office's white wall), not an overcast sky: where the sky reaches the horizon in at
  /// least a quarter of the columns and goes on below it by at least 15 % of the height, filling
  /// 75 % of that band, and the photo below does not mirror the photo above (calm water under
  /// an overcast sky, with water_mirror), the sky that reaches the horizon is taken out
  /// (GeometryEstimate::wall_not_sky_pixels). false: sky, as the mask says.
  bool wall_not_sky = true;
  /// Issue 11: a sky mask covering under 5 % of the frame (a white curtain in a window, a
  /// backdrop's clipped patch between near things) keeps only components with a clear sky's
  /// evidence: blue (hue 185-245 degrees, saturation >= 0.2) and reaching the top border along
  /// 15 % of the width, or running along half the top border whatever their colour. Without any
  /// left the photo is a bounded scene (bounded_scene_depth_m), not an outdoor one whose far
  /// billboard stands 46 m away (GeometryEstimate::little_sky_dropped_pixels). Not with an
  /// annotated horizon (an outdoor scene by the user's word). false: sky, as the mask says.
  bool little_sky_evidence = true;
  /// The sky matte's spill onto a surface beyond a sharp edge trimmed: on the surface side of
  /// the matte (alpha < 0.5), where sky and surface differ plainly in brightness, alpha is at
  /// most the pixel's unmixed share of the sky's colour (issue 11, helper haze11b; photo/sky_matte.h,
  /// trim_matte_spill), so no band of the sky's fog lies on a surface the photo shows plainly.
  /// false: the matte as the sky mask made it.
  bool trim_matte_spill = true;
  /// Trees and foliage (issue 11 item 3, photo/vegetation.h), under an open blue sky only:
  /// sky-coloured pixels above the horizon ringed by green foliage (sky under a canopy, between
  /// trunks, through leaves) are sky, so the occluder mesh has holes there and the sun passes; a
  /// structure that is mostly green foliage stands at the median ground distance of its trunks'
  /// feet (any column meeting the ground counts), canopy included, instead of needing contacts
  /// in 30 % of its columns. false: off (the estimate as before).
  bool vegetation = true;
  /// Issue 11: people near the camera, found by their faces (a frontal-face detector; Debian's
  /// opencv-data), stand at their faces' distance (focal length x 0.16 m / the face box's width,
  /// a plane facing the camera) over the head and body segmented from each face down to the
  /// frame's bottom, kept out of the depth's refinement. Annotated planes and hints win over
  /// them; a scene with less than 5 % of open sky keeps its depth, and a black-and-white photo
  /// has no people. false: off (also when the face cascade is not installed).
  bool people = true;
  /// Issue 11: people standing on the ground, found by their figures (a HOG people detector)
  /// where the ground's colours were modelled, stand at the distance of the ground under their
  /// feet (a plane facing the camera) instead of the ground plane's rising distance up their
  /// bodies; kept only where the figure is 0.9-2.1 m tall at that distance. Same conditions as
  /// `people`. false: off.
  bool standing_people = true;
  /// Issue 11: a frame around the picture (a scanned print's uneven dark edge, a light strip
  /// down a side: at most 3 % of the frame, near neutral, ending in a step to the picture) is
  /// not the scene: the sky is found inside it, and it takes the fog of the picture's edge
  /// beside it (GeometryEstimate::frame_border_pixels). false: the whole frame is the picture.
  bool frame_border = true;
  /// Issue 11: backlit land (a sunset or dusk silhouette: the frame's bottom the darkest part
  /// along 90 % of its width, at least 4x darker than what lies above its skyline) under a
  /// weak automatic horizon: the horizon goes to the land's median skyline, and what is above
  /// it and not as dark as the land (clouds, the glow) is sky (GeometryEstimate::backlit_land).
  /// false: off.
  bool backlit_land = true;
  /// Issue 11 (a sea, a salt flat, a snowfield): under a weak automatic horizon (the level
  /// fall-back, or a cue of confidence below 0.2) that the sky ends above, where the sky's lowest
  /// row lies along one straight line (slope at most 5 degrees; within 2 px in at least half of
  /// the columns and a tenth in each outer third, RMS at most 1 px) the horizon is raised to it
  /// (GeometryEstimate::horizon_raised_px): a sea line is the horizon. false: off.
  bool level_sky_line = true;
  /// Issue 11 item 3: a photo in which the sky mask finds no sky (an interior, a close-up, a
  /// wall, a field seen from above) shows no horizon and no ground running to it, so nothing in
  /// it is known to be far: when the camera height is not annotated (nor derived from a known
  /// length or an interior box) and no distance hint fixes the scale, the whole geometry is
  /// scaled (through the camera height) so that its far billboard stands this many metres ahead
  /// (from 46 m at the defaults). The depth's shape is unchanged, only its metres.
  double bounded_scene_depth_m = 8.0;
  /// With refine_depth, in such a bounded scene (and in a close-up left without sky) with no
  /// annotated plane or distance hint: the depth is the ground plane and the far billboard
  /// joined smoothly over `bounded_soft_rows` of the frame's height (photo/geometry.h,
  /// bounded_inverse_distance), not refined against the photo. Its horizon is a guess and no
  /// pixel's distance is known, and the refinement spread the guessed ground's near distances
  /// up through whatever the photo bounds by edges (a clip hanging in a plant, a cup's rim)
  /// into the far billboard: in dense fog clear cut-outs in the fogged frame, and a band along
  /// the horizon where the two met (issue 11 item 3, helper bounded13). false: refined.
  bool smooth_bounded_depth = true;
  double bounded_soft_rows = 0.1;
  /// A close-up (issue 11 item 3): where at least `closeup_min_defocused` of the frame's blocks
  /// (sky left out) are strongly blurred and at least `closeup_min_sharp` are sharp
  /// (photo/geometry.h, estimate_defocus: a shallow depth of field, which means a subject
  /// centimetres to a few metres away) and the sky mask covers at most
  /// `closeup_max_sky_fraction` of the frame (a subject filling it), with the same conditions as
  /// above, the geometry is scaled so that its far billboard stands `closeup_scene_depth_m`
  /// ahead. EXIF rarely survives in shared photos and gives no subject distance in most, so
  /// the photo's own focus is the cue.
  double closeup_scene_depth_m = 3.0;
  double closeup_min_defocused = 0.12, closeup_min_sharp = 0.1, closeup_max_sky_fraction = 0.5;
  /// ... or a small sharp subject (an insect, a flower's stamen) in a frame mostly strongly
  /// blurred: at least `closeup_small_subject_defocused` of the blocks blurred and at least
  /// `closeup_small_subject_sharp` sharp (gallery ladybird: 64 % and 4 %; a photo blurred all
  /// over, by shake or a missed focus, has no sharp block, and no landscape of the tuning half
  /// is even 30 % blurred).
  double closeup_small_subject_defocused = 0.4, closeup_small_subject_sharp = 0.02;
  /// Optional, caller-owned (mr/cancel.h): requested, the estimate stops at its next step with
  /// mr::Error(cancelled); its progress callback hears each step as it starts, in order
  /// "horizon", "sky mask", "depth", "refine" (and "light" for estimate_scene), with done = the
  /// steps finished and total = the steps planned (4, or 5), then the last step at done = total.
  /// Steps that do not apply (no photo, an interior box) pass at once.
  const CancelToken* cancel = nullptr;
};

/// Where a value came from.
enum class EstimateSource {
  annotations,   ///< given by the user
  known_length,  ///< camera height from the known length on the ground
  fallback,      ///< a conservative default (level camera; default camera height)
  // The horizon found automatically from the photo's line segments (photo/horizon.h):
  horizontal_vps,            ///< through two horizontal vanishing points
  horizontal_vp_and_zenith,  ///< through one, perpendicular to the vertical vanishing point
  zenith,                    ///< from the vertical vanishing point alone (and the focal length)
  horizontal_vp_level,       ///< through one horizontal vanishing point, roll assumed 0
  interior_box,              ///< camera height from the interior box's ceiling height and point
};
MR_API const char* to_string(EstimateSource source) noexcept;

struct MR_API GeometryEstimate {
  /// Position (0, h, 0) with h the camera height; yaw 0 (the photo's own heading); pitch and
  /// roll from the horizon.
  CameraPose pose;
  /// The horizon where it crosses the first and the last pixel column (pixel-centre coordinates).
  std::array<PixelPoint, 2> horizon{};
  EstimateSource horizon_source = EstimateSource::fallback;
  EstimateSource height_source = EstimateSource::fallback;
  /// How far to trust the geometry, in [0, 1]: 1 for an annotated horizon, 0.1 for the level
  /// fall-back (a guess: right for photos taken level, several percent off per degree of tilt),
  /// in between for an automatic horizon (at most 0.9; photo/horizon.h says how it is scored).
  double confidence = 0;
  /// Whether the sky is the automatic sky mask (else: everything above the horizon that no
  /// annotation covers).
  bool sky_from_mask = false;
  /// One channel "Z": metres along each pixel's ray, +inf for the sky. What mr::fog takes.
  Image distance_m;
  /// Pixels of the map that are sky, ground, on a vertical plane, inside a distance hint.
  std::size_t sky_pixels = 0, ground_pixels = 0, plane_pixels = 0, hint_pixels = 0;
  /// Pixels on the far billboard (EstimateOptions::billboard_depression_deg).
  std::size_t billboard_pixels = 0;
  /// Pixels on structures standing where they meet the ground (EstimateOptions::ground_contact).
  std::size_t contact_pixels = 0;
  /// Pixels on people found by their faces or figures (EstimateOptions::people,
  /// standing_people).
  std::size_t people_pixels = 0;
  /// People found standing on the ground by their figures (EstimateOptions::standing_people).
  std::size_t standing_people = 0;
  /// Pixels of a frame around the picture (a scanned print's border; issue 11), not the scene:
  /// each takes the distance, sky matte and confidence of the picture's nearest edge pixel (also
  /// included in the counts above).
  std::size_t frame_border_pixels = 0;
  /// Why the scene's metres differ from the default camera height's, for a person to read
  /// (EstimateOptions::bounded_scene_depth_m); empty when they do not.
  std::string scale_cue;
  /// The frame's blocks (sky left out) with strongly blurred / sharp edges (the close-up cue);
  /// 0 when not measured (an annotated or derived camera height, a distance hint, no photo).
  double defocused_fraction = 0, sharp_fraction = 0;
  /// With the automatic sky mask (issue 11 items 3 and 4), one channel each at the photo's size
  /// (empty otherwise). sky_alpha: the soft sky matte in [0, 1] (1 sky; fractional only along
  /// the sky's edge, as soft as the photo's edge there; 0 at and below the horizon); a pixel is
  /// sky (distance +inf) where alpha >= 0.5; a pixel with 0 < alpha < 0.5 lies on its surface's
  /// inverse distance scaled by (1 - 2 alpha), so its fog runs continuously from the surface's
  /// to the sky's as alpha rises; given to mr::fog (mr/scattering.h, its sky_alpha argument; mr
  /// fog --depth auto does), every fractional pixel's fog becomes the matte's mix of the
  /// surface's and the sky's. Along edges where sky and surface differ in colour the matte is
  /// the photo's own mix of the two colours (photo/sky_mask.h). depth_confidence: how far each
  /// pixel's distance is trusted, in [0, 1] (1: sky, annotated planes, hints and rooms, the
  /// ground plane from 4 degrees below the horizon, 0 at the horizon and linear in between; 0.3:
  /// structures standing on the ground; 0.05: the far billboard; a blurred sky edge scales it
  /// by (1 - 2 alpha)); the refinement keeps a pixel's own value with weight
  /// smoothstep(0.5, 1, confidence) and takes the photo-guided smooth value otherwise, so where
  /// the depth is uncertain the fog varies smoothly instead of jumping.
  Image sky_alpha, depth_confidence;
  /// Sky pixels found as sky seen through foliage (enclosed gaps; photo/sky_mask.h).
  std::size_t sky_gap_pixels = 0;
  /// With EstimateOptions::vegetation: foliage pixels (photo/vegetation.h), the sky seen through
  /// them that the sky mask had left out (counted in sky_pixels too), and the pixels of
  /// structures taken as trees (standing where their trunks meet the ground).
  std::size_t vegetation_pixels = 0, vegetation_gap_pixels = 0, tree_pixels = 0;
  /// With an interior_box annotation: pixels on the room's floor, walls or ceiling; the
  /// ceiling height (metres above the floor; unset when neither given nor marked); and the
  /// room's edges in the image (floor lines, wall corners up to the ceiling or twice the camera
  /// height, ceiling lines; pixel-centre coordinates, clipped in front of the camera) for
  /// render_estimate_overlay.
  std::size_t room_pixels = 0;
  std::optional<double> room_ceiling_height_m;
  std::vector<std::array<PixelPoint, 2>> room_edges;
  /// Issue 11: pixels by which a weak automatic horizon (the level fall-back, or a cue of
  /// confidence below 0.2) was lowered because the sky continued below it (0: not moved).
  double horizon_lowered_px = 0;
  /// Issue 11: pixels by which a weak automatic horizon was raised to the sky's level line
  /// (EstimateOptions::level_sky_line; 0: not moved).
  double horizon_raised_px = 0;
  /// Issue 11: the horizon was lowered to a backlit land's skyline (EstimateOptions::backlit_land).
  bool backlit_land = false;
  /// Issue 11: the horizon was lowered only to calm water's mirror line
  /// (EstimateOptions::water_mirror).
  bool lowered_to_water = false;
  /// Issue 11: the all-sky frame held lamps and was taken for a ceiling, without sky
  /// (EstimateOptions::lamps_not_sky).
  bool lamps_not_sky = false;
  /// Issue 11: pixels of "sky" taken out as a wall that goes on below the horizon
  /// (EstimateOptions::wall_not_sky; 0: none).
  std::size_t wall_not_sky_pixels = 0;
  /// Issue 11: pixels of a little "sky" without a clear sky's evidence taken out
  /// (EstimateOptions::little_sky_evidence; 0: none).
  std::size_t little_sky_dropped_pixels = 0;
  /// Issue 11: the roll (degrees) of the horizon the photo's lines gave, when it was rejected as
  /// implausible for a photo (beyond 15 degrees: the lines were not verticals or level ones) and
  /// the level fall-back taken instead; NaN otherwise.
  double horizon_rejected_roll_deg = std::numeric_limits<double>::quiet_NaN();
};

/// The camera pose whose horizon passes through the two points (pixel-centre coordinates), at
/// `camera_height_m` above the ground. Exact (no fitting). Throws mr::Error(invalid_argument)
/// naming "/horizon" for points that are not finite, less than 1 px apart, more than one image
/// size outside the image, or on a line more than 45 degrees from level.
MR_API CameraPose pose_from_horizon(const Camera& camera, const std::array<PixelPoint, 2>& horizon,
                             double camera_height_m);

/// The geometry of the annotated photo: pose from the horizon (else a level camera: horizon
/// through the principal point, low confidence) and camera height (else from known_length,
/// else from the interior box's ceiling height and ceiling point, else
/// options.default_camera_height_m); distance map from the ground plane (or the interior
/// box's room), the vertical planes and the distance hints (docs/annotations.md says which
/// covers which).
/// Throws mr::Error(invalid_argument) "/json/pointer: problem" for annotations that do not
/// fit this camera (a plane or known length on or above the horizon, ...) or are invalid.
MR_API GeometryEstimate estimate_geometry(const Camera& camera, const Annotations& annotations,
                                   const EstimateOptions& options = {});

/// The same with the photo (scene-linear, the camera's size; size_mismatch otherwise) and, when
/// options.automatic: without an annotated horizon, the horizon from the photo's vanishing points
/// (horizon_source says which cue; the level fall-back when none is usable); and the sky from
/// the automatic sky mask: above the horizon, sky-coloured, smooth, connected to the top border.
/// The mask also carves the sky out of plane polygons; pixels above the horizon that are
/// neither sky nor annotated are structures standing where they meet the ground
/// (EstimateOptions::ground_contact; docs/annotations.md gives the rules), else on the far
/// billboard (billboard_depression_deg), and so are ground pixels beneath them that would lie
/// behind them. With an interior_box the room covers every pixel: no sky mask, no billboards.
MR_API GeometryEstimate estimate_geometry(const Image& photo, const Camera& camera,
                                   const Annotations& annotations,
                                   const EstimateOptions& options = {});

/// The sun as fitted to the annotations' shadow pairs.
struct MR_API SunEstimate {
  Vec3 direction_to_sun;
  double azimuth_deg = 0, elevation_deg = 0;
  double rms_residual_deg = 0;    ///< angular residual of the pairs (RMS)
  double median_residual_px = 0;  ///< reprojection residual of the marks (median over pairs)
};

struct MR_API SceneEstimate {
  GeometryEstimate geometry;
  std::optional<SunEstimate> sun;  ///< with shadow pairs
  /// The scene for mr::fog: geometry.pose; the sun when fitted (its irradiance from the sun/sky
  /// ratio of the marked patches, with the sky radiance from the photo, when both are marked);
  /// without a fitted sun (overcast: sky light only) and with an automatic sky mask of at least
  /// 64 pixels and 1 % of the image, lighting.sky_radiance = the per-channel median of the sky
  /// pixels (else left unset: mr fog estimates it with the dark channel prior);
  /// with lamps and lamp_patches annotated, lighting.lamps: one per marked lamp, lifted to 3D
  /// with the distance map, its intensity fitted to the patches' shading (photo/lamps.h);
  /// scene.camera: the camera estimated with; everything else at FogScene's defaults.
  FogScene scene;
  /// One line per estimate made, for a person to read ("horizon: annotated, pitch -2.1 deg").
  std::vector<std::string> notes;
};

/// Everything estimate_geometry does, plus the light: the sun direction fitted to the shadow
/// pairs (Ceres; throws mr::Error(invalid_argument) naming the pair for bad or contradictory
/// pairs) and, with sunlit and shadowed patches, the sun/sky ratio; with lamps and lamp patches,
/// the lamps (throws mr::Error(invalid_argument) "/lamps, /lamp_patches: lamp <i>: ..." for a
/// lamp outside the image, in the sky or behind the camera, or contradictory shading). `photo` is
/// scene-linear RGB of the camera's size (size_mismatch otherwise).
MR_API SceneEstimate estimate_scene(const Image& photo, const Camera& camera,
                             const Annotations& annotations, const EstimateOptions& options = {});

/// The fog layer's top (metres above the ground, y = 0) for automatic fog when the scene gives
/// none (issue 11 item 4): real fog and haze lie in a layer, and the sky is seen through it, not
/// replaced by it. Half the medium's visibility (3.912 / mean sigma_t), within [30 m, 2 km]:
/// dense ground fog (visibility 40 m) 30 m, fog at 150 m visibility 75 m, haze at 3 km 1.5 km
/// (the boundary layer). `mr fog --depth auto` uses it (--layer-top auto, the default) when the
/// photo's geometry is estimated and neither --layer, --height-fog nor the scene file gives the
/// fog a top. Throws mr::Error(invalid_argument) for a medium without positive extinction.
MR_API double default_layer_top_m(const Medium& medium);

/// The camera of a photo for estimation (issue 4 item 1), principal point at the centre.
struct MR_API PhotoCamera {
  Camera camera;
  /// Where the focal length came from: "exif" (35 mm equivalent focal length),
  /// "vanishing points" (two or three orthogonal ones, f = sqrt(-(v1 - c) . (v2 - c))), or
  /// "default" (fallback_fov_deg across).
  std::string source;
  /// For "vanishing points": in (0, 0.9]; 0.9 x strength for a consistent orthogonal triple,
  /// 0.5 x strength for a single pair (orthogonality assumed); 1 for "exif", 0 for "default".
  double confidence = 0;
};
/// EXIF's focal length when the photo has one (as Camera::from_metadata); else the focal length
/// from the photo's orthogonal vanishing points when confident (>= 0.3) and the horizontal
/// field of view it implies is within [20, 120] degrees; else `fallback_fov_deg` across.
/// Throws mr::Error(invalid_argument) for an empty photo or a fallback outside (0, 180).
MR_API PhotoCamera camera_for_photo(const Image& photo, double fallback_fov_deg = 60.0);

/// A picture for a person to check the estimate with: the photo (scene-linear, RGB) with the
/// depth colour-mapped over it (log distance, near = red to far = blue, half blended), the sky
/// washed out towards white, the horizon as a red line, the plane polygons in yellow, the distance
/// hints in cyan, the shadow pairs in magenta and the patches in green / dark green; an arrow
/// toward the sun's azimuth at the top when the sun was fitted; lamps as orange circles, their
/// patches as orange polygons; the interior box's edges in white with its floor points as white
/// circles. Scene-linear RGB, the photo's size.
MR_API Image render_estimate_overlay(const Image& photo, const SceneEstimate& estimate,
                              const Annotations& annotations);

}  // namespace mr
