#include "render/shadow_traversal/kd_tree.h"

#include <tbb/task_group.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <string>
#include <utility>

#include "mr/error.h"
#include "render/shadow_traversal/simd8.h"
#include "render/shadow_traversal/triangle_test.h"

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

WoopRay prepare(const Ray& r) {
  return prepare_woop_ray(r.origin.data(), r.direction.data(), r.t_near, r.t_far);
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

namespace {

/// A triangle reference during the build: the triangle's part inside the node, bounded.
struct PrimRef {
  float lo[3], hi[3];
  std::uint32_t tri;
};

/// A subtree built on its own (a parallel task): nodes in pre-order, the left child right after
/// its parent; interior `a` = the right child's index and leaf `a` = the first reference, both
/// local to the fragment until spliced.
struct Fragment {
  std::vector<KdTree::Node> nodes;
  std::vector<std::uint32_t> refs;
};

void splice(Fragment& out, const Fragment& part) {
  const auto node_offset = std::uint32_t(out.nodes.size());
  const auto ref_offset = std::uint32_t(out.refs.size());
  out.nodes.reserve(out.nodes.size() + part.nodes.size());
  for (KdTree::Node n : part.nodes) {
    n.a += (n.flags & 3u) == kLeafAxis ? ref_offset : node_offset;
    out.nodes.push_back(n);
  }
  out.refs.insert(out.refs.end(), part.refs.begin(), part.refs.end());
}

/// Bounds of triangle v (9 floats) clipped to box b, conservative: Sutherland-Hodgman in double
/// against b widened by a relative 1e-6 (so a triangle that touches b, or misses it by rounding,
/// is kept), the result rounded outwards to float and clamped to b. False if the triangle misses
/// the widened box. A kd-tree leaf must hold every triangle that touches its box; a reference
/// the clip keeps needlessly only costs a test.
bool clipped_bounds(const float* v, const Box& b, PrimRef& out) {
  double poly[2][10][3];
  int count = 3;
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) poly[0][i][k] = v[3 * i + k];
  int cur = 0;
  for (int k = 0; k < 3; ++k) {
    const double widen = 1e-6 * std::max({std::fabs(double(b.lo[k])), std::fabs(double(b.hi[k])),
                                          double(b.hi[k]) - double(b.lo[k]), 1e-30});
    for (int side = 0; side < 2; ++side) {
      // Keep sign * (x_k - plane) >= 0.
      const double plane = side == 0 ? double(b.lo[k]) - widen : double(b.hi[k]) + widen;
      const double sign = side == 0 ? 1.0 : -1.0;
      const double(*in)[3] = poly[cur];
      double(*outp)[3] = poly[1 - cur];
      int n = 0;
      for (int i = 0; i < count; ++i) {
        const double* p = in[i];
        const double* q = in[(i + 1) % count];
        const double dp = sign * (p[k] - plane), dq = sign * (q[k] - plane);
        if (dp >= 0) {
          for (int c = 0; c < 3; ++c) outp[n][c] = p[c];
          ++n;
        }
        if ((dp < 0 && dq > 0) || (dp > 0 && dq < 0)) {
          const double s = dp / (dp - dq);
          for (int c = 0; c < 3; ++c) outp[n][c] = p[c] + s * (q[c] - p[c]);
          outp[n][k] = plane;  // exactly on the plane
          ++n;
        }
      }
      count = n;
      cur = 1 - cur;
      if (count == 0) return false;
    }
  }
  double lo[3] = {kInf, kInf, kInf}, hi[3] = {-kInf, -kInf, -kInf}, magnitude = 0;
  for (int i = 0; i < count; ++i)
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], poly[cur][i][k]);
      hi[k] = std::max(hi[k], poly[cur][i][k]);
    }
  for (int i = 0; i < 9; ++i) magnitude = std::max(magnitude, std::fabs(double(v[i])));
  const double slack = 1e-12 * magnitude;  // the double clip's own rounding, generously
  for (int k = 0; k < 3; ++k) {
    float l = std::nextafter(float(lo[k] - slack), -kInf);
    float h = std::nextafter(float(hi[k] + slack), kInf);
    l = std::clamp(l, b.lo[k], b.hi[k]);
    h = std::clamp(h, b.lo[k], b.hi[k]);
    out.lo[k] = l;
    out.hi[k] = h;
  }
  return true;
}

}  // namespace

/// A sample shadow ray's part inside a node during an SRDH build: [t0, t1] of ray `id`.
struct RayRef {
  float t0, t1;
  std::uint32_t id;
};

