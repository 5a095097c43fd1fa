// Issue 17: the kd-tree shadow traversals (render/shadow_traversal/kd_tree.h: standard, SATO,
// SRDH, multi-index) against Embree's rtcOccluded, the rope structure against root descents,
// the counters' bookkeeping, and renders through the CPU core with either traversal.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "bench/leuven_scene.h"
#include "bench/shadow_scenes.h"
#include "mr/mr.h"
#include "render/embree_scene.h"
#include "render/occluder_cache.h"
#include "render/shadow_traversal/kd_tree.h"
#include "render/shadow_traversal/multi_index_query.h"

namespace mr::render {
namespace {

using shadow::KdTree;
using shadow::Order;
using shadow::Ray;

std::vector<Ray> random_rays(int count, std::uint32_t seed, float lo, float hi) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> pos(lo, hi), dir(-1, 1), len(0.05f, 2.0f), u(0, 1);
  std::vector<Ray> rays(static_cast<std::size_t>(count));
  for (Ray& r : rays) {
    r.origin = {pos(rng), pos(rng), pos(rng)};
    r.direction = {dir(rng), dir(rng), dir(rng)};
    r.t_near = u(rng) < 0.5f ? 0.0f : 0.1f * u(rng);
    r.t_far = u(rng) < 0.2f ? INFINITY : len(rng);
  }
  return rays;
}

/// Why a ray may get different answers from two correct tests: in double precision, some
/// triangle's edge or vertex passes within `rel` (relative to the triangle's size) of the ray,
/// or a hit lies within `rel` of t_near / t_far, or the ray grazes the triangle's plane.
bool measure_zero_case(const TriangleMesh& mesh, const Ray& r, double rel = 1e-5) {
  const std::size_t n = mesh.triangle_count();
  for (std::size_t t = 0; t < n; ++t) {
    double v[3][3];
    for (int k = 0; k < 3; ++k)
      for (int c = 0; c < 3; ++c)
        v[k][c] =
            mesh.positions[3 * std::size_t(mesh.indices[3 * t + std::size_t(k)]) + std::size_t(c)];
    const double o[3] = {r.origin[0], r.origin[1], r.origin[2]};
    const double d[3] = {r.direction[0], r.direction[1], r.direction[2]};
    const double e1[3] = {v[1][0] - v[0][0], v[1][1] - v[0][1], v[1][2] - v[0][2]};
    const double e2[3] = {v[2][0] - v[0][0], v[2][1] - v[0][1], v[2][2] - v[0][2]};
    const double p[3] = {d[1] * e2[2] - d[2] * e2[1], d[2] * e2[0] - d[0] * e2[2],
                         d[0] * e2[1] - d[1] * e2[0]};
    const double det = e1[0] * p[0] + e1[1] * p[1] + e1[2] * p[2];
    const double scale = std::sqrt(e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]) *
                         std::sqrt(e2[0] * e2[0] + e2[1] * e2[1] + e2[2] * e2[2]) *
                         std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    if (std::fabs(det) <= rel * scale) {
      // Nearly in the plane: a grazing ray. Count it only if it comes near the triangle at all.
      continue;
    }
    const double s[3] = {o[0] - v[0][0], o[1] - v[0][1], o[2] - v[0][2]};
    const double u = (s[0] * p[0] + s[1] * p[1] + s[2] * p[2]) / det;
    const double q[3] = {s[1] * e1[2] - s[2] * e1[1], s[2] * e1[0] - s[0] * e1[2],
                         s[0] * e1[1] - s[1] * e1[0]};
    const double w = (d[0] * q[0] + d[1] * q[1] + d[2] * q[2]) / det;
    const double tt = (e2[0] * q[0] + e2[1] * q[1] + e2[2] * q[2]) / det;
    const double b0 = 1 - u - w;
    const double m = std::min({u, w, b0});
    const double tn = r.t_near, tf = r.t_far;
    const double t_tol = rel * std::max(1.0, std::fabs(tt));
    const bool in_t = tt > tn - t_tol && tt <= tf + t_tol;
    const bool near_edge = std::fabs(m) <= rel && in_t;
    const bool near_bound = m >= -rel && (std::fabs(tt - tn) <= t_tol ||
                                          (std::isfinite(tf) && std::fabs(tt - tf) <= t_tol));
    if (near_edge || near_bound) return true;
  }
  return false;
}

