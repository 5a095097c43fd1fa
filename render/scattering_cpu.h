// Private to libmr: the CPU reference implementation of the single-scattering core
// (DESIGN.md section 3): per-pixel ray marching with per-segment analytic integration, light
// paths through the medium in closed form, volumetric shadows through the occluder mesh
// (Embree), the surface term of the transmittance map, and the gradient-based image-space
// acceleration (sparse exact samples, gradient interpolation, exact recomputation where the
// depth or the shadowing differs).
#pragma once

#include <cstddef>

#include "mr/camera.h"
#include "mr/cancel.h"
#include "mr/image.h"
#include "mr/scene.h"

namespace mr::render {

class OccluderScene;

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
};
MarchPlan march_plan(const RenderSettings& settings);

/// MeshOptions::planar_merge_tolerance of the CPU backend's occluder mesh (issue 12): planar
/// rectangles of pixels whose corners lie within 2e-4 of their distance of one plane become a
/// triangulation of their boundary. The surface moves by at most 4e-4 of its distance, under the
/// mesh's own centre tolerance (1e-3) and the shadow rays' offset from it (1e-3 of the distance);
/// at 1080p on sample_photos/leuven it took 4.1 M triangles to 2.8 M, and R changed by < 1e-7
/// on average (relative). The Vulkan backend keeps the full mesh, and so, by default, does the
/// CPU backend since the merge measured a net loss there (libmr/src/scattering.cpp); this is the
/// tolerance for callers that decimate (tests, the BM_Stages merge row).
inline constexpr double kCpuPlanarMergeTolerance = 2e-4;

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
  const OccluderScene* occluders = nullptr;  ///< nullptr: nothing casts shadows
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

/// Renders every pixel of the outputs (all the distance map's size). Runs in parallel in the
/// calling TBB arena; deterministic.
void render_scattering_cpu(const CoreInputs& in, CoreOutputs& out);

}  // namespace mr::render