/// Binned SAH over clipped triangle bounds ("perfect splits" approximated by clipping straddling
/// triangles to each child: Wald & Havran 2006): O(references) per node, no sorting; references
/// are compact (28 bytes) and a node's list is freed before its children are built. Subtrees of
/// more than kParallelRefs references are built as TBB tasks and spliced.
///
/// With sample rays (SRDH, Feltman, Lee & Fatahalian 2012), the chance that a ray entering the
/// node enters a child is measured on the rays instead of taken as the surface-area ratio:
/// P(child) = (rays entering child + k SA(child)/SA(node)) / (rays entering node + k), k =
/// srdh_prior_rays (the SAH where few sample rays pass; exactly the SAH with none).
struct KdTree::Builder {
  const KdTreeOptions& o;
  const std::vector<float>& triangles;
  const std::vector<Ray>* rays = nullptr;  // SRDH's sample; null: SAH
  int max_depth = 0;
  // Subtrees built as tasks: big ones near the root, but not the root's children or
  // grandchildren, whose fragments (up to half the tree) would be copied once more into their
  // parent's at the end, raising the peak; below them each subtree is still built in parallel.
  static constexpr std::size_t kParallelRefs = 32768;
  static constexpr int kFirstParallelDepth = 2;
  static constexpr int kParallelDepths = 5;

  void leaf(Fragment& out, const std::vector<PrimRef>& refs) const {
    Node n{};
    n.split = 0;
    n.flags = kLeafAxis | (std::uint32_t(refs.size()) << 4);
    n.a = std::uint32_t(out.refs.size());
    n.b = kNone;
    for (const PrimRef& r : refs) out.refs.push_back(r.tri);
    out.nodes.push_back(n);
  }

