// The occluder surface's regular stretches as Embree grids (issue 12 item 4,
// OccluderSceneOptions::surface_grids): which pixels the grids cover, and a scene with grids
// answers every query as the same mesh given as quads only.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstddef>
#include <limits>
#include <random>
#include <vector>

#include "mr/camera.h"
#include "mr/image.h"
#include "mr/scene.h"
#include "render/embree_scene.h"
#include "render/occluder_mesh.h"
#include "tests/wall_and_mound_scene.h"

namespace mr::render {
namespace {

constexpr float kInfF = std::numeric_limits<float>::infinity();

// 10x7 pixels of a wall facing the camera at z = 5 m, its right part (x >= 6) at z = 10 m
// (a discontinuity: the corners of column 6 split), pixel (3, 2) sky.
struct SmallMap {
  Camera camera = Camera::from_horizontal_fov(10, 7, 40);
  CameraPose pose;
  Image distance_m{10, 7, 1};
};

SmallMap make_small_map() {
  SmallMap m;
  for (int y = 0; y < 7; ++y)
    for (int x = 0; x < 10; ++x) {
      const Vec3 w = m.pose.ray_direction(m.camera, x, y);
      const double z = x >= 6 ? 10.0 : 5.0;
      m.distance_m.at(x, y, 0) = (x == 3 && y == 2) ? kInfF : float(z / w.z);
    }
  return m;
}

TEST(SurfaceGrid, CoverageOnASmallMap) {
  const SmallMap m = make_small_map();
  MeshOptions with_layout;
  with_layout.pixel_layout = true;
  const TriangleMesh mesh =
      reconstruct_occluder_mesh(m.distance_m.view(), m.camera, m.pose, with_layout);
  ASSERT_TRUE(mesh.layout);
  // Off by default: no layout, and so no grids.
  EXPECT_FALSE(reconstruct_occluder_mesh(m.distance_m.view(), m.camera, m.pose).layout);
  const SurfacePixelLayout& layout = *mesh.layout;
  ASSERT_EQ(layout.width, 10);
  ASSERT_EQ(layout.height, 7);
  // A plane: no pixel fanned, 69 surface pixels.
  EXPECT_EQ(mesh.surface_triangle_count, 2u * 69u);
  for (int y = 0; y < 7; ++y)
    for (int x = 0; x < 10; ++x) {
      const std::uint8_t p = layout.pixel[std::size_t(y) * 10 + x];
      const bool sky = x == 3 && y == 2;
      EXPECT_EQ((p & SurfacePixelLayout::kSurface) != 0, !sky) << x << "," << y;
      // Eligible: every surface pixel but those with a corner on the split column 6 (the
      // sky pixel's neighbours keep one vertex per corner: their corners have one group).
      const bool eligible = !sky && x != 5 && x != 6;
      EXPECT_EQ((p & SurfacePixelLayout::kGridEligible) != 0, eligible) << x << "," << y;
    }
  // Bands of rows (0, 1), (2, 3), (4, 5); row 6 has no partner. The sky pixel takes (3, 3)
  // out of its band's grids.
  const std::vector<SurfaceGridRun> expected = {{0, 0, 5},  {0, 7, 10}, {1, 0, 3}, {1, 4, 5},
                                                {1, 7, 10}, {2, 0, 5},  {2, 7, 10}};
  EXPECT_EQ(surface_grid_runs(layout), expected);
  EXPECT_FALSE(surface_grid_covers(layout, 3, 3));
  EXPECT_TRUE(surface_grid_covers(layout, 4, 3));
  EXPECT_FALSE(surface_grid_covers(layout, 0, 6));
  // The scene: bands 0 and 2 cover 8 columns of 2 rows each, band 1 7; the rest are quads.
  OccluderSceneOptions with_grids;
  with_grids.surface_grids = true;
  const OccluderScene scene(mesh, with_grids);
  EXPECT_EQ(OccluderScene(mesh).grid_pixel_count(), 0u);  // off by default
  EXPECT_EQ(scene.grid_pixel_count(), std::size_t(2 * (8 + 7 + 8)));
  EXPECT_EQ(scene.surface_quad_count(), std::size_t(69 - 46));
  // Merged meshes carry no layout (their surface is not two triangles per pixel).
  MeshOptions merged = with_layout;
  merged.planar_merge_tolerance = 1e-3;
  EXPECT_FALSE(reconstruct_occluder_mesh(m.distance_m.view(), m.camera, m.pose, merged).layout);
}

// The wall-and-mound scene (tests/wall_and_mound_scene.h): discontinuities (the wall's outline),
// fanned pixels (the mound's creases), sky.
using test::wall_and_mound;
using test::WallAndMound;

TEST(SurfaceGrid, SameAnswersAsTheQuads) {
  const WallAndMound in = wall_and_mound();
  MeshOptions options;
  options.thickness_m = 0.3;  // extrusions after the surface: the grids' scene has a second BVH
  options.pixel_layout = true;
  const TriangleMesh mesh =
      reconstruct_occluder_mesh(in.distance_m.view(), in.camera, in.pose, options);
  OccluderSceneOptions with_grids, quads_only;
  with_grids.surface_grids = true;
  quads_only.surface_grids = false;
  const OccluderScene grids(mesh, with_grids);
  const OccluderScene quads(mesh, quads_only);
  // Both kinds of primitive in the grids' scene, none in the other's.
  EXPECT_GT(grids.grid_pixel_count(), 240u * 100u);
  EXPECT_GT(grids.surface_quad_count(), 500u);
  EXPECT_EQ(quads.grid_pixel_count(), 0u);
  EXPECT_EQ(2 * (grids.grid_pixel_count() + grids.surface_quad_count()),
            mesh.surface_triangle_count);

  // 1. Camera rays through every pixel centre: each runs along its pixel's diagonal c00-c11,
  // the edge the grid cells and the quads split on (the hardest case for a watertight test).
  const std::array<float, 3> eye{0.0f, 1.6f, 0.0f};
  int surface_hits = 0, distance_differs = 0;
  for (int y = 0; y < in.camera.height; ++y)
    for (int x = 0; x < in.camera.width; ++x) {
      const Vec3 w = in.pose.ray_direction(in.camera, x, y);
      const std::array<float, 3> d{float(w.x), float(w.y), float(w.z)};
      const float ta = grids.intersect_distance(eye, d, 0, kInfF);
      const float tb = quads.intersect_distance(eye, d, 0, kInfF);
      ASSERT_EQ(std::isfinite(ta), std::isfinite(tb)) << x << "," << y;
      ASSERT_EQ(std::isfinite(ta), std::isfinite(in.distance_m.at(x, y, 0))) << x << "," << y;
      if (!std::isfinite(ta)) continue;
      ++surface_hits;
      distance_differs += ta != tb;
      EXPECT_NEAR(ta, tb, 1e-5f * tb) << x << "," << y;
      EXPECT_EQ(grids.occluded(eye, d, 0, kInfF), quads.occluded(eye, d, 0, kInfF));
    }
  EXPECT_GT(surface_hits, 240 * 80);
  // 2. Shadow rays from points above the ground toward random directions, one at a time and
  // in packets (occluded_rays), including t ranges that end near the surface.
  std::mt19937 rng(17);
  std::uniform_real_distribution<float> px(-6, 8), py(0.05f, 5), pz(2, 30), unit(-1, 1),
      far(0.5f, 20);
  constexpr int kRays = 40000;
  std::vector<ShadowRay> rays(kRays);
  int hits = 0, disagree = 0;
  for (int i = 0; i < kRays; ++i) {
    ShadowRay& r = rays[std::size_t(i)];
    r.origin = {px(rng), py(rng), pz(rng)};
    r.direction = {unit(rng), unit(rng), unit(rng)};
    r.t_far = i % 2 ? kInfF : far(rng);
    const bool a = grids.occluded(r.origin, r.direction, r.t_near, r.t_far);
    const bool b = quads.occluded(r.origin, r.direction, r.t_near, r.t_far);
    disagree += a != b;
    hits += a;
  }
  EXPECT_GT(hits, kRays / 10);
  EXPECT_LT(hits, kRays - kRays / 10);
  EXPECT_EQ(disagree, 0) << "of " << kRays << " rays";
  std::vector<char> packet_grids(kRays), packet_quads(kRays);
  auto make = [&](std::size_t i) { return rays[i]; };
  occluded_rays(grids, rays.size(), make, [&](std::size_t i, bool b) { packet_grids[i] = b; });
  occluded_rays(quads, rays.size(), make, [&](std::size_t i, bool b) { packet_quads[i] = b; });
  EXPECT_EQ(packet_grids, packet_quads);
  std::printf("[ info ] %d camera-ray distances not bit-identical of %d\n", distance_differs,
              surface_hits);
}

}  // namespace
}  // namespace mr::render
