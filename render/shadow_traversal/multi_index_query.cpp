#include "render/shadow_traversal/multi_index_query.h"

#include <atomic>

#include "render/embree_scene.h"

namespace mr::render {

namespace {
// The previous outcome on this thread: the prediction for the next ray (starts "unoccluded").
thread_local bool previous_occluded = false;
std::atomic<std::uint64_t> packet_count{0};
}  // namespace

std::uint64_t MultiIndexShadowQuery::packets_traced() {
  return packet_count.load(std::memory_order_relaxed);
}

MultiIndexShadowQuery::MultiIndexShadowQuery(const TriangleMesh& mesh,
                                             const shadow::KdTreeOptions& options)
    : tree_(mesh, options) {}

bool MultiIndexShadowQuery::occluded(const std::array<float, 3>& origin,
                                     const std::array<float, 3>& direction, float t_near,
                                     float t_far) const {
  const bool hit =
      tree_.occluded_multi_index(shadow::Ray{origin, direction, t_near, t_far}, previous_occluded);
  previous_occluded = hit;
  return hit;
}

void MultiIndexShadowQuery::occluded8(const RayPacket8& rays, bool occluded_out[8]) const {
  packet_count.fetch_add(1, std::memory_order_relaxed);
  shadow::Ray ray[8];
  unsigned lanes = 0;
  int last = -1;
  for (int k = 0; k < 8; ++k) {
    occluded_out[k] = false;
    if (rays.valid[k] == 0) continue;
    ray[k] = {{rays.origin_x[k], rays.origin_y[k], rays.origin_z[k]},
              {rays.direction_x[k], rays.direction_y[k], rays.direction_z[k]},
              rays.t_near[k],
              rays.t_far[k]};
    lanes |= 1u << k;
    last = k;
  }
  if (last < 0) return;
  if ((lanes & (lanes - 1)) == 0) {  // one ray: the predicted single-ray traversal
    occluded_out[last] = tree_.occluded_multi_index(ray[last], previous_occluded);
    previous_occluded = occluded_out[last];
    return;
  }
  // The 8-wide packet traversal (same answers; faster than 8 single rays on every benchmark
  // scene, README "Shadow-ray traversal": one node fetch serves the packet's coherent rays).
  const unsigned hits = tree_.occluded8(ray, lanes);
  for (int k = 0; k < 8; ++k) occluded_out[k] = (hits >> k) & 1u;
  previous_occluded = occluded_out[last];
}

bool EmbreeShadowQuery::occluded(const std::array<float, 3>& origin,
                                 const std::array<float, 3>& direction, float t_near,
                                 float t_far) const {
  return scene_.occluded(origin, direction, t_near, t_far);
}

void EmbreeShadowQuery::occluded8(const RayPacket8& rays, bool occluded_out[8]) const {
  scene_.occluded8(rays, occluded_out);
}

}  // namespace mr::render