  void build(Fragment& out, std::vector<PrimRef>& refs, std::vector<RayRef>& ray_refs,
             const Box& box, int depth) const {
    const std::size_t n = refs.size();
    const float sa = surface_area(box);
    if (n <= std::size_t(o.max_leaf_size) || depth >= max_depth || !(sa > 0.0f))
      return leaf(out, refs);
    float best_cost = o.cost_intersect * float(n);  // the leaf's
    int best_axis = -1;
    float best_split = 0;
    const bool srdh = !ray_refs.empty();
    const float prior = o.srdh_prior_rays;
    const float ray_total = float(ray_refs.size());
    for (int axis = 0; axis < 3; ++axis) {
      const float lo = box.lo[axis], extent = box.hi[axis] - lo;
      if (!(extent > 0.0f)) continue;
      int starts[kBins] = {}, ends[kBins] = {};
      const float scale = float(kBins) / extent;
      for (const PrimRef& r : refs) {
        starts[std::clamp(int((r.lo[axis] - lo) * scale), 0, kBins - 1)]++;
        ends[std::clamp(int((r.hi[axis] - lo) * scale), 0, kBins - 1)]++;
      }
      int ray_starts[kBins] = {}, ray_ends[kBins] = {};
      if (srdh)
        for (const RayRef& rr : ray_refs) {
          const Ray& ray = (*rays)[rr.id];
          const float c0 = ray.origin[std::size_t(axis)] + ray.direction[std::size_t(axis)] * rr.t0;
          const float c1 = ray.origin[std::size_t(axis)] + ray.direction[std::size_t(axis)] * rr.t1;
          ray_starts[std::clamp(int((std::min(c0, c1) - lo) * scale), 0, kBins - 1)]++;
          ray_ends[std::clamp(int((std::max(c0, c1) - lo) * scale), 0, kBins - 1)]++;
        }
      // SA of a child is linear in the plane's position along the axis.
      const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
      const float side1 = box.hi[a1] - box.lo[a1], side2 = box.hi[a2] - box.lo[a2];
      const float face = side1 * side2, perimeter = side1 + side2;
      int n_left = 0, n_right = int(n), r_left = 0, r_right = int(ray_refs.size());
      for (int i = 1; i < kBins; ++i) {
        n_left += starts[i - 1];
        n_right -= ends[i - 1];
        r_left += ray_starts[i - 1];
        r_right -= ray_ends[i - 1];
        const float plane = lo + extent * float(i) / float(kBins);
        // A box a few ulps wide rounds planes onto its faces: no zero-thickness children.
        if (!(plane > lo && plane < box.hi[axis])) continue;
        float p_left = 2.0f * (face + (plane - lo) * perimeter) / sa;
        float p_right = 2.0f * (face + (box.hi[axis] - plane) * perimeter) / sa;
        if (srdh) {
          p_left = (float(r_left) + prior * p_left) / (ray_total + prior);
          p_right = (float(r_right) + prior * p_right) / (ray_total + prior);
        }
        float cost = o.cost_traversal +
                     o.cost_intersect * (p_left * float(n_left) + p_right * float(n_right));
        if (n_left == 0 || n_right == 0) cost *= o.empty_bonus;
        if (cost < best_cost) {
          best_cost = cost;
          best_axis = axis;
          best_split = plane;
        }
      }
    }
    if (best_axis < 0) return leaf(out, refs);
    Box bl = box, br = box;
    bl.hi[best_axis] = best_split;
    br.lo[best_axis] = best_split;
    // The left child's list is written over the parent's (each reference read before its slot
    // is written: at most one left entry per reference read), the right one into a new list.
    std::vector<PrimRef>& left = refs;
    std::vector<PrimRef> right;
    right.reserve(n / 2 + 16);
    std::size_t n_left = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const PrimRef r = refs[i];
      if (r.hi[best_axis] < best_split) {
        left[n_left++] = r;
      } else if (r.lo[best_axis] > best_split) {
        right.push_back(r);
      } else {  // straddles or touches the plane: clip to each side
        PrimRef c;
        c.tri = r.tri;
        const float* v = &triangles[9 * std::size_t(r.tri)];
        if (clipped_bounds(v, br, c)) right.push_back(c);
        if (clipped_bounds(v, bl, c)) left[n_left++] = c;
      }
    }
    // Separates nothing: a leaf (`refs` now holds the left copies: the same triangles, in order).
    if (n_left == n && right.size() == n) return leaf(out, refs);
    left.resize(n_left);
    std::vector<RayRef> rays_left, rays_right;
    for (const RayRef& rr : ray_refs) {
      const Ray& ray = (*rays)[rr.id];
      const float org = ray.origin[std::size_t(best_axis)],
                  d = ray.direction[std::size_t(best_axis)];
      if (d == 0.0f) {
        if (org <= best_split) rays_left.push_back(rr);
        if (org >= best_split) rays_right.push_back(rr);
        continue;
      }
      const float ts = (best_split - org) / d;
      RayRef first = rr, second = rr;  // along the ray
      first.t1 = std::min(rr.t1, ts);
      second.t0 = std::max(rr.t0, ts);
      std::vector<RayRef>& near_side = d > 0.0f ? rays_left : rays_right;
      std::vector<RayRef>& far_side = d > 0.0f ? rays_right : rays_left;
      if (first.t0 <= first.t1) near_side.push_back(first);
      if (second.t0 <= second.t1) far_side.push_back(second);
    }
    std::vector<RayRef>().swap(ray_refs);
    const auto index = std::uint32_t(out.nodes.size());
    Node node{};
    node.split = best_split;
    node.flags = std::uint32_t(best_axis);
    node.a = kNone;
    node.b = kNone;
    out.nodes.push_back(node);
    if (depth >= kFirstParallelDepth && depth < kFirstParallelDepth + kParallelDepths &&
        left.size() + right.size() > kParallelRefs) {
      Fragment right_part;
      right_part.nodes.reserve(4 * right.size());  // virtual: pages never written cost nothing
      right_part.refs.reserve(2 * right.size());
      tbb::task_group group;
      group.run([&] { build(right_part, right, rays_right, br, depth + 1); });
      build(out, left, rays_left, bl, depth + 1);
      group.wait();
      out.nodes[index].a = std::uint32_t(out.nodes.size());
      splice(out, right_part);
    } else {
      build(out, left, rays_left, bl, depth + 1);
      out.nodes[index].a = std::uint32_t(out.nodes.size());
      build(out, right, rays_right, br, depth + 1);
    }
  }
};

KdTree::KdTree(const TriangleMesh& mesh, const KdTreeOptions& options)
    : KdTree(mesh, std::vector<Ray>{}, options) {}

