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

#define EXPECT_CONTAINS(text, part) \
  EXPECT_NE(std::string(text).find(part), std::string::npos) << (text)

using test::InsertScene;
InsertScene make_scene() { return test::make_insert_scene(); }

void save_png(const Image& img, const std::string& name) {
  if (const char* dir = std::getenv("MR_INSERT_TEST_IMAGES")) {
    Image rgb(img.width(), img.height(), 3);
    for (int y = 0; y < img.height(); ++y)
      for (int x = 0; x < img.width(); ++x)
        for (int c = 0; c < 3; ++c)
          rgb.view().at(x, y, c) = img.at(x, y, std::min(c, img.channels() - 1));
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
  const Image photo = mcref::surface_radiance(s.camera, s.scene.pose, s.scene.lighting,
                                              s.photo_geometry, s.photo_materials, st);
  const Image want = mcref::surface_radiance(s.camera, s.scene.pose, s.scene.lighting,
                                             s.full_geometry, s.full_materials, st);
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
          err.view().at(x, y, c) = 5 * std::fabs(got.composite.at(x, y, c) - want.at(x, y, c)) /
                                   std::max(want.at(x, y, c), 1e-4f);
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
  const InsertResult r =
      insert_objects(photo, distance, s.camera, s.scene, {}, InsertOptions::preview());
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

// Normal maps: a flat plane whose normal texture holds one constant tilted normal is shaded
// exactly like a plane that is geometrically tilted to that normal (sun only, no sky, nothing
// that shadows either: the shading then depends only on the normal and the view direction, which
// the two share at every pixel). The expected normal is the texture's tangent-space one in the
// plane's own tangent frame (tangent, w cross(n, t), n), rotated by the placement's yaw. Bar:
// 1e-4 relative (float rounding of the two normals); and the map must change the shading (the
// untilted plane differs by more than 5 %).
TEST(InsertObjects, NormalMapShadesLikeATiltedPlane) {
  const Camera camera = Camera::from_horizontal_fov(64, 48, 40);
  FogScene scene;
  scene.pose.position_m = {0, 2, 0};
  scene.pose.pitch_deg = -30;
  scene.render.volumetric_shadows = false;  // nothing in the photo casts shadows
  scene.lighting.sun = Sun{{0.3, 0.8, -0.5}, {3, 3, 3}, 0.27};
  scene.lighting.sky_radiance = Rgb{0, 0, 0};
  Image distance(camera.width, camera.height, 1);
  for (float& d : distance.pixels()) d = 1000.0f;  // a far backdrop
  const Image photo = test::make_test_photo(camera.width, camera.height);

  const double tilt[3] = {0.35, -0.25, 0.9};  // tangent space: x along t, y along b, z along n
  const double len = std::sqrt(tilt[0] * tilt[0] + tilt[1] * tilt[1] + tilt[2] * tilt[2]);
  ObjectMesh mapped = make_primitive("plane");
  ObjectTexture texture;
  texture.source = "tilted_normals.png";
  texture.image = Image(2, 2, 3);
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 2; ++x)
      for (int c = 0; c < 3; ++c)
        texture.image.view().at(x, y, c) = float(0.5 * (tilt[c] / len + 1));
  mapped.textures.push_back(texture);
  mapped.materials.at(0).normal_texture = 0;
  ObjectPlacement placement;
  placement.position_m = {0, 0, 2 / std::tan(30 * 3.14159265358979 / 180)};
  placement.yaw_deg = 40;
  placement.scale = 2;

  // The expected normal in the object's frame, then in the world's (the placement's rotation).
  const auto& t = mapped.tangents.at(0);
  const double n_obj[3] = {0, 1, 0}, t_obj[3] = {t[0], t[1], t[2]};
  const double b_obj[3] = {t[3] * (n_obj[1] * t_obj[2] - n_obj[2] * t_obj[1]),
                           t[3] * (n_obj[2] * t_obj[0] - n_obj[0] * t_obj[2]),
                           t[3] * (n_obj[0] * t_obj[1] - n_obj[1] * t_obj[0])};
  double local[3];
  for (int c = 0; c < 3; ++c)
    local[c] = (t_obj[c] * tilt[0] + b_obj[c] * tilt[1] + n_obj[c] * tilt[2]) / len;
  const Mat4 M = placement_matrix(placement);
  const Vec3 world{M[0] * local[0] + M[1] * local[1] + M[2] * local[2],
                   M[4] * local[0] + M[5] * local[1] + M[6] * local[2],
                   M[8] * local[0] + M[9] * local[1] + M[10] * local[2]};
  ObjectPlacement tilted = placement;
  tilted.up = world;  // the scale is uniform: the direction is the normal's

  for (const InsertOptions& options : {InsertOptions::preview(), InsertOptions{}}) {
    auto render = [&](const ObjectMesh& mesh, const ObjectPlacement& where) {
      InsertObject o;
      o.mesh = mesh;
      o.placement = where;
      return insert_objects(photo, distance, camera, scene, std::span<const InsertObject>(&o, 1),
                            options);
    };
    const InsertResult with_map = render(mapped, placement);
    const InsertResult reference = render(make_primitive("plane"), tilted);
    const InsertResult flat = render(make_primitive("plane"), placement);
    std::size_t compared = 0, changed = 0;
    double worst = 0;
    for (int y = 0; y < camera.height; ++y)
      for (int x = 0; x < camera.width; ++x) {
        if (with_map.matte.at(x, y, 0) != 1.0f || reference.matte.at(x, y, 0) != 1.0f ||
            flat.matte.at(x, y, 0) != 1.0f)
          continue;
        ++compared;
        for (int c = 0; c < 3; ++c) {
          const float a = with_map.composite.at(x, y, c), b = reference.composite.at(x, y, c);
          ASSERT_GT(b, 0.0f);
          worst = std::max(worst, double(std::fabs(a - b) / b));
        }
        changed += std::fabs(with_map.composite.at(x, y, 1) - flat.composite.at(x, y, 1)) >
                   0.05f * flat.composite.at(x, y, 1);
      }
    std::printf("normal map vs tilted plane: %zu pixels, worst %.2e relative\n", compared, worst);
    EXPECT_GT(compared, 100u);
    EXPECT_LT(worst, 1e-4);
    EXPECT_EQ(changed, compared);
  }
}

// A normal texture that cannot hold normals (fewer than 3 channels) is an error naming the model
// and the texture, not a silent flat surface.
TEST(InsertObjects, BrokenNormalTextureIsAnErrorNamingIt) {
  const InsertScene s = make_scene();
  const Image distance = mcref::distance_map(s.camera, s.scene.pose, s.photo_geometry);
  const Image photo = test::make_test_photo(s.camera.width, s.camera.height);
  InsertObject o;
  o.mesh = make_primitive("box");
  o.mesh.source = "crate.glb";
  ObjectTexture texture;
  texture.source = "crate_normal.png";
  texture.image = Image(4, 4, 2);
  o.mesh.textures.push_back(texture);
  o.mesh.materials.at(0).normal_texture = 0;
  o.placement.position_m = {0, 0, 6};
  try {
    insert_objects(photo, distance, s.camera, s.scene, std::span<const InsertObject>(&o, 1),
                   InsertOptions::preview());
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_CONTAINS(std::string(e.what()), "crate.glb");
    EXPECT_CONTAINS(std::string(e.what()), "crate_normal.png");
    EXPECT_CONTAINS(std::string(e.what()), "channel");
  }
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
          EXPECT_NEAR(r.transmittance.at(x, y, 1), std::exp(-0.05f * r.distance_m.at(x, y, 0)),
                      1e-4f);
          checked += r.distance_m.at(x, y, 0) < distance.at(x, y, 0) - 3;
        }
    EXPECT_GT(checked, 50);
  }
  const InsertResult with = insert_objects(photo, distance, s.camera, scene, s.objects, opt);
  const InsertResult without = insert_objects(photo, distance, s.camera, scene, {}, opt);
  double darker = 0;
  for (int y = 0; y < s.camera.height; ++y)
    for (int x = 0; x < s.camera.width; ++x) {
      if (with.matte.at(x, y, 0) > 0 || with.distance_m.at(x, y, 0) != distance.at(x, y, 0))
        continue;
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
  EXPECT_THROW(
      insert_objects(photo, distance, s.camera, s.scene, std::span<const InsertObject>(&o, 1)),
      Error);
  o.mesh.positions[0][1] = 0;
  o.placement.scale = -1;
  EXPECT_THROW(
      insert_objects(photo, distance, s.camera, s.scene, std::span<const InsertObject>(&o, 1)),
      Error);
}