struct Agreement {
  int rays = 0, hits = 0, embree_disagreements = 0, unexplained = 0, kd_disagreements = 0;
};

/// Every kd traversal (and SRDH's ray-set-built tree; single rays and 8-wide packets) against
/// the standard one (must agree exactly: one triangle test) and the standard one against Embree
/// (disagreements must be measure-zero cases).
Agreement check_agreement(const TriangleMesh& mesh, const std::vector<Ray>& rays,
                          bool robust_embree) {
  Agreement a;
  OccluderSceneOptions options;
  options.robust = robust_embree;
  const OccluderScene embree(mesh, options);
  KdTree tree(mesh);
  std::vector<Ray> sample;
  for (std::size_t i = 0; i < rays.size(); i += 7) sample.push_back(rays[i]);
  tree.train_srdh(sample);
  // SRDH's own tree, its split costs measured on the sample rays.
  KdTree srdh_tree(mesh, sample);
  srdh_tree.train_srdh(sample);
  // The 8-wide packet traversal on both trees: packets of 8 consecutive rays (as the CPU core's
  // shadow loops make them), and again with a random subset of each packet's lanes (the others
  // must come back unoccluded). 2 = lane left out.
  std::vector<char> packet(rays.size()), packet_srdh(rays.size()), packet_some(rays.size(), 2);
  std::mt19937 lane_rng(std::uint32_t(rays.size()));
  for (std::size_t first = 0; first < rays.size(); first += 8) {
    Ray group[8] = {};
    unsigned lanes = 0;
    for (std::size_t k = 0; k < 8 && first + k < rays.size(); ++k) {
      group[k] = rays[first + k];
      lanes |= 1u << k;
    }
    const unsigned some = lanes & unsigned(lane_rng());
    const unsigned hits = tree.occluded8(group, lanes),
                   hits_srdh = srdh_tree.occluded8(group, lanes),
                   hits_some = tree.occluded8(group, some);
    EXPECT_EQ(hits & ~lanes, 0u);
    EXPECT_EQ(hits_some & ~some, 0u);
    for (std::size_t k = 0; k < 8 && first + k < rays.size(); ++k) {
      packet[first + k] = char((hits >> k) & 1u);
      packet_srdh[first + k] = char((hits_srdh >> k) & 1u);
      if ((some >> k) & 1u) packet_some[first + k] = char((hits_some >> k) & 1u);
    }
  }
  bool previous = false;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const Ray& r = rays[i];
    const bool standard = tree.occluded(r, Order::standard);
    const bool answers[] = {tree.occluded(r, Order::sato),
                            tree.occluded(r, Order::srdh),
                            tree.occluded_multi_index(r, true),
                            tree.occluded_multi_index(r, false),
                            tree.occluded_multi_index(r, previous),
                            srdh_tree.occluded(r, Order::standard),
                            srdh_tree.occluded(r, Order::srdh),
                            bool(packet[i]),
                            bool(packet_srdh[i])};
    for (bool b : answers) a.kd_disagreements += b != standard;
    if (packet_some[i] != 2) a.kd_disagreements += bool(packet_some[i]) != standard;
    previous = standard;
    const bool reference = embree.occluded(r.origin, r.direction, r.t_near, r.t_far);
    ++a.rays;
    a.hits += reference;
    if (reference != standard) {
      ++a.embree_disagreements;
      if (!measure_zero_case(mesh, r)) {
        ++a.unexplained;
        ADD_FAILURE() << "unexplained disagreement: origin " << r.origin[0] << "," << r.origin[1]
                      << "," << r.origin[2] << " dir " << r.direction[0] << "," << r.direction[1]
                      << "," << r.direction[2] << " t " << r.t_near << ".." << r.t_far << " embree "
                      << reference << " kd " << standard;
      }
    }
  }
  return a;
}

void report(const char* what, const Agreement& a) {
  std::printf(
      "%s: %d rays, %d occluded, %d disagree with Embree (all measure-zero cases: %s), "
      "%d kd traversals disagree\n",
      what, a.rays, a.hits, a.embree_disagreements, a.unexplained == 0 ? "yes" : "NO",
      a.kd_disagreements);
}

