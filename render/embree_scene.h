// Private to libmr: the occluder mesh in an Embree 3 scene, for shadow (occlusion) rays on the
// CPU (DESIGN.md section 3, "Occluder geometry").
#pragma once

#include <embree3/rtcore.h>

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <utility>
#include <vector>

#include "render/occluder_mesh.h"
#include "render/shadow_query.h"

namespace mr::render {

/// Eight rays for OccluderScene::occluded8, structure-of-arrays like Embree's RTCRay8 (so filling
/// it is cheap and vectorises). Directions need not be unit length; t_near / t_far are in units
/// of the direction's length, 0 <= t_near <= t_far. Lanes with valid[k] == 0 are ignored.
struct alignas(32) RayPacket8 {
  float origin_x[8], origin_y[8], origin_z[8];
  float direction_x[8], direction_y[8], direction_z[8];
  float t_near[8], t_far[8];
  int valid[8];  ///< -1 (or any non-zero value) = trace this lane, 0 = skip it
};

/// Embree's BVH builders: low = Morton codes (fastest build), medium = binned SAH (Embree's
/// default), high = SAH with spatial splits.
enum class BuildQuality { low, medium, high };

struct OccluderSceneOptions {
  /// Medium by default. Measured (Embree 3.13.5, 2 threads of an idle Xeon, 1920x1080 ground +
  /// pillars to the horizon, 3.37 M triangles): low builds in 0.32 s but traces sun shadow rays
  /// at 2.5 Mrays/s; medium builds in 0.83 s and traces 18.6 (rtcOccluded1) / 27 (8-wide)
  /// Mrays/s; high gains nothing over medium. Low's Morton codes are quantised over the scene's
  /// bounds, and a ground plane reaching the horizon stretches those to kilometres, lumping all
  /// nearby geometry together; even with depth capped at 200 m medium traced 1.5x faster. A
  /// render traces 10-100x more rays than there are triangles, so the build time is the cheap end.
  BuildQuality build_quality = BuildQuality::medium;
  /// Embree's robust mode: avoids optimisations that let a ray slip through the shared edge of
  /// two triangles. Off by default (a shadow ray that leaks through an edge changes one sample of
  /// a smooth integral), though it measured no slower with the medium build.
  bool robust = false;
  /// Embree's compact BVH for the surface (RTC_SCENE_FLAG_COMPACT: leaves hold vertex indices,
  /// about half the BVH memory, vertices fetched per test) instead of leaves holding their
  /// quads' vertices. Off by default: the indexed leaves were cheaper to build only while page
  /// faults dominated the build (render/huge_pages.h), and every leaf a ray visits pays for the
  /// gathers. Where the estimated depth is jagged (gallery/tune/dragonfly: 10-15 % of neighbour
  /// pairs over 1 % apart, so the surface is a fur of slivers along the view rays), a sun shadow
  /// ray crosses ~70 quad boxes before its hit (leuven's: ~14), and the sun bank render took
  /// 49 s CPU compact against 34 s without (same rays, same answers; README, issue 12).
  bool compact = false;
  /// Issue 12 item 4: the surface's regular stretches as Embree grids (RTC_GEOMETRY_TYPE_GRID,
  /// see surface_grid_runs) and only the rest as quads, when the mesh carries its pixel layout
  /// (TriangleMesh::layout). The same triangles (same vertices, same diagonal: R, T and S came
  /// out bit-identical); Embree builds its BVH over 2 x 2-pixel subgrids, a quarter of the
  /// quads' primitives, reading their vertices from one shared corner buffer. Off by default:
  /// on gallery-like estimated depth (BM_Stages 1080p normal, leuven) 29 % of the surface
  /// pixels are fanned and more sit at split corners, so only 1.09 M of 1.59 M pixels became
  /// grids; the BVH built 13 % faster (326 -> 285 ms nearly idle), but every shadow ray then
  /// traverses two BVHs (grids and quads) and the grid leaves gather their vertices: the
  /// render's CPU rose 8 % idle (1645 -> 1785 ms), 27 % at load 4 (medians of four pairs; the
  /// fresh wall even, a reused BVH's render slower; README, issue 12).
  bool surface_grids = false;
  /// Issue 12 item 4: the camera and pose the mesh was made for, to trace its surface in the
  /// image over a depth pyramid (render/shadow_traversal/depth_image_surface.h) instead of in
  /// an Embree BVH, where the mesh carries its pixel layout (MeshOptions::pixel_layout) and
  /// its surface triangles come first; the triangles after them (extrusions, blockers) stay in
  /// Embree. The same answers (both watertight); no BVH to build over the surface.
  struct DepthImageView {
    Camera camera;
    CameraPose pose;
  };
  std::optional<DepthImageView> depth_image;
};

/// Issue 12 item 4: one RTCGrid of the surface: pixels x_begin .. x_end - 1 of rows 2 * band
/// and 2 * band + 1, every one of them grid-eligible (SurfacePixelLayout), maximal along x.
struct SurfaceGridRun {
  int band = 0, x_begin = 0, x_end = 0;
  bool operator==(const SurfaceGridRun& o) const {
    return band == o.band && x_begin == o.x_begin && x_end == o.x_end;
  }
};
/// Whether OccluderScene gives pixel (x, y) to Embree as part of a grid: it and the other pixel
/// of its band's column (row y ^ 1) are both grid-eligible.
bool surface_grid_covers(const SurfacePixelLayout& layout, int x, int y);
/// The grids OccluderScene makes of a layout: the runs of covered pixels, band by band, left to
/// right. (Bands of two rows: an Embree subgrid is 2 x 2 cells, so a two-row grid fills its
/// subgrids; taller rectangles would cover fewer pixels around holes for no fewer subgrids.)
std::vector<SurfaceGridRun> surface_grid_runs(const SurfacePixelLayout& layout);

/// The occluder mesh in an Embree device + scene, ready for ray queries (RAII: released on
/// destruction; movable, not copyable). All query methods are const and safe to call from many
/// threads at once (Embree queries are). Coordinates are world metres (mr/scene.h). A moved-from
/// scene may only be destroyed or assigned to.
class DepthImageSurface;  // render/shadow_traversal/depth_image_surface.h

class OccluderScene {
 public:
  /// Builds the scene (see OccluderSceneOptions for the build quality). Takes the mesh by value
  /// and keeps it, sharing its buffers with Embree (no copy when the caller moves it in). An
  /// empty mesh gives a scene that occludes nothing. Uses TBB's worker threads (so
  /// tbb::global_control limits it). Throws mr::Error(invalid_argument) for a malformed mesh
  /// (indices not a multiple of 3 or out of range, non-finite positions) and mr::Error(internal)
  /// when Embree reports an error (the message is Embree's).
  explicit OccluderScene(TriangleMesh mesh, const OccluderSceneOptions& options = {});
  ~OccluderScene();
  OccluderScene(OccluderScene&& other) noexcept;
  OccluderScene& operator=(OccluderScene&& other) noexcept;
  OccluderScene(const OccluderScene&) = delete;
  OccluderScene& operator=(const OccluderScene&) = delete;

