// Issue 16: the scene document's versioned "objects" list (format version 4): round trips,
// older documents, validation errors naming the field, model files relative to the document.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <string>

#include "mr/error.h"
#include "mr/object_io.h"
#include "mr/scene_json.h"
#include "test_support.h"

namespace mr {
namespace {

namespace fs = std::filesystem;

#define EXPECT_CONTAINS(text, part) \
  EXPECT_NE(std::string(text).find(part), std::string::npos) << "in: " << (text)

std::string error_of(const std::string& text) {
  try {
    scene_from_json(text, "scene.json");
  } catch (const Error& e) {
    return e.what();
  }
  return "<no error>";
}

std::string doc(const std::string& objects, int version = kSceneFormatVersion) {
  return "{\"format\": \"libmr-scene\", \"version\": " + std::to_string(version) +
         ", \"objects\": " + objects + "}";
}

void expect_same(const SceneObject& a, const SceneObject& b) {
  EXPECT_EQ(a.mesh, b.mesh);
  EXPECT_EQ(a.placement.position_m.x, b.placement.position_m.x);
  EXPECT_EQ(a.placement.position_m.y, b.placement.position_m.y);
  EXPECT_EQ(a.placement.position_m.z, b.placement.position_m.z);
  EXPECT_EQ(a.placement.up.x, b.placement.up.x);
  EXPECT_EQ(a.placement.up.y, b.placement.up.y);
  EXPECT_EQ(a.placement.up.z, b.placement.up.z);
  EXPECT_EQ(a.placement.yaw_deg, b.placement.yaw_deg);
  EXPECT_EQ(a.placement.scale, b.placement.scale);
  ASSERT_EQ(a.material.has_value(), b.material.has_value());
  if (a.material) {
    EXPECT_EQ(a.material->diffuse_albedo, b.material->diffuse_albedo);
    EXPECT_EQ(a.material->specular_albedo, b.material->specular_albedo);
    EXPECT_EQ(a.material->roughness, b.material->roughness);
  }
}

TEST(SceneObjectsJson, RoundTripIsExact) {
  FogScene s;
  SceneObject sphere;
  sphere.mesh = "primitive:sphere";
  sphere.placement = {{0.1, 0, 7.3}, {0, 1, 0}, 12.5, 0.7};
  SceneObject chair;
  chair.mesh = "models/chair.glb";
  chair.placement = {{-2.25, 0.001, 11}, {0.1, 0.99, 0}, -170, 1.0 / 3.0};
  chair.material = Material{{0.2f, 0.3f, 0.1234567f}, 0.04f, 0.35f};
  s.objects = {sphere, chair};
  const std::string text = scene_to_json(s);
  EXPECT_CONTAINS(text, "\"version\": 5");
  EXPECT_CONTAINS(text, "\"mesh\": \"models/chair.glb\"");
  const FogScene back = scene_from_json(text, "round.json");
  ASSERT_EQ(back.objects.size(), 2u);
  expect_same(back.objects[0], sphere);
  expect_same(back.objects[1], chair);
  EXPECT_EQ(scene_to_json(back), text);
}

TEST(SceneObjectsJson, DefaultsAndOlderDocuments) {
  // Keys left out take ObjectPlacement's defaults.
  const FogScene s = scene_from_json(doc(R"([{"mesh": "primitive:box"}])"), "d.json");
  ASSERT_EQ(s.objects.size(), 1u);
  expect_same(s.objects[0], SceneObject{"primitive:box", {}, std::nullopt});
  // Documents of versions 1 to 3 have no objects, and still read.
  for (int v : {1, 2, 3}) {
    const FogScene old = scene_from_json(
        "{\"format\": \"libmr-scene\", \"version\": " + std::to_string(v) + "}", "old.json");
    EXPECT_TRUE(old.objects.empty());
    EXPECT_CONTAINS(error_of(doc("[]", v)),
                    "scene.json: /objects: objects are part of the format from version 4 on");
  }
}

TEST(SceneObjectsJson, ErrorsPointAtTheField) {
  EXPECT_CONTAINS(error_of(doc(R"([{"mesh": "primitive:teapot"}])")),
                  "scene.json: /objects/0/mesh: objects[0].mesh = \"primitive:teapot\": unknown "
                  "primitive");
  EXPECT_CONTAINS(error_of(doc(R"([{"mesh": "primitive:box"}, {"mesh": "a.glb", "placement": {"scale": 0}}])")),
                  "scene.json: /objects/1/placement/scale: objects[1].placement.scale = 0: must be "
                  "finite and > 0");
  EXPECT_CONTAINS(error_of(doc(R"([{"mesh": "a.glb", "placement": {"scale": -2}}])")),
                  "/objects/0/placement/scale");
  EXPECT_CONTAINS(error_of(doc(R"([{"mesh": "a.glb", "placement": {"up": [0, 0, 0]}}])")),
                  "/objects/0/placement/up");
  EXPECT_CONTAINS(error_of(doc(R"([{"mesh": "a.glb", "placement": {"scael": 2}}])")),
                  "did you mean \"scale\"");
  EXPECT_CONTAINS(error_of(doc(R"([{"placement": {}}])")), "/objects/0/mesh: missing");
  EXPECT_CONTAINS(error_of(doc(R"([{"mesh": 3}])")), "/objects/0/mesh: expected a string");
  EXPECT_CONTAINS(error_of(doc(R"({"mesh": "a.glb"})")), "/objects: expected an array");
  EXPECT_CONTAINS(error_of(doc(R"([{"mesh": "a.glb", "material": {"roughness": 3}}])")),
                  "/objects/0/material/roughness");
  // NaN has no JSON spelling: a scene holding one is refused when written.
  FogScene s;
  s.objects.push_back({"primitive:box", {}, std::nullopt});
  s.objects[0].placement.scale = std::nan("");
  try {
    scene_to_json(s);
    FAIL();
  } catch (const Error& e) {
    EXPECT_CONTAINS(e.what(), "objects[0].placement.scale = nan");
  }
}

// Model paths are relative to the document: load_scene finds them beside it (and names a
// missing one), resolve_object_mesh loads them from there.
TEST(SceneObjectsJson, ModelFilesAreRelativeToTheDocument) {
  test::ScratchDir dir;
  fs::create_directories(dir / "scenes" / "models");
  const fs::path box = "/usr/share/assimp/models/glTF2/BoxTextured-glTF-Binary/BoxTextured.glb";
  if (!fs::exists(box)) GTEST_FAIL() << "assimp-testmodels is not installed (scripts/setup)";
  fs::copy_file(box, dir / "scenes" / "models" / "box.glb");
  FogScene s;
  s.objects.push_back({"models/box.glb", {}, Material{{0.5f, 0.1f, 0.1f}, 0.04f, 0.3f}});
  s.objects.push_back({"primitive:cylinder", {}, std::nullopt});
  save_scene(dir / "scenes" / "scene.json", s);
  const FogScene back = load_scene(dir / "scenes" / "scene.json");
  ASSERT_EQ(back.objects.size(), 2u);
  EXPECT_EQ(object_mesh_path(back.objects[0], dir / "scenes"), dir / "scenes" / "models" / "box.glb");
  EXPECT_TRUE(object_mesh_path(back.objects[1], dir / "scenes").empty());
  const ObjectMesh m = resolve_object_mesh(back.objects[0], dir / "scenes");
  EXPECT_EQ(m.triangles.size(), 12u);
  for (const ObjectMaterial& mat : m.materials) {
    ASSERT_TRUE(mat.material);
    EXPECT_EQ(mat.material->roughness, 0.3f);
  }
  const ObjectMesh c = resolve_object_mesh(back.objects[1], dir / "scenes");
  EXPECT_EQ(c.source, "primitive:cylinder");

  // The model gone: load_scene names it.
  fs::remove(dir / "scenes" / "models" / "box.glb");
  try {
    load_scene(dir / "scenes" / "scene.json");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::io);
    EXPECT_CONTAINS(e.what(), "scene.json: /objects/0/mesh: model file ");
    EXPECT_CONTAINS(e.what(), "box.glb not found");
  }
}

}  // namespace
}  // namespace mr
