#include "render/cpu_backend.h"

#include <chrono>
#include <memory>
#include <optional>

#include "mr/cancel.h"
#include "render/embree_scene.h"
#include "render/occluder_cache.h"
#include "render/scattering_cpu.h"

namespace mr::render {

namespace {
using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}
}  // namespace

void CpuBackend::prepare_occluders(const CoreInputs& in, Occluders& occluders,
                                   FrameTimings& timings) {
  const FogScene& scene = *in.scene;
  if (!scene.render.volumetric_shadows) {  // the normals only
    build_occluder_mesh(in, 1, occluders, timings);
    return;
  }
  OccluderGeometryRequest request;
  request.distance_m = in.distance_m;
  request.camera = in.camera;
  request.pose = &scene.pose;
  request.blockers = &scene.blockers;
  int mesh_step = march_plan(scene.render).mesh_step;
  if (in.camera->width / mesh_step < 16 || in.camera->height / mesh_step < 16) mesh_step = 1;
  request.mesh_step = mesh_step;
  // The mesh is not decimated (MeshOptions::planar_merge_tolerance stays 0): at 1080p on
  // sample_photos/leuven the merge cost more in the mesh stage than it saved in the BVH
  // build, and its long merged triangles made every shadow ray dearer (render CPU 6.6 ->
  // 8.1 s, mesh + BVH CPU 2.9 -> 3.5 s), fresh or reused (issue 12 item 4).
  request.cancel = in.cancel;
  request.shadow_traversal = scene.render.shadow_traversal;  // issue 17
  request.surface_traversal = surface_traversal_from_environment();  // issue 12
  OccluderGeometryTimings gt;
  occluders.cached = occluder_geometry(request, &gt);
  timings.mesh_s = gt.mesh_s;
  timings.bvh_s = gt.bvh_s;
  occluders.completed_blockers = occluders.cached->completed_blockers;
  report_progress(in.cancel, "occluders", 2, 2);
}

void CpuBackend::render(const CoreInputs& in, Occluders& occluders, CoreOutputs& out,
                        FrameTimings& timings) {
  CoreInputs inputs = in;
  std::optional<OccluderScene> built;
  auto t = Clock::now();
  std::unique_ptr<SurfaceQueryCache> surface_queries;
  if (occluders.cached) {
    inputs.occluders = occluders.cached->occluders ? &*occluders.cached->occluders : nullptr;
    // Given back even when the render throws (cancelled): every answer in it is complete.
    if (inputs.occluders)
      surface_queries =
          occluders.cached->surface_queries.take(in.distance_m.width, in.distance_m.height);
    inputs.surface_queries = surface_queries.get();
  } else {
    if (occluders.mesh.triangle_count() > 0) built.emplace(std::move(occluders.mesh));
    timings.bvh_s = seconds_since(t);
    throw_if_cancelled(in.cancel, "render_scattering");
    report_progress(in.cancel, "occluders", 2, 2);
    inputs.occluders = built ? &*built : nullptr;
    t = Clock::now();
  }
  struct GiveBack {
    const Occluders& occluders;
    std::unique_ptr<SurfaceQueryCache>& cache;
    ~GiveBack() {
      if (cache) occluders.cached->surface_queries.give_back(std::move(cache));
    }
  } give_back{occluders, surface_queries};
  render_scattering_cpu(inputs, out);
  timings.scatter_s = seconds_since(t);
}

}  // namespace mr::render
