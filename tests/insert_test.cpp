// Inserting 3D objects into photos (issue 16): the differential renderer against the brute-force
// Monte Carlo reference (tests/mc_insert_reference.*, sharing no code with render/), occlusion
// by the photo's foreground, and the API's contracts.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "insert_scene.h"
#include "insert_test_meshes.h"
#include "mc_comparison_scene.h"
#include "mc_insert_reference.h"
#include "mc_reference.h"
#include "mr/error.h"
#include "mr/insert.h"
#include "mr/io.h"
#include "test_support.h"

namespace mr {
namespace {

using mcref::Box;
using mcref::Geometry;

using test::InsertScene;
InsertScene make_scene() { return test::make_insert_scene(); }

void save_png(const Image& img, const std::string& name) {
  if (const char* dir = std::getenv("MR_INSERT_TEST_IMAGES")) {
    Image rgb(img.width(), img.height(), 3);
    for (int y = 0; y < img.height(); ++y)
      for (int x = 0; x < img.width(); ++x)
        for (int c = 0; c < 3; ++c) rgb.view().at(x, y, c) = img.at(x, y, std::min(c, img.channels() - 1));
    write_image(std::string(dir) + "/" + name + ".png", rgb);
  }
}

TEST(InsertObjects, MatchesMonteCarloReference) {
  const InsertScene s = make_scene();
  mcref::RadianceSettings st;
  st.pixel_samples_per_axis = test::kMcSlowBuild ? 2 : 4;
  st.sun_samples = 16;
  st.sky_samples = test::kMcSlowBuild ? 64 : 256;
  st.seed = 7;
  const Image photo = mcref::surface_radiance(s.camera, s.scene.pose, s.scene.lighting, s.photo_geometry,
                                              s.photo_materials, st);
  const Image want = mcref::surface_radiance(s.camera, s.scene.pose, s.scene.lighting, s.full_geometry,
                                             s.full_materials, st);
  const Image distance = mcref::distance_map(s.camera, s.scene.pose, s.photo_geometry);
  const Image full_distance = mcref::distance_map(s.camera, s.scene.pose, s.full_geometry);

  InsertOptions options;  // full quality
  const InsertResult got = insert_objects(photo, distance, s.camera, s.scene, s.objects, options);
  save_png(photo, "mc_photo");
  save_png(want, "mc_with_objects");
  save_png(got.composite, "product_composite");
  save_png(got.matte, "product_matte");

  const int w = s.camera.width, h = s.camera.height;
  {
    Image err(w, h, 3);  // |got - want| / want x 5, per channel
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        for (int c = 0; c < 3; ++c)
          err.view().at(x, y, c) = 5 * std::fabs(got.composite.at(x, y, c) - want.at(x, y, c)) / std::max(want.at(x, y, c), 1e-4f);
    save_png(err, "error_x5");
  }
  const test::CompositeError e = test::composite_error(photo, want, got.composite, distance, full_distance);
  std::printf("composite mean rel error %.4f (n %zu); object pixels %.4f (n %zu); object-shadow region %.4f (n %zu)\n",
              e.mean, e.n, e.objects, e.n_objects, e.shadow, e.n_shadow);
  ASSERT_GT(e.n_shadow, 300u);  // the shadows are there to test
  ASSERT_GT(e.n_objects, 600u);
  EXPECT_LT(e.mean, 0.02);
  EXPECT_LT(e.shadow, 0.05);
  // The objects' shadows and the objects are really in the product's composite (not a photo
  // copy that would pass the mean on a mostly unchanged image).
  double darkening = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) darkening += photo.at(x, y, 1) - got.composite.at(x, y, 1);
  EXPECT_GT(darkening, 1.0);
}

TEST(InsertObjects, NoObjectsLeavesThePhotoUnchanged) {
  const InsertScene s = make_scene();
  const Image distance = mcref::distance_map(s.camera, s.scene.pose, s.photo_geometry);
  const Image photo = test::make_test_photo(s.camera.width, s.camera.height);
  const InsertResult r = insert_objects(photo, distance, s.camera, s.scene, {}, InsertOptions::preview());
  for (std::size_t i = 0; i < photo.pixels().size(); ++i)
    ASSERT_EQ(r.composite.pixels()[i], photo.pixels()[i]);
  for (float m : r.matte.pixels()) ASSERT_EQ(m, 0.0f);
}

// An object behind a foreground wall is hidden exactly where the depth map shows the wall; in
// front of it, it covers it.
TEST(InsertObjects, OccludedByTheForegroundExactlyWhereTheDepthSays) {
  Camera camera = Camera::from_horizontal_fov(96, 64, 50);
  FogScene scene;
  scene.pose.position_m = {0, 1.2, 0};
  scene.lighting.sun = Sun{direction_from_azimuth_elevation(150, 45), {3, 3, 3}, 0.27};
  scene.lighting.sky_radiance = Rgb{0.4f, 0.4f, 0.4f};
  Geometry open, walled;
  open.ground = walled.ground = true;
  walled.boxes.push_back(Box{{-0.4, 0, 6}, {0.3, 3, 6.2}});  // a post in the middle
  const Image d_open = mcref::distance_map(camera, scene.pose, open);
  const Image d_wall = mcref::distance_map(camera, scene.pose, walled);
  const Image photo = test::make_test_photo(camera.width, camera.height);
  auto insert_at = [&](const Image& d, double z) {
    InsertObject o;
    o.mesh = test::uv_sphere(1.2, 32, 64, {0.7f, 0.7f, 0.7f}, 0.5f);
    o.placement.position_m = {0, 1.2, z};
    InsertOptions opt = InsertOptions::preview();
    opt.samples_per_axis = 3;
    return insert_objects(photo, d, camera, scene, std::span<const InsertObject>(&o, 1), opt);
  };
  const int w = camera.width, h = camera.height;
  auto all3x3 = [&](int x, int y, bool wall) {
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx) {
        const int xx = std::clamp(x + dx, 0, w - 1), yy = std::clamp(y + dy, 0, h - 1);
        const bool is_wall = d_wall.at(xx, yy, 0) < d_open.at(xx, yy, 0) * 0.999f;
        if (is_wall != wall) return false;
      }
    return true;
  };
  // Behind (z = 10): hidden on the wall, unchanged elsewhere.
  const InsertResult behind_open = insert_at(d_open, 10), behind = insert_at(d_wall, 10);
  std::size_t hidden = 0, shown = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float m_open = behind_open.matte.at(x, y, 0), m = behind.matte.at(x, y, 0);
      if (all3x3(x, y, true)) {
        EXPECT_EQ(m, 0.0f) << x << "," << y;
        hidden += m_open > 0.5f;
      } else if (all3x3(x, y, false)) {
        EXPECT_EQ(m, m_open) << x << "," << y;
        shown += m_open > 0.5f;
      }
    }
  EXPECT_GT(hidden, 40u);  // the wall really hides part of the sphere
  EXPECT_GT(shown, 40u);
  // In front (z = 4): it covers the wall exactly as it covers open ground.
  const InsertResult front_open = insert_at(d_open, 4), front = insert_at(d_wall, 4);
  std::size_t covering = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      EXPECT_EQ(front.matte.at(x, y, 0), front_open.matte.at(x, y, 0)) << x << "," << y;
      covering += all3x3(x, y, true) && front.matte.at(x, y, 0) == 1.0f;
      if (front.matte.at(x, y, 0) == 1.0f) {
        EXPECT_LT(front.distance_m.at(x, y, 0), d_wall.at(x, y, 0));
      }
    }
  EXPECT_GT(covering, 40u);
}

