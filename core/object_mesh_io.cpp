// Model files (glTF 2.0, OBJ + MTL) through assimp into mr::ObjectMesh (core/object_mesh_io.h).
//
// Hostile input: assimp parses and bounds-checks the file (accessors against their buffers,
// indices against the vertices: aiProcess_ValidateDataStructure); this file then checks what the
// renderer relies on and assimp does not: finite vertices and transforms, the size limits of
// ObjectLoadOptions (before textures are decoded, from their headers), node nesting, and at least
// one triangle. Every error names the file.
#include "core/object_mesh_io.h"

#include <assimp/GltfMaterial.h>
#include <assimp/material.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <algorithm>
#include <assimp/Importer.hpp>
#include <cctype>
#include <cmath>
#include <cstring>
#include <optional>
#include <map>
#include <memory>
#include <new>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include "core/oiio_module.h"
#include "mr/error.h"

namespace mr::detail {

namespace {

namespace fs = std::filesystem;

constexpr int kMaxNodeDepth = 256;

class Importer {
 public:
  Importer(const fs::path& path, const ObjectLoadOptions& options)
      : path_(path), name_(path.string()), options_(options) {}

  ObjectMesh run();

 private:
  [[noreturn]] void fail(ErrorCode code, const std::string& problem) const {
    throw Error(code, name_ + ": " + problem);
  }
  void warn(const std::string& problem) { mesh_.warnings.push_back(name_ + ": " + problem); }

  void walk(const aiNode* node, const aiMatrix4x4& parent, int depth);
  void add_mesh(const aiMesh* m, const aiMatrix4x4& transform);
  std::uint32_t material(unsigned assimp_index);
  int texture(const aiMaterial* mat, std::initializer_list<std::pair<aiTextureType, unsigned>> slots,
              bool color, const std::string& role, const std::string& material_name);
  // Decoded texture or nullopt (missing / undecodable: the reason in `why`).
  std::optional<Image> decode_file(const fs::path& file, std::string& why) const;
  std::optional<Image> decode_embedded(const aiTexture* t, std::string& why) const;
  // Through OIIO's module: a file, or `size` bytes at `memory` (not null) named `filename`.
  std::optional<Image> decode(const std::string& filename, const void* memory, std::size_t size,
                              std::string& why) const;

