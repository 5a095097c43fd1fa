// Private to libmr: shadow casters the photo does not show (issue 13, section 1). The occluder
// mesh is the surface the photo shows, so the parts of a colonnade, a facade or a tree trunk
// above the frame, a wall beside it, the skyline behind it and a canopy overhead cast no shadow
// and the fog they shade gets full sunlight (measured +42 % in-scatter for tall pillars cut by
// the top of the frame). This adds them to the mesh, from two sources:
//  * completion: structures the photo shows cut by the frame's top or side edges are continued
//    beyond it along their own plane (mr::Blockers::Completion);
//  * the scene's explicit blockers: a skyline (height per azimuth), world-space polygons (an
//    off-frame wall or tree line) and a canopy (height and gap fraction).
#pragma once

#include <cstddef>
#include <vector>

#include "mr/camera.h"
#include "mr/image.h"
#include "mr/scene.h"
#include "render/occluder_mesh.h"

namespace mr::render {

/// What append_blockers added.
struct BlockerReport {
  std::vector<CompletedBlocker> completed;  ///< structures cut by the frame, continued
  std::size_t triangles = 0;  ///< triangles appended (completion and explicit blockers)
};

/// Appends the blockers' triangles to `mesh` (after everything in it; surface_triangle_count is
/// left as it is, so the surface layout of TriangleMesh holds). `distance_m` and `normals` are
/// the full-resolution maps (1 and 3 channels, the camera's size; normals from
/// estimate_normals). Completion runs when blockers.completion.enabled; skyline, polygons and
/// canopy whenever given. Deterministic. Throws mr::Error(invalid_argument) when the maps do not
/// match the camera.
BlockerReport append_blockers(TriangleMesh& mesh, ConstImageView distance_m,
                              ConstImageView normals, const Camera& camera, const CameraPose& pose,
                              const Blockers& blockers);

}  // namespace mr::render
