// Private to libmr: JPEG and OpenEXR files read and written directly through libjpeg(-turbo)
// and OpenEXR, PNG input through libpng, the codec libraries OpenImageIO itself uses, with the pixels and attributes
// OIIO 2.4 gives (tests/direct_codecs_test.cpp compares them file for file). Only what they
// reproduce exactly is taken: a file or header with anything else (a Canon maker note, ICC
// profiles, XMP, IPTC beyond the TIFF fields, CMYK, tiles, several parts, ...) goes to OIIO's
// module. Camera EXIF (the Exif, GPS and interoperability directories) is read and written here
// (libmr/src/jpeg_metadata.h).
#pragma once

#include <filesystem>
#include <memory>

#include "core/image_codec.h"

namespace mr::detail {

/// A reader if `path` is a JPEG, PNG or OpenEXR file these codecs read as OIIO would; nullptr
/// otherwise (not such a file, or one they leave to OIIO).
std::unique_ptr<ImageReader> open_direct_reader(const std::filesystem::path& path);
/// A writer for a .jpg/.jpeg path (nullptr for other extensions). It writes directly when the
/// header is one these codecs write as OIIO would, else through OIIO's module.
std::unique_ptr<ImageWriter> create_direct_writer(const std::filesystem::path& path);

// The codecs (libmr/src/jpeg_codec.cpp, exr_codec.cpp, png_codec.cpp): as above, for one
// format each.
std::unique_ptr<ImageReader> open_jpeg_reader(const std::filesystem::path& path);
std::unique_ptr<ImageReader> open_exr_reader(const std::filesystem::path& path);
std::unique_ptr<ImageReader> open_png_reader(const std::filesystem::path& path);
std::unique_ptr<ImageWriter> create_jpeg_writer(const std::filesystem::path& path);
/// Whether create_jpeg_writer's writer writes `spec` itself (else through OIIO's module).
bool writes_jpeg_directly(const ImageHeader& spec);

}  // namespace mr::detail
