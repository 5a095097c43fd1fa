// Private to libmr: a JPEG's metadata blocks as OIIO 2.4 reads and writes them, as far as
// libmr's direct JPEG codec takes them (libmr/src/jpeg_codec.cpp). EXIF: IFD0, the Exif,
// interoperability and GPS directories, with OIIO's tag tables, names and types (SHORT a uint16,
// LONG a uint32, (S)RATIONAL a float, ASCII a string, one BYTE an int, versions as text, the GPS
// version as int[4], ResolutionUnit "none" / "in" / "cm"; other types and unknown tags dropped,
// as OIIO drops them); a maker note is skipped, as OIIO does for all makes but Canon (whose notes
// it decodes: those blocks go to OIIO's module, as any block with something OIIO reads in a way
// not reproduced here: out-of-bounds values, a tag twice, loops).
#pragma once

#include <cstddef>
#include <vector>

#include "core/attributes.h"

namespace mr::detail {

/// Decodes a TIFF-structured EXIF block (after "Exif\0\0") into `out`, in directory order, as
/// OIIO does; false if OIIO would read it otherwise (see above).
bool decode_exif(const unsigned char* data, std::size_t size, AttributeList& out);
/// True if OIIO's JPEG writer puts `p` (by its name) into the EXIF block and encode_exif writes
/// what it writes for it (what OIIO's decoder then reads back).
bool is_exif_attribute(const Attribute& p);
/// True if encode_exif writes the block OIIO writes for these attributes.
bool can_encode_exif(const AttributeList& attributes);
/// "Exif\0\0" and a little-endian TIFF block as OIIO's encode_exif writes it for `attributes`
/// (IFD0 in the attributes' order, the Exif and GPS directories sorted; for an sRGB image an
/// Exif directory with its versions and ColorSpace 1; an empty IFD0 if nothing else), decoding
/// to the same attributes; empty if !can_encode_exif.
std::vector<char> encode_exif(const AttributeList& attributes);

// IPTC-IIM (an APP13 "Photoshop 3.0" block): OIIO writes IPTC:OriginatingProgram, IPTC:Creator,
// IPTC:CopyrightNotice, IPTC:Caption and, after each, Software, Artist, Copyright and
// ImageDescription as datasets 2:65, 2:80, 2:116, 2:120, and reads them back as the IPTC names
// (a repeated dataset replacing the value, Creator's joined with "; "). An empty text (on which
// OIIO 2.4's writer asserts and aborts) is left out.

/// Decodes the block after "Photoshop 3.0\0"; false if it holds anything but those datasets.
bool decode_iptc(const unsigned char* data, std::size_t size, AttributeList& out);
/// True if `p` is one of the eight attributes above.
bool is_iptc_attribute(const Attribute& p);
/// True if encode_iptc writes what OIIO writes for them (texts, no ";" for Creator to split).
bool can_encode_iptc(const AttributeList& attributes);
/// The APP13 block OIIO writes for `attributes`, or empty if none of the eight is there.
std::vector<char> encode_iptc(const AttributeList& attributes);

}  // namespace mr::detail
