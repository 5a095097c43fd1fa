// Private to libmr: the CPU backend of the scattering core (render/backend.h): the reference
// implementation, render_scattering_cpu (render/scattering_cpu.h), with volumetric shadows from
// Embree rays through a BVH of the occluder mesh, built in parallel with TBB and reused across
// renders of one photo (render/occluder_cache.h).
#pragma once

#include <string>

#include "render/backend.h"

namespace mr::render {

class CpuBackend final : public ScatteringBackend {
 public:
  std::string name() const override { return "cpu"; }
  /// With volumetric shadows: the normals, the mesh at the preset's resolution (MarchPlan::
  /// mesh_step) and its BVH, from the occluder cache. Without: the normals.
  void prepare_occluders(const CoreInputs& in, Occluders& occluders,
                         FrameTimings& timings) override;
  /// Uses the cached BVH, or builds one from occluders.mesh (what a GPU backend prepared before
  /// it failed; the mesh is moved into it).
  void render(const CoreInputs& in, Occluders& occluders, CoreOutputs& out,
              FrameTimings& timings) override;
};

}  // namespace mr::render
