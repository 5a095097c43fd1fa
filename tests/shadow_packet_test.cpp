// render::occluded_rays (render/embree_scene.h), the one 8-wide shadow-packet loop on the
// occluder scene, against one rtcOccluded1 query per ray (OccluderScene::occluded), for ray
// counts around the packet width (partial packets, none at all).
#include <gtest/gtest.h>

#include <array>
#include <cstddef>
#include <random>
#include <vector>

#include "render/embree_scene.h"
#include "render/occluder_mesh.h"

namespace mr::render {
namespace {

// A 2 m x 2 m square in the plane z = 5, centred on the z axis: rays from the origin toward
// z > 0 hit it when they point within its outline and reach z = 5.
OccluderScene square_at_z5() {
  TriangleMesh mesh;
  mesh.positions = {-1, -1, 5, 1, -1, 5, 1, 1, 5, -1, 1, 5};
  mesh.indices = {0, 1, 2, 0, 2, 3};
  mesh.surface_triangle_count = 2;
  return OccluderScene(std::move(mesh));
}

TEST(ShadowPackets, SameAnswerAsOneRayAtATime) {
  const OccluderScene scene = square_at_z5();
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> across(-0.4f, 0.4f), reach(3.0f, 8.0f);
  for (std::size_t count : {0u, 1u, 7u, 8u, 9u, 16u, 21u}) {
    std::vector<ShadowRay> rays(count);
    for (ShadowRay& ray : rays) {
      ray.origin = {0, 0, 0};
      ray.direction = {across(rng), across(rng), 1.0f};  // through the square's plane at |x|,|y| <= 2
      ray.t_far = reach(rng);                            // some stop before z = 5
    }
    std::vector<int> answers(count, -1);
    std::vector<std::size_t> order;
    occluded_rays(
        scene, count, [&](std::size_t i) { return rays.at(i); },
        [&](std::size_t i, bool blocked) {
          order.push_back(i);
          answers.at(i) = blocked ? 1 : 0;
        });
    ASSERT_EQ(order.size(), count);
    std::size_t hits = 0;
    for (std::size_t i = 0; i < count; ++i) {
      EXPECT_EQ(order[i], i);
      const bool expected = scene.occluded(rays[i].origin, rays[i].direction, rays[i].t_near, rays[i].t_far);
      EXPECT_EQ(answers[i], expected ? 1 : 0) << "ray " << i << " of " << count;
      hits += expected;
    }
    if (count >= 16) {  // the scene is a real test: both answers occur
      EXPECT_GT(hits, 0u);
      EXPECT_LT(hits, count);
    }
  }
}

}  // namespace
}  // namespace mr::render
