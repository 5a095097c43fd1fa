// Issue 16: model files through assimp (mr::load_object_mesh): real models from Debian's
// assimp-testmodels (glTF 2.0 .gltf / .glb / embedded, OBJ + MTL), and broken or hostile files,
// shipped ones and ones written here, which must give one clear error naming the file.
#include <gtest/gtest.h>

#include <OpenImageIO/imageio.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <string>

#include "mr/error.h"
#include "mr/object_io.h"
#include "mr/objects.h"
#include "test_support.h"

namespace mr {
namespace {

namespace fs = std::filesystem;

const fs::path kModels = "/usr/share/assimp/models";

#define REQUIRE_MODELS()                                                            \
  if (!fs::exists(kModels / "glTF2"))                                               \
    GTEST_FAIL() << "assimp-testmodels is not installed (scripts/setup installs it)";

std::string error_of(const fs::path& path, ErrorCode* code = nullptr,
                     const ObjectLoadOptions& options = {}) {
  try {
    load_object_mesh(path, options);
  } catch (const Error& e) {
    if (code) *code = e.code();
    return e.what();
  }
  return "<no error>";
}

#define EXPECT_CONTAINS(text, part) \
  EXPECT_NE(std::string(text).find(part), std::string::npos) << "in: " << (text)

// The glTF sample Box: a unit cube around the origin, its node turned -90 degrees about X.
void expect_unit_box(const ObjectMesh& m) {
  EXPECT_EQ(m.triangles.size(), 12u);
  EXPECT_NEAR(mesh_area(m), 6.0, 1e-5);
  EXPECT_NEAR(mesh_volume(m), 1.0, 1e-5);  // positive: outward after the node transform
  const Bounds3 b = mesh_bounds(m);
  EXPECT_NEAR(b.min.x, -0.5, 1e-6);
  EXPECT_NEAR(b.max.y, 0.5, 1e-6);
  EXPECT_NEAR(b.max.z, 0.5, 1e-6);
  ASSERT_EQ(m.normals.size(), m.positions.size());
  // Flat faces: every vertex normal equals its triangles' geometric normal (after the node's
  // rotation, applied to positions and normals alike).
  for (const auto& t : m.triangles) {
    const auto& a = m.positions[t[0]];
    const auto& b1 = m.positions[t[1]];
    const auto& c = m.positions[t[2]];
    const double e1[3] = {b1[0] - a[0], b1[1] - a[1], b1[2] - a[2]};
    const double e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                   e1[0] * e2[1] - e1[1] * e2[0]};
    const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    for (std::uint32_t i : t)
      for (int k = 0; k < 3; ++k) EXPECT_NEAR(m.normals[i][k], n[k] / len, 1e-5);
  }
}

// The sRGB decoding (IEC 61966-2-1), written out: the independent reference for OCIO's.
double srgb_to_linear(double c) {
  return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
}

TEST(ObjectMeshIo, GltfBoxTexturedWithItsPngLinearised) {
  REQUIRE_MODELS();
  const fs::path file = kModels / "glTF2/BoxTextured-glTF/BoxTextured.gltf";
  const ObjectMesh m = load_object_mesh(file);
  EXPECT_TRUE(m.warnings.empty()) << m.warnings.front();
  expect_unit_box(m);
  ASSERT_EQ(m.materials.size(), 1u);
  const ObjectMaterial& mat = m.materials[0];
  EXPECT_EQ(mat.name, "Texture");
  EXPECT_EQ(mat.metallic, 0.0f);    // metallicFactor 0
  EXPECT_EQ(mat.roughness, 1.0f);   // glTF's default roughnessFactor
  EXPECT_EQ(mat.base_color, (Rgb{1, 1, 1}));
  ASSERT_EQ(mat.base_color_texture, 0);
  EXPECT_EQ(mat.normal_texture, -1);
  ASSERT_EQ(m.textures.size(), 1u);
  const ObjectTexture& tex = m.textures[0];
  EXPECT_TRUE(tex.color);
  EXPECT_CONTAINS(tex.source, "CesiumLogoFlat.png");
  // Compare with the PNG's own 8-bit codes decoded by the sRGB formula.
  auto in = OIIO::ImageInput::open((file.parent_path() / "CesiumLogoFlat.png").string());
  ASSERT_TRUE(in);
  const int w = in->spec().width, h = in->spec().height, nc = in->spec().nchannels;
  ASSERT_EQ(tex.image.width(), w);
  ASSERT_EQ(tex.image.height(), h);
  std::vector<unsigned char> codes(std::size_t(w) * h * nc);
  ASSERT_TRUE(in->read_image(0, 0, 0, nc, OIIO::TypeDesc::UINT8, codes.data()));
  double max_err = 0, sum = 0;
  for (int y = 0; y < h; y += 7)
    for (int x = 0; x < w; x += 5)
      for (int c = 0; c < 3; ++c) {
        const double ref = srgb_to_linear(codes[(std::size_t(y) * w + x) * nc + c] / 255.0);
        max_err = std::max(max_err, std::abs(tex.image.at(x, y, c) - ref));
        sum += ref;
      }
  EXPECT_LT(max_err, 2e-3);  // OCIO's sRGB vs the formula
  EXPECT_GT(sum, 0);         // not a black texture
  // UVs: glTF's own convention (v down) kept; the accessor's range is [0, 6] x [0, 1].
  ASSERT_EQ(m.uvs.size(), m.positions.size());
  float umax = 0, vmax = 0;
  for (const auto& uv : m.uvs) umax = std::max(umax, uv[0]), vmax = std::max(vmax, uv[1]);
  EXPECT_NEAR(umax, 6.0f, 1e-6);
  EXPECT_NEAR(vmax, 1.0f, 1e-6);
  EXPECT_EQ(m.tangents.size(), m.positions.size());
}

// The same box as .glb (binary, embedded PNG) and as .gltf with data URIs: identical meshes and
// textures, decoded from memory.
TEST(ObjectMeshIo, GlbAndEmbeddedGltfMatchTheSeparateFiles) {
  REQUIRE_MODELS();
  const ObjectMesh ref = load_object_mesh(kModels / "glTF2/BoxTextured-glTF/BoxTextured.gltf");
  for (const char* variant : {"glTF2/BoxTextured-glTF-Binary/BoxTextured.glb",
                              "glTF2/BoxTextured-glTF-Embedded/BoxTextured.gltf"}) {
    const ObjectMesh m = load_object_mesh(kModels / variant);
    for (const std::string& w : m.warnings) ADD_FAILURE() << variant << ": " << w;
    ASSERT_EQ(m.positions, ref.positions) << variant;
    EXPECT_EQ(m.triangles, ref.triangles) << variant;
    EXPECT_EQ(m.uvs, ref.uvs) << variant;
    ASSERT_EQ(m.textures.size(), 1u) << variant;
    EXPECT_CONTAINS(m.textures[0].source, "embedded");
    ASSERT_EQ(m.textures[0].image.pixel_count(), ref.textures[0].image.pixel_count());
    ASSERT_EQ(m.textures[0].image.channels(), ref.textures[0].image.channels());
    for (std::size_t i = 0; i < m.textures[0].image.pixels().size(); ++i)
      ASSERT_EQ(m.textures[0].image.pixels()[i], ref.textures[0].image.pixels()[i]) << variant;
  }
}

// A real engine (Khronos 2CylinderEngine, many nodes with transforms): loads, closed enough to
// have a positive volume, every triangle and vertex sane.
TEST(ObjectMeshIo, TwoCylinderEngineGlb) {
  REQUIRE_MODELS();
  const ObjectMesh m = load_object_mesh(kModels / "glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb");
  EXPECT_GT(m.triangles.size(), 50000u);
  EXPECT_GT(m.materials.size(), 1u);
  EXPECT_NO_THROW(validate_object_mesh(m));
  const Bounds3 b = mesh_bounds(m);
  EXPECT_FALSE(b.empty());
  EXPECT_GT(mesh_area(m), 0);
}

// OBJ + MTL written on Windows (".\\tex.jpg"): Kd as base colour, Ns 0 -> roughness 1, the three
// JPEG textures found beside it.
TEST(ObjectMeshIo, ObjWithMtlAndWindowsTexturePaths) {
  REQUIRE_MODELS();
  const ObjectMesh m = load_object_mesh(kModels / "OBJ/spider.obj");
  EXPECT_NO_THROW(validate_object_mesh(m));
  EXPECT_GT(m.triangles.size(), 100u);
  EXPECT_NO_THROW(validate_object_mesh(m));
  int textured = 0;
  bool skin = false;
  for (const ObjectMaterial& mat : m.materials) {
    if (mat.base_color_texture >= 0) ++textured;
    EXPECT_EQ(mat.metallic, 0.0f);
    if (mat.name == "Skin") {
      skin = true;
      EXPECT_FLOAT_EQ(mat.base_color[0], 0.827451f);
      EXPECT_FLOAT_EQ(mat.base_color[2], 0.772549f);
      EXPECT_FLOAT_EQ(mat.roughness, 1.0f);  // Ns 0
      ASSERT_GE(mat.base_color_texture, 0);
      EXPECT_CONTAINS(m.textures[std::size_t(mat.base_color_texture)].source, "wal67ar_small.jpg");
    }
  }
  EXPECT_TRUE(skin);
  EXPECT_GE(textured, 3);
  EXPECT_GE(m.textures.size(), 3u);
  // The file's normals include zero ones, which are recomputed (a warning says so); no texture
  // is missing.
  for (const std::string& w : m.warnings) EXPECT_EQ(w.find("texture"), std::string::npos) << w;
  for (const ObjectTexture& t : m.textures) EXPECT_TRUE(t.color);
}

// OBJ with two materials, Ns 200 and 16: roughness (2 / (Ns + 2))^(1/4).
TEST(ObjectMeshIo, ObjPhongExponentBecomesRoughness) {
  REQUIRE_MODELS();
  const ObjectMesh m = load_object_mesh(kModels / "OBJ/cube_usemtl.obj");
  bool found200 = false, found16 = false;
  for (const ObjectMaterial& mat : m.materials) {
    if (mat.name == "mtl") {
      found200 = true;
      EXPECT_NEAR(mat.roughness, std::pow(2.0 / 202.0, 0.25), 1e-6);
    }
    if (mat.name == "mtl2") {
      found16 = true;
      EXPECT_NEAR(mat.roughness, std::pow(2.0 / 18.0, 0.25), 1e-6);
    }
  }
  EXPECT_TRUE(found200);
  EXPECT_TRUE(found16);
  EXPECT_NEAR(mesh_volume(m), mesh_volume(m), 0);  // finite
}

// ---- Broken and hostile files -------------------------------------------------------------

std::string base64(const std::string& bytes) {
  static const char* k = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  std::size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const unsigned v = (unsigned char)bytes[i] << 16 | (unsigned char)bytes[i + 1] << 8 |
                       (unsigned char)bytes[i + 2];
    out += {k[v >> 18], k[(v >> 12) & 63], k[(v >> 6) & 63], k[v & 63]};
  }
  if (i + 1 == bytes.size()) {
    const unsigned v = (unsigned char)bytes[i] << 16;
    out += {k[v >> 18], k[(v >> 12) & 63], '=', '='};
  } else if (i + 2 == bytes.size()) {
    const unsigned v = (unsigned char)bytes[i] << 16 | (unsigned char)bytes[i + 1] << 8;
    out += {k[v >> 18], k[(v >> 12) & 63], k[(v >> 6) & 63], '='};
  }
  return out;
}

