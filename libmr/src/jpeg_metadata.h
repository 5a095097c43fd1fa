// Private to libmr: a JPEG's metadata blocks as OIIO 2.4 reads and writes them, as far as
// libmr's direct JPEG codec takes them (libmr/src/jpeg_codec.cpp). EXIF: the TIFF fields (IFD0:
// ImageDescription, Make, Model, Orientation, XResolution, YResolution, ResolutionUnit, Software,
// DateTime, Artist, Copyright) as OIIO 2.4 names and types them (strings, Orientation an int, the
// resolutions floats, ResolutionUnit "none" / "in" / "cm"). Anything more in a block (the Exif and
// GPS sub-directories, maker notes, other tags) is left to OIIO's own decoder (the module).
#pragma once

#include <cstddef>
#include <vector>

#include "core/attributes.h"

namespace mr::detail {

/// Decodes a TIFF-structured EXIF block (after "Exif\0\0") into `out`, in directory order.
/// false if it holds anything but the fields above (or is malformed).
bool decode_tiff_fields(const unsigned char* data, std::size_t size, AttributeList& out);
/// True if `p` is one of the fields above, of the type OIIO gives it, and encodable exactly.
bool is_tiff_field(const Attribute& p);
/// "Exif\0\0" and a little-endian TIFF block with the fields of `attributes` (those
/// is_tiff_field takes; an empty directory if none, as OIIO writes).
std::vector<char> encode_tiff_fields(const AttributeList& attributes);

// IPTC-IIM (an APP13 "Photoshop 3.0" block): OIIO writes Software, Artist and Copyright there
// too, as datasets 2:65 OriginatingProgram, 2:80 Creator and 2:116 CopyrightNotice, and reads
// them back as "IPTC:OriginatingProgram", "IPTC:Creator", "IPTC:CopyrightNotice".

/// Decodes the block after "Photoshop 3.0\0"; false if it holds anything but those datasets.
bool decode_iptc(const unsigned char* data, std::size_t size, AttributeList& out);
/// The APP13 block OIIO writes for `attributes`, or empty if none of the three is there.
std::vector<char> encode_iptc(const AttributeList& attributes);

}  // namespace mr::detail
