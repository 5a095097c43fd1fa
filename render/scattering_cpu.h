// Private to libmr: the CPU reference implementation of the single-scattering core
// (DESIGN.md section 3): per-pixel ray marching with per-segment analytic integration, light
// paths through the medium in closed form, volumetric shadows through the occluder mesh
// (Embree), the surface term of the transmittance map, and the gradient-based image-space
// acceleration (sparse exact samples, gradient interpolation, exact recomputation where the
// depth or the shadowing differs).
#pragma once

#include "render/backend.h"  // CoreInputs, CoreOutputs, MarchPlan: shared by every backend

namespace mr::render {

/// MeshOptions::planar_merge_tolerance of the CPU backend's occluder mesh (issue 12): planar
/// rectangles of pixels whose corners lie within 2e-4 of their distance of one plane become a
/// triangulation of their boundary. The surface moves by at most 4e-4 of its distance, under the
/// mesh's own centre tolerance (1e-3) and the shadow rays' offset from it (1e-3 of the distance);
/// at 1080p on sample_photos/leuven it took 4.1 M triangles to 2.8 M, and R changed by < 1e-7
/// on average (relative). The Vulkan backend keeps the full mesh, and so, by default, does the
/// CPU backend since the merge measured a net loss there (render/cpu_backend.cpp); this is the
/// tolerance for callers that decimate (tests, the BM_Stages merge row).
inline constexpr double kCpuPlanarMergeTolerance = 2e-4;

/// Renders every pixel of the outputs (all the distance map's size). Runs in parallel in the
/// calling TBB arena; deterministic.
void render_scattering_cpu(const CoreInputs& in, CoreOutputs& out);

}  // namespace mr::render