// The interactive preview (mr::InsertPreview) renders only the screen tiles the objects, their
// shadows and their sky occlusion can touch, and resets the tiles a previous frame touched: its
// frames must equal insert_objects' image with the same options exactly (bit for bit), through a
// drag (the object moved, the stale shadow gone), a change of options, and no objects at all.
TEST(InsertPreview, FramesEqualTheFullRenderThroughADrag) {
  const InsertScene s = make_scene();
  const Image distance = mcref::distance_map(s.camera, s.scene.pose, s.photo_geometry);
  const Image photo = test::make_test_photo(s.camera.width, s.camera.height);
  InsertPreview preview(photo, distance, s.camera, s.scene, InsertOptions::preview());
  auto expect_same = [&](const InsertResult& got, const std::vector<InsertObject>& objects,
                         const InsertOptions& options, const char* what) {
    const InsertResult want = insert_objects(photo, distance, s.camera, s.scene, objects, options);
    std::size_t differ = 0, changed = 0;
    for (std::size_t i = 0; i < want.composite.pixels().size(); ++i) {
      differ += got.composite.pixels()[i] != want.composite.pixels()[i];
      changed += want.composite.pixels()[i] != photo.pixels()[i];
    }
    for (std::size_t i = 0; i < want.matte.pixels().size(); ++i) {
      differ += got.matte.pixels()[i] != want.matte.pixels()[i];
      differ += got.distance_m.pixels()[i] != want.distance_m.pixels()[i];
    }
    EXPECT_EQ(differ, 0u) << what;
    return changed;
  };
  std::vector<InsertObject> objects = s.objects;
  const std::size_t changed_first = expect_same(preview.render(objects, InsertOptions::preview()),
                                                objects, InsertOptions::preview(), "first");
  EXPECT_GT(changed_first, 500u);  // the objects and their shadows are there
  const auto first = preview.last_frame();
  EXPECT_TRUE(first.objects_rebuilt);
  EXPECT_GT(first.tiles_rendered, 0u);
  EXPECT_LT(first.tiles_rendered, first.tiles_total);
  std::printf("first frame: %zu of %zu tiles\n", first.tiles_rendered, first.tiles_total);
  // A drag: the sphere 1.5 m to the left and nearer, the box turned.
  objects[0].placement.position_m.x -= 1.5;
  objects[0].placement.position_m.z -= 1.0;
  objects[1].placement.yaw_deg = 30;
  expect_same(preview.render(objects, InsertOptions::preview()), objects, InsertOptions::preview(),
              "moved");
  // A move keeps the meshes: their BVH is refitted, not rebuilt, and the frame is still exact.
  EXPECT_FALSE(preview.last_frame().objects_rebuilt);
  EXPECT_TRUE(preview.last_frame().objects_refit);
  // Further along the drag, scaled, and with the sphere tilted.
  for (int step = 0; step < 3; ++step) {
    objects[0].placement.position_m.x += 0.4;
    objects[1].placement.scale *= 1.1;
    objects[0].placement.up = {0.2 * step, 1, 0};
    expect_same(preview.render(objects, InsertOptions::preview()), objects,
                InsertOptions::preview(), "dragged");
    EXPECT_TRUE(preview.last_frame().objects_refit);
  }
  // The idle refinement at the same placement reuses the objects' scene.
  expect_same(preview.render(objects, InsertOptions::preview_refined()), objects,
              InsertOptions::preview_refined(), "refined");
  EXPECT_FALSE(preview.last_frame().objects_rebuilt);
  // The full quality's settings through the preview, too (its hashed pattern; mesh_step is the
  // preview's).
  InsertOptions full;
  full.mesh_step = InsertOptions::preview().mesh_step;
  expect_same(preview.render(objects, full), objects, full, "full settings");
  // All objects removed: the photo again, exactly.
  const std::size_t last_rendered = preview.last_frame().tiles_rendered;
  const InsertResult& none = preview.render({}, InsertOptions::preview());
  EXPECT_EQ(preview.last_frame().tiles_reset, last_rendered);
  for (std::size_t i = 0; i < photo.pixels().size(); ++i)
    ASSERT_EQ(none.composite.pixels()[i], photo.pixels()[i]);
  for (float m : none.matte.pixels()) ASSERT_EQ(m, 0.0f);
  EXPECT_EQ(preview.last_frame().tiles_rendered, 0u);
}

