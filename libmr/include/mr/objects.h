// Inserted 3D objects (mixed reality, issue 16): triangle meshes with materials, placed in a
// photo's metric world (the world frame of mr/scene.h: metres, +Y up, the ground at y = 0).
//
// The data types here are shared by the loaders (glTF 2.0 / OBJ through assimp, built-in
// primitives), the placement on reconstructed surfaces, the scene document's `objects` list and
// the renderer that composites objects into photos by differential rendering.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "mr/export.h"
#include "mr/image.h"
#include "mr/material_model.h"
#include "mr/scene.h"

namespace mr {

/// A texture as loaded from a model file: linear float RGB(A) for colour data decoded through the
/// colour pipeline (base colour: sRGB -> scene-linear), raw values for data textures (normal,
/// metallic-roughness).
struct MR_API ObjectTexture {
  std::string source;  ///< file path or "<embedded N>", for messages
  Image image;         ///< width x height x channels, float
};

/// glTF 2.0's metallic-roughness material, plus an optional mr::Material (from material style
/// transfer) that replaces it when set.
struct MR_API ObjectMaterial {
  std::string name;
  Rgb base_color{0.8f, 0.8f, 0.8f};  ///< linear, in [0, 1]; multiplies base_color_texture
  float metallic = 0.0f;              ///< in [0, 1]
  float roughness = 0.5f;             ///< perceptual roughness in [0, 1]
  /// Indices into ObjectMesh::textures, or -1 for none.
  int base_color_texture = -1;
  int metallic_roughness_texture = -1;  ///< glTF packing: G = roughness, B = metallic
  int normal_texture = -1;              ///< tangent-space, glTF convention (+Y up)
  std::optional<Material> material;     ///< when set, shading uses this instead
};

/// An indexed triangle mesh in the object's own frame (metres, +Y up as in glTF).
struct MR_API ObjectMesh {
  std::string source;  ///< file path or primitive name, for messages
  std::vector<std::array<float, 3>> positions;
  std::vector<std::array<float, 3>> normals;  ///< per vertex, unit; empty = flat shading
  std::vector<std::array<float, 2>> uvs;      ///< per vertex; empty = untextured
  std::vector<std::array<float, 4>> tangents;  ///< per vertex, w = handedness; may be empty
  std::vector<std::array<std::uint32_t, 3>> triangles;
  std::vector<std::uint32_t> triangle_material;  ///< per triangle, index into materials
  std::vector<ObjectMaterial> materials;          ///< at least one
  std::vector<ObjectTexture> textures;
};

/// Where an object stands in the photo's world. The object's frame is scaled by scale, rotated
/// about its own up axis by yaw_deg, tilted so that its up axis is `up` (unit, world frame), and
/// its origin moved to position_m (world frame, metres).
struct MR_API ObjectPlacement {
  Vec3 position_m{0.0, 0.0, 5.0};
  Vec3 up{0.0, 1.0, 0.0};
  double yaw_deg = 0.0;
  double scale = 1.0;
};

/// One entry of a scene document's versioned `objects` list.
struct MR_API SceneObject {
  /// A model file (relative paths are relative to the scene document) or a built-in primitive:
  /// "primitive:sphere", "primitive:box", "primitive:plane", "primitive:cylinder".
  std::string mesh;
  ObjectPlacement placement;
  std::optional<Material> material;  ///< overrides every material of the mesh when set
};

}  // namespace mr
