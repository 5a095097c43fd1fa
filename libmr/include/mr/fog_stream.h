// Streaming sky-only fog: photo file + depth file -> fogged file in strips of rows, for batches.
//
// A scene lit by the sky alone (no sun, no lamps, no noise wisps; homogeneous or exponential
// height fog, with or without a layer) has a closed form per pixel (DESIGN.md section 3):
//   T = tau = exp(-sigma_t * optical_depth),  R = albedo L_sky (1 - tau),  C = I T + R
// (with sky light by direction, mr/sky_light.h, L_sky becomes L_in(view ray) from a low-res map).
// No pixel needs another, so decode, fog and encode run over strips of rows: the photo and the
// depth map are decoded strip by strip (OIIO scanline reads), converted through the same OCIO
// processors as mr::read_image / mr::write_image, fogged with the same closed form as the
// scattering core (render/medium.h, sky_only_inscatter), composited (photo/composite) and
// encoded strip by strip (OIIO scanline writes). Decoding, fogging and encoding of different
// strips overlap (a TBB pipeline), and no full-frame float image is ever held: peak memory is
// a few strips plus the codecs' own state. The output is the same as
// read_image -> read_depth -> mr::fog(photo, depth, camera, scene) -> write_image.
#pragma once

#include <cstddef>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>

#include "mr/camera.h"
#include "mr/cancel.h"
#include "mr/color.h"
#include "mr/depth.h"
#include "mr/export.h"
#include "mr/image.h"
#include "mr/io.h"
#include "mr/metadata.h"
#include "mr/scene.h"
#include "mr/sky_light.h"

namespace mr {

/// True if `scene` is lit by the sky alone with a closed form at every pixel: no sun, no lamps,
/// no noise. (Its sky radiance may still be unset: see StreamFogRequest.)
MR_API bool is_sky_only(const FogScene& scene);

/// One photo for FogStreamer.
struct MR_API StreamFogRequest {
  std::filesystem::path photo;   ///< 8/16-bit photo (JPEG, PNG, TIFF, ...)
  /// Optional: the photo already decoded by read_image (scene-linear, upright, with its
  /// metadata), e.g. because its sky radiance was estimated from it. Then only the depth map,
  /// the fog and the encoding stream, and any photo read_image reads is taken (float, turned by
  /// its EXIF Orientation, grey); `photo` only names it in messages. Must outlive the call.
  const Image* photo_image = nullptr;
  std::filesystem::path depth;   ///< its depth file (read as mr::read_depth reads it)
  std::filesystem::path output;  ///< written atomically, format from the extension
  DepthOptions depth_options;
  /// Medium and sky (is_sky_only must hold). The sky radiance must be set: 'auto' (the dark
  /// channel prior) needs the whole photo, so such a request does not stream.
  const FogScene* scene = nullptr;
  /// The camera for the photo's displayed size and header metadata (EXIF focal length). Only
  /// planar-z / disparity depth and height fog or a layer need it; it is called once, before
  /// any pixel is read. Empty: Camera::from_metadata.
  std::function<Camera(int width, int height, const Metadata& metadata)> camera;
  const ColorConfig* color = nullptr;  ///< nullptr: ColorConfig::from_environment()
  std::string input_colorspace;        ///< as ReadOptions::colorspace
  /// Written as the output's "Software" tag when not empty (the photo's own tag otherwise).
  std::string software;
  /// As for write_image (pixel type, colour space, JPEG quality, overwrite).
  WriteOptions write;
  /// The photo's sky light by direction (mr/sky_light.h, e.g. from mr::sky_light_from_photo
  /// with the scene's sky radiance and medium.g), needed when scene->lighting.sky_by_direction is
  /// true (else the request does not stream): its low-resolution map is sampled at each pixel's
  /// view ray as the strips are fogged. Must outlive the call.
  const SkyLight* sky_light = nullptr;
  /// Rows per strip (0: chosen from the width, a multiple of 16 so that JPEG MCU rows and
  /// OpenEXR's 16-line chunks are decoded once).
  int strip_rows = 0;
};

struct MR_API StreamFogResult {
  /// false: this request cannot stream (see `reason`); nothing was read beyond headers and
  /// nothing was written. Callers then take the full-frame path (read_image, mr::fog, ...),
  /// which also produces the proper errors for bad inputs and options.
  bool streamed = false;
  std::string reason;
  Camera camera;  ///< the camera used (valid when streamed)
  int width = 0, height = 0;
  /// As DepthMap: pixels with no surface (sky), and of those NaN or negative stored values.
  std::size_t no_surface_pixels = 0;
  std::size_t invalid_pixels = 0;
  std::size_t sky_threshold_pixels = 0;  ///< as DepthMap::sky_threshold_pixels
  std::size_t clamped_pixels = 0;        ///< as DepthMap::clamped_pixels
  std::size_t strips = 0;  ///< strips the photo was cut into
};

/// Fogs photo files with the streaming pipeline. Holds its strip buffers, reused from one photo
/// to the next (no fresh large allocations, hence no page faults, per photo in a batch). One
/// call at a time per FogStreamer; use one per concurrent photo. The strips of one photo are
/// fogged in parallel in the calling thread's TBB arena.
class MR_API FogStreamer {
 public:
  FogStreamer();
  ~FogStreamer();
  FogStreamer(const FogStreamer&) = delete;
  FogStreamer& operator=(const FogStreamer&) = delete;

  /// Fogs one photo, or returns streamed == false (with the reason) without writing anything
  /// when the request needs the full-frame path: a scene that is not sky-only or whose sky
  /// radiance is 'auto', a photo that is not 8/16-bit RGB(A) scanline data or that EXIF
  /// Orientation turns, a tiled or oddly typed depth file or one of another size, an output
  /// format / bit depth / colour space write_image would reject. Throws mr::Error naming the
  /// file for what only shows while decoding or encoding (truncated or corrupt pixels, an
  /// unwritable output; the output is then not created), and cancelled when `cancel` is
  /// requested (checked per strip).
  StreamFogResult fog_file(const StreamFogRequest& request, const CancelToken* cancel = nullptr);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace mr