// The objects join the fog: their distance replaces the photo's where they are in front (sky
// light only: T is exactly the view ray's transmittance), and with a sun they cast shafts (less
// in-scattered light on view rays through their shadows, where the photo is unchanged).
TEST(InsertObjects, FogTakesTheObjectsDepthAndShadows) {
  const InsertScene s = make_scene();
  const Image distance = mcref::distance_map(s.camera, s.scene.pose, s.photo_geometry);
  const Image photo = test::make_test_photo(s.camera.width, s.camera.height);
  FogScene scene = s.scene;
  scene.medium.sigma_t_per_m = {0.05f, 0.05f, 0.05f};
  scene.medium.layer_top_m = 8;
  InsertOptions opt = InsertOptions::preview();
  opt.fog = true;
  {
    FogScene overcast = scene;
    overcast.lighting.sun.reset();
    const InsertResult r = insert_objects(photo, distance, s.camera, overcast, s.objects, opt);
    ASSERT_FALSE(r.transmittance.empty());
    int checked = 0;
    for (int y = 0; y < s.camera.height; ++y)
      for (int x = 0; x < s.camera.width; ++x)
        if (r.distance_m.at(x, y, 0) < distance.at(x, y, 0)) {
          EXPECT_NEAR(r.transmittance.at(x, y, 1), std::exp(-0.05f * r.distance_m.at(x, y, 0)), 1e-4f);
          checked += r.distance_m.at(x, y, 0) < distance.at(x, y, 0) - 3;
        }
    EXPECT_GT(checked, 50);
  }
  const InsertResult with = insert_objects(photo, distance, s.camera, scene, s.objects, opt);
  const InsertResult without = insert_objects(photo, distance, s.camera, scene, {}, opt);
  double darker = 0;
  for (int y = 0; y < s.camera.height; ++y)
    for (int x = 0; x < s.camera.width; ++x) {
      if (with.matte.at(x, y, 0) > 0 || with.distance_m.at(x, y, 0) != distance.at(x, y, 0)) continue;
      const float a = with.inscatter.at(x, y, 1), b = without.inscatter.at(x, y, 1);
      // (The core's sparse-grid interpolation moves by up to ~1 % where the depth changed.)
      EXPECT_LE(a, b * 1.02f + 1e-6f) << x << "," << y;
      darker += b - a;
    }
  EXPECT_GT(darker, 0.05);  // the shafts are there
  save_png(with.composite, "fog_composite");
}

TEST(InsertObjects, BadMeshesGiveErrorsNamingTheSource) {
  const InsertScene s = make_scene();
  const Image distance = mcref::distance_map(s.camera, s.scene.pose, s.photo_geometry);
  const Image photo = test::make_test_photo(s.camera.width, s.camera.height);
  InsertObject o;
  o.mesh = test::box_mesh({0, 0, 0}, {1, 1, 1}, {0.5f, 0.5f, 0.5f}, 0.5f);
  o.mesh.source = "broken.glb";
  o.mesh.triangles.push_back({0, 1, 99});
  try {
    insert_objects(photo, distance, s.camera, s.scene, std::span<const InsertObject>(&o, 1));
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("broken.glb"), std::string::npos) << e.what();
  }
  o.mesh.triangles.pop_back();
  o.mesh.positions[0][1] = std::nanf("");
  EXPECT_THROW(insert_objects(photo, distance, s.camera, s.scene, std::span<const InsertObject>(&o, 1)), Error);
  o.mesh.positions[0][1] = 0;
  o.placement.scale = -1;
  EXPECT_THROW(insert_objects(photo, distance, s.camera, s.scene, std::span<const InsertObject>(&o, 1)), Error);
}

}  // namespace
}  // namespace mr
