// The one dispatch point of the scattering core (render/backend.h): which backend renders, the
// fall-back to the CPU, the occluder geometry and the timings.
#include "render/backend.h"

#include <tbb/task_arena.h>

#include <chrono>
#include <string>
#include <utility>

#include "mr/cancel.h"
#include "mr/error.h"
#include "render/blockers.h"
#include "render/cpu_backend.h"
#include "render/depth_downsample.h"
#include "render/occluder_cache.h"
#include "render/vulkan/vulkan_backend.h"

namespace mr::render {

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

constexpr const char* kWhat = "render_scattering";

#if defined(__SANITIZE_ADDRESS__)
// Mesa's Vulkan drivers leak under LeakSanitizer (even a bare device probe, from a driver the
// loader has unloaded, so no suppression can name it): sanitizer builds probe only when asked.
constexpr bool kProbeAutomatically = false;
#else
constexpr bool kProbeAutomatically = true;
#endif

// The GPU backend for `choice`, or nullptr for the CPU (with a notice under automatic).
vulkan::Backend* choose_gpu(Backend choice, FrameResult& result) {
  if (choice == Backend::automatic && !kProbeAutomatically) {
    result.notice = "vulkan: not probed in sanitizer builds; the CPU backend renders";
    return nullptr;
  }
  if (choice == Backend::cpu) return nullptr;
  try {
    return choice == Backend::vulkan ? &vulkan::Backend::shared()
                                     : &vulkan::Backend::shared_hardware();
  } catch (const vulkan::Unavailable& e) {
    if (choice == Backend::vulkan)
      throw Error(ErrorCode::invalid_argument,
                  std::string("render.backend is 'vulkan' but ") + e.what());
    // No usable hardware GPU: the CPU is the expected choice here, not a problem (a note for
    // verbose front ends; notice_is_warning stays false).
    result.notice = std::string(e.what()) + "; the CPU backend renders";
    if (std::string(e.what()).find("software device") != std::string::npos)
      result.notice += " (render.backend 'vulkan' forces it)";
    return nullptr;
  }
}

}  // namespace

ConstImageView Occluders::normals_view() const {
  if (cached) return cached->normals.view();
  if (!normals.empty()) return normals.view();
  return {};
}

void build_occluder_mesh(const CoreInputs& in, int mesh_step, Occluders& occluders,
                         FrameTimings& timings) {
  const Camera& camera = *in.camera;
  const FogScene& scene = *in.scene;
  const auto t = Clock::now();
  occluders.normals = estimate_normals(in.distance_m, camera, scene.pose);
  throw_if_cancelled(in.cancel, kWhat);
  if (!scene.render.volumetric_shadows) {
    timings.mesh_s = seconds_since(t);
    return;
  }
  // A coarse mesh builds and traces faster, unless the image is too small to coarsen.
  if (camera.width / mesh_step < 16 || camera.height / mesh_step < 16) mesh_step = 1;
  TriangleMesh mesh;
  if (mesh_step > 1) {
    const DownsampledDistance coarse = downsample_distance_nearest(in.distance_m, camera, mesh_step);
    mesh = reconstruct_occluder_mesh(coarse.distance_m.view(), coarse.camera, scene.pose);
  } else {
    mesh = reconstruct_occluder_mesh(in.distance_m, camera, scene.pose);
  }
  // What the photo does not show: structures cut by the frame, the scene's skyline, polygons
  // and canopy (the same mesh feeds every backend).
  const BlockerReport blockers = append_blockers(mesh, in.distance_m, occluders.normals.view(),
                                                 camera, scene.pose, scene.blockers);
  occluders.completed_blockers = blockers.completed;
  timings.mesh_s = seconds_since(t);
  occluders.mesh = std::move(mesh);
  throw_if_cancelled(in.cancel, kWhat);
  report_progress(in.cancel, "occluders", 1, 2);
}

FrameResult render_frame(const CoreInputs& given, CoreOutputs& out) {
  const FogScene& scene = *given.scene;
  FrameResult result;
  tbb::task_arena arena(scene.render.threads > 0 ? scene.render.threads
                                                 : tbb::task_arena::automatic);
  arena.execute([&] {
    const bool lights = scene.lighting.sun || !scene.lighting.lamps.empty();
    CpuBackend cpu;
    ScatteringBackend* backend = &cpu;
    vulkan::Backend* gpu = choose_gpu(scene.render.backend, result);
    if (gpu) backend = gpu;

    Occluders occluders;
    if (lights) {
      report_progress(given.cancel, "occluders", 0, 2);  // normals + mesh, BVH; "render"
      backend->prepare_occluders(given, occluders, result.timings);
    }
    CoreInputs in = given;
    in.normals = occluders.normals_view();
    in.occluders = nullptr;
    try {
      backend->render(in, occluders, out, result.timings);
      result.backend = backend->name();
    } catch (const BackendUnavailable& e) {  // e.g. out of device memory
      if (backend == &cpu) throw;
      if (scene.render.backend == Backend::vulkan)
        throw Error(ErrorCode::invalid_argument,
                    std::string("render.backend is 'vulkan' but ") + e.what());
      result.notice = std::string(e.what()) + "; the CPU backend renders";
      result.notice_is_warning = true;  // a GPU was there and failed
      // The GPU's normals and mesh serve the CPU as they are (it builds the BVH from the mesh).
      cpu.render(in, occluders, out, result.timings);
      result.backend = cpu.name();
    }
    result.timings.exact_pixels = out.exact_pixels;
    result.timings.interpolated_pixels = out.interpolated_pixels;
    result.timings.shadow_rays = out.shadow_rays;
    result.completed_blockers = std::move(occluders.completed_blockers);
  });
  return result;
}

}  // namespace mr::render