  fs::path path_;
  std::string name_;
  ObjectLoadOptions options_;
  const aiScene* scene_ = nullptr;
  ObjectMesh mesh_;
  std::map<unsigned, std::uint32_t> material_index_;
  std::map<std::pair<std::string, bool>, int> texture_index_;
  bool any_uvs_ = false, any_missing_uvs_ = false;
  std::vector<std::pair<std::size_t, std::size_t>> vertices_without_uvs_;  // [begin, end)
  std::size_t skipped_non_triangles_ = 0;
  bool uv_set_warned_ = false;
};

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

bool finite(const aiMatrix4x4& m) {
  const float* v = &m.a1;
  return std::all_of(v, v + 16, [](float x) { return std::isfinite(x); });
}

ObjectMesh Importer::run() {
  // The file itself: a regular file of a format we read, not absurdly large.
  std::error_code ec;
  const fs::file_status st = fs::status(path_, ec);
  if (ec || !fs::exists(st)) fail(ErrorCode::io, "model file not found");
  if (!fs::is_regular_file(st)) fail(ErrorCode::io, "not a regular file");
  const std::string ext = lower(path_.extension().string());
  if (ext != ".gltf" && ext != ".glb" && ext != ".obj")
    fail(ErrorCode::invalid_argument, "unsupported model format \"" + ext +
                                          "\"; libmr reads glTF 2.0 (.gltf, .glb) and OBJ (.obj)");
  const std::uintmax_t bytes = fs::file_size(path_, ec);
  if (ec) fail(ErrorCode::io, "cannot read the file size: " + ec.message());
  if (bytes == 0) fail(ErrorCode::corrupt_input, "the file is empty");
  if (bytes > options_.max_file_bytes)
    fail(ErrorCode::corrupt_input, "the file has " + std::to_string(bytes) +
                                       " bytes, more than the limit of " +
                                       std::to_string(options_.max_file_bytes));

  Assimp::Importer importer;
  // Flat-shaded parts keep their creases when assimp makes normals for a model without them.
  importer.SetPropertyFloat(AI_CONFIG_PP_GSN_MAX_SMOOTHING_ANGLE, 80.0f);
  const unsigned flags = aiProcess_Triangulate | aiProcess_SortByPType |
                         aiProcess_JoinIdenticalVertices | aiProcess_GenSmoothNormals |
                         aiProcess_ValidateDataStructure | aiProcess_FlipUVs;
  try {
    scene_ = importer.ReadFile(path_.string(), flags);
  } catch (const std::bad_alloc&) {
    fail(ErrorCode::corrupt_input, "out of memory while parsing the model (hostile sizes?)");
  } catch (const std::exception& e) {
    fail(ErrorCode::corrupt_input, std::string("cannot be read as a model: ") + e.what());
  }
  if (!scene_) {
    std::string why = importer.GetErrorString();
    while (!why.empty() && (why.back() == '\n' || why.back() == ' ')) why.pop_back();
    std::replace(why.begin(), why.end(), '\n', ' ');
    fail(ErrorCode::corrupt_input,
         "cannot be read as a model: " + (why.empty() ? std::string("unknown error") : why));
  }
  if (scene_->mFlags & AI_SCENE_FLAGS_INCOMPLETE)
    fail(ErrorCode::corrupt_input, "the file holds no complete scene (no meshes)");
  if (!scene_->mRootNode) fail(ErrorCode::corrupt_input, "the scene has no root node");

  mesh_.source = name_;
  walk(scene_->mRootNode, aiMatrix4x4(), 0);

  if (mesh_.triangles.empty())
    fail(ErrorCode::corrupt_input,
         skipped_non_triangles_ > 0
             ? "the model holds no triangles, only points or lines (" +
                   std::to_string(skipped_non_triangles_) + " such parts)"
             : std::string("the scene is empty: no triangles"));
  if (skipped_non_triangles_ > 0)
    warn("left out " + std::to_string(skipped_non_triangles_) +
         " parts made of points or lines (only triangles are rendered)");
  if (any_uvs_) {
    // Parts without texture coordinates next to parts with them: (0, 0) for theirs.
    mesh_.uvs.resize(mesh_.positions.size(), {0.0f, 0.0f});
  } else {
    mesh_.uvs.clear();
  }
  // Normals: assimp makes them when the file has none; non-finite ones (degenerate triangles,
  // broken files) are recomputed from the geometry.
  bool bad_normals = mesh_.normals.size() != mesh_.positions.size();
  for (const auto& n : mesh_.normals)
    if (!(std::isfinite(n[0]) && std::isfinite(n[1]) && std::isfinite(n[2])) ||
        !(n[0] * n[0] + n[1] * n[1] + n[2] * n[2] > 0.25f))
      bad_normals = true;
  if (bad_normals) {
    if (!mesh_.normals.empty()) warn("some normals were missing, zero or not finite: recomputed");
    compute_vertex_normals(mesh_);
  }
  compute_tangents(mesh_);
  if (mesh_.materials.empty()) mesh_.materials.emplace_back();
  validate_object_mesh(mesh_);  // what assimp let through and we did not catch: corrupt_input
  return std::move(mesh_);
}

void Importer::walk(const aiNode* node, const aiMatrix4x4& parent, int depth) {
  if (depth > kMaxNodeDepth)
    fail(ErrorCode::corrupt_input,
         "nodes nested deeper than " + std::to_string(kMaxNodeDepth) + " (a cycle?)");
  if (!finite(node->mTransformation))
    fail(ErrorCode::corrupt_input,
         "node \"" + std::string(node->mName.C_Str()) + "\" has a non-finite transform");
  const aiMatrix4x4 transform = parent * node->mTransformation;
  for (unsigned i = 0; i < node->mNumMeshes; ++i) {
    const unsigned index = node->mMeshes[i];
    if (index >= scene_->mNumMeshes || !scene_->mMeshes[index])
      fail(ErrorCode::corrupt_input, "node \"" + std::string(node->mName.C_Str()) +
                                         "\" names mesh " + std::to_string(index) + " of " +
                                         std::to_string(scene_->mNumMeshes));
    add_mesh(scene_->mMeshes[index], transform);
  }
  for (unsigned i = 0; i < node->mNumChildren; ++i)
    if (node->mChildren[i]) walk(node->mChildren[i], transform, depth + 1);
}

void Importer::add_mesh(const aiMesh* m, const aiMatrix4x4& transform) {
  const std::string mesh_name = "mesh \"" + std::string(m->mName.C_Str()) + "\"";
  if (!(m->mPrimitiveTypes & aiPrimitiveType_TRIANGLE)) {
    ++skipped_non_triangles_;
    return;
  }
  std::uint64_t triangles = 0;
  for (unsigned f = 0; f < m->mNumFaces; ++f)
    if (m->mFaces[f].mNumIndices == 3) ++triangles;
  if (mesh_.positions.size() + std::uint64_t(m->mNumVertices) > options_.max_vertices)
    fail(ErrorCode::corrupt_input, "more than " + std::to_string(options_.max_vertices) +
                                       " vertices (the limit of ObjectLoadOptions::max_vertices)");
  if (mesh_.triangles.size() + triangles > options_.max_triangles)
    fail(ErrorCode::corrupt_input,
         "more than " + std::to_string(options_.max_triangles) +
             " triangles (the limit of ObjectLoadOptions::max_triangles)");
  if (!m->mVertices) fail(ErrorCode::corrupt_input, mesh_name + " has no vertex positions");

  // Normals go through the inverse transpose; a mirroring transform turns the winding around.
  aiMatrix3x3 linear(transform);
  aiMatrix3x3 normal_matrix = linear;
  const float det = normal_matrix.Determinant();
  if (!(std::abs(det) > 0) || !std::isfinite(det))
    fail(ErrorCode::corrupt_input, mesh_name + " is placed by a singular transform");
  normal_matrix.Inverse().Transpose();

  const std::size_t base = mesh_.positions.size();
  for (unsigned i = 0; i < m->mNumVertices; ++i) {
    const aiVector3D& p = m->mVertices[i];
    if (!(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z)))
      fail(ErrorCode::corrupt_input,
           mesh_name + ": vertex " + std::to_string(i) + " is not finite (NaN or infinity)");
    const aiVector3D w = transform * p;
    if (!(std::isfinite(w.x) && std::isfinite(w.y) && std::isfinite(w.z)))
      fail(ErrorCode::corrupt_input,
           mesh_name + ": vertex " + std::to_string(i) + " is not finite once placed by its node");
    mesh_.positions.push_back({w.x, w.y, w.z});
    if (m->mNormals) {
      aiVector3D n = normal_matrix * m->mNormals[i];
      const float len = n.Length();
      mesh_.normals.push_back(len > 0 && std::isfinite(len)
                                  ? std::array<float, 3>{n.x / len, n.y / len, n.z / len}
                                  : std::array<float, 3>{NAN, NAN, NAN});  // recomputed later
    } else {
      mesh_.normals.push_back({NAN, NAN, NAN});
    }
  }
  if (m->mTextureCoords[0] && m->mNumUVComponents[0] >= 2) {
    any_uvs_ = true;
    mesh_.uvs.resize(base, {0.0f, 0.0f});
    for (unsigned i = 0; i < m->mNumVertices; ++i) {
      const aiVector3D& t = m->mTextureCoords[0][i];
      // Non-finite UVs would poison texture lookups; (0, 0) with a warning.
      if (std::isfinite(t.x) && std::isfinite(t.y)) {
        mesh_.uvs.push_back({t.x, t.y});
      } else {
        mesh_.uvs.push_back({0.0f, 0.0f});
        if (!uv_set_warned_) warn(mesh_name + ": non-finite texture coordinates set to (0, 0)");
        uv_set_warned_ = true;
      }
    }
  }
  const std::uint32_t material_id = material(m->mMaterialIndex);
  const bool flip = det < 0;
  for (unsigned f = 0; f < m->mNumFaces; ++f) {
    const aiFace& face = m->mFaces[f];
    if (face.mNumIndices != 3) continue;  // points or lines among triangles (SortByPType splits)
    std::array<std::uint32_t, 3> t{};
    for (int k = 0; k < 3; ++k) {
      const unsigned idx = face.mIndices[k];
      if (idx >= m->mNumVertices)
        fail(ErrorCode::corrupt_input, mesh_name + ": face " + std::to_string(f) +
                                           " uses vertex " + std::to_string(idx) + " of " +
                                           std::to_string(m->mNumVertices));
      t[std::size_t(k)] = static_cast<std::uint32_t>(base + idx);
    }
    if (flip) std::swap(t[1], t[2]);
    mesh_.triangles.push_back(t);
    mesh_.triangle_material.push_back(material_id);
  }
}

std::uint32_t Importer::material(unsigned assimp_index) {
  if (const auto it = material_index_.find(assimp_index); it != material_index_.end())
    return it->second;
  if (assimp_index >= scene_->mNumMaterials || !scene_->mMaterials[assimp_index])
    fail(ErrorCode::corrupt_input, "a mesh names material " + std::to_string(assimp_index) +
                                       " of " + std::to_string(scene_->mNumMaterials));
  const aiMaterial* mat = scene_->mMaterials[assimp_index];
  ObjectMaterial out;
  aiString name;
  if (mat->Get(AI_MATKEY_NAME, name) == AI_SUCCESS) out.name = name.C_Str();
  const std::string what = "material \"" + out.name + "\"";

  auto clamp01 = [&](float v, float fallback, const char* field) {
    if (!std::isfinite(v)) {
      warn(what + ": " + field + " is not finite; " + std::to_string(fallback) + " used");
      return fallback;
    }
    if (v < 0 || v > 1) warn(what + ": " + field + " outside [0, 1] clamped");
    return std::clamp(v, 0.0f, 1.0f);
  };
  aiColor4D color;
  if (mat->Get(AI_MATKEY_BASE_COLOR, color) == AI_SUCCESS ||
      mat->Get(AI_MATKEY_COLOR_DIFFUSE, color) == AI_SUCCESS) {
    out.base_color = {clamp01(color.r, 0.8f, "base colour"), clamp01(color.g, 0.8f, "base colour"),
                      clamp01(color.b, 0.8f, "base colour")};
  }
  float value = 0;
  if (mat->Get(AI_MATKEY_METALLIC_FACTOR, value) == AI_SUCCESS)
    out.metallic = clamp01(value, 0.0f, "metallic");
  else
    out.metallic = 0;  // OBJ: dielectric
  float shininess = 0;
  const std::string ext = lower(path_.extension().string());
  if (ext != ".obj" && mat->Get(AI_MATKEY_ROUGHNESS_FACTOR, value) == AI_SUCCESS) {
    out.roughness = clamp01(value, 1.0f, "roughness");
  } else if (mat->Get(AI_MATKEY_SHININESS, shininess) == AI_SUCCESS && std::isfinite(shininess) &&
             shininess >= 0) {
    // OBJ's Phong exponent Ns: Beckmann alpha = sqrt(2 / (Ns + 2)) (Walter et al. 2007), and the
    // perceptual roughness is sqrt(alpha) (alpha = roughness^2, as glTF and mr::Material).
    out.roughness = static_cast<float>(std::pow(2.0 / (double(shininess) + 2.0), 0.25));
  } else {
    out.roughness = ext == ".obj" ? 1.0f : 0.5f;
  }
  out.base_color_texture =
      texture(mat, {{aiTextureType_BASE_COLOR, 0}, {aiTextureType_DIFFUSE, 0}}, true,
              "base colour", out.name);
  out.metallic_roughness_texture =
      texture(mat, {{AI_MATKEY_GLTF_PBRMETALLICROUGHNESS_METALLICROUGHNESS_TEXTURE}}, false,
              "metallic-roughness", out.name);
  out.normal_texture = texture(mat, {{aiTextureType_NORMALS, 0}}, false, "normal", out.name);

  const auto id = static_cast<std::uint32_t>(mesh_.materials.size());
  mesh_.materials.push_back(std::move(out));
  material_index_.emplace(assimp_index, id);
  return id;
}

int Importer::texture(const aiMaterial* mat,
                      std::initializer_list<std::pair<aiTextureType, unsigned>> slots, bool color,
                      const std::string& role, const std::string& material_name) {
  aiString file;
  unsigned uv_index = 0;
  bool found = false;
  for (const auto& [type, n] : slots) {
    if (mat->GetTextureCount(type) > n &&
        mat->GetTexture(type, n, &file, nullptr, &uv_index) == AI_SUCCESS && file.length > 0) {
      found = true;
      break;
    }
  }
  if (!found) return -1;
  const std::string ref = file.C_Str();
  if (uv_index != 0 && !uv_set_warned_) {
    warn("material \"" + material_name + "\": its " + role + " texture uses UV set " +
         std::to_string(uv_index) + "; only the first UV set is read, so it is used for it");
    uv_set_warned_ = true;
  }
  const std::pair<std::string, bool> key{ref, color};
  if (const auto it = texture_index_.find(key); it != texture_index_.end()) return it->second;

  std::string why;
  std::optional<Image> image;
  std::string source;
  if (const aiTexture* embedded = scene_->GetEmbeddedTexture(ref.c_str())) {
    source = name_ + " <embedded " + ref + ">";
    image = decode_embedded(embedded, why);
  } else {
    // Relative to the model's folder. OBJ files written on Windows say ".\\tex.jpg": try the
    // path with its backslashes as separators too.
    const fs::path dir = path_.parent_path();
    std::string unix_ref = ref;
    std::replace(unix_ref.begin(), unix_ref.end(), '\\', '/');
    fs::path candidate = dir / fs::path(ref);
    std::error_code ec;
    if (!fs::is_regular_file(candidate, ec)) candidate = dir / fs::path(unix_ref);
    source = candidate.lexically_normal().string();
    if (ref.rfind("data:", 0) == 0 || ref.find("://") != std::string::npos) {
      why = "only files beside the model and embedded images are read, not URIs";
    } else if (!fs::is_regular_file(candidate, ec)) {
      why = "not found";
    } else {
      image = decode_file(candidate, why);
    }
  }
  if (!image) {
    const std::string problem = "material \"" + material_name + "\": " + role + " texture " +
                                source + ": " + why;
    if (options_.missing_textures_are_errors) fail(ErrorCode::io, problem);
    warn(problem + "; the material's factors are used without it");
    texture_index_.emplace(key, -1);
    return -1;
  }
  ObjectTexture t;
  t.source = source;
  t.image = std::move(*image);
  t.color = color;
  const int id = static_cast<int>(mesh_.textures.size());
  mesh_.textures.push_back(std::move(t));
  texture_index_.emplace(key, id);
  return id;
}

std::optional<Image> Importer::decode_file(const fs::path& file, std::string& why) const {
  return decode(file.string(), nullptr, 0, why);
}

std::optional<Image> Importer::decode_embedded(const aiTexture* t, std::string& why) const {
  if (t->mHeight == 0) {
    // Compressed (PNG, JPEG, ...): mWidth bytes; decode from memory, the hint naming the format.
    if (!t->pcData || t->mWidth == 0) {
      why = "empty embedded image";
      return std::nullopt;
    }
    std::string hint = lower(std::string(t->achFormatHint, strnlen(t->achFormatHint, 9)));
    if (hint.empty() || !std::all_of(hint.begin(), hint.end(), [](char c) { return std::isalnum(static_cast<unsigned char>(c)); }))
      hint = "png";
    if (hint == "jpeg") hint = "jpg";
    return decode("embedded." + hint, t->pcData, t->mWidth, why);
  }
  // Uncompressed BGRA8 texels.
  const std::uint64_t w = t->mWidth, h = t->mHeight;
  if (w > std::uint64_t(options_.max_texture_size) || h > std::uint64_t(options_.max_texture_size) ||
      w * h > options_.max_texture_pixels) {
    why = std::to_string(w) + "x" + std::to_string(h) + " is larger than the texture limit";
    return std::nullopt;
  }
  Image image(static_cast<int>(w), static_cast<int>(h), 4);
  for (std::uint64_t i = 0; i < w * h; ++i) {
    const aiTexel& px = t->pcData[i];
    float* dst = image.data() + i * 4;
    dst[0] = px.r / 255.0f;
    dst[1] = px.g / 255.0f;
    dst[2] = px.b / 255.0f;
    dst[3] = px.a / 255.0f;
  }
  return image;
}

std::optional<Image> Importer::decode(const std::string& filename, const void* memory,
                                      std::size_t size, std::string& why) const {
  std::vector<float> pixels;
  int width = 0, height = 0, stored = 0;
  if (!oiio_module().decode_texture(filename, memory, size, options_.max_texture_size,
                                    options_.max_texture_pixels, pixels, width, height, stored,
                                    why))
    return std::nullopt;
  const std::uint64_t w = std::uint64_t(width), h = std::uint64_t(height);
  // RGB or RGBA: grey is spread over the three colour channels.
  const int channels = (stored == 2 || stored == 4) ? 4 : 3;
  Image image(static_cast<int>(w), static_cast<int>(h), channels);
  float* dst = image.data();
  for (std::uint64_t i = 0; i < w * h; ++i) {
    const float* src = pixels.data() + i * std::uint64_t(stored);
    float* d = dst + i * std::uint64_t(channels);
    if (stored <= 2) {
      d[0] = d[1] = d[2] = src[0];
      if (stored == 2) d[3] = src[1];
    } else {
      d[0] = src[0];
      d[1] = src[1];
      d[2] = src[2];
      if (stored == 4) d[3] = src[3];
    }
    for (int c = 0; c < channels; ++c)
      if (!std::isfinite(d[c])) d[c] = 0;  // float textures: no NaN into the shading
  }
  return image;
}

}  // namespace

ObjectMesh import_object_mesh(const fs::path& path, const ObjectLoadOptions& options) {
  return Importer(path, options).run();
}

}  // namespace mr::detail
