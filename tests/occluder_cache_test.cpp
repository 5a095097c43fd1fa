// The CPU backend's occluder geometry reused across renders of one photo (render/occluder_cache.*,
// issue 12 item 4): a render whose fog and sun changed but whose depth map, camera, pose and
// blockers did not reuses the normals, mesh and BVH (mr::ScatteringLayers::Timings reports no
// mesh or BVH time then), and gives output identical, bit for bit, to a fresh render; any change
// of the geometry's inputs builds afresh.
#include <gtest/gtest.h>

#include <cstring>

#include "mr/mr.h"
#include "render/occluder_cache.h"
#include "scattering_scenes.h"

namespace mr {
namespace {

bool identical(const Image& a, const Image& b) {
  return a.width() == b.width() && a.height() == b.height() && a.channels() == b.channels() &&
         std::memcmp(a.data(), b.data(), sizeof(float) * a.pixels().size()) == 0;
}

struct Fixture {
  Camera camera = Camera::from_horizontal_fov(96, 64, 70);
  FogScene scene;
  Image depth, photo;
  Fixture() {
    scene.pose.position_m = {0, 1.6, 0};
    scene.pose.pitch_deg = 5;
    scene.medium.sigma_t_per_m = {0.03f, 0.03f, 0.03f};
    scene.medium.albedo = {0.9f, 0.9f, 0.9f};
    scene.medium.g = 0.5;
    scene.lighting.sky_radiance = Rgb{0.2f, 0.2f, 0.25f};
    scene.lighting.sun = Sun{direction_from_azimuth_elevation(-60, 20), {3, 3, 3}, 0.27};
    scene.render.quality = Quality::normal;
    scene.render.backend = Backend::cpu;
    depth = test::street_depth(camera, scene.pose);
    photo = Image(camera.width, camera.height, 3);
    for (float& v : photo.pixels()) v = 0.3f;
  }
  ScatteringLayers render(const FogScene& s, const Image& d) const {
    return render_scattering(photo, d, camera, s);
  }
};

TEST(OccluderCache, SliderChangesReuseTheGeometryWithIdenticalOutput) {
  const Fixture f;
  render::clear_occluder_geometry_cache();
  const ScatteringLayers first = f.render(f.scene, f.depth);
  EXPECT_GT(first.timings.mesh_s + first.timings.bvh_s, 0.0);  // built

  // The fog thickens and the sun moves (what mr-studio's sliders change).
  FogScene changed = f.scene;
  changed.medium.sigma_t_per_m = {0.05f, 0.05f, 0.05f};
  changed.lighting.sun->direction_to_sun = direction_from_azimuth_elevation(-40, 30);
  const ScatteringLayers reused = f.render(changed, f.depth);
  EXPECT_EQ(reused.timings.mesh_s, 0.0);  // reused: no mesh or BVH built
  EXPECT_EQ(reused.timings.bvh_s, 0.0);

  render::clear_occluder_geometry_cache();
  const ScatteringLayers fresh = f.render(changed, f.depth);
  EXPECT_GT(fresh.timings.mesh_s + fresh.timings.bvh_s, 0.0);
  EXPECT_TRUE(identical(reused.transmittance, fresh.transmittance));
  EXPECT_TRUE(identical(reused.inscatter, fresh.inscatter));
  EXPECT_TRUE(identical(reused.sun_visibility, fresh.sun_visibility));
  EXPECT_TRUE(identical(reused.optical_depth, fresh.optical_depth));
  // The shafts are there (the test would pass vacuously on an unshadowed scene).
  double shadowed = 0;
  for (float v : fresh.sun_visibility.pixels()) shadowed += v < 0.5f;
  EXPECT_GT(shadowed, 0.05 * f.camera.width * f.camera.height);
}

TEST(OccluderCache, AnyChangeOfTheGeometrysInputsBuildsAfresh) {
  const Fixture f;
  render::clear_occluder_geometry_cache();
  f.render(f.scene, f.depth);
  EXPECT_EQ(f.render(f.scene, f.depth).timings.mesh_s, 0.0);  // same inputs: reused

  Image depth = f.depth;
  depth.at(40, 40, 0) *= 1.01f;  // one pixel's depth
  EXPECT_GT(f.render(f.scene, depth).timings.mesh_s, 0.0);
  EXPECT_GT(f.render(f.scene, f.depth).timings.mesh_s, 0.0);  // back to the first map

  FogScene pose = f.scene;
  pose.pose.pitch_deg += 0.5;
  EXPECT_GT(f.render(pose, f.depth).timings.mesh_s, 0.0);

  FogScene blockers = f.scene;
  blockers.blockers.canopy = Blockers::Canopy{};
  EXPECT_GT(f.render(blockers, f.depth).timings.mesh_s, 0.0);

  FogScene quality = blockers;
  quality.render.quality = Quality::draft;  // a coarser mesh (mesh_step 2)
  EXPECT_GT(f.render(quality, f.depth).timings.mesh_s, 0.0);

  // And a reused render after all that equals a fresh one.
  const ScatteringLayers reused = f.render(quality, f.depth);
  EXPECT_EQ(reused.timings.mesh_s, 0.0);
  render::clear_occluder_geometry_cache();
  const ScatteringLayers fresh = f.render(quality, f.depth);
  EXPECT_TRUE(identical(reused.inscatter, fresh.inscatter));
  EXPECT_TRUE(identical(reused.transmittance, fresh.transmittance));
}

}  // namespace
}  // namespace mr