TEST(ShadowTraversal, AgreesWithEmbreeOnRandomSoup) {
  for (float size : {0.05f, 0.3f}) {
    const TriangleMesh mesh = bench::random_soup(3000, size, 5);
    const auto rays = random_rays(20000, 9, -0.3f, 1.3f);
    for (bool robust : {false, true}) {
      const Agreement a = check_agreement(mesh, rays, robust);
      report(robust ? "soup (robust Embree)" : "soup", a);
      EXPECT_EQ(a.kd_disagreements, 0);
      EXPECT_EQ(a.unexplained, 0);
      EXPECT_GT(a.hits, a.rays / 20);  // a real test: both answers occur often
      EXPECT_LT(a.hits, a.rays - a.rays / 20);
      EXPECT_LE(a.embree_disagreements, a.rays / 1000);
    }
  }
}

TEST(ShadowTraversal, AgreesWithEmbreeOnThinOccluders) {
  // Slivers: 1 m long, 1 mm wide, random orientation.
  TriangleMesh mesh;
  bench::MeshBuilder b(mesh);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0, 1), e(-1, 1);
  for (int k = 0; k < 4000; ++k) {
    const std::array<float, 3> p{u(rng), u(rng), u(rng)},
        l{0.5f * e(rng), 0.5f * e(rng), 0.5f * e(rng)};
    const std::uint32_t i0 = b.vertex(p);
    const std::uint32_t i1 = b.vertex({p[0] + l[0], p[1] + l[1], p[2] + l[2]});
    const std::uint32_t i2 =
        b.vertex({p[0] + 1e-3f * e(rng), p[1] + 1e-3f * e(rng), p[2] + 1e-3f * e(rng)});
    b.triangle(i0, i1, i2);
  }
  bench::finish(mesh);
  const auto rays = random_rays(20000, 13, -0.2f, 1.2f);
  const Agreement a = check_agreement(mesh, rays, false);
  report("thin occluders", a);
  EXPECT_EQ(a.kd_disagreements, 0);
  EXPECT_EQ(a.unexplained, 0);
  EXPECT_GT(a.hits, a.rays / 20);
  EXPECT_LT(a.hits, a.rays - a.rays / 20);
}

TEST(ShadowTraversal, AgreesWithEmbreeOnGridsIncludingRaysThroughEdgesAndVertices) {
  const int n = 32;
  const TriangleMesh mesh = bench::grid_scene(n, 3);
  std::vector<Ray> rays;
  // Rays through exactly representable points of the z = 0 grid: vertices (i, j), edge midpoints
  // (i + 1/2, j), (i, j + 1/2) and diagonal midpoints (i + 1/2, j + 1/2, on the edge the two
  // triangles of a quad share), from above with slanted directions (powers of two: exact).
  const std::array<std::array<float, 3>, 4> dirs = {
      {{0, 0, -1}, {0.125f, 0.25f, -1}, {-0.5f, 0.25f, -1}, {0.25f, -0.125f, -1}}};
  for (int j = 1; j < n - 1; j += 3)
    for (int i = 1; i < n - 1; i += 3)
      for (const auto& target : std::array<std::array<float, 2>, 4>{{{float(i), float(j)},
                                                                     {i + 0.5f, float(j)},
                                                                     {float(i), j + 0.5f},
                                                                     {i + 0.5f, j + 0.5f}}})
        for (const auto& d : dirs) {
          const float h = 8;  // start at z = 8 (above all layers), reach z = 0 at t = 8
          Ray r;
          r.origin = {target[0] + h * d[0], target[1] + h * d[1], h};  // exact
          r.direction = {-d[0], -d[1], d[2]};
          r.t_near = 7.5f;  // only the bottom layer (z = 0 at t = 8) is in range
          r.t_far = 8.5f;
          rays.push_back(r);
        }
  // And random rays over the stack.
  const auto more = random_rays(20000, 21, -2.0f, float(n) + 2.0f);
  rays.insert(rays.end(), more.begin(), more.end());
  for (bool robust : {false, true}) {
    const Agreement a = check_agreement(mesh, rays, robust);
    report(robust ? "grid (robust Embree)" : "grid", a);
    EXPECT_EQ(a.kd_disagreements, 0);
    EXPECT_EQ(a.unexplained, 0);
  }
  // The watertight test itself: every structured ray hits the bottom grid (closed edges).
  KdTree tree(mesh);
  int structured = 0, structured_hits = 0;
  for (const Ray& r : rays) {
    if (r.t_near != 7.5f) continue;
    ++structured;
    structured_hits += tree.occluded(r, Order::standard);
  }
  EXPECT_GT(structured, 500);
  EXPECT_EQ(structured_hits, structured);
}