  /// Whether any triangle lies on the ray origin + t * direction for t_near <= t <= t_far
  /// (rtcOccluded1). `direction` need not be unit length; t is in units of its length.
  bool occluded(const std::array<float, 3>& origin, const std::array<float, 3>& direction,
                float t_near, float t_far) const;
  /// occluded() for up to eight rays at once (rtcOccluded8 where the CPU runs Embree's native
  /// 8-wide packets, else one ray at a time): occluded_out[k] is set for every lane; invalid
  /// lanes get false.
  void occluded8(const RayPacket8& rays, bool occluded_out[8]) const;
  /// Distance t (in units of |direction|) to the nearest triangle on the ray within
  /// [t_near, t_far], or +infinity if there is none (rtcIntersect1; the surface's from the
  /// image's walk where the scene has one, see OccluderSceneOptions::depth_image). For tests, and
  /// to check whether a point (e.g. a lamp) is enclosed by geometry.
  float intersect_distance(const std::array<float, 3>& origin,
                           const std::array<float, 3>& direction, float t_near, float t_far) const;

  std::size_t triangle_count() const { return mesh_.triangle_count(); }
  /// The mesh the scene traces (positions carry one float of padding at the end for Embree).
  const TriangleMesh& mesh() const { return mesh_; }
  /// How many surface pixels Embree holds as grids (OccluderSceneOptions::surface_grids), and
  /// how many surface quads it holds as quads (the other pixels' and the fanned pixels' pairs).
  std::size_t grid_pixel_count() const;
  std::size_t surface_quad_count() const;
  /// Issue 12 item 4: where the surface is traced in the image (OccluderSceneOptions::
  /// depth_image), builds Embree's BVH over it as well, and queries use that from then on (the
  /// same answers). The occluder cache does not call it: it chooses once per geometry, by the
  /// surface's slivers (render/occluder_cache.cpp), and keeps the choice for every render. For
  /// a caller that learns later that the BVH pays. Safe while other threads query the scene
  /// (they switch once it is built); a no-op when it has nothing to build.
  void build_surface_bvh() const;
  /// Whether the surface is traced in the image (no BVH over it built yet).
  bool traces_surface_in_image() const { return tracing_image(); }
  /// Whether occluded8 uses Embree's native 8-wide packet kernel.
  bool native_packets() const { return native_ray8_; }
  /// Issue 17: another traversal of the same mesh (render/shadow_query.h) that occluded_rays
  /// uses instead of Embree; null (the default): Embree. Set before the scene is shared.
  void set_shadow_query(std::shared_ptr<const ShadowQuery> query) { shadow_query_ = std::move(query); }
  const ShadowQuery* shadow_query() const { return shadow_query_.get(); }

