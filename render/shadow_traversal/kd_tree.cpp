#include "render/shadow_traversal/kd_tree.h"

#include <tbb/task_group.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <utility>

#include "mr/error.h"

namespace mr::render::shadow {

namespace {

constexpr std::uint32_t kNone = ~0u;
constexpr std::uint32_t kLeafAxis = 3;
constexpr int kBins = 32;
constexpr int kStackSize = 128;
constexpr int kMaxTested = 32;  // lifted triangles a ray remembers having tested
constexpr float kInf = std::numeric_limits<float>::infinity();

float surface_area(const Box& b) {
  const float dx = std::max(0.0f, b.hi[0] - b.lo[0]);
  const float dy = std::max(0.0f, b.hi[1] - b.lo[1]);
  const float dz = std::max(0.0f, b.hi[2] - b.lo[2]);
  return 2.0f * (dx * dy + dy * dz + dz * dx);
}

Box clip(const Box& a, const Box& b) {
  Box c;
  for (int k = 0; k < 3; ++k) {
    c.lo[k] = std::max(a.lo[k], b.lo[k]);
    c.hi[k] = std::min(a.hi[k], b.hi[k]);
  }
  return c;
}

/// The ray, prepared for the watertight test (Woop et al. 2013, section 3).
struct WoopRay {
  float o[3], d[3], inv[3];
  int kx, ky, kz;
  float sx, sy, sz;
  float t_near, t_far;
  bool valid;
};

WoopRay prepare(const Ray& r) {
  WoopRay w{};
  for (int k = 0; k < 3; ++k) {
    w.o[k] = r.origin[k];
    w.d[k] = r.direction[k];
    w.inv[k] = 1.0f / r.direction[k];
  }
  w.t_near = r.t_near;
  w.t_far = r.t_far;
  const float ax = std::fabs(w.d[0]), ay = std::fabs(w.d[1]), az = std::fabs(w.d[2]);
  w.kz = ax > ay ? (ax > az ? 0 : 2) : (ay > az ? 1 : 2);
  w.kx = (w.kz + 1) % 3;
  w.ky = (w.kx + 1) % 3;
  if (w.d[w.kz] < 0.0f) std::swap(w.kx, w.ky);  // keep the winding
  w.valid = w.d[w.kz] != 0.0f && std::isfinite(w.d[w.kz]) && r.t_far > r.t_near;
  if (w.valid) {
    w.sx = w.d[w.kx] / w.d[w.kz];
    w.sy = w.d[w.ky] / w.d[w.kz];
    w.sz = 1.0f / w.d[w.kz];
  }
  return w;
}

/// Watertight ray-triangle test: edges and vertices hit (closed triangle), t_near < t <= t_far.
bool hit_triangle(const WoopRay& r, const float* v) {
  const float a[3] = {v[0] - r.o[0], v[1] - r.o[1], v[2] - r.o[2]};
  const float b[3] = {v[3] - r.o[0], v[4] - r.o[1], v[5] - r.o[2]};
  const float c[3] = {v[6] - r.o[0], v[7] - r.o[1], v[8] - r.o[2]};
  const float ax = a[r.kx] - r.sx * a[r.kz], ay = a[r.ky] - r.sy * a[r.kz];
  const float bx = b[r.kx] - r.sx * b[r.kz], by = b[r.ky] - r.sy * b[r.kz];
  const float cx = c[r.kx] - r.sx * c[r.kz], cy = c[r.ky] - r.sy * c[r.kz];
  float u = cx * by - cy * bx;
  float vv = ax * cy - ay * cx;
  float w = bx * ay - by * ax;
  if (u == 0.0f || vv == 0.0f || w == 0.0f) {  // the paper's fallback: exact in double
    u = float(double(cx) * double(by) - double(cy) * double(bx));
    vv = float(double(ax) * double(cy) - double(ay) * double(cx));
    w = float(double(bx) * double(ay) - double(by) * double(ax));
  }
  if ((u < 0.0f || vv < 0.0f || w < 0.0f) && (u > 0.0f || vv > 0.0f || w > 0.0f)) return false;
  const float det = u + vv + w;
  if (det == 0.0f) return false;
  const float az = r.sz * a[r.kz], bz = r.sz * b[r.kz], cz = r.sz * c[r.kz];
  const float t = (u * az + vv * bz + w * cz) / det;
  return t > r.t_near && t <= r.t_far;
}

/// The ray's parameter interval inside box b (slab test), or empty (lo > hi).
void clip_to_box(const WoopRay& r, const Box& b, float& lo, float& hi) {
  lo = r.t_near;
  hi = r.t_far;
  for (int k = 0; k < 3; ++k) {
    if (r.d[k] == 0.0f) {
      if (r.o[k] < b.lo[k] || r.o[k] > b.hi[k]) {
        lo = 1.0f;
        hi = 0.0f;
        return;
      }
      continue;
    }
    float t0 = (b.lo[k] - r.o[k]) * r.inv[k], t1 = (b.hi[k] - r.o[k]) * r.inv[k];
    if (t0 > t1) std::swap(t0, t1);
    // Rounding slack: a leaf skipped here would lose its triangles' hits.
    const float e = 1e-6f * std::max(std::fabs(t0), std::fabs(t1));
    lo = std::max(lo, t0 - e);
    hi = std::min(hi, t1 + e);
  }
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Build

struct KdTree::BuildNode {
  Box box{};
  bool leaf = true;
  int axis = 0;
  float split = 0;
  std::unique_ptr<BuildNode> left, right;
  std::vector<std::uint32_t> prims;
};

struct KdTree::Context {
  const KdTreeOptions* options;
  std::vector<Box> tri_boxes;
  int max_depth = 0;

  std::unique_ptr<BuildNode> build(std::vector<std::uint32_t> refs, const Box& box, int depth) {
    auto node = std::make_unique<BuildNode>();
    node->box = box;
    const std::size_t n = refs.size();
    const KdTreeOptions& o = *options;
    const float leaf_cost = o.cost_intersect * float(n);
    const float sa = surface_area(box);
    if (n <= std::size_t(o.max_leaf_size) || depth >= max_depth || !(sa > 0.0f)) {
      node->prims = std::move(refs);
      return node;
    }
    float best_cost = leaf_cost;
    int best_axis = -1;
    float best_split = 0;
    for (int axis = 0; axis < 3; ++axis) {
      const float lo = box.lo[axis], extent = box.hi[axis] - lo;
      if (!(extent > 0.0f)) continue;
      int starts[kBins] = {}, ends[kBins] = {};
      const float scale = float(kBins) / extent;
      for (std::uint32_t t : refs) {
        const Box& tb = tri_boxes[t];
        const float tlo = std::max(tb.lo[axis], lo), thi = std::min(tb.hi[axis], box.hi[axis]);
        starts[std::clamp(int((tlo - lo) * scale), 0, kBins - 1)]++;
        ends[std::clamp(int((thi - lo) * scale), 0, kBins - 1)]++;
      }
      int n_left = 0, n_right = int(n);
      for (int i = 1; i < kBins; ++i) {
        n_left += starts[i - 1];
        n_right -= ends[i - 1];
        const float plane = lo + extent * float(i) / float(kBins);
        Box bl = box, br = box;
        bl.hi[axis] = plane;
        br.lo[axis] = plane;
        float cost = o.cost_traversal + o.cost_intersect *
                                            (surface_area(bl) * float(n_left) +
                                             surface_area(br) * float(n_right)) /
                                            sa;
        if (n_left == 0 || n_right == 0) cost *= o.empty_bonus;
        if (cost < best_cost) {
          best_cost = cost;
          best_axis = axis;
          best_split = plane;
        }
      }
    }
    if (best_axis < 0) {
      node->prims = std::move(refs);
      return node;
    }
    std::vector<std::uint32_t> left, right;
    left.reserve(n / 2 + 1);
    right.reserve(n / 2 + 1);
    for (std::uint32_t t : refs) {
      const Box& tb = tri_boxes[t];
      const float tlo = std::max(tb.lo[best_axis], box.lo[best_axis]);
      const float thi = std::min(tb.hi[best_axis], box.hi[best_axis]);
      if (tlo <= best_split) left.push_back(t);
      if (thi >= best_split) right.push_back(t);
    }
    if (left.size() == n && right.size() == n) {  // the split separates nothing
      node->prims = std::move(refs);
      return node;
    }
    refs.clear();
    refs.shrink_to_fit();
    node->leaf = false;
    node->axis = best_axis;
    node->split = best_split;
    Box bl = box, br = box;
    bl.hi[best_axis] = best_split;
    br.lo[best_axis] = best_split;
    if (n > 20000) {
      tbb::task_group group;
      group.run([&] { node->left = build(std::move(left), bl, depth + 1); });
      node->right = build(std::move(right), br, depth + 1);
      group.wait();
    } else {
      node->left = build(std::move(left), bl, depth + 1);
      node->right = build(std::move(right), br, depth + 1);
    }
    return node;
  }
};

KdTree::KdTree(const TriangleMesh& mesh, const KdTreeOptions& options) {
  const std::size_t vertices = mesh.positions.size() / 3;  // ignores OccluderScene's padding
  if (mesh.indices.size() % 3 != 0)
    throw Error(ErrorCode::invalid_argument, "kd-tree: occluder mesh has " +
                                                 std::to_string(mesh.indices.size()) +
                                                 " indices, not a multiple of 3");
  const std::size_t count = mesh.indices.size() / 3;
  triangles_.resize(9 * count);
  Context ctx;
  ctx.options = &options;
  ctx.tri_boxes.resize(count);
  Box bounds{{kInf, kInf, kInf}, {-kInf, -kInf, -kInf}};
  for (std::size_t t = 0; t < count; ++t) {
    Box& tb = ctx.tri_boxes[t];
    tb = Box{{kInf, kInf, kInf}, {-kInf, -kInf, -kInf}};
    for (int v = 0; v < 3; ++v) {
      const std::uint32_t index = mesh.indices[3 * t + std::size_t(v)];
      if (index >= vertices)
        throw Error(ErrorCode::invalid_argument,
                    "kd-tree: occluder mesh index " + std::to_string(3 * t + std::size_t(v)) +
                        " is " + std::to_string(index) + ", but the mesh has " +
                        std::to_string(vertices) + " vertices");
      for (int k = 0; k < 3; ++k) {
        const float x = mesh.positions[3 * std::size_t(index) + std::size_t(k)];
        if (!std::isfinite(x))
          throw Error(ErrorCode::invalid_argument,
                      "kd-tree: occluder mesh vertex " + std::to_string(index) + " is not finite");
        triangles_[9 * t + 3 * std::size_t(v) + std::size_t(k)] = x;
        tb.lo[k] = std::min(tb.lo[k], x);
        tb.hi[k] = std::max(tb.hi[k], x);
      }
    }
    for (int k = 0; k < 3; ++k) {
      bounds.lo[k] = std::min(bounds.lo[k], tb.lo[k]);
      bounds.hi[k] = std::max(bounds.hi[k], tb.hi[k]);
    }
  }
  if (count == 0) bounds = Box{{0, 0, 0}, {0, 0, 0}};
  bounds_ = bounds;
  ctx.max_depth = int(8 + 1.3 * std::log2(double(std::max<std::size_t>(count, 1))));
  std::vector<std::uint32_t> all(count);
  for (std::size_t t = 0; t < count; ++t) all[t] = std::uint32_t(t);
  std::unique_ptr<BuildNode> root = ctx.build(std::move(all), bounds, 0);

  // Flatten depth first (left child right after its parent), recording what the multi-index
  // parts and the SATO order need.
  std::vector<Box> node_boxes;
  std::vector<int> node_depth;
  std::vector<std::uint32_t> parent;
  std::vector<float> subtree_cost, subtree_area;
  struct Frame {
    BuildNode* node;
    std::uint32_t parent;
    int depth;
  };
  // Iterative pre-order (right pushed first so left comes next).
  std::vector<Frame> todo{{root.get(), kNone, 0}};
  std::vector<std::pair<std::uint32_t, BuildNode*>> right_links;  // (parent index, right node)
  std::vector<BuildNode*> flat_build;
  while (!todo.empty()) {
    Frame f = todo.back();
    todo.pop_back();
    const std::uint32_t index = std::uint32_t(nodes_.size());
    // A right child: patch its parent's link.
    if (f.parent != kNone && nodes_[f.parent].a == kNone && index != f.parent + 1)
      nodes_[f.parent].a = index;
    Node n{};
    max_depth_ = std::max(max_depth_, f.depth);
    if (f.node->leaf) {
      n.split = 0;
      n.flags = kLeafAxis | (std::uint32_t(f.node->prims.size()) << 4);
      n.a = std::uint32_t(refs_.size());
      n.b = std::uint32_t(leaf_nodes_.size());
      refs_.insert(refs_.end(), f.node->prims.begin(), f.node->prims.end());
      leaf_nodes_.push_back(index);
      leaf_boxes_.push_back(f.node->box);
    } else {
      n.split = f.node->split;
      n.flags = std::uint32_t(f.node->axis);
      n.a = kNone;  // patched when the right child is emitted
      n.b = kNone;
      todo.push_back({f.node->right.get(), index, f.depth + 1});
      todo.push_back({f.node->left.get(), index, f.depth + 1});
    }
    nodes_.push_back(n);
    node_boxes.push_back(f.node->box);
    node_depth.push_back(f.depth);
    parent.push_back(f.parent);
    flat_build.push_back(f.node);
  }
  // Bottom-up: SAH cost and triangle area of every subtree (children have larger indices).
  subtree_cost.assign(nodes_.size(), 0.0f);
  subtree_area.assign(nodes_.size(), 0.0f);
  for (std::size_t i = nodes_.size(); i-- > 0;) {
    const Node& n = nodes_[i];
    if ((n.flags & 3u) == kLeafAxis) {
      const std::uint32_t count_here = n.flags >> 4;
      subtree_cost[i] = options.cost_intersect * float(count_here);
      float area = 0;
      for (std::uint32_t k = 0; k < count_here; ++k) {
        const float* v = &triangles_[9 * std::size_t(refs_[n.a + k])];
        const float e1[3] = {v[3] - v[0], v[4] - v[1], v[5] - v[2]};
        const float e2[3] = {v[6] - v[0], v[7] - v[1], v[8] - v[2]};
        const float cx = e1[1] * e2[2] - e1[2] * e2[1], cy = e1[2] * e2[0] - e1[0] * e2[2],
                    cz = e1[0] * e2[1] - e1[1] * e2[0];
        area += 0.5f * std::sqrt(cx * cx + cy * cy + cz * cz);
      }
      subtree_area[i] = area;
    } else {
      const std::size_t l = i + 1, r = n.a;
      const float sa = surface_area(node_boxes[i]);
      subtree_cost[i] = options.cost_traversal +
                        (sa > 0 ? (surface_area(node_boxes[l]) * subtree_cost[l] +
                                   surface_area(node_boxes[r]) * subtree_cost[r]) /
                                      sa
                                : subtree_cost[l] + subtree_cost[r]);
      subtree_area[i] = subtree_area[l] + subtree_area[r];
      // SATO: the child with the larger occlusion chance per unit of traversal cost first. The
      // chance that a random line through a box meets a triangle of area A in it is about
      // 2 A / SA(box) (mean projected area A / 2 over SA / 4); capped at 1 (the areas overlap).
      auto score = [&](std::size_t c) {
        const double sa_c = std::max(1e-30, double(surface_area(node_boxes[c])));
        return std::min(1.0, 2.0 * double(subtree_area[c]) / sa_c) /
               std::max(1e-30, double(subtree_cost[c]));
      };
      const double score_l = score(l), score_r = score(r);
      if (score_l >= score_r) nodes_[i].flags |= 4u | 8u;  // SRDH starts as SATO
    }
  }
  root.reset();
  if (options.multi_index) {
    build_ropes();
    lift_primitives(options, subtree_cost, node_boxes, node_depth, parent);
  } else {
    leaf_boxes_.clear();
    leaf_boxes_.shrink_to_fit();
  }
}

void KdTree::build_ropes() {
  ropes_.assign(leaf_nodes_.size(), {kNone, kNone, kNone, kNone, kNone, kNone});
  if (nodes_.empty()) return;
  struct Frame {
    std::uint32_t node;
    std::array<std::uint32_t, 6> ropes;
  };
  std::vector<Frame> todo{{0, {kNone, kNone, kNone, kNone, kNone, kNone}}};
  while (!todo.empty()) {
    Frame f = todo.back();
    todo.pop_back();
    const Node& n = nodes_[f.node];
    const std::uint32_t axis = n.flags & 3u;
    if (axis == kLeafAxis) {
      const Box& box = leaf_boxes_[n.b];
      // Popov et al. 2007: push each rope down to the smallest node holding the whole face.
      for (int face = 0; face < 6; ++face) {
        std::uint32_t r = f.ropes[std::size_t(face)];
        const int face_axis = face / 2;
        while (r != kNone) {
          const Node& t = nodes_[r];
          const std::uint32_t ta = t.flags & 3u;
          if (ta == kLeafAxis) break;
          if (int(ta) == face_axis)
            r = (face & 1) ? r + 1 : t.a;  // the child adjacent to the face
          else if (t.split <= box.lo[ta])
            r = t.a;
          else if (t.split >= box.hi[ta])
            r = r + 1;
          else
            break;
        }
        ropes_[n.b][std::size_t(face)] = r;
      }
      continue;
    }
    Frame left{f.node + 1, f.ropes}, right{n.a, f.ropes};
    left.ropes[2 * axis + 1] = n.a;
    right.ropes[2 * axis] = f.node + 1;
    todo.push_back(right);
    todo.push_back(left);
  }
}

void KdTree::lift_primitives(const KdTreeOptions& options, const std::vector<float>& subtree_cost,
                             const std::vector<Box>& node_boxes,
                             const std::vector<int>& node_depth,
                             const std::vector<std::uint32_t>& parent) {
  const std::size_t count = triangle_count();
  if (count == 0) return;
  std::vector<Box> boxes(count);
  double mean_area = 0;
  for (std::size_t t = 0; t < count; ++t) {
    const float* v = &triangles_[9 * t];
    Box& b = boxes[t];
    for (int k = 0; k < 3; ++k) {
      b.lo[k] = std::min({v[k], v[3 + k], v[6 + k]});
      b.hi[k] = std::max({v[k], v[3 + k], v[6 + k]});
    }
    mean_area += surface_area(b);
  }
  mean_area /= double(count);
  // One leaf per triangle (its first): the ancestors of that leaf are the candidate places.
  std::vector<std::uint32_t> first_leaf(count, kNone);
  for (std::uint32_t leaf = 0; leaf < leaf_nodes_.size(); ++leaf) {
    const Node& n = nodes_[leaf_nodes_[leaf]];
    for (std::uint32_t k = 0; k < (n.flags >> 4); ++k) {
      std::uint32_t& f = first_leaf[refs_[n.a + k]];
      if (f == kNone) f = leaf_nodes_[leaf];
    }
  }
  struct Candidate {
    float gain;
    std::uint32_t triangle;
  };
  std::vector<std::vector<Candidate>> per_node(nodes_.size());
  for (std::size_t t = 0; t < count; ++t) {
    if (first_leaf[t] == kNone || !(surface_area(boxes[t]) > options.lift_area_ratio * mean_area))
      continue;
    float best_gain = options.lift_min_gain;
    std::uint32_t best = kNone;
    for (std::uint32_t n = parent[first_leaf[t]]; n != kNone; n = parent[n]) {
      const float sa = surface_area(node_boxes[n]);
      if (!(sa > 0)) continue;
      const float p_hit = std::min(1.0f, surface_area(clip(boxes[t], node_boxes[n])) / sa);
      const float gain = (p_hit - options.cost_intersect / subtree_cost[n]) *
                         (1.0f - std::exp(-options.lift_lambda * float(node_depth[n])));
      if (gain > best_gain) {
        best_gain = gain;
        best = n;
      }
    }
    if (best != kNone) per_node[best].push_back({best_gain, std::uint32_t(t)});
  }
  for (std::size_t n = 0; n < nodes_.size(); ++n) {
    auto& c = per_node[n];
    if (c.empty()) continue;
    std::sort(c.begin(), c.end(), [](const Candidate& a, const Candidate& b) {
      return a.gain > b.gain || (a.gain == b.gain && a.triangle < b.triangle);
    });
    if (c.size() > std::size_t(options.lift_max_per_node)) c.resize(std::size_t(options.lift_max_per_node));
    nodes_[n].b = std::uint32_t(lifted_ranges_.size());
    lifted_ranges_.push_back({std::uint32_t(lifted_prims_.size()), std::uint32_t(c.size())});
    for (const Candidate& k : c) lifted_prims_.push_back(k.triangle);
  }
}

std::size_t KdTree::memory_bytes(bool multi_index_parts) const {
  std::size_t bytes = nodes_.size() * sizeof(Node) + refs_.size() * sizeof(std::uint32_t) +
                      triangles_.size() * sizeof(float);
  if (multi_index_parts)
    bytes += leaf_boxes_.size() * sizeof(Box) + leaf_nodes_.size() * sizeof(std::uint32_t) +
             ropes_.size() * sizeof(ropes_[0]) + lifted_ranges_.size() * sizeof(lifted_ranges_[0]) +
             lifted_prims_.size() * sizeof(std::uint32_t);
  return bytes;
}

// ---------------------------------------------------------------------------------------------
// Traversal

template <bool kCount>
bool KdTree::stack_traverse(const Ray& ray, int order_bit, bool use_lifted, float t_start,
                            KindCounters* /*counters*/, std::uint64_t& nodes,
                            std::uint64_t& prims) const {
  const WoopRay r = prepare(ray);
  if (!r.valid || nodes_.empty()) return false;
  float t0, t1;
  clip_to_box(r, bounds_, t0, t1);
  t0 = std::max(t0, t_start);
  if (!(t0 <= t1)) return false;
  struct Entry {
    std::uint32_t node;
    float t_min, t_max;
  };
  Entry stack[kStackSize];
  int top = 0;
  std::uint32_t tested[kMaxTested];
  int tested_count = 0;
  std::uint32_t node = 0;
  float t_min = t0, t_max = t1;
  for (;;) {
    const Node* n = &nodes_[node];
    if constexpr (kCount) ++nodes;
    const std::uint32_t axis = n->flags & 3u;
    if (axis != kLeafAxis) {
      if (use_lifted && n->b != kNone) {
        const auto& range = lifted_ranges_[n->b];
        for (std::uint32_t k = 0; k < range[1]; ++k) {
          const std::uint32_t t = lifted_prims_[range[0] + k];
          if constexpr (kCount) ++prims;
          if (hit_triangle(r, &triangles_[9 * std::size_t(t)])) return true;
          if (tested_count < kMaxTested) tested[tested_count++] = t;
        }
      }
      const std::uint32_t left = node + 1, right = n->a;
      const float o = r.o[axis], d = r.d[axis], split = n->split;
      // Child intervals along the ray. With d == 0 the ray stays on one side (both if on the plane).
      bool visit_left, visit_right;
      float left_min = t_min, left_max = t_max, right_min = t_min, right_max = t_max;
      if (d == 0.0f) {
        visit_left = o <= split;
        visit_right = o >= split;
      } else {
        const float t_split = (split - o) * r.inv[axis];
        const float e = 1e-6f * std::max(std::fabs(t_min), std::fabs(t_max));
        // Which child the ray is in first.
        const bool left_first = d > 0.0f;
        const float first_max = std::min(t_max, t_split + e);
        const float second_min = std::max(t_min, t_split - e);
        const bool visit_first = t_min <= first_max;
        const bool visit_second = second_min <= t_max;
        if (left_first) {
          visit_left = visit_first;
          visit_right = visit_second;
          left_max = first_max;
          right_min = second_min;
        } else {
          visit_right = visit_first;
          visit_left = visit_second;
          right_max = first_max;
          left_min = second_min;
        }
      }
      bool left_before;  // visit order when both are entered
      if (order_bit < 0)
        left_before = d >= 0.0f;
      else
        left_before = (n->flags >> order_bit) & 1u;
      if (visit_left && visit_right) {
        if (top >= kStackSize)  // never at the depths the build allows; a full restart is correct
          return stack_traverse<kCount>(ray, -1, false, -kInf, nullptr, nodes, prims);
        if (left_before) {
          stack[top++] = {right, right_min, right_max};
          node = left;
          t_min = left_min;
          t_max = left_max;
        } else {
          stack[top++] = {left, left_min, left_max};
          node = right;
          t_min = right_min;
          t_max = right_max;
        }
        continue;
      }
      if (visit_left) {
        node = left;
        t_min = left_min;
        t_max = left_max;
        continue;
      }
      if (visit_right) {
        node = right;
        t_min = right_min;
        t_max = right_max;
        continue;
      }
    } else {
      const std::uint32_t count = n->flags >> 4;
      for (std::uint32_t k = 0; k < count; ++k) {
        const std::uint32_t t = refs_[n->a + k];
        if (tested_count > 0) {
          bool seen = false;
          for (int j = 0; j < tested_count; ++j) seen = seen || tested[j] == t;
          if (seen) continue;
        }
        if constexpr (kCount) ++prims;
        if (hit_triangle(r, &triangles_[9 * std::size_t(t)])) return true;
      }
    }
    if (top == 0) return false;
    --top;
    node = stack[top].node;
    t_min = stack[top].t_min;
    t_max = stack[top].t_max;
  }
}

std::uint32_t KdTree::descend(std::uint32_t node, const std::array<float, 3>& p,
                              const std::array<float, 3>& direction, int entry_face,
                              std::uint64_t& visited) const {
  for (;;) {
    const Node& n = nodes_[node];
    ++visited;
    const std::uint32_t axis = n.flags & 3u;
    if (axis == kLeafAxis) return node;
    if (entry_face >= 0 && int(axis) == entry_face / 2) {
      node = (entry_face & 1) ? node + 1 : n.a;  // the side adjacent to the face crossed
    } else if (p[axis] < n.split) {
      node = node + 1;
    } else if (p[axis] > n.split) {
      node = n.a;
    } else {
      node = direction[axis] > 0.0f ? n.a : node + 1;
    }
  }
}

std::uint32_t KdTree::leaf_at(const std::array<float, 3>& p,
                              const std::array<float, 3>& direction) const {
  std::uint64_t visited = 0;
  return nodes_[descend(0, p, direction, -1, visited)].b;
}

std::uint32_t KdTree::rope_step(std::uint32_t leaf, int face, const std::array<float, 3>& p,
                                const std::array<float, 3>& direction) const {
  const std::uint32_t r = ropes_[leaf][std::size_t(face)];
  if (r == kNone) return kNone;
  std::uint64_t visited = 0;
  return nodes_[descend(r, p, direction, face, visited)].b;
}

template <bool kCount>
bool KdTree::rope_walk(const Ray& ray, KindCounters* counters, std::uint64_t& nodes,
                       std::uint64_t& prims) const {
  const WoopRay r = prepare(ray);
  if (!r.valid || nodes_.empty()) return false;
  float t0, t1;
  clip_to_box(r, bounds_, t0, t1);
  if (!(t0 <= t1)) return false;
  const std::array<float, 3> dir = ray.direction;
  std::array<float, 3> p = {r.o[0] + r.d[0] * t0, r.o[1] + r.d[1] * t0, r.o[2] + r.d[2] * t0};
  std::uint64_t visited = 0;
  std::uint32_t node = descend(0, p, dir, -1, visited);
  float t = t0;
  const std::size_t max_steps = leaf_boxes_.size() + 16;
  for (std::size_t step = 0; step < max_steps; ++step) {
    const Node& n = nodes_[node];
    const std::uint32_t count = n.flags >> 4;
    for (std::uint32_t k = 0; k < count; ++k) {
      if constexpr (kCount) ++prims;
      if (hit_triangle(r, &triangles_[9 * std::size_t(refs_[n.a + k])])) {
        if constexpr (kCount) nodes += visited;
        return true;
      }
    }
    const Box& box = leaf_boxes_[n.b];
    float t_exit = kInf;
    int face = -1;
    for (int k = 0; k < 3; ++k) {
      if (r.d[k] > 0.0f) {
        const float te = (box.hi[k] - r.o[k]) * r.inv[k];
        if (te < t_exit) {
          t_exit = te;
          face = 2 * k + 1;
        }
      } else if (r.d[k] < 0.0f) {
        const float te = (box.lo[k] - r.o[k]) * r.inv[k];
        if (te < t_exit) {
          t_exit = te;
          face = 2 * k;
        }
      }
    }
    if (face < 0 || t_exit > t1) break;
    const std::uint32_t rope = ropes_[n.b][std::size_t(face)];
    if (rope == kNone) break;
    t = std::max(t, t_exit);
    p = {r.o[0] + r.d[0] * t, r.o[1] + r.d[1] * t, r.o[2] + r.d[2] * t};
    const std::uint32_t next = descend(rope, p, dir, face, visited);
    if (next == node) {  // no progress (rounding): finish with a root descent
      if constexpr (kCount) {
        nodes += visited;
        if (counters) ++counters->rope_fallbacks;
      }
      return stack_traverse<kCount>(ray, -1, false, t, nullptr, nodes, prims);
    }
    node = next;
  }
  if constexpr (kCount) nodes += visited;
  return false;
}

bool KdTree::occluded(const Ray& ray, Order order, KindCounters* counters) const {
  const int bit = order == Order::standard ? -1 : order == Order::sato ? 2 : 3;
  std::uint64_t nodes = 0, prims = 0;
  if (!counters) return stack_traverse<false>(ray, bit, false, -kInf, nullptr, nodes, prims);
  const bool hit = stack_traverse<true>(ray, bit, false, -kInf, counters, nodes, prims);
  Counters& c = hit ? counters->occluded : counters->unoccluded;
  ++c.rays;
  c.nodes += nodes;
  c.primitives += prims;
  return hit;
}

bool KdTree::occluded_multi_index(const Ray& ray, bool predict_occluded,
                                  KindCounters* counters) const {
  std::uint64_t nodes = 0, prims = 0;
  if (!counters)
    return predict_occluded ? stack_traverse<false>(ray, -1, true, -kInf, nullptr, nodes, prims)
                            : rope_walk<false>(ray, nullptr, nodes, prims);
  const bool hit = predict_occluded
                       ? stack_traverse<true>(ray, -1, true, -kInf, counters, nodes, prims)
                       : rope_walk<true>(ray, counters, nodes, prims);
  Counters& c = hit ? counters->occluded : counters->unoccluded;
  ++c.rays;
  c.nodes += nodes;
  c.primitives += prims;
  return hit;
}

// ---------------------------------------------------------------------------------------------
// SRDH's order from a sample ray set

void KdTree::train_srdh(const std::vector<Ray>& sample_rays) {
  struct Stats {
    double entered[2] = {0, 0}, occluded[2] = {0, 0}, cost[2] = {0, 0};
  };
  std::vector<Stats> stats(nodes_.size());
  struct Result {
    bool hit;
    double cost;  // any-hit cost of this subtree for this ray, front to back
  };
  // Visits every node the ray's segment enters (no early exit), so both children of a node get
  // their statistics; returns the subtree's own any-hit outcome and cost.
  auto probe = [&](auto&& self, const WoopRay& r, std::uint32_t node, float t_min,
                   float t_max) -> Result {
    const Node& n = nodes_[node];
    const std::uint32_t axis = n.flags & 3u;
    if (axis == kLeafAxis) {
      const std::uint32_t count = n.flags >> 4;
      double cost = 1;
      for (std::uint32_t k = 0; k < count; ++k) {
        cost += 1.5;
        if (hit_triangle(r, &triangles_[9 * std::size_t(refs_[n.a + k])])) return {true, cost};
      }
      return {false, cost};
    }
    const float o = r.o[axis], d = r.d[axis];
    bool visit[2];
    float lo[2] = {t_min, t_min}, hi[2] = {t_max, t_max};
    if (d == 0.0f) {
      visit[0] = o <= n.split;
      visit[1] = o >= n.split;
    } else {
      const float ts = (n.split - o) * r.inv[axis];
      const float e = 1e-6f * std::max(std::fabs(t_min), std::fabs(t_max));
      const int first = d > 0.0f ? 0 : 1;
      hi[first] = std::min(t_max, ts + e);
      lo[1 - first] = std::max(t_min, ts - e);
      visit[first] = t_min <= hi[first];
      visit[1 - first] = lo[1 - first] <= t_max;
    }
    const std::uint32_t child[2] = {node + 1, n.a};
    Result res[2] = {{false, 0}, {false, 0}};
    Stats& s = stats[node];
    for (int c = 0; c < 2; ++c) {
      if (!visit[c]) continue;
      res[c] = self(self, r, child[c], lo[c], hi[c]);
      s.entered[c] += 1;
      s.occluded[c] += res[c].hit ? 1 : 0;
      s.cost[c] += res[c].cost;
    }
    const int first = d >= 0.0f ? 0 : 1;
    const double cost = 1 + res[first].cost + (res[first].hit ? 0 : res[1 - first].cost);
    return {res[0].hit || res[1].hit, cost};
  };
  for (const Ray& ray : sample_rays) {
    const WoopRay r = prepare(ray);
    if (!r.valid || nodes_.empty()) continue;
    float t0, t1;
    clip_to_box(r, bounds_, t0, t1);
    if (!(t0 <= t1)) continue;
    probe(probe, r, 0, t0, t1);
  }
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    const Stats& s = stats[i];
    if ((nodes_[i].flags & 3u) == kLeafAxis || s.entered[0] + s.entered[1] == 0) continue;
    double score[2];
    for (int c = 0; c < 2; ++c) {
      const double p = (s.occluded[c] + 1) / (s.entered[c] + 2);  // Laplace: unseen = 1/2
      const double cost = s.entered[c] > 0 ? s.cost[c] / s.entered[c] : 1.0;
      score[c] = p / cost;
    }
    if (score[0] >= score[1])
      nodes_[i].flags |= 8u;
    else
      nodes_[i].flags &= ~8u;
  }
}

}  // namespace mr::render::shadow