// A cancelled frame leaves the preview consistent: the next frame is exact.
TEST(InsertPreview, CancelledFrameThenExactFrame) {
  const InsertScene s = make_scene();
  const Image distance = mcref::distance_map(s.camera, s.scene.pose, s.photo_geometry);
  const Image photo = test::make_test_photo(s.camera.width, s.camera.height);
  InsertPreview preview(photo, distance, s.camera, s.scene, InsertOptions::preview());
  preview.render(s.objects, InsertOptions::preview());
  std::vector<InsertObject> moved = s.objects;
  moved[0].placement.position_m.x += 1.0;
  CancelToken cancel;
  cancel.request();
  EXPECT_THROW(preview.render(moved, InsertOptions::preview(), &cancel), Error);
  moved[0].placement.position_m.x += 0.5;
  const InsertResult& got = preview.render(moved, InsertOptions::preview());
  const InsertResult want =
      insert_objects(photo, distance, s.camera, s.scene, moved, InsertOptions::preview());
  for (std::size_t i = 0; i < want.composite.pixels().size(); ++i)
    ASSERT_EQ(got.composite.pixels()[i], want.composite.pixels()[i]) << i;
  InsertOptions fogged = InsertOptions::preview();
  fogged.fog = true;
  EXPECT_THROW(preview.render(moved, fogged), Error);
}

