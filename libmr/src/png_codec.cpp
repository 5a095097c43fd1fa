// PNG input through libpng as OpenImageIO 2.4's png plugin reads it (libmr/src/direct_codecs.h):
// png_set_expand (bit depths below 8, a palette), 16-bit samples byte-swapped to the host, and
// the same attributes in the same order (oiio:Gamma and oiio:ColorSpace from the sRGB / gAMA
// chunks, DateTime from tIME, the text chunks with OIIO's key names, the pHYs resolution in
// inches or without a unit). Only files without alpha (OIIO associates it, with its own
// arithmetic) and without an ICC profile, EXIF, XMP, a background colour, an offset, a pixel
// aspect or interlacing are taken; the rest goes to OIIO's module. libpng's errors longjmp back
// here.
#include <png.h>

#include <cmath>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "direct_codecs.h"
#include "mr/error.h"

namespace mr::detail {

namespace {

struct PngErrors {
  std::string message;
  bool warned = false;
};

void on_error(png_structp png, png_const_charp message) {
  auto* errors = static_cast<PngErrors*>(png_get_error_ptr(png));
  if (errors && errors->message.empty()) errors->message = message ? message : "";
  png_longjmp(png, 1);
}

// OIIO's plugin ignores libpng's warnings; a header with one is left to it all the same.
void on_warning(png_structp png, png_const_charp) {
  auto* errors = static_cast<PngErrors*>(png_get_error_ptr(png));
  if (errors) errors->warned = true;
}

class PngReader final : public ImageReader {
 public:
  explicit PngReader(std::string path) : path_(std::move(path)) {}
  ~PngReader() override {
    if (png_) png_destroy_read_struct(&png_, info_ ? &info_ : nullptr, nullptr);
    if (file_) std::fclose(file_);
  }

  // false: not a file this reader takes (OIIO's module reads it).
  bool open() {
    file_ = std::fopen(path_.c_str(), "rb");
    if (!file_) return false;
    unsigned char signature[8] = {};
    if (std::fread(signature, 1, 8, file_) != 8 || png_sig_cmp(signature, 0, 8) != 0) return false;
    png_ = png_create_read_struct(PNG_LIBPNG_VER_STRING, &errors_, on_error, on_warning);
    if (!png_) return false;
    info_ = png_create_info_struct(png_);
    if (!info_) return false;
    if (setjmp(png_jmpbuf(png_))) return false;  // a damaged header: OIIO's module says what
    png_init_io(png_, file_);
    png_set_sig_bytes(png_, 8);
    png_read_info(png_, info_);
    png_uint_32 width = 0, height = 0;
    int bit_depth = 0, colour_type = 0, interlace = 0;
    png_get_IHDR(png_, info_, &width, &height, &bit_depth, &colour_type, &interlace, nullptr,
                 nullptr);
    if (interlace != PNG_INTERLACE_NONE || (colour_type & PNG_COLOR_MASK_ALPHA) ||
        png_get_valid(png_, info_, PNG_INFO_tRNS) || png_get_valid(png_, info_, PNG_INFO_iCCP) ||
        png_get_valid(png_, info_, PNG_INFO_bKGD) || png_get_valid(png_, info_, PNG_INFO_eXIf) ||
        png_get_valid(png_, info_, PNG_INFO_sPLT))
      return false;
    if (png_get_valid(png_, info_, PNG_INFO_oFFs) &&
        (png_get_x_offset_pixels(png_, info_) != 0 || png_get_y_offset_pixels(png_, info_) != 0))
      return false;
    png_set_expand(png_);
    if (bit_depth == 16) png_set_swap(png_);  // PNG is big-endian; this host is not
    png_read_update_info(png_, info_);
    png_get_IHDR(png_, info_, &width, &height, &bit_depth, &colour_type, nullptr, nullptr, nullptr);
    const int channels = png_get_channels(png_, info_);
    if ((channels != 1 && channels != 3) || (bit_depth != 8 && bit_depth != 16)) return false;
    if (width > 0x7FFFFFFF || height > 0x7FFFFFFF) return false;
    spec_.width = int(width), spec_.height = int(height), spec_.nchannels = channels;
    spec_.format = bit_depth == 16 ? kTypeUInt16 : kTypeUInt8;
    spec_.channelnames =
        channels == 1 ? std::vector<std::string>{"Y"} : std::vector<std::string>{"R", "G", "B"};
    if (!attributes() || errors_.warned) return false;
    format_name_ = "png";
    row_.resize(png_get_rowbytes(png_, info_));
    return true;
  }

