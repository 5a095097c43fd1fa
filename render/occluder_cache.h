// Private to libmr: the CPU backend's occluder geometry (normals, occluder mesh, its Embree
// scene: a BVH, or for jagged depth the surface's walk in the image) of the latest render, reused
// by the next render of the same depth map, camera, pose and blockers (issue 12 item 4: mr-studio
// re-renders one photo for every fog or sun slider change, and the geometry depends on neither).
// Process-wide, up to three entries: a new geometry is built only after every entry that is not
// small against it (a quarter of its memory, all kept entries together) is dropped, so the next
// photo of a batch replaces the last (peak memory does not grow) while mr-studio's small draft
// geometry stays beside its view-sized one (each edit renders both). A render still using an entry
// keeps it alive (shared ownership).
#pragma once

#include <cstddef>
#include <memory>
#include <optional>
#include <vector>

#include "mr/camera.h"
#include "mr/cancel.h"
#include "mr/image.h"
#include "mr/scene.h"
#include "render/embree_scene.h"
#include "render/occluder_mesh.h"
#include "render/surface_query_cache.h"

namespace mr::render {

struct OccluderGeometry {
  Image normals;                           ///< estimate_normals of the full-resolution map
  std::optional<OccluderScene> occluders;  ///< nullopt: no triangles (nothing casts shadows)
  std::vector<CompletedBlocker> completed_blockers;  ///< what append_blockers continued
  /// The surface's AO and sun-disk answers of the latest render with this geometry, for the
  /// next (render/surface_query_cache.h).
  SurfaceQuerySlot surface_queries;
};

/// How the Embree scene traces the mesh's surface (issue 12): automatic (the default) chooses by
/// its slivers and the depth's zig-zag (render/occluder_cache.cpp), bvh and image force Embree's
/// BVH or the walk in the image (render/shadow_traversal/depth_image_surface.h). Only with
/// ShadowTraversal::embree.
enum class SurfaceTraversal { automatic, bvh, image };

/// MR_SURFACE_TRAVERSAL=bvh|image forces one (benchmarks, A/B); unset or anything else:
/// automatic. Read once per process.
SurfaceTraversal surface_traversal_from_environment();

struct OccluderGeometryRequest {
  ConstImageView distance_m;  ///< full resolution, 1 channel, the camera's size
  const Camera* camera = nullptr;
  const CameraPose* pose = nullptr;
  const Blockers* blockers = nullptr;
  /// Mesh resolution (MarchPlan::mesh_step; 1 = full) and options.
  int mesh_step = 1;
  MeshOptions mesh_options;
  const CancelToken* cancel = nullptr;  ///< checked between the stages
  /// multi_index: the scene's shadow queries go to the multi-index kd-tree (issue 17), built
  /// with the BVH (its time is in bvh_s) and attached with OccluderScene::set_shadow_query.
  ShadowTraversal shadow_traversal = ShadowTraversal::embree;
  SurfaceTraversal surface_traversal = SurfaceTraversal::automatic;
};

struct OccluderGeometryTimings {
  double mesh_s = 0;  ///< normals, mesh and blockers (0 when reused)
  double bvh_s = 0;   ///< the Embree build or the image's pyramid (0 when reused)
  bool reused = false;
};

/// The geometry for `request`: the cached one when its inputs are identical (depth values
/// compared bit for bit, camera, pose, blockers, mesh step and options), else built (normals,
/// mesh at mesh_step with the blockers appended, Embree scene) and cached. Thread-safe; two
/// renders missing at once both build (both are kept, the later one first). Throws what the
/// builders throw, and mr::Error(cancelled) when the token is requested between stages.
std::shared_ptr<const OccluderGeometry> occluder_geometry(const OccluderGeometryRequest& request,
                                                          OccluderGeometryTimings* timings);

/// Drops the cached entries and unmaps the render scratch kept for reuse (trim_huge_page_pool;
/// tests, memory, and "fresh geometry" benchmarks).
void clear_occluder_geometry_cache();

}  // namespace mr::render
