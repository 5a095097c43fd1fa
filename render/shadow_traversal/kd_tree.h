// Private to libmr: a kd-tree over a triangle mesh for shadow (any-hit) rays, with the traversal
// orders seed 004 compares itself with and the seed's multi-index tree (issue 17).
//
//  * Build: binned SAH (32 planes per axis per node) over each reference's bounds *clipped to the
//    node*: a triangle straddling a split plane is clipped (conservatively) to each child's box
//    and rebounded, so a long diagonal triangle is not copied into every leaf its box overlaps
//    (Wald & Havran 2006's "perfect splits", binned). Costs C_trav = 1, C_isect = 1.5,
//    empty-space bonus 0.8 (leaf if no split is cheaper, at most 2 triangles or at depth
//    8 + 1.3 log2 N). O(references) per node, no sorting, 28-byte references freed before the
//    children are built; big subtrees at depths 2-6 are built as TBB tasks.
//  * Triangle test: watertight (Woop, Benthin & Wald 2013, JCGT 2(1)), with the double-precision
//    fallback for zero edge functions. A hit is t_near < t <= t_far (Embree's rule) with all three
//    edge functions >= 0 or all <= 0: points on an edge or a vertex count, for both triangles
//    sharing it (closed triangles); a ray in the triangle's plane (determinant 0) misses it. Every
//    leaf's triangles are tested over the whole ray segment, not only the leaf's part of it, so a
//    leaf skipped by rounding at a split plane loses a hit only if no other visited leaf holds
//    the triangle.
//  * Orders (any-hit traversal with a stack):
//      standard     front to back along the ray (as for a nearest hit);
//      sato         Nah & Manocha 2014: a fixed order per node, the child with the larger
//                   occlusion chance per unit of traversal cost first, here
//                   min(1, 2 x its triangles' area / its box's area) over its SAH cost (in the
//                   spirit of the paper's surface-area metrics; no ray set);
//      srdh         Feltman, Lee & Fatahalian 2012's idea of specialising to a representative
//                   shadow-ray set: the order per node from sample rays (the child with the
//                   larger measured P(occluded | entered) / measured cost first), on
//                   the SAH tree or on SRDH's own tree (the constructor taking
//                   sample rays: split costs from the rays' measured child-entry chances).
//      multi-index  seed 004 (Liang & Huang 2019): (a) lifted primitive indices: triangles whose
//                   box surface area exceeds `lift_area_ratio` x the mean are candidates; each
//                   goes to the ancestor of its leaf with the largest gain
//                   (P_hit - C_isect / C_node) (1 - exp(-lambda depth)), P_hit = SA(triangle box
//                   in node) / SA(node), if that exceeds `lift_min_gain`; at most
//                   `lift_max_per_node` per node; they stay in their leaves too, and a ray
//                   remembers the lifted triangles it tested and skips them there. A ray
//                   predicted occluded tests a node's lifted triangles before descending
//                   (front to back, as the standard traversal).
//                   (b) neighbour (rope) indices: each leaf face points to the smallest node
//                   holding the whole neighbouring face (Havran; Popov et al. 2007), so a ray
//                   predicted unoccluded walks leaf to leaf without restarting from the root.
//                   Built for all leaves (the seed builds them only for leaves that primary rays
//                   see, from the light's leaf outwards, to save memory).
//                   (c) the prediction: the caller says which kind it expects (ShadowQuery: the
//                   previous ray of the same loop, i.e. the previous march sample or pixel).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "render/occluder_mesh.h"

