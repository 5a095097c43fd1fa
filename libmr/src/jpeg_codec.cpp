// JPEG through libjpeg(-turbo) as OpenImageIO 2.4's jpeg plugin does it
// (libmr/src/direct_codecs.h): libjpeg's defaults for decoding (ISLOW DCT, fancy upsampling, RGB or
// grey out), the same attributes (oiio:ColorSpace, jpeg:subsampling, the JFIF density as
// XResolution, YResolution, ResolutionUnit and PixelAspectRatio, a COM marker as ImageDescription,
// a camera's EXIF block), and for writing the same quality, chroma subsampling, JFIF density,
// EXIF and IPTC. libjpeg's errors longjmp back here (its default error_exit would exit the
// process).
#include <algorithm>
#include <cmath>
#include <csetjmp>
#include <cstddef>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <set>
#include <string>
#include <vector>

#include <jpeglib.h>  // after <cstdio>: it uses FILE and size_t without including them

#include "core/oiio_module.h"
#include "direct_codecs.h"
#include "jpeg_metadata.h"
#include "mr/error.h"

namespace mr::detail {

namespace {

struct ErrorManager {
  jpeg_error_mgr pub;
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX] = {};
  bool failed = false;  // a warning (corrupt data, premature end) or an error
};

void error_exit(j_common_ptr cinfo) {
  auto* err = reinterpret_cast<ErrorManager*>(cinfo->err);
  (*cinfo->err->format_message)(cinfo, err->message);
  err->failed = true;
  std::longjmp(err->jump, 1);
}

// Warnings (premature end of data, corrupt data) fail the read, as in OIIO's plugin.
void output_message(j_common_ptr cinfo) {
  auto* err = reinterpret_cast<ErrorManager*>(cinfo->err);
  if (err->failed) return;
  (*cinfo->err->format_message)(cinfo, err->message);
  err->failed = true;
}

void install(ErrorManager& err) {
  jpeg_std_error(&err.pub);
  err.pub.error_exit = error_exit;
  err.pub.output_message = output_message;
}

// OIIO's jpeg:subsampling names for the luma sampling factors (chroma 1x1).
std::string subsampling_name(const jpeg_decompress_struct& c) {
  if (c.num_components != 3) return "";
  const auto* k = c.comp_info;
  if (k[1].h_samp_factor != 1 || k[1].v_samp_factor != 1 || k[2].h_samp_factor != 1 ||
      k[2].v_samp_factor != 1)
    return "";
  const int h = k[0].h_samp_factor, v = k[0].v_samp_factor;
  if (h == 1 && v == 1) return "4:4:4";
  if (h == 2 && v == 1) return "4:2:2";
  if (h == 2 && v == 2) return "4:2:0";
  if (h == 4 && v == 1) return "4:1:1";
  return "";
}

// An APP13 block's signature, with its NUL.
constexpr char kPhotoshop[] = "Photoshop 3.0";

bool starts_with(const jpeg_saved_marker_ptr m, const char* text, std::size_t n) {
  return m->data_length >= n && std::memcmp(m->data, text, n) == 0;
}

class JpegReader final : public ImageReader {
 public:
  explicit JpegReader(std::string path) : path_(std::move(path)) {}
  ~JpegReader() override {
    if (created_) jpeg_destroy_decompress(&cinfo_);
    if (file_) std::fclose(file_);
  }

  // false: not a file these codecs take (OIIO's module reads it).
  bool open() {
    file_ = std::fopen(path_.c_str(), "rb");
    if (!file_) return false;
    unsigned char magic[3] = {};
    if (std::fread(magic, 1, 3, file_) != 3 || magic[0] != 0xFF || magic[1] != 0xD8 ||
        magic[2] != 0xFF)
      return false;
    std::rewind(file_);
    cinfo_.err = &err_.pub;
    install(err_);
    if (setjmp(err_.jump)) return false;  // a damaged header: OIIO's module says what is wrong
    jpeg_create_decompress(&cinfo_);
    created_ = true;
    jpeg_stdio_src(&cinfo_, file_);
    for (int m = 0; m < 16; ++m) jpeg_save_markers(&cinfo_, JPEG_APP0 + m, 0xFFFF);
    jpeg_save_markers(&cinfo_, JPEG_COM, 0xFFFF);
    if (jpeg_read_header(&cinfo_, TRUE) != JPEG_HEADER_OK || err_.failed) return false;
    const bool grey = cinfo_.jpeg_color_space == JCS_GRAYSCALE && cinfo_.num_components == 1;
    const bool colour =
        (cinfo_.jpeg_color_space == JCS_YCbCr || cinfo_.jpeg_color_space == JCS_RGB) &&
        cinfo_.num_components == 3;
    if (!grey && !colour) return false;  // CMYK, YCCK: OIIO converts them
    if (!header_attributes()) return false;
    jpeg_start_decompress(&cinfo_);
    if (err_.failed) return false;
    spec_.width = int(cinfo_.output_width), spec_.height = int(cinfo_.output_height);
    spec_.nchannels = cinfo_.output_components;
    spec_.format = kTypeUInt8;
    spec_.channelnames = spec_.nchannels == 1 ? std::vector<std::string>{"Y"}
                                              : std::vector<std::string>{"R", "G", "B"};
    format_name_ = "jpeg";
    row_.resize(std::size_t(spec_.width) * std::size_t(spec_.nchannels));
    return true;
  }