// The preview's fixed sample pattern has no salt-and-pepper speckle: a speckle is a pixel of the
// composite, inside an object or on the photo's surfaces the objects shade, that differs from
// the median of its 3 x 3 block by more than 10 % (measured: hashed 59, fixed 8, which are the
// test photo's texture and shadow edges). The hashed (per-pixel rotated) pattern with the same
// few rays has many; the fixed one at most a fifth of them.
TEST(InsertPreview, FixedPatternHasNoSpeckle) {
  const InsertScene s = make_scene();
  const Image distance = mcref::distance_map(s.camera, s.scene.pose, s.photo_geometry);
  const Image photo = test::make_test_photo(s.camera.width, s.camera.height);
  const float kSpeckle = 0.1f;  // relative to the block's median
  auto speckles = [&](bool fixed) {
    InsertOptions o = InsertOptions::preview();
    o.fixed_pattern = fixed;
    const InsertResult r = insert_objects(photo, distance, s.camera, s.scene, s.objects, o);
    std::size_t count = 0;
    for (int y = 1; y + 1 < s.camera.height; ++y)
      for (int x = 1; x + 1 < s.camera.width; ++x) {
        // Inside the objects (every neighbour fully covered) or off them (none covered): the
        // composite's green relative to the median of the 3 x 3 block.
        int covered = 0;
        float v[9];
        int k = 0;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            covered += r.matte.at(x + dx, y + dy, 0) == 1.0f;
            v[k++] = r.composite.at(x + dx, y + dy, 1);
          }
        if (covered != 0 && covered != 9) continue;
        if (covered == 0 && r.shadow.at(x, y, 1) == 1.0f) continue;  // untouched photo
        const float c = r.composite.at(x, y, 1);
        std::nth_element(v, v + 4, v + 9);
        count += std::fabs(c - v[4]) > kSpeckle * v[4];
      }
    return count;
  };
  const std::size_t hashed = speckles(false), fixed = speckles(true);
  std::printf("speckles: hashed pattern %zu, fixed pattern %zu\n", hashed, fixed);
  EXPECT_GT(hashed, 30u);
  EXPECT_LE(fixed * 5, hashed);
}

}  // namespace
}  // namespace mr
