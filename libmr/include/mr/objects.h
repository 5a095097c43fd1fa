// Inserted 3D objects (mixed reality, issue 16): triangle meshes with materials, placed in a
// photo's metric world (the world frame of mr/scene.h: metres, +Y up, the ground at y = 0).
// mr/scene.h includes this header (FogScene::objects), so it includes nothing of scene.h's.
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
#include "mr/vec3.h"

namespace mr {

/// A texture as loaded from a model file: linear float RGB(A) for colour data decoded through the
/// colour pipeline (base colour: sRGB -> scene-linear), raw values for data textures (normal,
/// metallic-roughness).
struct MR_API ObjectTexture {
  std::string source;  ///< file path or "<embedded N>", for messages
  /// width x height x 3 (RGB) or 4 (RGBA) floats, the top row first (uv (0, 0) is the top-left
  /// corner of the top-left pixel, glTF's convention).
  Image image;
  /// True for colour data (base colour): converted from sRGB to scene-linear when loaded.
  /// False for data (normal, metallic-roughness): the stored values, integers normalised to [0, 1].
  bool color = false;
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

/// An indexed triangle mesh in the object's own frame (metres, +Y up as in glTF). Triangles are
/// counter-clockwise seen from their front (outside), so cross(p1 - p0, p2 - p0) points out.
struct MR_API ObjectMesh {
  std::string source;  ///< file path or primitive name, for messages
  std::vector<std::array<float, 3>> positions;
  std::vector<std::array<float, 3>> normals;  ///< per vertex, unit; empty = flat shading
  /// Per vertex; empty = untextured. glTF's convention: u to the right, v down, (0, 0) the
  /// top-left corner of a texture (OBJ's bottom-left v is flipped on loading).
  std::vector<std::array<float, 2>> uvs;
  std::vector<std::array<float, 4>> tangents;  ///< per vertex, w = handedness; may be empty
  std::vector<std::array<std::uint32_t, 3>> triangles;
  std::vector<std::uint32_t> triangle_material;  ///< per triangle, index into materials
  std::vector<ObjectMaterial> materials;          ///< at least one
  std::vector<ObjectTexture> textures;
  /// What the loader replaced or left out (a missing texture, a points-only part, recomputed
  /// normals), one line each naming the file; empty for a clean load. Front ends show them.
  std::vector<std::string> warnings;
};

/// Where an object stands in the photo's world. The object's frame is scaled by scale, rotated
/// about its own up axis by yaw_deg, tilted so that its up axis is `up` (unit, world frame), and
/// its origin moved to position_m (world frame, metres):
///   world = position_m + R_tilt(+Y -> up) R_y(yaw) (scale p).
/// Yaw turns as the camera's does (mr/scene.h): positive turns the object's +Z toward +X;
/// R_tilt is the smallest rotation taking +Y to `up` (180 degrees about +X for up = -Y).
struct MR_API ObjectPlacement {
  Vec3 position_m{0.0, 0.0, 5.0};
  Vec3 up{0.0, 1.0, 0.0};
  double yaw_deg = 0.0;
  double scale = 1.0;  ///< uniform, > 0 (1: the model's own metres)
};

/// One entry of a scene document's versioned `objects` list.
struct MR_API SceneObject {
  /// A model file (relative paths are relative to the scene document) or a built-in primitive:
  /// "primitive:sphere", "primitive:box", "primitive:plane", "primitive:cylinder".
  std::string mesh;
  ObjectPlacement placement;
  std::optional<Material> material;  ///< overrides every material of the mesh when set
};

/// How model files are loaded (mr::load_object_mesh, mr/object_io.h). The limits guard against
/// hostile or absurd files: a model above them fails with a clear error naming the file rather
/// than exhausting memory.
struct MR_API ObjectLoadOptions {
  /// A texture that is missing or cannot be decoded: false (default): the material keeps its
  /// factors without that texture and ObjectMesh::warnings says so (real-world OBJ files often
  /// name textures that did not travel with them); true: mr::Error(io) naming both files.
  bool missing_textures_are_errors = false;
  std::uint64_t max_triangles = 20'000'000;  ///< in the whole model, after triangulation
  std::uint64_t max_vertices = 20'000'000;
  int max_texture_size = 16384;                      ///< pixels along either side
  std::uint64_t max_texture_pixels = 64'000'000;     ///< width x height of one texture
  std::uint64_t max_file_bytes = 2'000'000'000;      ///< the model file itself
};

// ---------------------------------------------------------------------------------------------
// Built-in primitives (core/primitives.cpp)
// ---------------------------------------------------------------------------------------------

/// Prefix of a SceneObject::mesh naming a built-in primitive ("primitive:sphere").
inline constexpr const char* kPrimitivePrefix = "primitive:";

/// The names make_primitive knows: "sphere", "box", "plane", "cylinder".
MR_API std::vector<std::string> primitive_names();

/// A built-in primitive, standing on y = 0 and centred on the Y axis, with unit outward
/// per-vertex normals, UVs, tangents and one default material (ObjectMaterial{}):
///   "sphere":   radius 0.5 m, centre (0, 0.5, 0) (UV sphere, u = longitude, v = latitude down);
///   "box":      the 1 m cube [-0.5, 0.5] x [0, 1] x [-0.5, 0.5], flat faces (24 vertices);
///   "plane":    1 x 1 m at y = 0, x, z in [-0.5, 0.5], normal +Y (one-sided, open);
///   "cylinder": radius 0.5 m, y in [0, 1], flat caps.
/// Closed ones are watertight (every edge, with vertices welded by position, is shared by
/// exactly two triangles, in opposite directions). `segments` sets the sphere's and cylinder's
/// number of segments around the axis (>= 3; the sphere has segments / 2 rings); 0: 64.
/// Throws mr::Error(invalid_argument) naming an unknown primitive and listing the known ones.
MR_API ObjectMesh make_primitive(const std::string& name, int segments = 0);

// ---------------------------------------------------------------------------------------------
// Geometry of meshes and placements (core/object_geometry.cpp)
// ---------------------------------------------------------------------------------------------

/// A 4x4 matrix, row-major: world = M * (x, y, z, 1).
using Mat4 = std::array<double, 16>;

/// An axis-aligned box; empty (min > max) when it holds no point.
struct MR_API Bounds3 {
  Vec3 min{1.0, 1.0, 1.0};
  Vec3 max{-1.0, -1.0, -1.0};
  bool empty() const { return min.x > max.x || min.y > max.y || min.z > max.z; }
};

/// Throws mr::Error(invalid_argument) "<what>.<field> = <value>: <rule>" for a placement that
/// cannot be used: non-finite position or yaw, scale not finite and > 0, up not finite or zero.
MR_API void validate_placement(const ObjectPlacement& placement,
                               const std::string& what = "placement");

/// The placement's transform (see ObjectPlacement), with `up` normalised. Validates first.
MR_API Mat4 placement_matrix(const ObjectPlacement& placement);

/// The mesh moved into the world by the placement: positions transformed, normals and tangents
/// rotated (the scale is uniform, so they stay unit); everything else copied.
MR_API ObjectMesh apply_placement(const ObjectMesh& mesh, const ObjectPlacement& placement);

/// Bounds of the mesh's positions in its own frame, and in the world once placed (the bounds of
/// the placed vertices, exact, not of the transformed box).
MR_API Bounds3 mesh_bounds(const ObjectMesh& mesh);
MR_API Bounds3 world_bounds(const ObjectMesh& mesh, const ObjectPlacement& placement);

/// Throws mr::Error(invalid_argument) "<what>.<field> = <value>: <rule>" for an entry that
/// cannot be used: an empty mesh, an unknown "primitive:" name, a bad placement or material.
/// (Whether a model file exists is checked where the document's folder is known: load_scene.)
MR_API void validate_scene_object(const SceneObject& object, const std::string& what = "object");

/// Checks a mesh's invariants (what the renderer relies on): positions finite; every index in
/// range; normals, uvs and tangents empty or one per vertex, finite; triangle_material one per
/// triangle (or empty: material 0) and in range; at least one material with factors in range
/// and texture indices -1 or in range. Throws mr::Error(corrupt_input) naming mesh.source and
/// the first problem.
MR_API void validate_object_mesh(const ObjectMesh& mesh);

/// Recomputes per-vertex normals as the normalised sum of the area-weighted normals of the
/// triangles around each vertex (a vertex on no triangle, or with a zero sum, gets +Y).
MR_API void compute_vertex_normals(ObjectMesh& mesh);

/// Computes per-vertex tangents (xyz unit, orthogonal to the normal; w = +-1 handedness, the
/// bitangent being w cross(n, t)) from the UVs, summed over the triangles around each vertex
/// (Lengyel's method). Needs normals and uvs; without them the tangents are cleared.
MR_API void compute_tangents(ObjectMesh& mesh);

/// Total surface area (m^2) and the enclosed volume (m^3, the divergence theorem; positive for
/// a closed, outward-facing mesh) of the triangles, in the mesh's frame.
MR_API double mesh_area(const ObjectMesh& mesh);
MR_API double mesh_volume(const ObjectMesh& mesh);

}  // namespace mr
