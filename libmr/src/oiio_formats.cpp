// Private to libmr: how mr's pixel types and files map onto OpenImageIO's writers, shared by
// write_image (io.cpp) and the streaming fog pipeline (fog_stream.cpp).
#include "oiio_formats.h"

#include <map>
#include <set>

namespace mr::detail {

DataType stored_type(PixelType t) {
  switch (t) {
    case PixelType::uint8: return kTypeUInt8;
    case PixelType::uint16: return kTypeUInt16;
    case PixelType::half: return kTypeHalf;
    default: return kTypeFloat;
  }
}

// Pixel types each writer can store without silently converting. Formats not listed take all.
bool format_supports(const std::string& format, PixelType t) {
  static const std::map<std::string, std::set<PixelType>> kSupported = {
      {"jpeg", {PixelType::uint8}},
      {"bmp", {PixelType::uint8}},
      {"targa", {PixelType::uint8}},
      {"webp", {PixelType::uint8}},
      {"png", {PixelType::uint8, PixelType::uint16}},
      {"openexr", {PixelType::half, PixelType::float32}},
      {"hdr", {PixelType::float32}},
      {"pnm", {PixelType::uint8, PixelType::uint16, PixelType::float32}},
  };
  auto it = kSupported.find(format);
  return it == kSupported.end() || it->second.count(t) > 0;
}

PixelType automatic_pixel_type(const std::string& format) {
  if (format == "openexr" || format == "hdr") return PixelType::float32;
  if (format == "tiff") return PixelType::uint16;
  return PixelType::uint8;
}

// Attributes that describe the input file's encoding, not the picture: never carried over.
void drop_encoding_attributes(AttributeList& attrs) {
  for (const char* name : {"oiio:BitsPerSample", "oiio:ColorSpace", "oiio:Gamma", "Compression",
                           "CompressionQuality", "oiio:UnassociatedAlpha", "tiff:RowsPerStrip",
                           "tiff:Compression", "tiff:PhotometricInterpretation",
                           "tiff:PlanarConfiguration", "png:compressionLevel", "ICCProfile",
                           "jpeg:subsampling", "openexr:chunkCount", "openexr:lineOrder",
                           // OIIO 2.4 reads these EXIF tags but cannot write them back (it
                           // prints a debug line); both describe the encoding or are constant.
                           "Exif:YCbCrSubsampling", "GPS:VersionID"})
    attrs.remove(name);
}

}  // namespace mr::detail
