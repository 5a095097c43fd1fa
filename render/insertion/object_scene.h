// Private to libmr: inserted objects (mr/objects.h) in world space and in an Embree scene, for the
// differential renderer of issue 16 (render/insertion/differential.h). Unlike the occluder mesh
// (render/embree_scene.h), whose rays only ask "blocked?", the camera's rays must find which
// triangle they hit and where on it (to shade it), so this scene also answers rtcIntersect queries
// with the triangle and its barycentrics.
#pragma once

#include <embree3/rtcore.h>

#include <array>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "mr/image.h"
#include "mr/material_model.h"
#include "mr/objects.h"
#include "render/embree_scene.h"
#include "render/math.h"
#include "render/surface_shading.h"

namespace mr::render::insertion {

/// The material of an object's triangles as the renderer shades it: the metallic-roughness
/// parameters (glTF 2.0) with their textures, or an mr::Material that replaces them.
struct ShadingMaterial {
  Rgb base_color{0.8f, 0.8f, 0.8f};
  float metallic = 0, roughness = 0.5f;
  const Image* base_color_texture = nullptr;          ///< linear RGB(A), or null
  const Image* metallic_roughness_texture = nullptr;  ///< G = roughness, B = metallic, or null
  /// Tangent space (glTF: R, G, B = x, y, z of the normal as (n + 1) / 2; +Y up the texture),
  /// or null. Applied also under an mr::Material (it describes the shape, not the material).
  const Image* normal_texture = nullptr;
  std::optional<Material> material;  ///< when set: diffuse, F0 and roughness from it
};

/// What a surface point of an object reflects with (render/surface_shading.h's split form):
/// radiance = diffuse_albedo * diffuse + f0 * specular_f0 + specular_bias, per channel.
struct SurfaceReflectance {
  Rgb diffuse_albedo{}, f0{};
  float roughness = 0.5f;
};

/// Every inserted object's triangles in world metres (placement applied), with what shading
/// needs per vertex and per triangle. Holds copies of the meshes' textures.
struct WorldObjects {
  std::vector<float> positions;  ///< x, y, z per vertex (plus one float of padding at the end)
  std::vector<float> normals;    ///< x, y, z per vertex (unit; zero where the mesh had none)
  std::vector<float> uvs;        ///< u, v per vertex (0 where the mesh had none)
  /// x, y, z, w per vertex: the unit tangent (rotated into the world) and the handedness w (the
  /// bitangent is w cross(n, t), glTF's convention); all zero where the mesh has none. Filled
  /// only for meshes with a normal texture (from the mesh's tangents, else generated from its
  /// UVs by mr::compute_tangents); empty when no mesh needs them.
  std::vector<float> tangents;
  std::vector<std::uint32_t> indices;            ///< 3 per triangle
  std::vector<std::uint32_t> triangle_material;  ///< per triangle, index into materials
  std::vector<std::uint8_t> smooth;  ///< per triangle: 1 = interpolate vertex normals, 0 = flat
  std::vector<ShadingMaterial> materials;
  std::vector<std::shared_ptr<const Image>> textures;  ///< owned; materials point into them
  /// Per object: bounding sphere (centre, radius) in world metres, for the renderer's cheap
  /// "can this object matter here?" tests.
  std::vector<std::array<float, 4>> bounds;
  /// The same spheres (same centres) with the tightest radius about that centre (the farthest
  /// vertex): what the renderer's exact culls use (camera-ray rectangles, shadow cones, ray vs
  /// sphere tests), so they skip work without changing a result. `bounds` (the box's
  /// half-diagonal, up to sqrt(3) larger) stays the measure of the sky influence cut.
  std::vector<std::array<float, 4>> tight_bounds;

  /// Per append_object call: where its vertices and (kept) triangles are, and whether it has
  /// tangents (move_objects needs them).
  struct Range {
    std::uint32_t first_vertex = 0, vertex_count = 0, first_triangle = 0, triangle_count = 0;
    bool tangents = false;
  };
  std::vector<Range> objects;