TEST(ShadowTraversal, AgreesWithEmbreeOnTheBenchmarkScenes) {
  for (const bench::ShadowScene& s : {bench::atrium(), bench::forest()}) {
    // Shadow rays from random points on random triangles to the point light.
    std::mt19937 rng(17);
    std::uniform_real_distribution<float> u(0, 1);
    std::vector<Ray> rays;
    const std::size_t n = s.mesh.triangle_count();
    for (int k = 0; k < 6000; ++k) {
      const std::size_t t = std::size_t(u(rng) * float(n)) % n;
      float a = u(rng), b = u(rng);
      if (a + b > 1) a = 1 - a, b = 1 - b;
      std::array<float, 3> p{};
      for (int c = 0; c < 3; ++c) {
        const float* v0 = &s.mesh.positions[3 * s.mesh.indices[3 * t]];
        const float* v1 = &s.mesh.positions[3 * s.mesh.indices[3 * t + 1]];
        const float* v2 = &s.mesh.positions[3 * s.mesh.indices[3 * t + 2]];
        p[std::size_t(c)] = v0[c] + a * (v1[c] - v0[c]) + b * (v2[c] - v0[c]);
      }
      Ray r;
      r.origin = p;
      r.direction = {s.point_light[0] - p[0], s.point_light[1] - p[1], s.point_light[2] - p[2]};
      r.t_near = 1e-4f;
      r.t_far = 1.0f;
      rays.push_back(r);
    }
    const Agreement a = check_agreement(s.mesh, rays, false);
    report(s.name.c_str(), a);
    EXPECT_EQ(a.kd_disagreements, 0);
    EXPECT_EQ(a.unexplained, 0);
  }
}

TEST(ShadowTraversal, RopesReachTheLeafARootDescentFinds) {
  for (const TriangleMesh& mesh : {bench::random_soup(5000, 0.1f, 2), bench::forest().mesh}) {
    const KdTree tree(mesh);
    ASSERT_GT(tree.leaf_count(), 100u);
    std::mt19937 rng(1);
    std::uniform_real_distribution<float> u(0.01f, 0.99f), e(-1, 1);
    int checked = 0, boundary = 0, ties = 0;
    const std::size_t stride = std::max<std::size_t>(1, tree.leaf_count() / 3000);
    for (std::uint32_t leaf = 0; leaf < tree.leaf_count(); leaf += std::uint32_t(stride)) {
      const shadow::Box& box = tree.leaf_box(leaf);
      for (int face = 0; face < 6; ++face) {
        const int axis = face / 2;
        std::array<float, 3> p{}, dir{};
        for (int k = 0; k < 3; ++k) {
          p[std::size_t(k)] = box.lo[k] + u(rng) * (box.hi[k] - box.lo[k]);
          dir[std::size_t(k)] = 0.5f * e(rng);
        }
        p[std::size_t(axis)] = (face & 1) ? box.hi[axis] : box.lo[axis];
        dir[std::size_t(axis)] = (face & 1) ? 1.0f : -1.0f;
        const std::uint32_t via_rope = tree.rope_step(leaf, face, p, dir);
        const float bound = (face & 1) ? tree.bounds().hi[axis] : tree.bounds().lo[axis];
        if (via_rope == ~0u) {  // only on the scene's boundary
          EXPECT_EQ(p[std::size_t(axis)], bound);
          ++boundary;
          continue;
        }
        const std::uint32_t by_descent = tree.leaf_at(p, dir);
        // p on an edge of the face (tiny leaves: the random point rounded onto the box's
        // boundary on another axis) lies in several neighbours; either is right.
        bool on_edge = false;
        for (int k = 0; k < 3; ++k)
          on_edge = on_edge || (k != axis &&
                                (p[std::size_t(k)] == box.lo[k] || p[std::size_t(k)] == box.hi[k]));
        if (on_edge) ++ties;
        if (!on_edge) {
          EXPECT_EQ(via_rope, by_descent) << "leaf " << leaf << " face " << face;
        }
        // The neighbour touches the face and holds p.
        const shadow::Box& nb = tree.leaf_box(via_rope);
        EXPECT_EQ((face & 1) ? nb.lo[axis] : nb.hi[axis], p[std::size_t(axis)]);
        for (int k = 0; k < 3; ++k) {
          EXPECT_LE(nb.lo[k], p[std::size_t(k)]);
          EXPECT_GE(nb.hi[k], p[std::size_t(k)]);
        }
        ++checked;
      }
    }
    EXPECT_GT(checked, 1000);
    EXPECT_GT(boundary, 0);
    EXPECT_LT(ties, checked / 100);
    std::printf("ropes: %d faces checked, %d on the scene boundary, %d points on a face's edge\n",
                checked, boundary, ties);
  }
}

