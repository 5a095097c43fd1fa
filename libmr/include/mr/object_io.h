// Inserted 3D objects (issue 16), the API side: loading model files and resolving a scene
// document's objects, and placing an object on the photo's reconstructed surface at a clicked
// pixel. The data types are in mr/objects.h (a core type, shared with the renderer).
#pragma once

#include <filesystem>
#include <string>

#include "mr/camera.h"
#include "mr/export.h"
#include "mr/image.h"
#include "mr/objects.h"
#include "mr/scene.h"

namespace mr {

/// Loads a model: glTF 2.0 (.gltf with its .bin and images, .glb with embedded ones) or OBJ with
/// its MTL, through assimp. Node transforms are baked into the vertices (the object's frame is
/// the file's root frame; glTF's unit is the metre, and OBJ files, which have no unit, are taken
/// to be in metres too); polygons are triangulated; points and lines are left out (a warning);
/// normals come from the file, else are made (smooth within 80 degrees), tangents are computed
/// from the UVs. The glTF metallic-roughness material is read (base colour factor and texture,
/// metallic and roughness factors and their texture, the normal texture); an OBJ material gives
/// its Kd as base colour, roughness from its Phong exponent Ns (alpha = sqrt(2 / (Ns + 2)),
/// roughness = sqrt(alpha)), metallic 0. Textures are decoded through OIIO: the base colour from
/// sRGB to scene-linear through the colour pipeline (ColorConfig::from_environment()), data
/// textures as stored. A missing or undecodable texture is left out with a warning in
/// ObjectMesh::warnings (ObjectLoadOptions::missing_textures_are_errors makes it an error).
/// Throws mr::Error naming the file: io (missing, unreadable), invalid_argument (another
/// format), corrupt_input (truncated, unparsable, NaN or infinite vertices, indices out of
/// range, no triangles, above a limit of ObjectLoadOptions).
MR_API ObjectMesh load_object_mesh(const std::filesystem::path& path,
                                   const ObjectLoadOptions& options = {});

/// Where a scene object's mesh comes from: the model file (SceneObject::mesh, relative paths
/// taken relative to `document_dir`, the scene document's folder), or an empty path for a
/// "primitive:NAME".
MR_API std::filesystem::path object_mesh_path(const SceneObject& object,
                                              const std::filesystem::path& document_dir);

/// The mesh of a scene object, in its own frame (place it with apply_placement(mesh,
/// object.placement)): make_primitive for "primitive:NAME", else load_object_mesh of
/// object_mesh_path. When object.material is set, every material of the mesh gets it
/// (ObjectMaterial::material). Validates the object first (validate_scene_object).
MR_API ObjectMesh resolve_object_mesh(const SceneObject& object,
                                      const std::filesystem::path& document_dir,
                                      const ObjectLoadOptions& options = {});

/// How place_at_pixel stands an object on a surface.
struct MR_API PlaceAtPixelOptions {
  /// world: the object stands upright (up = +Y) wherever it is put; surface_normal: its up is
  /// the surface's normal (on a wall, a slope), estimated from the depth map around the pixel.
  enum class Up { world, surface_normal };
  Up up = Up::world;
  /// Half-size of the depth neighbourhood the surface plane is fitted to, in pixels (1..64).
  int window_radius_px = 3;
  double yaw_deg = 0;  ///< copied into the placement
  double scale = 1;    ///< copied into the placement (> 0)
};

/// An ObjectPlacement standing on the photo's reconstructed surface at image position (x, y)
/// (continuous image coordinates: pixel (i, j) covers [i, i+1) x [j, j+1), as a click gives
/// them): the position is where the pixel's camera ray meets the surface (a plane fitted
/// robustly to the depth map's world points around it, so it does not depend on one pixel's
/// noise and a neighbourhood across a depth edge keeps the clicked side), `up` the world's +Y or
/// the surface normal (facing the camera). Where no plane can be fitted the position is the
/// clicked pixel's distance along the ray, and Up::surface_normal falls back to +Y.
/// `distance_m`: distance along the ray (mr/depth.h), the camera's size, channel 0 used.
/// Throws mr::Error: invalid_argument for a position outside the image, a pixel without a
/// surface (sky, unknown depth) or bad options; size_mismatch for a distance image of another size.
MR_API ObjectPlacement place_at_pixel(const Camera& camera, const CameraPose& pose,
                                      const Image& distance_m, double x, double y,
                                      const PlaceAtPixelOptions& options = {});

}  // namespace mr