  void read_scanlines(int y0, int y1, int chbegin, int chend, DataType type, void* data) override {
    if (y0 != next_row_ || y1 > spec_.height || chbegin < 0 || chend > spec_.nchannels ||
        chbegin >= chend)
      throw Error(ErrorCode::internal, path_ + ": JPEG rows read out of order");
    const int n = spec_.nchannels, nc = chend - chbegin, w = spec_.width;
    const std::size_t out_row = std::size_t(w) * nc * type.size();
    for (int y = y0; y < y1; ++y) {
      read_row();
      auto* out = static_cast<unsigned char*>(data) + std::size_t(y - y0) * out_row;
      if (type.is(DataType::kUInt8) && nc == n) {
        std::memcpy(out, row_.data(), row_.size());
        continue;
      }
      for (int x = 0; x < w; ++x)
        for (int c = 0; c < nc; ++c) {
          const unsigned char v = row_[std::size_t(x) * n + chbegin + c];
          const std::size_t k = std::size_t(x) * nc + c;
          // OIIO's convert_type: integers scale to [0, 1] by a float multiply.
          if (type.is(DataType::kUInt8))
            out[k] = v;
          else if (type.is(DataType::kFloat))
            reinterpret_cast<float*>(out)[k] = float(v) * (1.0f / 255.0f);
          else
            throw Error(ErrorCode::internal, path_ + ": JPEG read as " + type.base_name());
        }
    }
  }

  void read_image(DataType type, void* data) override {
    read_scanlines(0, spec_.height, 0, spec_.nchannels, type, data);
  }

