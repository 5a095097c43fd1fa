// The JSON scene document: a FogScene as a versioned, human-editable file, so every run can be
// saved, reloaded and repeated from the CLI, the GUI or code (DESIGN.md section 2).
// The format (every key, unit, default and range) is documented in docs/scene.md.
//
//   {"format": "libmr-scene", "version": 1, "camera_pose": {...}, "medium": {...},
//    "lighting": {...}, "render": {...}, "camera": {...}}   ("camera" optional)
//
// Missing keys take the FogScene defaults, so {"format": "libmr-scene", "version": 1} is a
// complete scene. Unknown keys are errors (they are usually typos).
#pragma once

#include <filesystem>
#include <string>

#include "mr/export.h"
#include "mr/scene.h"

namespace mr {

/// The value of the document's "format" key.
inline constexpr const char* kSceneFormatName = "libmr-scene";
/// The newest document version this libmr reads and the one it writes. Readers accept every
/// version from 1 up to this one. Version 2 added the optional "camera" (the rest of the
/// format, defaults included, is version 1's). Version 3 added "blockers" (shadow casters the
/// photo does not show) with the completion of structures cut by the frame on by default;
/// documents of versions 1 and 2 read with it off, so they render as before. Version 4 added
/// "objects" (3D objects inserted into the photo, mr/objects.h; mesh paths relative to the
/// document); older documents have none. Version 5 added "render": {"shadow_traversal"} (issue
/// 17: Embree or the multi-index kd-tree for the CPU core's shadow rays; same answers); it is
/// read in version-4 documents too (builds before the bump wrote it there when not "embree").
inline constexpr int kSceneFormatVersion = 5;

/// Parses a scene document. `source_name` (usually the file name) starts every error message.
/// The result has passed validate_scene.
/// Throws mr::Error(invalid_argument) with a one-line message naming the source, the JSON
/// pointer of the offending value and what was found, e.g.
///   "scene.json: /lighting/lamps/1/position_m: expected an array of 3 numbers, found a string"
///   "scene.json: line 3, column 14: syntax error while parsing object - ..."
///   "scene.json: /medium/g: medium.g = 1.2: must be in (-1, 1)"
MR_API FogScene scene_from_json(const std::string& text, const std::string& source_name = "<scene>");

/// Writes a scene as a document of kSceneFormatVersion: pretty-printed (2-space indent), every
/// field written, and exact: scene_from_json(scene_to_json(s)) equals s field by field (floats
/// and doubles are written with enough digits to read back bit for bit).
/// Throws mr::Error(invalid_argument) from validate_scene for a scene that could not be read
/// back (a NaN, say), so a document written by libmr is always one it accepts.
MR_API std::string scene_to_json(const FogScene& scene);

/// The camera of a photo `width` x `height` from a scene's recorded camera: the recorded one when
/// the size is the same (bit for bit); for a resized photo of the same aspect ratio (within 1 %)
/// the focal length scales with the width and the principal point with each axis. Throws
/// mr::Error(invalid_argument) naming both sizes when the aspect ratio differs (a rotated or
/// cropped photo: the recorded focal length does not carry over), or for an invalid camera or
/// size.
MR_API Camera camera_for_image(const SceneCamera& camera, int width, int height);

/// The SceneCamera recording `camera` (its size, focal length and principal point; the principal
/// point is left out when it is the image's centre).
MR_API SceneCamera scene_camera(const Camera& camera);

/// Reads and parses a scene file; errors name the file as given. The model files of its objects
/// (relative to the file's folder) must exist: a missing one is an io error naming it.
/// Throws mr::Error: io when the file or a model file cannot be read, invalid_argument for its
/// content.
MR_API FogScene load_scene(const std::filesystem::path& path);

/// Writes scene_to_json(scene) to `path` atomically: into a temporary file in the same folder,
/// then renamed over `path`, so readers see the old file or the new one, never a partial one,
/// and a failure leaves nothing behind. Throws mr::Error: invalid_argument for an invalid
/// scene (nothing is written), io when the file cannot be written (naming the path).
MR_API void save_scene(const std::filesystem::path& path, const FogScene& scene);

}  // namespace mr
