// Private to libmr: the interface of a shadow-ray (any-hit) query over the occluder mesh, which
// Embree (render/embree_scene.h, OccluderScene) and the multi-index kd-tree of seed 004
// (render/shadow_traversal/multi_index_query.h) both implement, so that the CPU core's shadow
// loops (render::occluded_rays) can run on either (issue 17; RenderSettings::shadow_traversal).
#pragma once

#include <array>

namespace mr::render {

struct RayPacket8;  // render/embree_scene.h

/// Answers "does any triangle lie on this ray segment?" for the occluder mesh. Implementations are
/// const and safe to call from many threads at once. Semantics (those of Embree's rtcOccluded):
/// the segment is origin + t * direction for t_near < t <= t_far (t in units of |direction|,
/// which need not be 1); triangle edges and vertices count as hits; a ray in a triangle's plane
/// does not hit it.
class ShadowQuery {
 public:
  virtual ~ShadowQuery() = default;
  /// One ray.
  virtual bool occluded(const std::array<float, 3>& origin, const std::array<float, 3>& direction,
                        float t_near, float t_far) const = 0;
  /// Up to eight rays: occluded_out[k] is set for every lane; lanes with valid[k] == 0 get false.
  /// Consecutive lanes are consecutive rays of a shadow loop (march samples along one view ray,
  /// neighbouring pixels), which an implementation may use to predict a ray's outcome.
  virtual void occluded8(const RayPacket8& rays, bool occluded_out[8]) const = 0;
  /// A short name for reports ("embree", "multi-index").
  virtual const char* name() const = 0;
};

}  // namespace mr::render
