// Private to libmr: opening image files for reading and writing. JPEG, PNG and OpenEXR, the
// batch formats, go directly through libjpeg, libpng and OpenEXR (libmr/src/direct_codecs.h);
// every other format, and any file of theirs the direct codecs do not take as OIIO would
// (EXIF, CMYK, tiles, ...), through OpenImageIO's module (core/oiio_module.h).
#pragma once

#include <filesystem>
#include <memory>

#include "core/image_codec.h"

namespace mr::detail {

/// Throws mr::Error(io) "<path>: not a readable image (...)" (the file is not checked to be a
/// regular file here: callers do that first).
std::unique_ptr<ImageReader> open_image_reader(const std::filesystem::path& path);
/// A writer for `path`'s extension, or nullptr if no format takes it.
std::unique_ptr<ImageWriter> create_image_writer(const std::filesystem::path& path);
/// True if a reader takes files with `path`'s extension.
bool is_readable_extension(const std::filesystem::path& path);

}  // namespace mr::detail
