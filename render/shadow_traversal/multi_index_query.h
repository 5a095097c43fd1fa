// Private to libmr: the shadow-query implementations of issue 17 (render/shadow_query.h): the
// multi-index kd-tree of seed 004 (render/shadow_traversal/kd_tree.h) with its per-ray
// prediction, and Embree's OccluderScene behind the same interface.
#pragma once

#include <cstdint>
#include <memory>

#include "render/occluder_mesh.h"
#include "render/shadow_query.h"
#include "render/shadow_traversal/kd_tree.h"

namespace mr::render {

class OccluderScene;

/// The multi-index tree answering shadow queries. The prediction of a ray's kind (occluded:
/// lifted primitive indices first; unoccluded: rope walk) is the outcome of the previous ray the
/// same thread traced: in the CPU core's shadow loops that is the previous march sample along the
/// same view ray or the neighbouring pixel's ray (seed 004 predicts from the previous frame).
/// occluded8 traces a packet of two or more rays with the tree's 8-wide packet traversal instead
/// (KdTree::occluded8: same answers, 1.4-2x faster on the benchmarks; no ropes or lifted indices).
class MultiIndexShadowQuery final : public ShadowQuery {
 public:
  explicit MultiIndexShadowQuery(const TriangleMesh& mesh,
                                 const shadow::KdTreeOptions& options = {});
  bool occluded(const std::array<float, 3>& origin, const std::array<float, 3>& direction,
                float t_near, float t_far) const override;
  void occluded8(const RayPacket8& rays, bool occluded_out[8]) const override;
  const char* name() const override { return "multi-index"; }
  const shadow::KdTree& tree() const { return tree_; }
  /// Packets traced by all MultiIndexShadowQuery objects so far (tests: that a render used it).
  static std::uint64_t packets_traced();

 private:
  shadow::KdTree tree_;
};

/// Embree (OccluderScene::occluded / occluded8) behind the ShadowQuery interface. Holds a
/// reference: the scene must outlive it.
class EmbreeShadowQuery final : public ShadowQuery {
 public:
  explicit EmbreeShadowQuery(const OccluderScene& scene) : scene_(scene) {}
  bool occluded(const std::array<float, 3>& origin, const std::array<float, 3>& direction,
                float t_near, float t_far) const override;
  void occluded8(const RayPacket8& rays, bool occluded_out[8]) const override;
  const char* name() const override { return "embree"; }

 private:
  const OccluderScene& scene_;
};

}  // namespace mr::render