KdTree::KdTree(const TriangleMesh& mesh, const std::vector<Ray>& srdh_rays,
               const KdTreeOptions& options) {
  const std::size_t vertices = mesh.positions.size() / 3;  // ignores OccluderScene's padding
  if (mesh.indices.size() % 3 != 0)
    throw Error(ErrorCode::invalid_argument, "kd-tree: occluder mesh has " +
                                                 std::to_string(mesh.indices.size()) +
                                                 " indices, not a multiple of 3");
  const std::size_t count = mesh.indices.size() / 3;
  triangles_.resize(9 * count);
  std::vector<PrimRef> all(count);
  Box bounds{{kInf, kInf, kInf}, {-kInf, -kInf, -kInf}};
  for (std::size_t t = 0; t < count; ++t) {
    PrimRef& r = all[t];
    r.tri = std::uint32_t(t);
    for (int k = 0; k < 3; ++k) {
      r.lo[k] = kInf;
      r.hi[k] = -kInf;
    }
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
        r.lo[k] = std::min(r.lo[k], x);
        r.hi[k] = std::max(r.hi[k], x);
      }
    }
    for (int k = 0; k < 3; ++k) {
      bounds.lo[k] = std::min(bounds.lo[k], r.lo[k]);
      bounds.hi[k] = std::max(bounds.hi[k], r.hi[k]);
    }
  }
  if (count == 0) bounds = Box{{0, 0, 0}, {0, 0, 0}};
  bounds_ = bounds;
  Builder builder{options, triangles_};
  builder.max_depth = int(8 + 1.3 * std::log2(double(std::max<std::size_t>(count, 1))));
  std::vector<RayRef> ray_refs;
  if (!srdh_rays.empty() && count > 0) {
    builder.rays = &srdh_rays;
    for (std::size_t i = 0; i < srdh_rays.size(); ++i) {
      const WoopRay r = prepare(srdh_rays[i]);
      if (!r.valid) continue;
      float t0, t1;
      clip_to_box(r, bounds, t0, t1);
      if (t0 <= t1) ray_refs.push_back({t0, t1, std::uint32_t(i)});
    }
  }
  Fragment tree;
  // Generous reservations (product meshes: about 6 nodes and 6 references per triangle): only
  // the pages written become resident, and growing by copying would double the peak.
  tree.nodes.reserve(12 * count + 64);
  tree.refs.reserve(12 * count + 64);
  builder.build(tree, all, ray_refs, bounds, 0);
  nodes_ = std::move(tree.nodes);
  refs_ = std::move(tree.refs);
  // (No shrink_to_fit: it would copy, doubling the peak; the unused capacity is never touched.)

  // Leaf numbers (pre-order), the depth, and SATO's order: one recursion with the boxes on its
  // stack (no per-node arrays: the product's trees have tens of millions of nodes).
  struct Subtree {
    float cost, area;  // SAH cost; triangle area (leaves' sums; shared triangles count twice)
  };
  std::uint32_t leaves = 0;
  auto annotate = [&](auto&& self, std::uint32_t i, const Box& box, int depth) -> Subtree {
    max_depth_ = std::max(max_depth_, depth);
    Node& n = nodes_[i];
    const std::uint32_t axis = n.flags & 3u;
    if (axis == kLeafAxis) {
      n.b = leaves++;
      const std::uint32_t count_here = n.flags >> 4;
      float area = 0;
      for (std::uint32_t k = 0; k < count_here; ++k) {
        const float* v = &triangles_[9 * std::size_t(refs_[n.a + k])];
        const float e1[3] = {v[3] - v[0], v[4] - v[1], v[5] - v[2]};
        const float e2[3] = {v[6] - v[0], v[7] - v[1], v[8] - v[2]};
        const float cx = e1[1] * e2[2] - e1[2] * e2[1], cy = e1[2] * e2[0] - e1[0] * e2[2],
                    cz = e1[0] * e2[1] - e1[1] * e2[0];
        area += 0.5f * std::sqrt(cx * cx + cy * cy + cz * cz);
      }
      return {options.cost_intersect * float(count_here), area};
    }
    Box bl = box, br = box;
    bl.hi[axis] = n.split;
    br.lo[axis] = n.split;
    const Subtree l = self(self, i + 1, bl, depth + 1);
    const Subtree r = self(self, n.a, br, depth + 1);
    const float sa = surface_area(box), sa_l = surface_area(bl), sa_r = surface_area(br);
    const float cost =
        options.cost_traversal + (sa > 0 ? (sa_l * l.cost + sa_r * r.cost) / sa : l.cost + r.cost);
    // SATO: the child with the larger occlusion chance per unit of traversal cost first. The
    // chance that a random line through a box meets a triangle of area A in it is about
    // 2 A / SA(box) (mean projected area A / 2 over SA / 4); capped at 1 (the areas overlap).
    auto score = [](const Subtree& c, float sa_c) {
      return std::min(1.0, 2.0 * double(c.area) / std::max(1e-30, double(sa_c))) /
             std::max(1e-30, double(c.cost));
    };
    if (score(l, sa_l) >= score(r, sa_r)) n.flags |= 4u | 8u;  // SRDH starts as SATO
    return {cost, l.area + r.area};
  };
  if (!nodes_.empty()) annotate(annotate, 0, bounds_, 0);
  leaf_count_ = leaves;
  if (options.multi_index) build_multi_index(options);
}