  void read_scanlines(int y0, int y1, int chbegin, int chend, DataType type, void* data) override {
    if (y0 != next_row_ || y1 > spec_.height || chbegin < 0 || chend > spec_.nchannels ||
        chbegin >= chend)
      throw Error(ErrorCode::internal, path_ + ": PNG rows read out of order");
    const int n = spec_.nchannels, nc = chend - chbegin, w = spec_.width;
    const bool wide = spec_.format.is(DataType::kUInt16);
    const std::size_t out_row = std::size_t(w) * nc * type.size();
    for (int y = y0; y < y1; ++y) {
      read_row();
      auto* out = static_cast<unsigned char*>(data) + std::size_t(y - y0) * out_row;
      if (type == spec_.format && nc == n) {
        std::memcpy(out, row_.data(), out_row);
        continue;
      }
      for (int x = 0; x < w; ++x)
        for (int c = 0; c < nc; ++c) {
          const std::size_t from = std::size_t(x) * n + chbegin + c, k = std::size_t(x) * nc + c;
          std::uint16_t v = 0;
          if (wide)
            std::memcpy(&v, row_.data() + 2 * from, 2);
          else
            v = row_[from];
          // OIIO's convert_type: integers scale to [0, 1] by a float multiply.
          if (type == spec_.format && wide)
            reinterpret_cast<std::uint16_t*>(out)[k] = v;
          else if (type == spec_.format)
            out[k] = static_cast<unsigned char>(v);
          else if (type.is(DataType::kFloat))
            reinterpret_cast<float*>(out)[k] =
                wide ? float(v) * (1.0f / 65535.0f) : float(v) * (1.0f / 255.0f);
          else
            throw Error(ErrorCode::internal, path_ + ": PNG read as " + type.base_name());
        }
    }
  }

  void read_image(DataType type, void* data) override {
    read_scanlines(0, spec_.height, 0, spec_.nchannels, type, data);
  }

 private:
  // OIIO's attributes, in its order; false where it reads something not reproduced here.
  bool attributes() {
    int intent = 0;
    double gamma = 0;
    if (png_get_sRGB(png_, info_, &intent)) {
      spec_.attribute("oiio:ColorSpace", "sRGB");
    } else if (png_get_gAMA(png_, info_, &gamma) && gamma > 0.0) {
      // OIIO rounds 1/gamma to hundredths ("Gamma2.2", not 2.19998).
      float g = float(1.0 / gamma);
      g = std::roundf(float(100.0 * g)) / 100.0f;
      spec_.set(Attribute("oiio:Gamma", g));
      if (g == 1.0f) {
        spec_.attribute("oiio:ColorSpace", "linear");
      } else {
        char name[64];
        std::snprintf(name, sizeof name, "Gamma%.2g", double(g));
        spec_.attribute("oiio:ColorSpace", name);
      }
    } else {
      spec_.attribute("oiio:ColorSpace", "sRGB");  // no information: OIIO assumes sRGB
    }
    png_timep time = nullptr;
    if (png_get_tIME(png_, info_, &time) && time) {
      char date[64];
      std::snprintf(date, sizeof date, "%4d:%02d:%02d %02d:%02d:%02d", time->year, time->month,
                    time->day, time->hour, time->minute, time->second);
      spec_.attribute("DateTime", date);
    }
    png_textp text = nullptr;
    const int texts = png_get_text(png_, info_, &text, nullptr);
    for (int i = 0; i < texts; ++i) {
      const std::string key = text[i].key ? text[i].key : "";
      const std::string value = text[i].text ? text[i].text : "";  // up to a NUL, as OIIO
      std::string name = key;
      if (iequals(key, "Description"))
        name = "ImageDescription";
      else if (iequals(key, "Author"))
        name = "Artist";
      else if (iequals(key, "Title"))
        name = "DocumentName";
      else if (iequals(key, "XML:com.adobe.xmp") || iequals(key, "Raw profile type exif"))
        return false;  // XMP, EXIF: OIIO decodes them
      // OIIO replaces an attribute of the same name (its writer stores oiio:ColorSpace as text).
      if (name.empty()) return false;
      spec_.attribute(name, value);
    }
    png_uint_32 xres = 0, yres = 0;
    int unit = 0;
    if (png_get_pHYs(png_, info_, &xres, &yres, &unit)) {
      float scale = 1;
      if (unit == PNG_RESOLUTION_METER) {
        scale = float(2.54 / 100.0);  // to inches, as OIIO
        spec_.attribute("ResolutionUnit", "inch");
      } else {
        spec_.attribute("ResolutionUnit", "none");
      }
      spec_.set(Attribute("XResolution", float(xres) * scale));
      spec_.set(Attribute("YResolution", float(yres) * scale));
    }
    const float aspect = float(png_get_pixel_aspect_ratio(png_, info_));
    if (aspect != 0 && aspect != 1) return false;  // a pixel aspect: OIIO's
    return true;
  }

  void read_row() {
    if (setjmp(png_jmpbuf(png_))) fail();
    png_read_row(png_, row_.data(), nullptr);
    ++next_row_;
  }

  [[noreturn]] void fail() {
    throw Error(ErrorCode::corrupt_input,
                path_ + ": cannot decode pixels (PNG error: " +
                    (errors_.message.empty() ? std::string("truncated?") : errors_.message) + ")");
  }

  std::string path_;
  std::FILE* file_ = nullptr;
  png_structp png_ = nullptr;
  png_infop info_ = nullptr;
  PngErrors errors_;
  int next_row_ = 0;
  std::vector<unsigned char> row_;
};

}  // namespace

std::unique_ptr<ImageReader> open_png_reader(const std::filesystem::path& path) {
  auto reader = std::make_unique<PngReader>(path.string());
  if (!reader->open()) return nullptr;
  return reader;
}

}  // namespace mr::detail
