// OpenEXR files read directly through OpenEXR as OpenImageIO 2.4's openexr plugin reads them
// (libmr/src/direct_codecs.h): single-part scanline files with one channel or R,G,B(,A), all
// half or all float, and header attributes of the common types. Anything else goes to OIIO.
#include <ImfChannelList.h>
#include <ImfFloatAttribute.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfIntAttribute.h>
#include <ImfStandardAttributes.h>
#include <ImfStringAttribute.h>
#include <ImfTestFile.h>

#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "direct_codecs.h"
#include "mr/error.h"

namespace mr::detail {

namespace {

const char* compression_name(Imf::Compression c) {
  switch (c) {
    case Imf::NO_COMPRESSION:
      return "none";
    case Imf::RLE_COMPRESSION:
      return "rle";
    case Imf::ZIPS_COMPRESSION:
      return "zips";
    case Imf::ZIP_COMPRESSION:
      return "zip";
    case Imf::PIZ_COMPRESSION:
      return "piz";
    case Imf::PXR24_COMPRESSION:
      return "pxr24";
    case Imf::B44_COMPRESSION:
      return "b44";
    case Imf::B44A_COMPRESSION:
      return "b44a";
    case Imf::DWAA_COMPRESSION:
      return "dwaa";
    case Imf::DWAB_COMPRESSION:
      return "dwab";
    default:
      return nullptr;
  }
}

class ExrReader final : public ImageReader {
 public:
  explicit ExrReader(std::string path) : path_(std::move(path)) {}

  bool open() {
    {
      std::FILE* f = std::fopen(path_.c_str(), "rb");
      if (!f) return false;
      unsigned char magic[4] = {};
      const bool exr = std::fread(magic, 1, 4, f) == 4 && magic[0] == 0x76 && magic[1] == 0x2f &&
                       magic[2] == 0x31 && magic[3] == 0x01;
      std::fclose(f);
      if (!exr) return false;
    }
    try {
      bool tiled = false, deep = false, multipart = false;
      if (!Imf::isOpenExrFile(path_.c_str(), tiled, deep, multipart) || tiled || deep || multipart)
        return false;
      file_ = std::make_unique<Imf::InputFile>(path_.c_str());
    } catch (const std::exception&) {
      return false;  // OIIO's module says what is wrong
    }
    const Imf::Header& h = file_->header();
    const Imath::Box2i dw = h.dataWindow();
    spec_.width = dw.max.x - dw.min.x + 1, spec_.height = dw.max.y - dw.min.y + 1;
    if (dw.min.x != 0 || dw.min.y != 0 || h.displayWindow() != dw) return false;  // windows: OIIO's
    // Channels: one, or R,G,B(,A) (OIIO orders those so), all of one type.
    std::vector<std::string> names;
    Imf::PixelType type = Imf::HALF;
    for (auto c = h.channels().begin(); c != h.channels().end(); ++c) {
      if (c.channel().xSampling != 1 || c.channel().ySampling != 1) return false;
      if (!names.empty() && c.channel().type != type) return false;
      type = c.channel().type;
      names.push_back(c.name());
    }
    if (type == Imf::UINT) return false;
    if (names.size() == 3 && names == std::vector<std::string>{"B", "G", "R"})
      names = {"R", "G", "B"};
    else if (names.size() == 4 && names == std::vector<std::string>{"A", "B", "G", "R"})
      names = {"R", "G", "B", "A"}, spec_.alpha_channel = 3;
    else if (names.size() != 1)
      return false;
    spec_.nchannels = int(names.size());
    spec_.channelnames = names;
    spec_.format = type == Imf::HALF ? kTypeHalf : kTypeFloat;
    format_name_ = "openexr";
    return header_attributes(h);
  }