std::vector<float> KdTree::subtree_costs(const KdTreeOptions& options) const {
  std::vector<float> cost(nodes_.size(), 0.0f);
  auto rec = [&](auto&& self, std::uint32_t i, const Box& box) -> float {
    const Node& n = nodes_[i];
    const std::uint32_t axis = n.flags & 3u;
    if (axis == kLeafAxis) return cost[i] = options.cost_intersect * float(n.flags >> 4);
    Box bl = box, br = box;
    bl.hi[axis] = n.split;
    br.lo[axis] = n.split;
    const float cl = self(self, i + 1, bl), cr = self(self, n.a, br);
    const float sa = surface_area(box);
    return cost[i] = options.cost_traversal +
                     (sa > 0 ? (surface_area(bl) * cl + surface_area(br) * cr) / sa : cl + cr);
  };
  if (!nodes_.empty()) rec(rec, 0, bounds_);
  return cost;
}

void KdTree::build_multi_index(const KdTreeOptions& options) {
  // Lifting first: its temporary per-node costs are freed before the leaf boxes and ropes (24
  // bytes per leaf each) are allocated, which lowers the peak.
  lift_primitives(options);
  leaf_boxes_.assign(leaf_count_, Box{});
  auto rec = [&](auto&& self, std::uint32_t i, const Box& box) -> void {
    const Node& n = nodes_[i];
    const std::uint32_t axis = n.flags & 3u;
    if (axis == kLeafAxis) {
      leaf_boxes_[n.b] = box;
      return;
    }
    Box bl = box, br = box;
    bl.hi[axis] = n.split;
    br.lo[axis] = n.split;
    self(self, i + 1, bl);
    self(self, n.a, br);
  };
  if (!nodes_.empty()) rec(rec, 0, bounds_);
  build_ropes();
}

void KdTree::build_ropes() {
  ropes_.assign(leaf_count_, {kNone, kNone, kNone, kNone, kNone, kNone});
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

void KdTree::lift_primitives(const KdTreeOptions& options) {
  lifted_ranges_.clear();
  lifted_prims_.clear();
  for (Node& n : nodes_)
    if ((n.flags & 3u) != kLeafAxis) n.b = kNone;
  const std::size_t count = triangle_count();
  if (count == 0 || nodes_.empty()) return;
  auto triangle_box = [&](std::size_t t) {
    const float* v = &triangles_[9 * t];
    Box b;
    for (int k = 0; k < 3; ++k) {
      b.lo[k] = std::min({v[k], v[3 + k], v[6 + k]});
      b.hi[k] = std::max({v[k], v[3 + k], v[6 + k]});
    }
    return b;
  };
  double mean_area = 0;
  for (std::size_t t = 0; t < count; ++t) mean_area += surface_area(triangle_box(t));
  mean_area /= double(count);
  const std::vector<float> subtree_cost = subtree_costs(options);
  struct Candidate {
    std::uint32_t node;
    float gain;
    std::uint32_t triangle;
  };
  std::vector<Candidate> candidates;
  // Each triangle once, at its first leaf in pre-order: that leaf's ancestors (the recursion's
  // path, deepest first) are the candidate places.
  std::vector<bool> seen(count, false);
  struct Ancestor {
    std::uint32_t node;
    int depth;
    Box box;
  };
  std::vector<Ancestor> path;
  auto rec = [&](auto&& self, std::uint32_t i, const Box& box, int depth) -> void {
    const Node& n = nodes_[i];
    const std::uint32_t axis = n.flags & 3u;
    if (axis == kLeafAxis) {
      for (std::uint32_t k = 0; k < (n.flags >> 4); ++k) {
        const std::uint32_t t = refs_[n.a + k];
        if (seen[t]) continue;
        seen[t] = true;
        const Box tb = triangle_box(t);
        if (!(surface_area(tb) > options.lift_area_ratio * mean_area)) continue;
        float best_gain = options.lift_min_gain;
        std::uint32_t best = kNone;
        for (std::size_t a = path.size(); a-- > 0;) {
          const Ancestor& anc = path[a];
          const float sa = surface_area(anc.box);
          if (!(sa > 0)) continue;
          const float p_hit = std::min(1.0f, surface_area(clip(tb, anc.box)) / sa);
          const float gain = (p_hit - options.cost_intersect / subtree_cost[anc.node]) *
                             (1.0f - std::exp(-options.lift_lambda * float(anc.depth)));
          if (gain > best_gain) {
            best_gain = gain;
            best = anc.node;
          }
        }
        if (best != kNone) candidates.push_back({best, best_gain, t});
      }
      return;
    }
    Box bl = box, br = box;
    bl.hi[axis] = n.split;
    br.lo[axis] = n.split;
    path.push_back({i, depth, box});
    self(self, i + 1, bl, depth + 1);
    self(self, n.a, br, depth + 1);
    path.pop_back();
  };
  rec(rec, 0, bounds_, 0);
  // Per node, the largest gains first (ties: the lower triangle index).
  std::sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) {
    if (a.node != b.node) return a.node < b.node;
    return a.gain > b.gain || (a.gain == b.gain && a.triangle < b.triangle);
  });
  for (std::size_t i = 0; i < candidates.size();) {
    const std::uint32_t n = candidates[i].node;
    std::size_t end = i;
    while (end < candidates.size() && candidates[end].node == n) ++end;
    const std::size_t kept = std::min(end - i, std::size_t(std::max(0, options.lift_max_per_node)));
    if (kept > 0) {
      nodes_[n].b = std::uint32_t(lifted_ranges_.size());
      lifted_ranges_.push_back({std::uint32_t(lifted_prims_.size()), std::uint32_t(kept)});
      for (std::size_t k = i; k < i + kept; ++k) lifted_prims_.push_back(candidates[k].triangle);
    }
    i = end;
  }
}

