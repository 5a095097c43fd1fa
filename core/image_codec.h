// Private to libmr: an image file open for reading or writing, whichever library does the work:
// libjpeg, libpng and OpenEXR directly (core/direct_codecs.cpp) or OpenImageIO through its
// module (core/oiio_module.cpp). No OIIO types here: pixel types are OIIO's type codes as
// DataType and attributes an AttributeList (core/attributes.h), so that libmr.so needs no OIIO
// library at all (issue 12, start-up).
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "core/attributes.h"

namespace mr::detail {

/// What libmr uses of OIIO::ImageSpec: the shape, the stored types and the attributes.
struct ImageHeader {
  int width = 0, height = 0, depth = 1, nchannels = 0;
  int tile_width = 0;  ///< 0: scanlines
  int alpha_channel = -1;
  DataType format = kTypeUInt8;
  std::vector<DataType> channelformats;  ///< empty unless channels differ in type
  std::vector<std::string> channelnames;
  AttributeList extra_attribs;

  /// As ImageSpec::get_int_attribute / get_string_attribute (case-insensitive names; a string
  /// only from a string attribute).
  int get_int_attribute(std::string_view name, int fallback = 0) const {
    return extra_attribs.get_int(name, fallback);
  }
  std::string get_string_attribute(std::string_view name) const {
    const auto it = extra_attribs.find(name, kTypeString, false);
    return it == extra_attribs.cend() ? std::string() : it->string_value();
  }
  /// As ImageSpec::attribute: replaces an attribute of the same name in any case, in place,
  /// else appends.
  void attribute(std::string_view name, std::string_view value) { set(Attribute(name, value)); }
  void attribute(std::string_view name, int value) { set(Attribute(name, value)); }
  void set(const Attribute& value) {
    const auto it = extra_attribs.find(value.name, kTypeUnknown, false);
    if (it == extra_attribs.end())
      extra_attribs.push_back(value);
    else
      *it = value;
  }
};

/// An open image file. Errors throw mr::Error naming the file.
class ImageReader {
 public:
  virtual ~ImageReader() = default;
  const ImageHeader& spec() const { return spec_; }
  /// OIIO's name of the format: "jpeg", "png", "openexr", "tiff", ...
  const std::string& format_name() const { return format_name_; }
  /// Rows [y0, y1) (of the data window, in order) of channels [chbegin, chend) as `type`,
  /// packed. In the file's own type (`type` == spec().format) without a conversion buffer.
  virtual void read_scanlines(int y0, int y1, int chbegin, int chend, DataType type,
                              void* data) = 0;
  /// The whole image, all channels as `type`, packed (tiled files too).
  virtual void read_image(DataType type, void* data) = 0;

 protected:
  ImageHeader spec_;
  std::string format_name_;
};

/// A file being written: open, rows in order, close. Errors throw mr::Error naming the file.
class ImageWriter {
 public:
  virtual ~ImageWriter() = default;
  const std::string& format_name() const { return format_name_; }
  /// Writes to `path` (the temporary file of an atomic output); `name` is the output's name
  /// for messages.
  virtual void open(const std::string& path, const std::string& name, const ImageHeader& spec) = 0;
  virtual void write_scanlines(int y0, int y1, DataType type, const void* data) = 0;
  /// All rows at once (for OIIO's writers: ImageOutput::write_image, tiled formats too).
  virtual void write_image(DataType type, const void* data) = 0;
  virtual void close() = 0;

 protected:
  std::string format_name_;
};

}  // namespace mr::detail