namespace mr::render::shadow {

/// A shadow ray: origin + t * direction, t_near < t <= t_far.
struct Ray {
  std::array<float, 3> origin{}, direction{};
  float t_near = 0.0f;
  float t_far = 0.0f;
};

enum class Order { standard, sato, srdh };

/// Work of a set of rays, split by outcome (exact counts; time is measured by the caller).
struct Counters {
  std::uint64_t rays = 0;
  std::uint64_t nodes = 0;       ///< nodes visited (interior and leaf; for ropes, every node
                                 ///< entered while descending from a rope's target counts too)
  std::uint64_t primitives = 0;  ///< ray-triangle tests
  Counters& operator+=(const Counters& o) {
    rays += o.rays;
    nodes += o.nodes;
    primitives += o.primitives;
    return *this;
  }
};
struct KindCounters {
  Counters occluded, unoccluded;
  std::uint64_t rope_fallbacks = 0;  ///< rope walks that fell back to a root descent
  /// occluded8: packets traced and the nodes they fetched (a node counts once per packet; the
  /// per-ray `nodes` above count it for every ray of the packet still active there).
  std::uint64_t packets = 0, packet_nodes = 0;
  KindCounters& operator+=(const KindCounters& o) {
    occluded += o.occluded;
    unoccluded += o.unoccluded;
    rope_fallbacks += o.rope_fallbacks;
    packets += o.packets;
    packet_nodes += o.packet_nodes;
    return *this;
  }
};

struct KdTreeOptions {
  float cost_traversal = 1.0f;
  float cost_intersect = 1.5f;
  float empty_bonus = 0.8f;  ///< cost factor of a split with an empty side
  int max_leaf_size = 2;     ///< at most this many triangles: always a leaf
  bool multi_index = true;   ///< lifted indices and ropes (else only the plain tree)
  float lift_area_ratio =
      0.5f;                  ///< candidate: triangle box area > this x the mean (seed: 0.45-0.6)
  float lift_lambda = 0.6f;  ///< the seed's depth curve
  float lift_min_gain = 0.05f;
  int lift_max_per_node = 2;
  /// SRDH build: the weight, in sample rays, of the surface-area prior in a node's measured
  /// child-entry chances (few rays through a node: nearly the SAH).
  float srdh_prior_rays = 8.0f;
};

struct Box {
  float lo[3], hi[3];
};

class KdTree {
 public:
  /// Builds the tree over `mesh` (its triangles are copied; the mesh may go away). Positions may
  /// carry OccluderScene's float of padding. Throws mr::Error(invalid_argument) for a malformed
  /// mesh (as OccluderScene does).
  explicit KdTree(const TriangleMesh& mesh, const KdTreeOptions& options = {});
  /// SRDH's tree (Feltman, Lee & Fatahalian 2012, adapted to a kd-tree): the split costs use the
  /// chance, measured on `srdh_rays` (a representative sample of the frame's shadow rays), that
  /// a ray entering a node enters each child, blended with the surface-area ratio
  /// (KdTreeOptions::srdh_prior_rays); SRDH's occlusion term (rays stopped in the first child
  /// do not reach the second) is not modelled. With no rays it is the SAH tree above. Same
  /// answers as any tree.
  KdTree(const TriangleMesh& mesh, const std::vector<Ray>& srdh_rays,
         const KdTreeOptions& options = {});
  /// Adds the multi-index parts (leaf boxes, ropes, lifted indices) to a tree built without them
  /// (the constructor calls it when options.multi_index; separate so that their cost can be
  /// measured on its own).
  void build_multi_index(const KdTreeOptions& options);

  /// Any hit with a stack traversal in the given order (the baseline and SATO; SRDH once
  /// train_srdh has run, else it behaves as SATO). `counters` may be null.
  bool occluded(const Ray& ray, Order order, KindCounters* counters = nullptr) const;
  /// The multi-index traversal: `predict_occluded` true = lifted indices first (front-to-back
  /// stack traversal), false = rope walk. Same answers as occluded().
  bool occluded_multi_index(const Ray& ray, bool predict_occluded,
                            KindCounters* counters = nullptr) const;
  /// Up to eight rays traced together (the CPU core's 8-wide shadow packets): the standard
  /// front-to-back stack traversal, one node fetch per packet, 8-wide SIMD interval and
  /// watertight triangle tests (GCC/Clang vector extensions compiled for AVX2 on x86-64, checked
  /// at run time; without AVX2 the rays are traced one by one, same answers). Each
  /// ray's interval at a node is computed exactly as occluded(ray, Order::standard) computes it,
  /// and a ray is tested only against the leaves whose interval it enters, with the same float
  /// operations: its answer is that traversal's, bit for bit (only the visiting order differs).
  /// Lane k (rays[k]) is traced when bit k of `lanes` is set; returns the occluded lanes' bits.
  /// No lifted indices or ropes (per-ray structures); any tree (plain, SRDH's or multi-index).
  unsigned occluded8(const Ray* rays, unsigned lanes, KindCounters* counters = nullptr) const;
  /// SRDH's per-node order from a representative ray set (each traced through both children of
  /// every node it enters, recording where it is occluded and how much work each child took).
  void train_srdh(const std::vector<Ray>& sample_rays);

