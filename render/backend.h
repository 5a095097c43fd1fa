// Private to libmr: the interface every backend of the scattering core implements (DESIGN.md
// section 2; Filament's driver interface is the model), the inputs and outputs they share, and
// the one dispatch point (render_frame) that chooses a backend, falls back to the CPU, has the
// occluder geometry built and reports the timings. The backends differ only in how they find
// visibility (Embree rays through a BVH vs shadow maps rasterized from the mesh) and how they
// schedule the work; the physics both evaluate is shared (render/physics/, shaders/).
//
//   CpuBackend (render/cpu_backend.h)            render_scattering_cpu, Embree + TBB
//   vulkan::Backend (render/vulkan/vulkan_backend.h)  Vulkan compute, shadow maps
//
// docs/architecture.md says how to add a backend.
#pragma once

#include <array>
#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include "mr/camera.h"
#include "mr/cancel.h"
#include "mr/error.h"
#include "mr/image.h"
#include "mr/scene.h"
#include "render/occluder_mesh.h"

namespace mr::render {

class OccluderScene;
class SurfaceQueryCache;
struct OccluderGeometry;

/// March steps and grid spacing of a quality preset (RenderSettings overrides applied).
struct MarchPlan {
  int steps = 32;        ///< view-ray segments placed uniformly in transmittance
  int lamp_steps = 16;   ///< extra segments per lamp, equiangular around its closest approach
  int grid_step = 2;     ///< sparse-sample spacing in pixels (1: every pixel exact)
  int sun_surface_rays = 4;  ///< shadow rays over the sun's disk at surfaces (soft sun)
  int ao_rays = 8;           ///< ambient-occlusion rays at sparse samples
  /// Occluder mesh resolution: one vertex row per mesh_step pixel rows (nearest surface of each
  /// block, render/depth_downsample.h); 1 = full resolution. Draft uses 2: its mesh and BVH
  /// build ~3x faster, but shadow edges move by up to one coarse pixel (at normal quality that
  /// doubled the Monte Carlo reference error, 0.54 % -> 1.25 %, for a 25 % shorter 1080p render).
  int mesh_step = 1;
  /// AO rays where those ao_rays disagree (partly occluded, where the estimate errs): the rest of
  /// one low-discrepancy set of this many (render/physics/occlusion.h); a multiple of ao_rays.
  int ao_partial_rays = 32;
};
MarchPlan march_plan(const RenderSettings& settings);

struct CoreInputs {
  const Camera* camera = nullptr;
  const FogScene* scene = nullptr;
  ConstImageView distance_m;          ///< 1 channel, +inf = sky
  ConstImageView normals;             ///< 3 channels, world; may be empty when no sun/lamps
  /// The photo (scene-linear, >= 3 channels, the distance map's size), or empty. Where the
  /// occluder mesh says a sun-facing surface is shadowed but the photo shows it as bright as its
  /// sunlit neighbours on the same plane (silhouettes, shadow edges the mesh misplaces), the
  /// surface term takes the sun as unshadowed (S from the light path's transmittance) instead of
  /// S = 1. Empty: the mesh alone decides.
  ConstImageView photo;
  /// The CPU backend's form of the occluders (a BVH); nullptr: nothing casts shadows. The Vulkan
  /// backend takes the mesh itself (Occluders::mesh) and ignores this.
  const OccluderScene* occluders = nullptr;
  /// The CPU backend's kept answers of the surface's shadow queries for these occluders, or
  /// nullptr (render/surface_query_cache.h: read and completed by the render).
  SurfaceQueryCache* surface_queries = nullptr;
  std::array<float, 3> sky_radiance{};
  /// Checked between rows of every pass (a relaxed load per row); requested: the core throws
  /// mr::Error(cancelled) and the outputs hold a partial render the caller must drop.
  const CancelToken* cancel = nullptr;
};

struct CoreOutputs {
  ImageView transmittance;   ///< 3 channels
  ImageView inscatter;       ///< 3 channels
  ImageView sun_visibility;  ///< 1 channel
  ImageView optical_depth;   ///< 3 channels
  std::size_t exact_pixels = 0, interpolated_pixels = 0, shadow_rays = 0;
  /// Wall seconds of the passes (bench/bench_scattering.cpp prints them): the exact samples on
  /// the sparse grid, the interpolation with its exact recomputations, and the per-pixel surface
  /// term of T (with the AOVs).
  double grid_s = 0, interpolation_s = 0, surface_s = 0;
};

/// What casts shadows in one frame, in the form a backend prepared it (prepare_occluders).
struct Occluders {
  Image normals;      ///< world normals of the distance map (empty without sun or lamps)
  TriangleMesh mesh;  ///< the occluder mesh (with blockers); the GPU rasterizes it
  /// The CPU backend's normals, mesh and BVH, shared across renders of one photo (issue 12).
  std::shared_ptr<const OccluderGeometry> cached;
  std::vector<CompletedBlocker> completed_blockers;  ///< structures cut by the frame, continued

