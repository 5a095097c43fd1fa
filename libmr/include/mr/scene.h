// mr::FogScene: everything the scattering core needs besides the photo and its depth:
// where the camera stands, the medium, the lights, and how carefully to render.
//
// World frame: metres, +Y up, the ground (for photos) at y = 0. With yaw = pitch = roll = 0 the
// camera looks along +Z, image x points along +X and image y along -Y (image rows go down).
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <optional>
#include <vector>

#include "mr/camera.h"
#include "mr/export.h"
#include "mr/objects.h"
#include "mr/vec3.h"

namespace mr {

/// Where the camera stands and how it is turned, in the world frame.
struct MR_API CameraPose {
  Vec3 position_m{0, 1.6, 0};
  double yaw_deg = 0;    ///< heading: positive turns the view to the right (toward +X)
  double pitch_deg = 0;  ///< positive tilts the view up
  double roll_deg = 0;   ///< positive rotates the camera clockwise about its view axis, as seen
                         ///< from behind (the horizon then tilts counter-clockwise in the image)

  /// The camera's unit axes in the world: forward, right (image +x), up (image -y).
  /// forward = (sin(yaw) cos(pitch), sin(pitch), cos(yaw) cos(pitch));
  /// right0 = (cos(yaw), 0, -sin(yaw)); up0 = cross(forward, right0);
  /// right = cos(roll) right0 - sin(roll) up0; up = sin(roll) right0 + cos(roll) up0.
  std::array<Vec3, 3> axes() const;
  /// Unit world direction through the centre of pixel (x, y):
  /// normalize(u right - v up + forward), u = (x + 0.5 - cx) / f, v = (y + 0.5 - cy) / f.
  Vec3 ray_direction(const Camera& camera, double x, double y) const;
};

/// A world direction from azimuth (degrees, 0 = +Z, 90 = +X) and elevation above the
/// horizon (degrees): (cos(el) sin(az), sin(el), cos(el) cos(az)).
MR_API Vec3 direction_from_azimuth_elevation(double azimuth_deg, double elevation_deg);

/// The participating medium (DESIGN.md section 3).
/// Extinction sigma_t(x) = sigma_t * rho(x), scattering sigma_s = albedo * sigma_t.
struct MR_API Medium {
  Rgb sigma_t_per_m{0.0261f, 0.0261f, 0.0261f};  ///< at density 1 (150 m visibility)
  Rgb albedo{1, 1, 1};                           ///< in [0, 1]
  double g = 0;  ///< Henyey-Greenstein asymmetry, in (-1, 1); > 0 scatters forward

  /// Exponential height fog: rho(x) = exp(-(x.y - base_height_m) / scale_height_m).
  /// Without it the density is 1 everywhere (inside the layer).
  struct HeightFog {
    double base_height_m = 0;
    double scale_height_m = 20;  ///< > 0
  };
  std::optional<HeightFog> height_fog;
  /// Density is 0 outside base <= y <= top (world heights). Defaults: unbounded.
  double layer_bottom_m = -std::numeric_limits<double>::infinity();
  double layer_top_m = std::numeric_limits<double>::infinity();