  void read_scanlines(int y0, int y1, int chbegin, int chend, DataType type, void* data) override {
    if (y0 < 0 || y1 > spec_.height || y0 >= y1 || chbegin < 0 || chend > spec_.nchannels ||
        chbegin >= chend)
      throw Error(ErrorCode::internal, path_ + ": EXR rows out of range");
    Imf::PixelType as;
    if (type.is(DataType::kFloat))
      as = Imf::FLOAT;
    else if (type.is(DataType::kHalf))
      as = Imf::HALF;
    else
      throw Error(ErrorCode::internal, path_ + ": EXR read as " + type.base_name());
    const int nc = chend - chbegin;
    const std::size_t x_stride = std::size_t(nc) * type.size();
    const std::size_t y_stride = x_stride * std::size_t(spec_.width);
    // The frame buffer addresses pixel (0, 0): rows y0..y1 land at data.
    char* base = static_cast<char*>(data) - std::ptrdiff_t(y0) * std::ptrdiff_t(y_stride);
    Imf::FrameBuffer fb;
    for (int c = chbegin; c < chend; ++c)
      fb.insert(spec_.channelnames[c],
                Imf::Slice(as, base + std::size_t(c - chbegin) * type.size(), x_stride, y_stride));
    try {
      file_->setFrameBuffer(fb);
      file_->readPixels(y0, y1 - 1);
    } catch (const std::exception& e) {
      throw Error(ErrorCode::corrupt_input,
                  path_ + ": cannot decode pixels (OpenEXR error: " + e.what() + ")");
    }
  }

  void read_image(DataType type, void* data) override {
    read_scanlines(0, spec_.height, 0, spec_.nchannels, type, data);
  }

 private:
  // OIIO's names for the header's attributes; false for any it maps in ways not done here.
  bool header_attributes(const Imf::Header& h) {
    // OIIO's order: the colour space and compression first, the rest by name (the header's
    // own order), the subimage count last.
    spec_.attribute("oiio:ColorSpace", "Linear");
    const char* compression = compression_name(h.compression());
    if (!compression) return false;
    spec_.attribute("compression", compression);
    for (auto a = h.begin(); a != h.end(); ++a) {
      const std::string name = a.name();
      const std::string type = a.attribute().typeName();
      if (name == "channels" || name == "dataWindow" || name == "displayWindow") continue;
      if (name == "lineOrder") {
        if (h.lineOrder() != Imf::INCREASING_Y) return false;
        continue;
      }
      if (name == "compression") {
        continue;
      } else if (name == "pixelAspectRatio") {
        spec_.set(Attribute("PixelAspectRatio", h.pixelAspectRatio()));
      } else if (name == "screenWindowWidth") {
        spec_.set(Attribute("screenWindowWidth", h.screenWindowWidth()));
      } else if (name == "screenWindowCenter") {
        const Imath::V2f v = h.screenWindowCenter();
        const float xy[2] = {v.x, v.y};
        spec_.set(
            Attribute("screenWindowCenter", DataType(DataType::kFloat, DataType::kVec2), 1, xy));
      } else if (type == "string") {
        const std::string& v = static_cast<const Imf::StringAttribute&>(a.attribute()).value();
        if (v.empty()) return false;  // OIIO drops some empty ones
        // capDate is "YYYY:MM:DD HH:MM:SS", as EXIF's DateTime: OIIO keeps the text.
        const std::string oiio_name = name == "comments"  ? "ImageDescription"
                                      : name == "owner"   ? "Copyright"
                                      : name == "capDate" ? "DateTime"
                                                          : name;
        spec_.attribute(oiio_name, v);
      } else if (type == "float") {
        if (name == "expTime" || name == "aperture" || name == "xDensity" || name == "utcOffset" ||
            name == "longitude" || name == "latitude" || name == "altitude" || name == "focus" ||
            name == "isoSpeed")
          return false;  // OIIO renames these
        spec_.set(Attribute(name, static_cast<const Imf::FloatAttribute&>(a.attribute()).value()));
      } else if (type == "int") {
        spec_.set(Attribute(name, static_cast<const Imf::IntAttribute&>(a.attribute()).value()));
      } else {
        return false;
      }
    }
    spec_.attribute("oiio:subimages", 1);
    return true;
  }

  std::string path_;
  std::unique_ptr<Imf::InputFile> file_;
};

}  // namespace

std::unique_ptr<ImageReader> open_exr_reader(const std::filesystem::path& path) {
  auto reader = std::make_unique<ExrReader>(path.string());
  if (!reader->open()) return nullptr;
  return reader;
}

}  // namespace mr::detail