 private:
  // The attributes OIIO's plugin sets, in its order; false for markers it leaves to OIIO.
  bool header_attributes() {
    // OIIO's plugin reads an APP1 whose text (up to its NUL) is "Exif" (EXIF) or the XMP
    // namespace, an APP13 "Photoshop 3.0" (IPTC), APP2 "ICC_PROFILE" blocks and COM; libjpeg
    // reads APP0 JFIF and APP14 Adobe. Other blocks (an MPF APP2, XMP extensions, makers' own
    // APPn) it ignores, and so does this.
    const std::string xmp = "http://ns.adobe.com/xap/1.0/";
    int exif_blocks = 0, iptc_blocks = 0;
    for (jpeg_saved_marker_ptr m = cinfo_.marker_list; m; m = m->next) {
      const char* text = reinterpret_cast<const char*>(m->data);
      const bool has_nul = std::memchr(m->data, 0, m->data_length) != nullptr;
      if (m->marker == JPEG_APP0 + 1 || m->marker == JPEG_APP0 + 13) {
        if (!has_nul) return false;  // OIIO's strcmp would read past the block
        if (m->marker == JPEG_APP0 + 1 && text == xmp) return false;  // XMP: OIIO's
        exif_blocks += m->marker == JPEG_APP0 + 1 && std::string_view(text) == "Exif";
        iptc_blocks += m->marker == JPEG_APP0 + 13 && std::string_view(text) == kPhotoshop;
      } else if (m->marker == JPEG_APP0 + 2 && starts_with(m, "ICC_PROFILE", 11)) {
        return false;  // an ICC profile: OIIO's (it decodes the profile into attributes)
      }
    }
    if (exif_blocks > 1 || iptc_blocks > 1) return false;  // which wins: OIIO's business
    spec_.attribute("oiio:ColorSpace", "sRGB");
    const std::string subsampling = subsampling_name(cinfo_);
    if (!subsampling.empty()) spec_.attribute("jpeg:subsampling", subsampling);
    for (jpeg_saved_marker_ptr m = cinfo_.marker_list; m; m = m->next) {
      const char* text = reinterpret_cast<const char*>(m->data);
      if (m->marker == JPEG_APP0 + 1 && std::string_view(text) == "Exif") {
        AttributeList exif;
        if (m->data_length < 6 || !decode_exif(m->data + 6, m->data_length - 6, exif))
          return false;  // read otherwise by OIIO
        for (const Attribute& p : exif) spec_.set(p);
      } else if (m->marker == JPEG_APP0 + 13 && std::string_view(text) == kPhotoshop) {
        AttributeList iptc;
        if (!decode_iptc(m->data + sizeof kPhotoshop, m->data_length - sizeof kPhotoshop, iptc))
          return false;  // more than the datasets OIIO writes for the TIFF fields
        for (const Attribute& p : iptc) spec_.set(p);
      } else if (m->marker == JPEG_COM) {
        if (spec_.extra_attribs.find("ImageDescription", kTypeString, false) ==
            spec_.extra_attribs.cend())
          spec_.attribute("ImageDescription",
                          std::string_view(reinterpret_cast<const char*>(m->data), m->data_length));
      }
    }
    // The JFIF density, after the EXIF block: a density (both above 1) replaces the EXIF
    // resolution, a density of 1 (libjpeg's default 1:1) leaves it; either gives the pixel
    // aspect (a density of 0, no JFIF, leaves the EXIF's). Then, if there is a resolution, the
    // JFIF unit replaces any EXIF one (as OIIO 2.4's plugin does).
    float xdensity = spec_.extra_attribs.get_float("XResolution");
    float ydensity = spec_.extra_attribs.get_float("YResolution");
    if (cinfo_.X_density && cinfo_.Y_density) {
      xdensity = float(cinfo_.X_density), ydensity = float(cinfo_.Y_density);
      if (xdensity > 1 && ydensity > 1) {
        spec_.set(Attribute("XResolution", xdensity));
        spec_.set(Attribute("YResolution", ydensity));
      }
    }
    const bool has_resolution = spec_.extra_attribs.contains("XResolution");
    if (xdensity != 0 && ydensity != 0) {
      if (xdensity != ydensity) return false;  // a pixel aspect: OIIO's (it also swaps them)
      if (has_resolution) {
        switch (cinfo_.density_unit) {
          case 0:
            spec_.attribute("ResolutionUnit", "none");
            break;
          case 1:
            spec_.attribute("ResolutionUnit", "in");
            break;
          case 2:
            spec_.attribute("ResolutionUnit", "cm");
            break;
          default:
            return false;
        }
      }
    }
    // An EXIF unit that stands (no resolution to go with it): which type OIIO gives it is its
    // own business.
    if (!(has_resolution && xdensity != 0 && ydensity != 0) &&
        spec_.extra_attribs.contains("ResolutionUnit"))
      return false;
    return true;
  }

  void read_row() {
    if (setjmp(err_.jump)) fail();
    JSAMPROW row = row_.data();
    if (jpeg_read_scanlines(&cinfo_, &row, 1) != 1) err_.failed = true;
    if (err_.failed) fail();
    ++next_row_;
  }

  [[noreturn]] void fail() {
    throw Error(ErrorCode::corrupt_input,
                path_ + ": cannot decode pixels (JPEG error: " +
                    (err_.message[0] ? std::string(err_.message) : std::string("truncated?")) +
                    ")");
  }