  /// The normals to render with: the cached geometry's, else `normals` (may be empty).
  ConstImageView normals_view() const;
};

/// Seconds per stage and counts of one frame (mr::ScatteringLayers::Timings reports them).
struct FrameTimings {
  double mesh_s = 0;     ///< depth -> normals, occluder mesh, blockers
  double bvh_s = 0;      ///< Embree scene build (CPU)
  double scatter_s = 0;  ///< the backend's render
  std::size_t exact_pixels = 0, interpolated_pixels = 0, shadow_rays = 0;
  // GPU backends only: each stage's device time, plus the host's staging copies.
  double upload_s = 0, shadow_maps_s = 0, gpu_scatter_s = 0, download_s = 0;
  int tiles = 0;
};

/// A backend of the scattering core. Both calls run in the caller's TBB arena; both may throw
/// mr::Error(cancelled) when in.cancel is requested.
class ScatteringBackend {
 public:
  virtual ~ScatteringBackend() = default;
  /// "cpu", or "vulkan: <device name>": what mr::ScatteringLayers::backend reports.
  virtual std::string name() const = 0;
  /// Builds what this backend needs for shadows and the surface term: the normals, and with
  /// RenderSettings::volumetric_shadows the occluder geometry in this backend's form. Called
  /// only when the scene has a sun or lamps. Reports "occluders" progress (1 or 2 of 2).
  virtual void prepare_occluders(const CoreInputs& in, Occluders& occluders,
                                 FrameTimings& timings) = 0;
  /// Renders every pixel of `out` (all the distance map's size) from `in` (whose normals are
  /// occluders.normals_view()) and the prepared `occluders` (prepared by this or, after a
  /// fall-back, another backend). Deterministic. Sets timings.scatter_s and the counts.
  virtual void render(const CoreInputs& in, Occluders& occluders, CoreOutputs& out,
                      FrameTimings& timings) = 0;
};

/// Builds the normals and, with RenderSettings::volumetric_shadows, the occluder mesh at
/// `mesh_step` (1 = full resolution) with the scene's blockers, into `occluders`; for backends
/// that take the mesh itself. Reports "occluders" 1 of 2 after the mesh.
void build_occluder_mesh(const CoreInputs& in, int mesh_step, Occluders& occluders,
                         FrameTimings& timings);

/// The thrown-and-caught reason a backend cannot render here (no loader, no device, only a
/// software device where a hardware one was asked for, out of device memory): the dispatcher
/// falls back to the CPU on it under Backend::automatic.
class BackendUnavailable : public Error {
 public:
  explicit BackendUnavailable(const std::string& message)
      : Error(ErrorCode::invalid_argument, message) {}
};

struct FrameResult {
  std::string backend;  ///< what rendered: ScatteringBackend::name()
  std::string notice;   ///< one line when Backend::automatic fell back to the CPU
  /// false when the fall-back is the expected choice here (no GPU, a sanitizer build); true
  /// when a usable GPU failed (e.g. out of device memory).
  bool notice_is_warning = false;
  FrameTimings timings;
  std::vector<CompletedBlocker> completed_blockers;
};

/// The one place that decides which backend renders (in.scene->render.backend: automatic = a
/// hardware GPU through Vulkan, else the CPU with a notice; cpu; vulkan = Vulkan on any device,
/// lavapipe included, or mr::Error), has it prepare the occluders (only with sun or lamps) and
/// render every pixel of `out`, and falls back to the CPU when the GPU fails under automatic.
/// Runs in a TBB arena of in.scene->render.threads threads (0: all cores). `in.normals` and
/// `in.occluders` are ignored (the backend's own are used). Throws mr::Error: invalid_argument
/// when 'vulkan' was asked for and is unavailable, cancelled.
FrameResult render_frame(const CoreInputs& in, CoreOutputs& out);

}  // namespace mr::render
