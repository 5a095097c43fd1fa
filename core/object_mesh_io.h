// Private to libmr: reading model files (glTF 2.0 .gltf/.glb, OBJ + MTL) through assimp into an
// mr::ObjectMesh. The public entry point is mr::load_object_mesh (mr/object_io.h), which also
// takes the colour textures from sRGB to scene-linear through the colour pipeline (OCIO, in the
// API layer); here they are decoded to floats as stored (integers normalised to [0, 1]).
#pragma once

#include <filesystem>

#include "mr/objects.h"

namespace mr::detail {

/// The model with node transforms baked into its vertices (the object's frame is the file's root
/// frame: metres, +Y up, as glTF defines and as OBJ files are taken to be), triangles only,
/// materials and textures (ObjectTexture::color marks the sRGB ones, still encoded).
/// Throws mr::Error naming the file: io (missing, unreadable, a texture missing under
/// missing_textures_are_errors), invalid_argument (not .gltf/.glb/.obj), corrupt_input (the
/// model cannot be parsed, is truncated, has non-finite vertices, indices out of range, no
/// triangles, or exceeds a limit of ObjectLoadOptions).
ObjectMesh import_object_mesh(const std::filesystem::path& path, const ObjectLoadOptions& options);

}  // namespace mr::detail