  std::string path_;
  std::FILE* file_ = nullptr;
  jpeg_decompress_struct cinfo_{};
  ErrorManager err_;
  bool created_ = false;
  int next_row_ = 0;
  std::vector<unsigned char> row_;
};

// The attributes the direct writer writes as OIIO's plugin would (the rest of the header goes
// to OIIO's module).
bool writable_attributes(const ImageHeader& spec) {
  // ImageDescription: a COM marker (before the EXIF block), in IFD0 and as IPTC Caption, as
  // OIIO's plugin writes it. Exif:ExifVersion, Exif:FlashPixVersion (UNDEFINED in OIIO's table)
  // OIIO never writes from the attributes: it writes "0230" and "0100".
  static const std::set<std::string> handled = {"oiio:ColorSpace", "Compression",
                                                "jpeg:subsampling", "ResolutionUnit"};
  for (const Attribute& p : spec.extra_attribs) {
    const std::string& name = p.name;
    if (handled.count(name)) continue;
    const bool exif = is_exif_attribute(p), iptc = is_iptc_attribute(p);
    if (!exif && !iptc) return false;  // XMP, ICC, Canon:*, ...: OIIO's
  }
  if (!can_encode_exif(spec.extra_attribs) || !can_encode_iptc(spec.extra_attribs)) return false;
  // Blocks beyond a JPEG marker's 65533 bytes: what OIIO does with them is its business.
  const auto description = spec.extra_attribs.find("ImageDescription", kTypeString, false);
  if ((description != spec.extra_attribs.cend() && description->string_value().size() > 65000) ||
      encode_exif(spec.extra_attribs).size() > 65533 ||
      encode_iptc(spec.extra_attribs).size() > 65533)
    return false;
  // A Canon's attributes: OIIO writes a maker note from its Canon:* ones.
  const auto make = spec.extra_attribs.find("Make", kTypeUnknown, false);
  if (make != spec.extra_attribs.cend() && iequals(make->get_string(), "Canon")) return false;
  // A resolution: equal in x and y and whole (the JFIF density holds it exactly).
  const bool has_x = spec.extra_attribs.contains("XResolution");
  const bool has_y = spec.extra_attribs.contains("YResolution");
  const float xres = spec.extra_attribs.get_float("XResolution");
  if (has_x != has_y || (has_x && (xres != spec.extra_attribs.get_float("YResolution") ||
                                   xres != std::floor(xres) || !(xres >= 1 && xres <= 65535))))
    return false;
  const std::string colour = spec.get_string_attribute("oiio:ColorSpace");
  // An sRGB image's Exif ColorSpace 1 against another value from the attributes: which one
  // OIIO keeps is its business.
  if (colour == "sRGB" && spec.extra_attribs.contains("Exif:ColorSpace", kTypeUnknown, false) &&
      spec.get_int_attribute("Exif:ColorSpace") != 1)
    return false;
  const std::string sub = spec.get_string_attribute("jpeg:subsampling");
  const std::string compression = spec.get_string_attribute("Compression");
  const std::string unit = spec.get_string_attribute("ResolutionUnit");
  return spec.nchannels == 3 &&
         (sub.empty() || sub == "4:4:4" || sub == "4:2:2" || sub == "4:2:0") &&
         (compression.empty() || compression.rfind("jpeg:", 0) == 0) &&
         spec.extra_attribs.find("PixelAspectRatio") == spec.extra_attribs.cend() &&
         (unit.empty() || unit == "none" || unit == "in" || unit == "cm") &&
         // "sRGB" OIIO marks in an Exif directory (done here); other names (the config's
         // "srgb_texture", "srgb_rolloff") it writes nothing for. Other spellings of "srgb":
         // whatever OIIO does with them.
         (colour == "sRGB" || !iequals(colour, "srgb"));
}

class JpegWriter final : public ImageWriter {
 public:
  explicit JpegWriter(std::filesystem::path output) : output_(std::move(output)) {
    format_name_ = "jpeg";
  }
  ~JpegWriter() override {
    if (created_) jpeg_destroy_compress(&cinfo_);
    if (file_) std::fclose(file_);
  }