  std::size_t triangle_count() const { return triangles_.size() / 9; }
  std::size_t node_count() const { return nodes_.size(); }
  std::size_t leaf_count() const { return leaf_count_; }
  std::size_t empty_leaf_count() const;
  /// Leaf triangle references (a triangle is referenced by every leaf it touches).
  std::size_t reference_count() const { return refs_.size(); }
  std::size_t lifted_count() const { return lifted_prims_.size(); }
  int max_depth() const { return max_depth_; }
  /// Bytes held: nodes, triangle references, triangles, and (multi-index) leaf boxes, ropes and
  /// lifted indices.
  std::size_t memory_bytes(bool multi_index_parts) const;

  // For tests of the rope structure.
  /// The leaf holding point p (ties on a split plane go to the side `direction` points to).
  std::uint32_t leaf_at(const std::array<float, 3>& p, const std::array<float, 3>& direction) const;
  /// The leaf a rope walk reaches from `leaf` through face `face` (0..5: -x, +x, -y, +y, -z, +z)
  /// at point p on that face, or ~0u if the face is on the scene's boundary.
  std::uint32_t rope_step(std::uint32_t leaf, int face, const std::array<float, 3>& p,
                          const std::array<float, 3>& direction) const;
  const Box& leaf_box(std::uint32_t leaf) const { return leaf_boxes_[leaf]; }
  const Box& bounds() const { return bounds_; }

  struct Node {
    float split;
    // bits 0-1: axis (3 = leaf); bit 2: SATO left first; bit 3: SRDH left first;
    // leaf: bits 4-31 = triangle count.
    std::uint32_t flags;
    std::uint32_t a;  // interior: right child (left = this + 1); leaf: first reference
    std::uint32_t b;  // interior: lifted range index or ~0u; leaf: leaf number
  };

 private:
  struct Builder;
  template <bool kCount>
  bool stack_traverse(const Ray& ray, int order_bit, bool use_lifted, float t_start,
                      KindCounters* counters, std::uint64_t& nodes, std::uint64_t& prims) const;
  template <bool kCount>
  unsigned packet_traverse(const Ray* rays, unsigned lanes, KindCounters* counters) const;
  template <bool kCount>
  bool rope_walk(const Ray& ray, KindCounters* counters, std::uint64_t& nodes,
                 std::uint64_t& prims) const;
  /// Every subtree's SAH cost (C_trav, C_isect of `options`), per node.
  std::vector<float> subtree_costs(const KdTreeOptions& options) const;
  void build_ropes();
  void lift_primitives(const KdTreeOptions& options);
  std::uint32_t descend(std::uint32_t node, const std::array<float, 3>& p,
                        const std::array<float, 3>& direction, int entry_face,
                        std::uint64_t& visited) const;

  std::vector<float> triangles_;     // 9 floats per triangle (v0, v1, v2)
  std::vector<std::uint32_t> refs_;  // leaf triangle references
  std::vector<Node> nodes_;
  Box bounds_{};
  int max_depth_ = 0;
  std::size_t leaf_count_ = 0;
  // Multi-index parts.
  std::vector<Box> leaf_boxes_;                              // per leaf number
  std::vector<std::array<std::uint32_t, 6>> ropes_;          // per leaf number: node index or ~0u
  std::vector<std::array<std::uint32_t, 2>> lifted_ranges_;  // (first, count) in lifted_prims_
  std::vector<std::uint32_t> lifted_prims_;
};

}  // namespace mr::render::shadow