  std::size_t triangle_count() const { return indices.size() / 3; }
  std::size_t vertex_count() const { return positions.size() / 3; }
};

/// The object-to-world transform of a placement (mr/objects.h): scale, then yaw about the
/// object's +Y, then the rotation taking +Y to `up` (the shortest one), then the translation.
struct PlacementTransform {
  double rotation[3][3]{};  ///< row-major, applied to column vectors
  double scale = 1;
  Vec3d translation{0, 0, 0};
  Vec3d apply(const Vec3d& p) const;
  Vec3d rotate(const Vec3d& v) const;  ///< directions (normals): rotation only
};
PlacementTransform placement_transform(const ObjectPlacement& placement);

/// Appends `mesh` placed by `placement` (with `material_override` replacing every material when
/// set). Drops degenerate triangles (zero area after placement). Throws mr::Error
/// (invalid_argument) naming mesh.source for malformed meshes (indices out of range, non-finite
/// positions, mismatched attribute arrays, material or texture indices out of range), and for a
/// non-positive or non-finite scale.
void append_object(WorldObjects& world, const ObjectMesh& mesh, const ObjectPlacement& placement,
                   const std::optional<Material>& material_override = std::nullopt);

/// Moves the objects of `world` (appended by append_object from these meshes, in this order) to
/// new placements in place: positions, normals, tangents and bounding spheres rewritten with
/// append_object's arithmetic (the result equals a fresh append's bit for bit), the buffers kept
/// (so an ObjectScene sharing them can refit()). False when that cannot be done (another number
/// of objects or vertices, or the placement changes which triangles are degenerate): then the
/// world is partly moved and must be built again. Throws like append_object for a bad placement.
bool move_objects(WorldObjects& world, std::span<const ObjectMesh* const> meshes,
                  std::span<const ObjectPlacement> placements);

/// The reflectance at a hit (triangle `prim`, barycentrics u, v): the material's parameters,
/// times its textures sampled bilinearly (repeat) at the interpolated uv.
SurfaceReflectance reflectance_at(const WorldObjects& world, std::uint32_t prim, float u, float v);

/// The shading normal at a hit with the material's normal texture applied: `n` (the interpolated
/// vertex normal, or the geometric one of a flat triangle, unit, on the side the mesh's normals
/// point to) perturbed by the texture's tangent-space normal sampled bilinearly at the
/// interpolated uv, in the frame of the interpolated tangent (made orthogonal to n), the
/// bitangent w cross(n, t) and n. Returns n unchanged without a normal texture, without tangents,
/// or where the texture's normal is degenerate.
Vec3f normal_mapped(const WorldObjects& world, std::uint32_t prim, float u, float v,
                    const Vec3f& n);

/// A camera-ray hit on an object.
struct ObjectHit {
  float t = std::numeric_limits<float>::infinity();  ///< in units of the direction's length
  std::uint32_t prim = 0;
  float u = 0, v = 0;  ///< barycentrics of vertices 1 and 2
  bool hit() const { return t < std::numeric_limits<float>::infinity(); }
};

/// The objects in an Embree scene (RAII; not copyable). Queries are const and thread-safe.
class ObjectScene {
 public:
  /// Keeps a reference to `world`, which must outlive the scene and stay unchanged. An empty
  /// world gives a scene that nothing hits.
  /// `fast_build`: Embree's low-quality (Morton) build, several times faster to build and a
  /// little slower to trace (the interactive preview rebuilds it on every move of a drag).
  /// `refittable` (implies the fast build's two-level scene): the geometry's BVH is built so
  /// that refit() can update it when only the vertices moved (Embree's
  /// RTC_BUILD_QUALITY_REFIT): what a drag needs, where the topology stays and only the
  /// placement changes.
  explicit ObjectScene(const WorldObjects& world, bool fast_build = false, bool refittable = false);
  ~ObjectScene();
  ObjectScene(const ObjectScene&) = delete;
  ObjectScene& operator=(const ObjectScene&) = delete;

  ObjectHit intersect(const Vec3f& origin, const Vec3f& direction, float t_near,
                      float t_far = std::numeric_limits<float>::infinity()) const;
  /// For each ray i: blocked[i] = whether a triangle lies on it (rtcOccluded1 per ray).
  void occluded(std::span<const ShadowRay> rays, bool* blocked) const;
  bool empty() const { return scene_ == nullptr; }
  /// After the world's positions were overwritten in place (same buffer, same vertex count, same
  /// triangles): refits the BVH to them instead of rebuilding it (much cheaper; traversal gets
  /// a little slower as the boxes of moved parts grow). The hits are the same as a fresh build's
  /// (a BVH decides the order rays meet triangles, not where). Throws mr::Error(internal) when
  /// the scene is not refittable or the buffer changed.
  void refit();
  const WorldObjects& world() const { return world_; }

 private:
  const WorldObjects& world_;
  RTCDevice device_ = nullptr;
  RTCScene scene_ = nullptr;
  RTCGeometry geometry_ = nullptr;  // held only when refittable
  const float* positions_ = nullptr;
  std::size_t vertex_count_ = 0;
};

}  // namespace mr::render::insertion
