// Inserted 3D objects, the API layer (mr/object_io.h): model loading with the colour textures
// taken to scene-linear through the colour pipeline, scene objects resolved against their
// document's folder, and placement at a clicked pixel (photo/object_placement).
#include <cmath>
#include <string>

#include "core/object_mesh_io.h"
#include "mr/color.h"
#include "mr/error.h"
#include "mr/object_io.h"
#include "photo/object_placement.h"

namespace mr {

namespace fs = std::filesystem;

ObjectMesh load_object_mesh(const fs::path& path, const ObjectLoadOptions& options) {
  ObjectMesh mesh = detail::import_object_mesh(path, options);
  // Base colour textures are sRGB-encoded (glTF 2.0 section 3.9.2; OBJ's map_Kd by practice).
  bool any_color = false;
  for (const ObjectTexture& t : mesh.textures) any_color = any_color || t.color;
  if (any_color) {
    const ColorConfig color = ColorConfig::from_environment();
    for (ObjectTexture& t : mesh.textures)
      if (t.color) color.convert(t.image.view(), colorspace::srgb, colorspace::scene_linear);
  }
  return mesh;
}

fs::path object_mesh_path(const SceneObject& object, const fs::path& document_dir) {
  if (object.mesh.rfind(kPrimitivePrefix, 0) == 0) return {};
  const fs::path file(object.mesh);
  return file.is_absolute() || document_dir.empty() ? file : document_dir / file;
}

ObjectMesh resolve_object_mesh(const SceneObject& object, const fs::path& document_dir,
                               const ObjectLoadOptions& options) {
  validate_scene_object(object);
  const std::string prefix = kPrimitivePrefix;
  ObjectMesh mesh = object.mesh.rfind(prefix, 0) == 0
                        ? make_primitive(object.mesh.substr(prefix.size()))
                        : load_object_mesh(object_mesh_path(object, document_dir), options);
  if (object.material)
    for (ObjectMaterial& m : mesh.materials) m.material = object.material;
  return mesh;
}

ObjectPlacement place_at_pixel(const Camera& camera, const CameraPose& pose,
                               const Image& distance_m, double x, double y,
                               const PlaceAtPixelOptions& options) {
  if (!(std::isfinite(options.scale) && options.scale > 0))
    throw Error(ErrorCode::invalid_argument,
                "place_at_pixel: scale = " + std::to_string(options.scale) + ": must be > 0");
  if (!std::isfinite(options.yaw_deg))
    throw Error(ErrorCode::invalid_argument, "place_at_pixel: yaw_deg must be finite");
  const photo::SurfaceAtPixel s = photo::surface_at_pixel(camera, pose, distance_m.view(), x, y,
                                                          options.window_radius_px);
  ObjectPlacement p;
  p.position_m = s.position_m;
  p.up = options.up == PlaceAtPixelOptions::Up::surface_normal && s.normal_valid ? s.normal
                                                                                : Vec3{0, 1, 0};
  p.yaw_deg = options.yaw_deg;
  p.scale = options.scale;
  return p;
}

}  // namespace mr