  /// Wisps: rho is multiplied by max(0, 1 + amplitude * fbm(x / scale_m)), fbm a sum of
  /// `octaves` octaves of gradient noise in [-1, 1], deterministic for a seed. The noise
  /// modulates the view ray only; light paths use the smooth density (see README).
  struct Noise {
    double amplitude = 0;  ///< in [0, 1]; 0 = off
    double scale_m = 10;   ///< size of the largest wisps
    int octaves = 4;       ///< 1..8
    std::uint32_t seed = 1;
  } noise;
};

/// Sunlight: parallel rays from `direction_to_sun` with `irradiance` (scene-linear units per
/// unit area, perpendicular to the rays) above the fog layer.
struct MR_API Sun {
  Vec3 direction_to_sun{0, 1, 0};  ///< normalised by the core
  Rgb irradiance{3, 3, 3};
  double angular_radius_deg = 0.27;  ///< > 0 gives soft shaft edges (penumbra)
  /// True: `irradiance` is replaced, per photo, by one relative to the photo's exposure
  /// (mr::exposure_relative_sun_irradiance in mr/fog.h, with the scene's sky radiance), when a
  /// photo is rendered (render_scattering needs the photo then). A scene document whose sun has
  /// no irradiance, or "auto", sets it. (Last, so that Sun{dir, irradiance, radius} still works.)
  bool irradiance_auto = false;
};

/// A point lamp, optionally a spot: radiant intensity I (per steradian), irradiance at x is
/// I / |p - x|^2, attenuated by the fog between p and x and blocked by the scene.
struct MR_API Lamp {
  Vec3 position_m;
  Rgb intensity_per_sr{100, 90, 70};
  /// Spot lamps: the cone's axis and half-angles. Full intensity within inner_angle_deg,
  /// smoothly falling to 0 at outer_angle_deg (at most 180). outer_angle_deg == 180: a point lamp.
  Vec3 spot_direction{0, -1, 0};
  double inner_angle_deg = 180;
  double outer_angle_deg = 180;
  /// True: `intensity_per_sr` gives only the colour (its chromaticity), and its strength is set
  /// per photo relative to the photo's exposure (photo::exposure_relative_lamp, photo/lamps.h:
  /// a white surface at the lamp's nearest surface is lit as bright as the photo's bright
  /// surfaces), when a photo is rendered (render_scattering needs the photo then). A scene
  /// document's lamp without intensity_per_sr, or "auto", sets it; `mr fog --lamp x,y,z` too.
  bool intensity_auto = false;
};

struct MR_API Lighting {
  std::optional<Sun> sun;
  /// Isotropic sky radiance L_sky lighting the fog (and standing in for its multiple
  /// scattering). nullopt: estimated from the photo (the Koschmieder airlight estimate).
  std::optional<Rgb> sky_radiance;
  std::vector<Lamp> lamps;
  /// Sky light by direction (mr/sky_light.h, issue 11): true: the fog's sky in-scatter along
  /// each view ray takes the photo's own sky around that direction (phase-weighted; the ground
  /// below the horizon) instead of the uniform L_sky, so sunsets, sky gradients and cloud
  /// colours survive haze; needs the photo. false: the uniform L_sky. nullopt ("auto" in a scene
  /// document): the front end decides (`mr fog`: by direction when it estimates the geometry,
  /// --depth auto); the library renders it as false.
  std::optional<bool> sky_by_direction;
};

enum class Quality { draft, normal, final };
/// Which implementation of the scattering core renders. automatic: Vulkan on a GPU when one is
/// usable, else the CPU (with a notice in ScatteringLayers::backend_notice); a software Vulkan
/// device (lavapipe) is never picked automatically, the CPU backend being faster there.
/// vulkan: the Vulkan backend on the best device, lavapipe included; an error if there is none.
enum class Backend { automatic, cpu, vulkan };
/// How the CPU backend answers its shadow rays (issue 17): Embree's BVH (the default), or the
/// multi-index kd-tree of seed 004 (lifted primitive indices, leaf ropes, per-ray prediction).
/// Both give the same answers (watertight triangle tests aside: see render/shadow_traversal/);
/// the table in README.md ("Shadow-ray traversal") says which is faster where.
enum class ShadowTraversal { embree, multi_index };

/// How the core renders. Quality presets set the march steps and the gradient-acceleration
/// grid; explicit fields override them (0 = from the preset).
struct MR_API RenderSettings {
  Quality quality = Quality::normal;
  Backend backend = Backend::automatic;
  int march_steps = 0;          ///< view-ray steps per pixel (lamps and shafts add more)
  int grid_step = 0;            ///< sparse-sample spacing in pixels, 1..3 (1: every pixel exact)
  bool gradient_acceleration = true;
  bool volumetric_shadows = true;  ///< trace the occluder mesh (false: lights never blocked)
  bool light_path_attenuation = true;  ///< fog dims light on its way in (false: for tests)
  double max_distance_m = 0;  ///< how far sky rays march; 0 = automatic (transmittance 1e-4
                              ///< or leaving the layer, at most 100 km)
  std::uint32_t seed = 1;     ///< jitter seed; equal seeds give identical images
  int threads = 0;            ///< 0: all cores
  ShadowTraversal shadow_traversal = ShadowTraversal::embree;  ///< CPU backend only
};

/// The intrinsics of the camera a scene was made for (what `mr estimate` found: EXIF, the
/// vanishing points or a default), so that a scene reused with another run keeps its focal
/// length. A focal length in pixels is tied to an image size, so the size is kept with it: for a
/// photo of another size with the same aspect ratio (a resized copy) the focal length and the
/// principal point scale with it (mr::camera_for_image in mr/scene_json.h).
struct MR_API SceneCamera {
  int width = 0, height = 0;  ///< the image size (pixels) focal_px and principal_point_px refer to
  double focal_px = 0;        ///< > 0
  /// In pixels of that image ((0, 0) = top-left corner of the top-left pixel); nullopt: the
  /// image's centre.
  std::optional<std::array<double, 2>> principal_point_px;
};

/// Geometry that shadows the scene but that the photo does not show (docs/scene.md,
/// "blockers"): the occluder mesh is what the photo shows, so a colonnade or a facade cut by the
/// top of the photo, a wall beside the frame or a canopy overhead would otherwise let full
/// sunlight into the fog they shade. All of it casts shadows only (it is never seen). Heights
/// are world y (the ground at 0), azimuths as for the sun (0 = +Z, 90 = +X).
struct MR_API Blockers {
  /// Structures cut by the frame's top and side edges, continued beyond the frame along their
  /// own plane: vertical ones straight up to a height estimated from the tops of vertical
  /// structures the photo shows at a similar distance, else to max_height_m; other surfaces
  /// cut by the top, and everything cut by a side edge except floors, by up to max_extent_m.
  /// Free-standing structures narrower than prism_max_width_m at the frame's top (pillars,
  /// trunks) become boxes as deep as they are wide (or as their visible side shows), from their
  /// visible foot up.
  struct Completion {
    bool enabled = true;
    double max_height_m = 30;      ///< > 0, world y
    double max_extent_m = 30;      ///< > 0, metres along the surface beyond the frame
    double prism_max_width_m = 3;  ///< >= 0; 0: no boxes
  } completion;
  /// A skyline above the frame: a vertical wall standing on the ground, distance_m from the
  /// camera (horizontally), whose top is at height_m at each azimuth, linear in between (the
  /// samples sorted by azimuth; the wall closes around when they span 360 degrees).
  struct SkylineSample {
    double azimuth_deg = 0;
    double height_m = 0;  ///< >= 0
  };
  struct Skyline {
    double distance_m = 50;  ///< > 0
    std::vector<SkylineSample> samples;  ///< at least 2
  };
  std::optional<Skyline> skyline;
  /// An off-frame wall or tree line: a planar convex polygon in the world (3 or more corners,
  /// in order around it).
  struct Polygon {
    std::vector<Vec3> corners_m;
  };
  std::vector<Polygon> polygons;
  /// A canopy overhead: a horizontal layer at height_m over a disk of radius_m around the
  /// camera, made of cells of cell_m x cell_m of which a fraction gap_fraction (chosen
  /// deterministically by the seed) are gaps that let the sun through.
  struct Canopy {
    double height_m = 8;        ///< > 0
    double gap_fraction = 0.3;  ///< in [0, 1]
    double radius_m = 30;       ///< > 0
    double cell_m = 1;          ///< > 0
    std::uint32_t seed = 1;
  };
  std::optional<Canopy> canopy;
};

/// A structure cut by the frame that the render continued beyond it (Blockers::Completion):
/// what was guessed and how much to trust it, so a front end can show it or ask the user.
struct MR_API CompletedBlocker {
  enum class Edge { top, left, right };
  Edge edge = Edge::top;
  int first_px = 0, last_px = 0;  ///< pixels along that edge: columns (top) or rows (sides)
  bool vertical = false;  ///< continued straight up (else along its own plane, by max_extent_m)
  bool prism = false;     ///< closed as a box (a free-standing pillar or trunk)
  double top_m = 0;       ///< world height it was continued to (vertical ones), else 0
  /// In [0, 1]: 0.7 when the height comes from the visible tops of structures at a similar
  /// distance, 0.3 when it is Completion::max_height_m, 0.4 for surfaces continued along their
  /// plane; a box's guessed depth takes 0.1 off.
  double confidence = 0;
};

/// A whole fog scene (the JSON scene document, docs/scene.md, holds the same).
struct MR_API FogScene {
  CameraPose pose;
  Medium medium;
  Lighting lighting;
  RenderSettings render;
  /// The camera the scene was estimated or rendered for; nullopt: none recorded (the photo's
  /// EXIF or a default then decides, as before).
  std::optional<SceneCamera> camera;
  /// Shadow casters the photo does not show (completion of structures cut by the frame on).
  Blockers blockers;
  /// 3D objects inserted into the photo (issue 16; mr/objects.h), in document order. Their
  /// relative mesh paths are relative to the scene document (mr::resolve_object_mesh).
  std::vector<SceneObject> objects;
};

}  // namespace mr