TEST(ShadowTraversal, CountersAreConsistent) {
  const TriangleMesh mesh = bench::random_soup(4000, 0.1f, 8);
  KdTree tree(mesh);
  const auto rays = random_rays(10000, 4, -0.2f, 1.2f);
  std::vector<Ray> sample(rays.begin(), rays.begin() + 1000);
  tree.train_srdh(sample);
  shadow::KindCounters standard, sato, srdh, lifted, roped;
  int occluded = 0;
  for (const Ray& r : rays) {
    occluded += tree.occluded(r, Order::standard, &standard);
    tree.occluded(r, Order::sato, &sato);
    tree.occluded(r, Order::srdh, &srdh);
    tree.occluded_multi_index(r, true, &lifted);
    tree.occluded_multi_index(r, false, &roped);
  }
  ASSERT_GT(occluded, 1000);
  ASSERT_LT(occluded, 9000);
  for (const auto* c : {&standard, &sato, &srdh, &lifted, &roped}) {
    EXPECT_EQ(c->occluded.rays, std::uint64_t(occluded));
    EXPECT_EQ(c->unoccluded.rays, rays.size() - std::uint64_t(occluded));
    EXPECT_GE(c->occluded.primitives, c->occluded.rays);  // an occluded ray tested its blocker
    EXPECT_GT(c->unoccluded.nodes, 0u);
  }
  // An unoccluded ray visits every node its segment enters, in any order: the fixed orders
  // change nothing for it.
  EXPECT_EQ(sato.unoccluded.nodes, standard.unoccluded.nodes);
  EXPECT_EQ(sato.unoccluded.primitives, standard.unoccluded.primitives);
  EXPECT_EQ(srdh.unoccluded.nodes, standard.unoccluded.nodes);
  EXPECT_EQ(srdh.unoccluded.primitives, standard.unoccluded.primitives);
  // Lifted triangles are tested at most once per ray: an unoccluded ray tests at most the
  // lifted ones on its path more than the standard traversal does.
  EXPECT_GE(lifted.unoccluded.primitives, standard.unoccluded.primitives);
  EXPECT_LE(lifted.unoccluded.primitives,
            standard.unoccluded.primitives +
                lifted.unoccluded.rays * 2 * std::uint64_t(tree.max_depth()));
  EXPECT_EQ(lifted.unoccluded.nodes, standard.unoccluded.nodes);
  // 8-wide packets of consecutive rays: a ray is active at exactly the nodes its own interval
  // enters (the standard traversal's), so unoccluded rays count the same nodes and triangle
  // tests as there; a node fetched for a packet serves its active rays at once.
  shadow::KindCounters packets;
  int packet_occluded = 0;
  for (std::size_t first = 0; first < rays.size(); first += 8) {
    const unsigned lanes = (1u << std::min<std::size_t>(8, rays.size() - first)) - 1u;
    packet_occluded += __builtin_popcount(tree.occluded8(&rays[first], lanes, &packets));
  }
  EXPECT_EQ(packet_occluded, occluded);
  EXPECT_EQ(packets.occluded.rays, std::uint64_t(occluded));
  EXPECT_EQ(packets.unoccluded.rays, rays.size() - std::uint64_t(occluded));
  EXPECT_EQ(packets.packets, (rays.size() + 7) / 8);
  EXPECT_EQ(packets.unoccluded.nodes, standard.unoccluded.nodes);
  EXPECT_EQ(packets.unoccluded.primitives, standard.unoccluded.primitives);
  EXPECT_GE(packets.occluded.primitives, packets.occluded.rays);
  EXPECT_LE(packets.packet_nodes, packets.occluded.nodes + packets.unoccluded.nodes);
  EXPECT_GE(packets.packet_nodes * 8, packets.occluded.nodes + packets.unoccluded.nodes);
  std::printf("8-wide packets of random rays: %.1f node fetches per packet, %.1f per ray\n",
              double(packets.packet_nodes) / double(packets.packets),
              double(packets.occluded.nodes + packets.unoccluded.nodes) / double(rays.size()));
  // The rope walk tests the triangles of the leaves along the ray: no more than the stack
  // traversal (which may also enter leaves the ray only grazes within its rounding slack).
  EXPECT_LE(roped.unoccluded.primitives, standard.unoccluded.primitives);
  EXPECT_GT(roped.unoccluded.primitives, standard.unoccluded.primitives * 9 / 10);
  EXPECT_GT(tree.lifted_count(), 0u);
}