// One triangle as a glTF with its buffer in a data URI; the accessors' counts, the indices and
// the positions can be made hostile.
std::string triangle_gltf(const float (&positions)[9], const std::uint16_t (&indices)[3],
                          long long position_count = 3, long long index_count = 3,
                          int mode = 4) {
  std::string buffer(reinterpret_cast<const char*>(positions), sizeof positions);
  buffer.append(reinterpret_cast<const char*>(indices), sizeof indices);
  buffer.append(2, '\0');  // pad to 4 bytes
  const std::string uri = "data:application/octet-stream;base64," + base64(buffer);
  return R"({"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
  "nodes": [{"mesh": 0}],
  "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "mode": )" +
         std::to_string(mode) + R"(}]}],
  "buffers": [{"byteLength": )" + std::to_string(buffer.size()) + R"(, "uri": ")" + uri + R"("}],
  "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36},
                  {"buffer": 0, "byteOffset": 36, "byteLength": 6}],
  "accessors": [
    {"bufferView": 0, "componentType": 5126, "count": )" +
         std::to_string(position_count) + R"(, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
    {"bufferView": 1, "componentType": 5123, "count": )" +
         std::to_string(index_count) + R"(, "type": "SCALAR"}]})";
}

const float kTriangle[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
const std::uint16_t kIndices[3] = {0, 1, 2};

TEST(ObjectMeshIo, HandWrittenTriangleLoads) {
  test::ScratchDir dir;
  test::write_bytes(dir / "tri.gltf", triangle_gltf(kTriangle, kIndices));
  const ObjectMesh m = load_object_mesh(dir / "tri.gltf");
  ASSERT_EQ(m.triangles.size(), 1u);
  EXPECT_NEAR(mesh_area(m), 0.5, 1e-7);
  // No normals in the file: made, facing +Z (counter-clockwise seen from +Z).
  for (const auto& n : m.normals) EXPECT_NEAR(n[2], 1.0f, 1e-6);
}

TEST(ObjectMeshIo, NanAndInfiniteVerticesAreErrors) {
  test::ScratchDir dir;
  float nan_tri[9] = {0, 0, 0, 1, 0, 0, 0, std::numeric_limits<float>::quiet_NaN(), 0};
  test::write_bytes(dir / "nan.gltf", triangle_gltf(nan_tri, kIndices));
  ErrorCode code{};
  std::string e = error_of(dir / "nan.gltf", &code);
  EXPECT_EQ(code, ErrorCode::corrupt_input) << e;
  EXPECT_CONTAINS(e, "nan.gltf");
  EXPECT_CONTAINS(e, "not finite");
  // assimp's own test file with infinite coordinates.
  REQUIRE_MODELS();
  e = error_of(kModels / "glTF2/BoxWithInfinites-glTF-Binary/BoxWithInfinites.glb", &code);
  EXPECT_CONTAINS(e, "BoxWithInfinites.glb");
  EXPECT_EQ(code, ErrorCode::corrupt_input) << e;
}

TEST(ObjectMeshIo, HugeCountsAndBadIndicesAreErrors) {
  test::ScratchDir dir;
  // Accessor counts far beyond their 36-byte buffer view.
  test::write_bytes(dir / "huge_index_count.gltf",
                    triangle_gltf(kTriangle, kIndices, 3, 2'000'000'000LL));
  test::write_bytes(dir / "huge_vertex_count.gltf",
                    triangle_gltf(kTriangle, kIndices, 1'500'000'000LL, 3));
  const std::uint16_t bad[3] = {0, 1, 60000};
  test::write_bytes(dir / "bad_index.gltf", triangle_gltf(kTriangle, bad));
  for (const char* name : {"huge_index_count.gltf", "huge_vertex_count.gltf", "bad_index.gltf"}) {
    ErrorCode code{};
    const std::string e = error_of(dir / name, &code);
    EXPECT_CONTAINS(e, name);
    EXPECT_EQ(code, ErrorCode::corrupt_input) << e;
  }
  REQUIRE_MODELS();
  for (const char* name : {"glTF2/IndexOutOfRange/AllIndicesOutOfRange.gltf",
                           "glTF2/RecursiveNodes/RecursiveNodes.gltf"}) {
    ErrorCode code{};
    const std::string e = error_of(kModels / name, &code);
    EXPECT_CONTAINS(e, fs::path(name).filename().string());
    EXPECT_EQ(code, ErrorCode::corrupt_input) << e;
  }
  // assimp drops the faces with out-of-range indices and repairs mismatched arrays: what is
  // left must be a valid mesh (every index in range), never a crash.
  for (const char* name : {"glTF2/IndexOutOfRange/IndexOutOfRange.gltf",
                           "glTF2/IncorrectVertexArrays/Cube.gltf"}) {
    ErrorCode code{};
    const std::string e = error_of(kModels / name, &code);
    if (e == "<no error>") {
      const ObjectMesh m = load_object_mesh(kModels / name);
      EXPECT_NO_THROW(validate_object_mesh(m)) << name;
      EXPECT_FALSE(m.triangles.empty()) << name;
    } else {
      EXPECT_CONTAINS(e, fs::path(name).filename().string());
    }
  }
}

TEST(ObjectMeshIo, TruncatedAndGarbageFilesAreErrors) {
  REQUIRE_MODELS();
  test::ScratchDir dir;
  const std::string glb =
      test::read_bytes(kModels / "glTF2/BoxTextured-glTF-Binary/BoxTextured.glb");
  ASSERT_GT(glb.size(), 1000u);
  for (std::size_t keep : {std::size_t(10), std::size_t(100), glb.size() / 2, glb.size() - 10}) {
    const fs::path f = dir / ("cut" + std::to_string(keep) + ".glb");
    test::write_bytes(f, glb.substr(0, keep));
    ErrorCode code{};
    const std::string e = error_of(f, &code);
    EXPECT_CONTAINS(e, f.filename().string());
    // Cut inside the embedded PNG, the mesh may survive with the texture left out; otherwise
    // the model is refused.
    if (e == "<no error>") {
      const ObjectMesh m = load_object_mesh(f);
      EXPECT_FALSE(m.warnings.empty()) << keep;
    } else {
      EXPECT_EQ(code, ErrorCode::corrupt_input) << e;
    }
  }
  test::write_bytes(dir / "garbage.gltf", "{\"asset\": {\"version\": \"2.0\"}, \"meshes\": [");
  test::write_bytes(dir / "empty.obj", "");
  test::write_bytes(dir / "text.obj", "this is not a model\n");
  for (const char* name : {"garbage.gltf", "empty.obj", "text.obj"}) {
    ErrorCode code{};
    const std::string e = error_of(dir / name, &code);
    EXPECT_CONTAINS(e, name);
    EXPECT_EQ(code, ErrorCode::corrupt_input) << e;
  }
}

TEST(ObjectMeshIo, MissingFilesAndOtherFormatsAreErrors) {
  test::ScratchDir dir;
  ErrorCode code{};
  std::string e = error_of(dir / "nowhere.glb", &code);
  EXPECT_EQ(code, ErrorCode::io);
  EXPECT_CONTAINS(e, "nowhere.glb: model file not found");
  test::write_bytes(dir / "chair.fbx", "Kaydara FBX Binary");
  e = error_of(dir / "chair.fbx", &code);
  EXPECT_EQ(code, ErrorCode::invalid_argument);
  EXPECT_CONTAINS(e, "chair.fbx");
  EXPECT_CONTAINS(e, ".gltf, .glb");
  REQUIRE_MODELS();
  e = error_of(kModels / "glTF2/MissingBin/BoxTextured.gltf", &code);
  EXPECT_CONTAINS(e, "BoxTextured.gltf");
  EXPECT_EQ(code, ErrorCode::corrupt_input) << e;
}

TEST(ObjectMeshIo, PointsOnlyAndEmptyScenesAreErrors) {
  REQUIRE_MODELS();
  ErrorCode code{};
  // Mesh_PrimitiveMode_00: points.
  std::string e = error_of(
      kModels / "glTF2/glTF-Asset-Generator/Mesh_PrimitiveMode/Mesh_PrimitiveMode_00.gltf", &code);
  EXPECT_EQ(code, ErrorCode::corrupt_input) << e;
  EXPECT_CONTAINS(e, "Mesh_PrimitiveMode_00.gltf");
  EXPECT_CONTAINS(e, "no triangles");
  test::ScratchDir dir;
  test::write_bytes(dir / "lines.gltf", triangle_gltf(kTriangle, kIndices, 3, 3, /*LINES*/ 1));
  e = error_of(dir / "lines.gltf", &code);
  EXPECT_CONTAINS(e, "lines.gltf");
  EXPECT_CONTAINS(e, "no triangles");
  for (const char* name : {"glTF2/TestNoRootNode/NoScene.gltf",
                           "glTF2/TestNoRootNode/SceneWithoutNodes.gltf"}) {
    e = error_of(kModels / name, &code);
    EXPECT_CONTAINS(e, fs::path(name).filename().string());
    EXPECT_EQ(code, ErrorCode::corrupt_input) << e;
  }
}

// Missing textures: the documented fallback (left out, a warning naming both files), or an
// error when asked.
TEST(ObjectMeshIo, MissingTextureWarnsOrFailsAsAsked) {
  REQUIRE_MODELS();
  test::ScratchDir dir;
  const fs::path src = kModels / "glTF2/BoxTextured-glTF";
  fs::copy_file(src / "BoxTextured.gltf", dir / "BoxTextured.gltf");
  fs::copy_file(src / "BoxTextured0.bin", dir / "BoxTextured0.bin");
  const ObjectMesh m = load_object_mesh(dir / "BoxTextured.gltf");
  expect_unit_box(m);
  EXPECT_EQ(m.materials.at(0).base_color_texture, -1);
  EXPECT_TRUE(m.textures.empty());
  ASSERT_EQ(m.warnings.size(), 1u);
  EXPECT_CONTAINS(m.warnings[0], "BoxTextured.gltf");
  EXPECT_CONTAINS(m.warnings[0], "CesiumLogoFlat.png: not found");
  ObjectLoadOptions strict;
  strict.missing_textures_are_errors = true;
  ErrorCode code{};
  const std::string e = error_of(dir / "BoxTextured.gltf", &code, strict);
  EXPECT_EQ(code, ErrorCode::io);
  EXPECT_CONTAINS(e, "CesiumLogoFlat.png");
  // A corrupt texture file counts as missing.
  test::write_bytes(dir / "CesiumLogoFlat.png", "\x89PNG\r\n\x1a\n truncated");
  const ObjectMesh c = load_object_mesh(dir / "BoxTextured.gltf");
  EXPECT_EQ(c.materials.at(0).base_color_texture, -1);
  ASSERT_EQ(c.warnings.size(), 1u);
  EXPECT_CONTAINS(c.warnings[0], "CesiumLogoFlat.png");
}

TEST(ObjectMeshIo, SizeLimitsGiveClearErrors) {
  REQUIRE_MODELS();
  const fs::path box = kModels / "glTF2/BoxTextured-glTF/BoxTextured.gltf";
  ObjectLoadOptions tight;
  tight.max_triangles = 5;
  ErrorCode code{};
  std::string e = error_of(box, &code, tight);
  EXPECT_EQ(code, ErrorCode::corrupt_input);
  EXPECT_CONTAINS(e, "more than 5 triangles");
  tight = {};
  tight.max_vertices = 10;
  e = error_of(box, &code, tight);
  EXPECT_CONTAINS(e, "more than 10 vertices");
  // A texture above the size limit is refused from its header, like a missing one.
  tight = {};
  tight.max_texture_size = 64;
  const ObjectMesh m = load_object_mesh(box, tight);
  EXPECT_TRUE(m.textures.empty());
  ASSERT_EQ(m.warnings.size(), 1u);
  EXPECT_CONTAINS(m.warnings[0], "larger than the texture limit");
}

}  // namespace
}  // namespace mr
