// Private to libmr: how mr's pixel types and files map onto OpenImageIO's writers, shared by
// write_image (io.cpp) and the streaming fog pipeline (fog_stream.cpp).
#pragma once

#include <string>

#include "core/attributes.h"
#include "mr/io.h"

namespace mr::detail {

/// The stored type (OIIO's code) of a pixel type.
DataType stored_type(PixelType t);
/// Pixel types each writer (OIIO format name) stores without silently converting; formats not
/// listed take all.
bool format_supports(const std::string& format, PixelType t);
/// The stored type of PixelType::automatic for a format.
PixelType automatic_pixel_type(const std::string& format);
/// Removes the attributes that describe the input file's encoding, not the picture.
void drop_encoding_attributes(AttributeList& attrs);

}  // namespace mr::detail
