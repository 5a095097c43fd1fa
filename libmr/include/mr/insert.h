// mr::insert_objects: put 3D objects into a photo (mixed reality, issue 16; DESIGN.md section 1
// item 7): lit by the photo's estimated light, casting shadows onto the photo's reconstructed
// surfaces and receiving theirs, hidden by the photo's foreground, composited by differential
// rendering (Debevec 1998), and optionally fogged with the rest of the photo.
#pragma once

#include <memory>
#include <optional>
#include <span>
#include <string>

#include "mr/camera.h"
#include "mr/cancel.h"
#include "mr/export.h"
#include "mr/fog.h"
#include "mr/image.h"
#include "mr/material_model.h"
#include "mr/objects.h"
#include "mr/scene.h"

namespace mr {

/// One object to insert: its mesh (loaded, or a primitive), where it stands, and optionally a
/// material that replaces all of the mesh's.
struct MR_API InsertObject {
  ObjectMesh mesh;
  ObjectPlacement placement;
  std::optional<Material> material;
};

struct MR_API InsertOptions {
  /// Camera rays per pixel = samples_per_axis^2 (anti-aliased edges), 1..8.
  int samples_per_axis = 4;
  /// Shadow rays per pixel over the sun's disk (soft shadows), 1..64, and cosine-weighted sky
  /// rays per pixel (the sky's soft "ambient occlusion" shadows), 0..128.
  int sun_rays = 16;
  int sky_rays = 64;
  /// Photo pixels farther than this many bounding radii from every object trace no sky rays
  /// against the objects (an object hides at most (1 / this)^2 of their sky: 0.4 % at 16).
  double sky_influence_radii = 16;
  /// Count those radii in the objects' tight bounding radius (the farthest vertex from their
  /// box's centre) instead of the box's half-diagonal (up to sqrt(3) larger for round objects).
  bool sky_influence_tight = false;
  /// Relative tolerance of the depth test against the photo's distance map.
  double depth_tolerance = 2e-3;
  /// The photo's occluder mesh at one vertex row per mesh_step pixel rows (1 = full resolution;
  /// coarser builds faster, shadow edges move by up to one coarse pixel).
  int mesh_step = 1;
  /// After compositing, fog the result with the scene's medium (mr::fog with the objects' depth
  /// and their triangles among the shadow casters, so they cast shafts).
  bool fog = false;
  /// Every pixel draws the same sun, sky and sub-pixel sample directions (stratum centres), so
  /// neighbouring pixels agree and nothing shimmers between frames: a few samples give smooth,
  /// slightly banded penumbrae instead of salt-and-pepper speckle (the preview's choice). Off:
  /// each pixel's pattern is rotated by a hash of the pixel (what full quality converges with).
  bool fixed_pattern = false;
  int threads = 0;  ///< 0: all cores