TEST(ShadowTraversal, QueryInterfaceMatchesEmbreeInPackets) {
  const TriangleMesh mesh = bench::random_soup(2000, 0.2f, 12);
  OccluderScene scene(mesh);
  const auto query = std::make_shared<MultiIndexShadowQuery>(mesh);
  const EmbreeShadowQuery embree(scene);
  const auto rays = random_rays(4001, 5, -0.2f, 1.2f);
  std::vector<int> via_embree(rays.size()), via_tree(rays.size());
  auto make = [&](std::size_t i) {
    return ShadowRay{rays[i].origin, rays[i].direction, rays[i].t_near, rays[i].t_far};
  };
  occluded_rays(scene, rays.size(), make, [&](std::size_t i, bool b) { via_embree[i] = b; });
  scene.set_shadow_query(query);
  ASSERT_EQ(scene.shadow_query(), query.get());
  occluded_rays(scene, rays.size(), make, [&](std::size_t i, bool b) { via_tree[i] = b; });
  int disagreements = 0, hits = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    hits += via_tree[i];
    if (via_embree[i] != via_tree[i]) {
      ++disagreements;
      EXPECT_TRUE(measure_zero_case(mesh, rays[i]));
    }
    EXPECT_EQ(bool(via_embree[i]),
              embree.occluded(rays[i].origin, rays[i].direction, rays[i].t_near, rays[i].t_far));
  }
  EXPECT_LE(disagreements, 4);
  EXPECT_GT(hits, 400);
  // Moving the scene keeps the attached traversal.
  OccluderScene moved(std::move(scene));
  EXPECT_EQ(moved.shadow_query(), query.get());
}

