// Private to libmr: how mr's pixel types and files map onto OpenImageIO's writers, shared by
// write_image (io.cpp) and the streaming fog pipeline (fog_stream.cpp).
#pragma once

#include <OpenImageIO/paramlist.h>
#include <OpenImageIO/typedesc.h>

#include <string>

#include "mr/io.h"

namespace mr::detail {

OIIO::TypeDesc to_oiio(PixelType t);
/// Pixel types each writer (OIIO format name) stores without silently converting; formats not
/// listed take all.
bool format_supports(const std::string& format, PixelType t);
/// The stored type of PixelType::automatic for a format.
PixelType automatic_pixel_type(const std::string& format);
/// Removes the attributes that describe the input file's encoding, not the picture.
void drop_encoding_attributes(OIIO::ParamValueList& attrs);

}  // namespace mr::detail