  /// Interactive preview settings: 1 camera ray, 1 sun ray (the sun's centre: a hard shadow;
  /// the real sun's penumbra is below a preview pixel) and 8 sky rays per pixel in a fixed
  /// pattern, mesh_step 2, sky influence 4 tight radii (objects' ambient occlusion cut where it is
  /// below 6 %).
  static InsertOptions preview();
  /// The preview's refinement when the user stops (mr-studio's idle pass, InsertPreview):
  /// 2 x 2 camera rays (anti-aliased edges), 8 sun and 32 sky rays, still a fixed pattern.
  static InsertOptions preview_refined();
};

/// The layers of a photo with inserted objects, all the photo's size, scene-linear float.
struct MR_API InsertResult {
  Image composite;        ///< the photo with the objects (fogged when InsertOptions::fog)
  Image clear_composite;  ///< the composite before fog (= composite without fog)
  Image matte;            ///< 1 channel: the objects' coverage after occlusion, in [0, 1]
  Image shadow;           ///< R,G,B: the photo's shading with / without the objects (1: unchanged)
  Image difference;       ///< R,G,B: clear_composite - photo
  Image distance_m;  ///< 1 channel: the objects' distance where they are in front, else the photo's
  Image transmittance, inscatter;  ///< the fog's T and R (empty without fog)
  Lighting lighting;  ///< the light used, resolved (sky radiance and automatic strengths set)
  struct Timings {
    double mesh_s = 0;    ///< normals, occluder mesh, BVHs
    double render_s = 0;  ///< the differential render
    double fog_s = 0;
    double total_s = 0;
    std::size_t triangles = 0;  ///< inserted triangles
    std::size_t shadow_rays = 0, camera_rays = 0;
  } timings;
};

/// Inserts `objects` into `photo` (scene-linear RGB(A)) whose `distance_m` (1 channel, metres
/// along each pixel's ray, +inf = sky) `camera` sees from scene.pose, under scene.lighting
/// (a sky radiance or sun irradiance given as automatic is estimated from the photo as
/// mr::render_scattering does; there must be a sun or a sky). Deterministic.
/// Throws mr::Error: invalid_argument (bad options, a malformed mesh or placement, naming the
/// mesh's source), size_mismatch, cancelled.
MR_API InsertResult insert_objects(const Image& photo, const Image& distance_m,
                                   const Camera& camera, const FogScene& scene,
                                   std::span<const InsertObject> objects,
                                   const InsertOptions& options = {},
                                   const CancelToken* cancel = nullptr);

/// An interactive preview of objects in one photo (mr-studio's insertion tool, issue 16). The
/// constructor does once what does not depend on the objects: the light resolved (as
/// insert_objects does), the photo's normals, its occluder mesh (at options.mesh_step) and Embree
/// scene, and the bounds of its surface in 8 x 8-pixel screen tiles. Each render() then
/// builds the objects' scene only when the meshes changed (when only placements changed, as in
/// a drag, it moves the vertices and refits the BVH) and
/// re-renders only the tiles the objects, their shadows, their sky occlusion or their lamp
/// shadows can touch (the tile tests are conservative: the frame equals insert_objects' composite
/// with the same options), resetting to the photo the tiles the previous frame touched and this
/// one does not. Not thread-safe: one render at a time (mr-studio's worker holds it).
class MR_API InsertPreview {
 public:
  /// Throws as insert_objects does for bad inputs; mr::Error(cancelled).
  InsertPreview(const Image& photo, const Image& distance_m, const Camera& camera,
                const FogScene& scene, const InsertOptions& options = InsertOptions::preview(),
                const CancelToken* cancel = nullptr);
  ~InsertPreview();
  InsertPreview(InsertPreview&&) noexcept;
  InsertPreview& operator=(InsertPreview&&) noexcept;
  InsertPreview(const InsertPreview&) = delete;
  InsertPreview& operator=(const InsertPreview&) = delete;

  /// Renders a frame with `options`' sampling (samples_per_axis, sun_rays, sky_rays,
  /// sky_influence_radii, depth_tolerance, fixed_pattern, threads; mesh_step is the
  /// constructor's; options.fog must be false: fog the composite with mr::fog, giving it the
  /// result's distance_m). The result's composite, matte, shadow, difference and distance_m
  /// are the photo's size; clear_composite, transmittance and inscatter stay empty. The
  /// reference is valid until the next render() or the preview's destruction. Cancelled
  /// (mr::Error cancelled): the next frame is still right.
  const InsertResult& render(std::span<const InsertObject> objects,
                             const InsertOptions& options = InsertOptions::preview(),
                             const CancelToken* cancel = nullptr);

  /// Replaces the light (sun, sky, lamps; automatic strengths resolved against the photo as the
  /// constructor does); the photo's geometry is kept. The next frame renders with it.
  void set_lighting(const Lighting& lighting);

  struct FrameStats {
    std::size_t tiles_total = 0;
    std::size_t tiles_rendered = 0;  ///< tiles the objects may change (shaded this frame)
    std::size_t tiles_reset = 0;     ///< tiles the previous frame changed, reset to the photo
    bool objects_rebuilt = false;    ///< the objects' scene was built (else reused or refitted)
    /// Only placements changed: the objects' vertices were moved and their BVH refitted.
    bool objects_refit = false;
    double objects_s = 0, render_s = 0, total_s = 0;
  };
  const FrameStats& last_frame() const;
  /// The constructor's time: normals, occluder mesh and BVH, tile bounds.
  double prepare_seconds() const;
  /// The light used (sky radiance and automatic strengths resolved).
  const Lighting& lighting() const;
  const Camera& camera() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// The objects' triangles, placed, as blocker polygons (mr::Blockers::polygons) so that the fog
/// core's light paths see them (degenerate triangles dropped).
MR_API std::vector<Blockers::Polygon> object_shadow_polygons(std::span<const InsertObject> objects);

}  // namespace mr