// The traversal is a render option of the scene document too ("render": {"shadow_traversal"},
// format version 5): read back exactly; written always, like every key; optional when read
// (absent: Embree); read in version-4 documents too (the builds before the version bump wrote it
// there), refused in versions 1-3; any other value is an error naming the key.
TEST(ShadowTraversal, SceneDocumentCarriesTheTraversal) {
  FogScene s;
  s.render.shadow_traversal = ShadowTraversal::embree;
  const std::string plain = scene_to_json(s);
  EXPECT_NE(plain.find("\"version\": 5"), std::string::npos) << plain;
  EXPECT_NE(plain.find("\"shadow_traversal\": \"embree\""), std::string::npos) << plain;
  EXPECT_EQ(scene_from_json(plain).render.shadow_traversal, ShadowTraversal::embree);
  const std::string head = "{\"format\": \"libmr-scene\", \"version\": ";
  EXPECT_EQ(scene_from_json(head + "5, \"render\": {}}").render.shadow_traversal,
            ShadowTraversal::embree);
  EXPECT_EQ(scene_from_json(head + "4, \"render\": {\"shadow_traversal\": \"multi-index\"}}")
                .render.shadow_traversal,
            ShadowTraversal::multi_index);
  for (int v : {1, 2, 3}) {
    try {
      scene_from_json(
          head + std::to_string(v) + ", \"render\": {\"shadow_traversal\": \"embree\"}}",
          "old.json");
      ADD_FAILURE() << "no error for shadow_traversal in a version-" << v << " document";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(
                    "old.json: /render/shadow_traversal: shadow_traversal is part of the format "
                    "from version 5 on"),
                std::string::npos)
          << e.what();
    }
  }
  s.render.shadow_traversal = ShadowTraversal::multi_index;
  const std::string text = scene_to_json(s);
  const std::string key = "\"shadow_traversal\": \"multi-index\"";
  const std::size_t at = text.find(key);
  ASSERT_NE(at, std::string::npos) << text;
  EXPECT_EQ(scene_from_json(text).render.shadow_traversal, ShadowTraversal::multi_index);
  // Written explicitly as "embree": read as Embree.
  std::string explicit_embree = text;
  explicit_embree.replace(at, key.size(), "\"shadow_traversal\": \"embree\"");
  EXPECT_EQ(scene_from_json(explicit_embree).render.shadow_traversal, ShadowTraversal::embree);
  // A wrong value: a clear error naming the key and the choices.
  std::string wrong = text;
  wrong.replace(at, key.size(), "\"shadow_traversal\": \"kd\"");
  try {
    scene_from_json(wrong, "scene.json");
    ADD_FAILURE() << "no error for shadow_traversal \"kd\"";
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("/render/shadow_traversal"), std::string::npos) << what;
    EXPECT_NE(what.find("multi-index"), std::string::npos) << what;
  }
}

// Renders through the CPU core (public API) with either traversal give identical images.
TEST(ShadowTraversal, CpuRendersAreIdenticalWithEitherTraversal) {
  const bench::Inputs& in = bench::leuven_inputs(320, 180);
  FogScene s = bench::leuven_sun_scene(Quality::draft);
  s.render.backend = Backend::cpu;
  s.render.threads = 2;
  s.render.shadow_traversal = ShadowTraversal::embree;
  const std::uint64_t packets0 = MultiIndexShadowQuery::packets_traced();
  const ScatteringLayers a = render_scattering(in.photo, in.depth, in.camera, s);
  const std::uint64_t packets1 = MultiIndexShadowQuery::packets_traced();
  s.render.shadow_traversal = ShadowTraversal::multi_index;
  const ScatteringLayers b = render_scattering(in.photo, in.depth, in.camera, s);
  const std::uint64_t packets2 = MultiIndexShadowQuery::packets_traced();
  EXPECT_EQ(packets1, packets0);         // Embree's render did not use the tree
  EXPECT_GT(packets2, packets1 + 1000);  // the other one did, for its shadow rays
  std::printf("multi-index render: %llu shadow packets on the tree\n",
              (unsigned long long)(packets2 - packets1));
  ASSERT_EQ(a.inscatter.pixels().size(), b.inscatter.pixels().size());
  std::size_t differing = 0;
  for (std::size_t i = 0; i < a.inscatter.pixels().size(); ++i)
    differing += a.inscatter.pixels()[i] != b.inscatter.pixels()[i] ||
                 a.transmittance.pixels()[i] != b.transmittance.pixels()[i];
  for (std::size_t i = 0; i < a.sun_visibility.pixels().size(); ++i)
    differing += a.sun_visibility.pixels()[i] != b.sun_visibility.pixels()[i];
  EXPECT_EQ(differing, 0u);
  // Not a trivial image: sunlit fog with shadows in it (shafts).
  double lo = INFINITY, hi = 0;
  for (float v : b.inscatter.pixels()) {
    lo = std::min(lo, double(v));
    hi = std::max(hi, double(v));
  }
  EXPECT_GT(hi, 0.0);
  EXPECT_GT(hi, 2 * lo);
  render::clear_occluder_geometry_cache();
}

}  // namespace
}  // namespace mr::render