  void open(const std::string& path, const std::string& name, const ImageHeader& spec) override {
    name_ = name;
    if (!writable_attributes(spec)) {
      fallback_.reset(oiio_module().create_writer(output_.string()));
      if (!fallback_) throw Error(ErrorCode::invalid_argument, name + ": no JPEG writer");
      // Without the empty texts OIIO's IPTC encoder asserts on (it aborts the process): the
      // file OIIO would write if it did not.
      ImageHeader header = spec;
      for (auto it = header.extra_attribs.begin(); it != header.extra_attribs.end();)
        if (is_iptc_attribute(*it) && it->type.is(DataType::kString) && it->string_value().empty())
          it = header.extra_attribs.erase(it);
        else
          ++it;
      fallback_->open(path, name, header);
      return;
    }
    file_ = std::fopen(path.c_str(), "wb");
    if (!file_) throw Error(ErrorCode::io, name + ": cannot write: cannot open " + path);
    width_ = spec.width;
    int quality = 98;  // OIIO's default
    const std::string compression = spec.get_string_attribute("Compression");
    if (compression.size() > 5) quality = std::clamp(std::atoi(compression.c_str() + 5), 1, 100);
    const std::vector<char> exif = encode_exif(spec.extra_attribs);
    const std::vector<char> iptc = encode_iptc(spec.extra_attribs);
    const std::string sub = spec.get_string_attribute("jpeg:subsampling");
    const std::string unit = spec.get_string_attribute("ResolutionUnit");
    const float xres = spec.extra_attribs.get_float("XResolution");
    const float yres = spec.extra_attribs.get_float("YResolution");

    cinfo_.err = &err_.pub;
    install(err_);
    if (setjmp(err_.jump)) fail();
    jpeg_create_compress(&cinfo_);
    created_ = true;
    jpeg_stdio_dest(&cinfo_, file_);
    cinfo_.image_width = JDIMENSION(spec.width);
    cinfo_.image_height = JDIMENSION(spec.height);
    cinfo_.input_components = 3;
    cinfo_.in_color_space = JCS_RGB;
    jpeg_set_defaults(&cinfo_);
    // JFIF density from the resolution attributes, as OIIO's plugin sets it.
    if (xres > 0 && yres > 0) {  // else libjpeg's 1:1 without a unit
      cinfo_.density_unit = UINT8(unit == "in" ? 1 : unit == "cm" ? 2 : 0);
      cinfo_.X_density = UINT16(std::clamp(int(xres), 1, 65535));
      cinfo_.Y_density = UINT16(std::clamp(int(yres), 1, 65535));
    }
    jpeg_set_quality(&cinfo_, quality, TRUE);
    const int h = sub == "4:4:4" ? 1 : 2, v = sub == "4:4:4" || sub == "4:2:2" ? 1 : 2;
    cinfo_.comp_info[0].h_samp_factor = h, cinfo_.comp_info[0].v_samp_factor = v;
    for (int c = 1; c < 3; ++c)
      cinfo_.comp_info[c].h_samp_factor = cinfo_.comp_info[c].v_samp_factor = 1;
    jpeg_start_compress(&cinfo_, TRUE);
    // As OIIO's plugin: the description as a COM marker (with its NUL), always an EXIF block
    // (an empty one without fields), then IPTC.
    const auto description = spec.extra_attribs.find("ImageDescription", kTypeString, false);
    if (description != spec.extra_attribs.cend() && !description->string_value().empty()) {
      const std::string& text = description->string_value();
      jpeg_write_marker(&cinfo_, JPEG_COM, reinterpret_cast<const JOCTET*>(text.c_str()),
                        unsigned(text.size() + 1));
    }
    jpeg_write_marker(&cinfo_, JPEG_APP0 + 1, reinterpret_cast<const JOCTET*>(exif.data()),
                      unsigned(exif.size()));
    if (!iptc.empty())
      jpeg_write_marker(&cinfo_, JPEG_APP0 + 13, reinterpret_cast<const JOCTET*>(iptc.data()),
                        unsigned(iptc.size()));
    if (err_.failed) fail();
  }

  void write_scanlines(int y0, int y1, DataType type, const void* data) override {
    if (fallback_) return fallback_->write_scanlines(y0, y1, type, data);
    if (!type.is(DataType::kUInt8))
      throw Error(ErrorCode::internal, name_ + ": JPEG rows given as " + type.base_name());
    if (setjmp(err_.jump)) fail();
    const auto* rows = static_cast<const unsigned char*>(data);
    for (int y = y0; y < y1; ++y) {
      JSAMPROW row = const_cast<JSAMPROW>(rows + std::size_t(y - y0) * std::size_t(width_) * 3);
      jpeg_write_scanlines(&cinfo_, &row, 1);
    }
    if (err_.failed) fail();
  }

  void write_image(DataType type, const void* data) override {
    if (fallback_) return fallback_->write_image(type, data);
    write_scanlines(0, int(cinfo_.image_height), type, data);
  }

  void close() override {
    if (fallback_) return fallback_->close();
    if (setjmp(err_.jump)) fail();
    jpeg_finish_compress(&cinfo_);
    const bool flushed = std::fflush(file_) == 0 && !std::ferror(file_);
    const bool closed = std::fclose(file_) == 0;
    file_ = nullptr;
    if (!flushed || !closed || err_.failed)
      throw Error(ErrorCode::io, name_ + ": writing failed: " +
                                     (err_.message[0] ? err_.message : "cannot write the file"));
  }

 private:
  [[noreturn]] void fail() {
    throw Error(ErrorCode::io, name_ + ": writing failed: JPEG error: " + err_.message);
  }

  std::filesystem::path output_;
  std::string name_;
  std::unique_ptr<ImageWriter> fallback_;
  std::FILE* file_ = nullptr;
  jpeg_compress_struct cinfo_{};
  ErrorManager err_;
  bool created_ = false;
  int width_ = 0;
};

}  // namespace

std::unique_ptr<ImageReader> open_jpeg_reader(const std::filesystem::path& path) {
  auto reader = std::make_unique<JpegReader>(path.string());
  if (!reader->open()) return nullptr;
  return reader;
}

bool writes_jpeg_directly(const ImageHeader& spec) {
  return writable_attributes(spec);
}

std::unique_ptr<ImageWriter> create_jpeg_writer(const std::filesystem::path& path) {
  return std::make_unique<JpegWriter>(path);
}

}  // namespace mr::detail