std::size_t KdTree::empty_leaf_count() const {
  std::size_t empty = 0;
  for (const Node& n : nodes_) empty += n.flags == kLeafAxis;  // a leaf of 0 triangles
  return empty;
}

std::size_t KdTree::memory_bytes(bool multi_index_parts) const {
  std::size_t bytes = nodes_.size() * sizeof(Node) + refs_.size() * sizeof(std::uint32_t) +
                      triangles_.size() * sizeof(float);
  if (multi_index_parts)
    bytes += leaf_boxes_.size() * sizeof(Box) +
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
      // Child intervals along the ray. With d == 0 the ray stays on one side (both if on the
      // plane).
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
// 8-wide packets (the CPU core's shadow packets: consecutive march samples or pixels, coherent)

namespace {

// The 8-wide helpers (F8, I8, bits, blend, vmax, vmin) are render/shadow_traversal/simd8.h's.
// The operations below are the scalar traversal's, lane by lane, in the same order and
// rounding (kd_tree.cpp is compiled with -ffp-contract=off: no fused multiply-adds on either
// side), so each lane's answer is the single-ray answer bit for bit.
MR_PACKET_TARGET inline void vabs(const F8& a, F8& out) {  // std::fabs
  out = reinterpret_cast<F8>(reinterpret_cast<I8>(a) & 0x7fffffff);
}
// a[k] for k given per lane by the masks (k == 0: is0, k == 1: is1, else k == 2).
MR_PACKET_TARGET inline void select3(const I8& is0, const I8& is1, const F8& a0, const F8& a1,
                                     const F8& a2, F8& out) {
  out = reinterpret_cast<F8>((is0 & reinterpret_cast<I8>(a0)) | (is1 & reinterpret_cast<I8>(a1)) |
                             (~(is0 | is1) & reinterpret_cast<I8>(a2)));
}

struct alignas(32) Packet {
  F8 o[3], d[3], inv[3];
  F8 sx, sy, sz, t_near, t_far;
  I8 kx0, kx1, ky0, ky1, kz0, kz1;  // which axis kx, ky, kz are, per lane
  WoopRay w[8];                     // for the lanes that need hit_triangle's exact fallback
};

// hit_triangle for the lanes of `active`, 8 at once: the lanes whose answer is a hit.
MR_PACKET_TARGET unsigned hit_triangle8(const Packet& p, const float* v, unsigned active) {
  F8 a[3], b[3], c[3];
  for (int k = 0; k < 3; ++k) {
    a[k] = v[k] - p.o[k];
    b[k] = v[3 + k] - p.o[k];
    c[k] = v[6 + k] - p.o[k];
  }
  F8 akx, aky, akz, bkx, bky, bkz, ckx, cky, ckz;
  select3(p.kx0, p.kx1, a[0], a[1], a[2], akx);
  select3(p.ky0, p.ky1, a[0], a[1], a[2], aky);
  select3(p.kz0, p.kz1, a[0], a[1], a[2], akz);
  select3(p.kx0, p.kx1, b[0], b[1], b[2], bkx);
  select3(p.ky0, p.ky1, b[0], b[1], b[2], bky);
  select3(p.kz0, p.kz1, b[0], b[1], b[2], bkz);
  select3(p.kx0, p.kx1, c[0], c[1], c[2], ckx);
  select3(p.ky0, p.ky1, c[0], c[1], c[2], cky);
  select3(p.kz0, p.kz1, c[0], c[1], c[2], ckz);
  const F8 ax = akx - p.sx * akz, ay = aky - p.sy * akz;
  const F8 bx = bkx - p.sx * bkz, by = bky - p.sy * bkz;
  const F8 cx = ckx - p.sx * ckz, cy = cky - p.sy * ckz;
  const F8 u = cx * by - cy * bx;
  const F8 vv = ax * cy - ay * cx;
  const F8 w = bx * ay - by * ax;
  const F8 zero = {};
  const unsigned exact = bits((u == zero) | (vv == zero) | (w == zero)) & active;
  const I8 outside =
      ((u < zero) | (vv < zero) | (w < zero)) & ((u > zero) | (vv > zero) | (w > zero));
  const F8 det = u + vv + w;
  const F8 az = p.sz * akz, bz = p.sz * bkz, cz = p.sz * ckz;
  const F8 t = (u * az + vv * bz + w * cz) / det;
  unsigned hit = bits(~outside & (det != zero) & (t > p.t_near) & (t <= p.t_far)) & active & ~exact;
  // A zero edge function: the paper's fallback in double, lane by lane (rare: edges, vertices).
  for (unsigned e = exact; e != 0; e &= e - 1) {
    const int k = __builtin_ctz(e);
    if (hit_triangle(p.w[k], v)) hit |= 1u << k;
  }
  return hit;
}

}  // namespace

template <bool kCount>
MR_PACKET_TARGET unsigned KdTree::packet_traverse(const Ray* rays, unsigned lanes,
                                                  KindCounters* counters) const {
  Packet p;
  alignas(32) float t0s[8] = {}, t1s[8] = {};
  std::uint64_t lane_nodes[8] = {}, lane_prims[8] = {};
  unsigned pending = 0;  // lanes still looking for a hit
  for (int k = 0; k < 8; ++k) {
    WoopRay& w = p.w[k];
    if (lanes & (1u << k)) {
      w = prepare(rays[k]);
    } else {
      w = WoopRay{};
      w.kx = 0, w.ky = 1, w.kz = 2;
    }
    for (int j = 0; j < 3; ++j) {
      p.o[j][k] = w.o[j];
      p.d[j][k] = w.d[j];
      p.inv[j][k] = w.inv[j];
    }
    p.sx[k] = w.sx, p.sy[k] = w.sy, p.sz[k] = w.sz;
    p.t_near[k] = w.t_near, p.t_far[k] = w.t_far;
    p.kx0[k] = -(w.kx == 0), p.kx1[k] = -(w.kx == 1);
    p.ky0[k] = -(w.ky == 0), p.ky1[k] = -(w.ky == 1);
    p.kz0[k] = -(w.kz == 0), p.kz1[k] = -(w.kz == 1);
    if (!(lanes & (1u << k)) || !w.valid || nodes_.empty()) continue;
    float t0, t1;
    clip_to_box(w, bounds_, t0, t1);
    t0 = std::max(t0, -kInf);  // as stack_traverse with t_start = -inf
    if (!(t0 <= t1)) continue;
    t0s[k] = t0;
    t1s[k] = t1;
    pending |= 1u << k;
  }
  unsigned hits = 0;
  if (pending != 0) {
    struct alignas(32) Entry {
      F8 t_min, t_max;
      unsigned mask;
      std::uint32_t node;
    };
    Entry stack[kStackSize];
    int top = 0;
    F8 t_min, t_max;
    std::memcpy(&t_min, t0s, sizeof t_min);
    std::memcpy(&t_max, t1s, sizeof t_max);
    unsigned mask = pending;  // lanes whose interval reaches this node
    std::uint32_t node = 0;
    for (;;) {
      const Node* n = &nodes_[node];
      if constexpr (kCount) {
        ++counters->packet_nodes;
        for (unsigned m = mask; m != 0; m &= m - 1) ++lane_nodes[__builtin_ctz(m)];
      }
      const std::uint32_t axis = n->flags & 3u;
      bool descended = false;
      if (axis != kLeafAxis) {
        // stack_traverse's child intervals, lane by lane.
        const F8& o = p.o[axis];
        const F8& d = p.d[axis];
        const F8 split = F8{} + n->split;
        const F8 zero = {};
        const I8 flat = d == zero;
        const I8 left_first = d > zero;
        const F8 t_split = (split - o) * p.inv[axis];
        F8 e, first_max, second_min;
        F8 abs_min, abs_max;
        vabs(t_min, abs_min);
        vabs(t_max, abs_max);
        vmax(abs_min, abs_max, e);
        e = 1e-6f * e;
        vmin(t_max, t_split + e, first_max);
        vmax(t_min, t_split - e, second_min);
        const I8 visit_first = t_min <= first_max, visit_second = second_min <= t_max;
        I8 crossing_left, crossing_right, visit_left, visit_right;
        blend(left_first, visit_first, visit_second, crossing_left);
        blend(left_first, visit_second, visit_first, crossing_right);
        blend(flat, o <= split, crossing_left, visit_left);
        blend(flat, o >= split, crossing_right, visit_right);
        const I8 cut_left = ~flat & left_first, cut_right = ~flat & ~left_first;
        const unsigned to_left = bits(visit_left) & mask, to_right = bits(visit_right) & mask;
        F8 left_min, left_max, right_min, right_max;
        blend(cut_right, second_min, t_min, left_min);
        blend(cut_left, first_max, t_max, left_max);
        blend(cut_left, second_min, t_min, right_min);
        blend(cut_right, first_max, t_max, right_max);
        const std::uint32_t left = node + 1, right = n->a;
        if (to_left != 0 && to_right != 0) {
          if (top >= kStackSize) {  // never at the depths the build allows: finish ray by ray
            for (unsigned m = pending; m != 0; m &= m - 1) {
              const int k = __builtin_ctz(m);
              if (occluded(rays[k], Order::standard)) hits |= 1u << k;
            }
            pending = 0;
            break;
          }
          // The first live lane's direction picks the order (any order gives the same answers).
          const bool left_before = d[__builtin_ctz(mask)] >= 0.0f;
          if (left_before) {
            stack[top++] = {right_min, right_max, to_right, right};
            node = left, mask = to_left, t_min = left_min, t_max = left_max;
          } else {
            stack[top++] = {left_min, left_max, to_left, left};
            node = right, mask = to_right, t_min = right_min, t_max = right_max;
          }
          descended = true;
        } else if (to_left != 0) {
          node = left, mask = to_left, t_min = left_min, t_max = left_max;
          descended = true;
        } else if (to_right != 0) {
          node = right, mask = to_right, t_min = right_min, t_max = right_max;
          descended = true;
        }
      } else {
        const std::uint32_t count = n->flags >> 4;
        for (std::uint32_t k = 0; k < count && mask != 0; ++k) {
          const float* v = &triangles_[9 * std::size_t(refs_[n->a + k])];
          if constexpr (kCount)
            for (unsigned m = mask; m != 0; m &= m - 1) ++lane_prims[__builtin_ctz(m)];
          const unsigned h = hit_triangle8(p, v, mask);
          hits |= h;
          pending &= ~h;
          mask &= ~h;
        }
        if (pending == 0) break;
      }
      if (descended) continue;
      // Pop the next node that a lane still looking for a hit reaches.
      mask = 0;
      while (top > 0 && mask == 0) {
        --top;
        mask = stack[top].mask & pending;
        node = stack[top].node;
        t_min = stack[top].t_min;
        t_max = stack[top].t_max;
      }
      if (mask == 0) break;
    }
  }
  if constexpr (kCount) {
    ++counters->packets;
    for (int k = 0; k < 8; ++k) {
      if (!(lanes & (1u << k))) continue;
      Counters& c = (hits >> k) & 1u ? counters->occluded : counters->unoccluded;
      ++c.rays;
      c.nodes += lane_nodes[k];
      c.primitives += lane_prims[k];
    }
  }
  return hits;
}

unsigned KdTree::occluded8(const Ray* rays, unsigned lanes, KindCounters* counters) const {
  lanes &= 0xffu;
  static const bool packet_isa = MR_PACKET_ISA_PRESENT();
  if (!packet_isa) {  // the same answers and counts, ray by ray
    unsigned hits = 0;
    for (unsigned m = lanes; m != 0; m &= m - 1) {
      const int k = __builtin_ctz(m);
      if (occluded(rays[k], Order::standard, counters)) hits |= 1u << k;
    }
    return hits;
  }
  return counters ? packet_traverse<true>(rays, lanes, counters)
                  : packet_traverse<false>(rays, lanes, nullptr);
}

// ---------------------------------------------------------------------------------------------
// SRDH's order from a sample ray set

void KdTree::train_srdh(const std::vector<Ray>& sample_rays) {
  struct Stats {  // compact: one per node of a tree of tens of millions of nodes
    std::uint32_t entered[2] = {0, 0}, occluded[2] = {0, 0};
    float cost[2] = {0, 0};
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
      s.cost[c] += float(res[c].cost);
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
      const double p = (s.occluded[c] + 1.0) / (s.entered[c] + 2.0);  // Laplace: unseen = 1/2
      const double cost = s.entered[c] > 0 ? double(s.cost[c]) / s.entered[c] : 1.0;
      score[c] = p / cost;
    }
    if (score[0] >= score[1])
      nodes_[i].flags |= 8u;
    else
      nodes_[i].flags &= ~8u;
  }
}

}  // namespace mr::render::shadow