 private:
  struct ErrorSink;
  struct SurfaceGrids;
  void release() noexcept;
  /// Attaches the surface (the first `surface` triangles, in pairs) to scene_ as grids and quads.
  void attach_surface_grids(std::size_t surface, RTCBuildQuality quality);
  /// Attaches `count` triangles or quads (`type`) over the mesh's vertices to `target`, their
  /// indices read from `indices` at `offset_bytes` with `stride_bytes` (shared, not copied).
  void attach_indexed(RTCScene target, RTCGeometryType type, const std::uint32_t* indices,
                      std::size_t offset_bytes, std::size_t stride_bytes, std::size_t count,
                      RTCBuildQuality quality);

  TriangleMesh mesh_;
  std::unique_ptr<ErrorSink> errors_;  // heap-allocated: Embree keeps a pointer to it
  RTCDevice device_ = nullptr;
  RTCScene scene_ = nullptr;        // the surface triangles (mesh_.surface_triangle_count)
  RTCScene extra_scene_ = nullptr;  // the triangles after them, if any (extrusions, blockers)
  bool native_ray8_ = false;
  std::shared_ptr<const ShadowQuery> shadow_query_;
  std::unique_ptr<SurfaceGrids> grids_;  // buffers Embree reads the grids and other quads from
  std::size_t surface_quads_ = 0;
  std::unique_ptr<DepthImageSurface> image_surface_;  // set: the surface is traced in the image
  // build_surface_bvh: once built (the flag set), queries trace the surface in scene_ again.
  std::unique_ptr<std::atomic<bool>> surface_bvh_ready_ =
      std::make_unique<std::atomic<bool>>(false);
  std::unique_ptr<std::mutex> surface_bvh_mutex_ = std::make_unique<std::mutex>();
  bool surface_bvh_quads_ = false;
  RTCBuildQuality surface_bvh_quality_ = RTC_BUILD_QUALITY_MEDIUM;
  bool tracing_image() const;
};

/// One shadow ray for occluded_rays: from `origin` along `direction` (need not be unit length),
/// over t_near <= t <= t_far in units of the direction's length.
struct ShadowRay {
  std::array<float, 3> origin{}, direction{};
  float t_near = 0.0f;
  float t_far = std::numeric_limits<float>::infinity();
};

/// The shadow-packet loop on the occluder scene: traces `count` rays eight at a time
/// (OccluderScene::occluded8). `make_ray(i)` returns ray i (a ShadowRay); `blocked(i, bool)` is
/// told, in order, whether ray i hit the scene. Lanes past `count` are not traced.
template <class MakeRay, class Blocked>
void occluded_rays(const OccluderScene& scene, std::size_t count, MakeRay&& make_ray, Blocked&& blocked) {
  RayPacket8 packet;
  bool hit[8];
  for (std::size_t first = 0; first < count; first += 8) {
    for (int k = 0; k < 8; ++k) {
      const std::size_t i = first + std::size_t(k);
      packet.valid[k] = i < count ? -1 : 0;
      if (i >= count) continue;
      const ShadowRay ray = make_ray(i);
      packet.origin_x[k] = ray.origin[0];
      packet.origin_y[k] = ray.origin[1];
      packet.origin_z[k] = ray.origin[2];
      packet.direction_x[k] = ray.direction[0];
      packet.direction_y[k] = ray.direction[1];
      packet.direction_z[k] = ray.direction[2];
      packet.t_near[k] = ray.t_near;
      packet.t_far[k] = ray.t_far;
    }
    if (const ShadowQuery* query = scene.shadow_query())
      query->occluded8(packet, hit);
    else
      scene.occluded8(packet, hit);
    for (int k = 0; k < 8 && first + std::size_t(k) < count; ++k) blocked(first + std::size_t(k), hit[k]);
  }
}

/// Ambient occlusion at a surface point: the fraction of `ray_count` cosine-weighted rays over the
/// hemisphere around `normal` that travel `max_distance_m` without hitting the scene (1 = fully
/// open, 0 = enclosed). The rays start a little off the surface (1e-4 of the point's distance
/// from the world origin, at least 0.1 mm) so the point's own triangles do not block them.
/// Deterministic: the seed turns one low-discrepancy ray set (render/physics/occlusion.h), the
/// same for every point, in a frame that turns continuously with the normal, carried from the
/// unit `pole` (a direction no normal faces away from: the camera's backward axis), so that
/// nearby points with similar normals get consistent estimates. partial_ray_count (a multiple
/// of ray_count, or <= ray_count for none): where the first ray_count rays (every k-th of a set
/// of that many) disagree, the rest of that set too. `normal` need not be unit length. Traces
/// 8-wide packets; *rays_traced (if given) gets the count. Throws mr::Error(invalid_argument)
/// for ray_count < 1, a partial_ray_count that is not a multiple, a non-positive or non-finite
/// max_distance_m, or a zero or non-finite normal.
float ambient_occlusion(const OccluderScene& scene, const std::array<float, 3>& point,
                        const std::array<float, 3>& normal, int ray_count, float max_distance_m,
                        std::uint32_t seed, const std::array<float, 3>& pole = {0, 0, -1},
                        int partial_ray_count = 0, int* rays_traced = nullptr);

}  // namespace mr::render
