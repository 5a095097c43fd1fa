// Image files: reading and writing through OpenImageIO, colour through OpenColorIO.
#pragma once

#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>

#include "mr/color.h"
#include "mr/export.h"
#include "mr/image.h"

namespace mr {

/// How pixels are stored in a file.
enum class PixelType { automatic, uint8, uint16, half, float32 };

/// Parses "8", "16", "half", "float" (also "uint8", "uint16", "32", "f16", "f32").
/// Throws mr::Error(invalid_argument) otherwise.
MR_API PixelType parse_pixel_type(const std::string& text);
MR_API const char* to_string(PixelType type) noexcept;

/// What a file holds, without decoding the pixels.
struct MR_API ImageFileInfo {
  int width = 0, height = 0, channels = 0;
  PixelType pixel_type = PixelType::float32;  ///< as stored (integer types other than 8/16 map
                                              ///< to float32)
  std::string format;                         ///< OIIO format name: "jpeg", "openexr", ...
  /// EXIF Orientation of the stored pixels, 1..8 (1: none or absent or invalid). width and
  /// height are as stored; read_image (apply_orientation) swaps them for 5..8.
  int orientation = 1;
  /// The file's "Software" tag (EXIF / TIFF / PNG text / EXR attribute), empty if none: `mr fog`
  /// marks its outputs with it so that it never takes a user's photo for one of them.
  std::string software;
};

/// Reads the header of an image file. Throws mr::Error(io) naming the file if it cannot be
/// opened, is not a regular file (a FIFO, a device, a folder) or is not an image.
MR_API ImageFileInfo probe_image(const std::filesystem::path& path);

struct MR_API ReadOptions {
  /// Colour space of the file's pixels. Empty: the file's own tag (oiio:ColorSpace) if the
  /// config knows it, else sRGB for 8/16-bit integer files and scene_linear for float files.
  std::string colorspace;
  /// Convert to scene-linear (true) or return the stored values as floats (false; integer
  /// files normalised to [0, 1]).
  bool to_scene_linear = true;
  /// Colour config; nullptr: ColorConfig::from_environment().
  const ColorConfig* color = nullptr;
  /// Fail with corrupt_input if any pixel is NaN or infinite.
  bool reject_non_finite = true;
  /// Turn the pixels as the file's own EXIF Orientation tag (2..8; phones write 6 and 8) says
  /// they are displayed, exactly (pixels moved, not resampled; width and height swap for 5..8),
  /// and set the metadata's Orientation to 1 so that a written copy is not turned twice.
  /// false: the stored layout, with the file's Orientation left in the metadata.
  bool apply_orientation = true;
};

/// The largest image read_image decodes, in pixels (width x height), and the default limit
/// (250 megapixels: 3 GB of float RGB, ~10 GB once rendered). Checked from the file's header,
/// before any pixel is decoded; larger files fail with corrupt_input naming the file and size.
inline constexpr std::uint64_t kDefaultMaxDecodedPixels = 250'000'000;
MR_API std::uint64_t max_decoded_pixels() noexcept;
/// Process-wide (the CLI's --max-megapixels); 0 restores the default. Thread-safe.
MR_API void set_max_decoded_pixels(std::uint64_t pixels) noexcept;

/// Reads a whole image (first subimage, all channels) as float32 with its metadata, turned
/// upright by its EXIF Orientation (ReadOptions::apply_orientation).
/// Throws mr::Error: io (missing, unreadable, not an image), corrupt_input (truncated,
/// non-finite pixels), color. The message names the file.
MR_API Image read_image(const std::filesystem::path& path, const ReadOptions& options = {});

struct MR_API WriteOptions {
  /// Stored pixel type. automatic: float32 for EXR/HDR/PFM, uint16 for TIFF, else uint8.
  PixelType pixel_type = PixelType::automatic;
  /// Colour space to encode into. Empty: sRGB for integer pixel types, scene_linear for float.
  std::string colorspace;
  const ColorConfig* color = nullptr;  ///< nullptr: ColorConfig::from_environment()
  int jpeg_quality = 95;               ///< 1..100
  /// Replace an existing file. When false, an existing file is an error (io).
  bool overwrite = true;
};

/// Writes `image` (scene-linear, 1..4 channels, the first three as colour) to `path`, format
/// from the extension, metadata (EXIF, ...) carried over. Atomic: the pixels go to a temporary
/// file in the same folder which is renamed over `path` only when complete; on any failure the
/// temporary file is removed and `path` is untouched. Throws mr::Error(io | invalid_argument).
MR_API void write_image(const std::filesystem::path& path, const Image& image,
                 const WriteOptions& options = {});

/// One layer of a multi-layer EXR. Channels are named "<layer>.<channel>", or just "<channel>"
/// when `name` is empty (the main R,G,B layer).
struct MR_API ExrLayer {
  std::string name;      ///< "", "transmittance", "inscatter", "depth", ...
  const Image* image;    ///< its channel_names() give the channel part ("R","G","B" / "Z")
  bool is_data = false;  ///< data layers (depth) are never colour-converted
};

/// Writes the layers into one OpenEXR file that oiiotool, Nuke and Blender read as layers
/// (e.g. R,G,B + transmittance.R/G/B + inscatter.R/G/B + depth.Z). All layers must have the
/// same size. Colour layers are written in scene-linear. Atomic like write_image.
MR_API void write_exr_layers(const std::filesystem::path& path, std::span<const ExrLayer> layers,
                      const Metadata& metadata, PixelType pixel_type = PixelType::half);

/// Throws mr::Error(io) "<path>: is a FIFO (named pipe); outputs are only written as regular
/// files ..." when `path` exists and is not a regular file (not following symbolic links: a
/// symbolic link, a FIFO, a device, a folder). A missing path is fine. Every writer of libmr
/// checks this; front ends call it to refuse a target before any work.
MR_API void check_output_path(const std::filesystem::path& path);

/// Writes `text` (a JSON document, a report) to `path` as libmr writes its images: into a
/// hidden temporary beside it, synced, then renamed into place, so no reader sees a partial
/// file and an interrupted run leaves nothing (remove_unfinished_outputs() knows it). `path`
/// must not be anything but a regular file (check_output_path). With overwrite == false an
/// existing file is an error and is left alone. Throws mr::Error(io) naming `path`.
MR_API void write_text_file(const std::filesystem::path& path, std::string_view text,
                     bool overwrite = true);

/// Removes the hidden temporary files of the outputs libmr is writing right now (every writer
/// writes a temporary beside its output and renames it into place when complete), leaving
/// finished outputs and inputs alone. Async-signal-safe (only unlink(2)): meant for a signal
/// handler that ends the process at once, so that no partial file is left behind.
MR_API void remove_unfinished_outputs() noexcept;

/// True if `path` has an extension OpenImageIO can write.
MR_API bool is_writable_image_extension(const std::filesystem::path& path);
/// True if `path` has an extension OpenImageIO can read.
MR_API bool is_readable_image_extension(const std::filesystem::path& path);

}  // namespace mr
