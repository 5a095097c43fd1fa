// libmr_oiio.so: libmr's calls into OpenImageIO (the table in core/oiio_module.h). A module of
// its own so that libOpenImageIO, and the 260 libraries it pulls in, are mapped only by the runs
// that read or write a format other than JPEG, PNG or OpenEXR, resample, or load a model's
// textures. Built from the same calls libmr made directly before (same parameters, same
// messages); mr::Error is header-only, so the module throws it without linking libmr.
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <memory>
#include <string>

#include "core/oiio_attributes.h"
#include "core/oiio_module.h"
#include "mr/error.h"

namespace mr::detail {

namespace {

ImageHeader to_header(const OIIO::ImageSpec& spec) {
  ImageHeader h;
  h.width = spec.width, h.height = spec.height, h.depth = spec.depth;
  h.nchannels = spec.nchannels, h.tile_width = spec.tile_width;
  h.alpha_channel = spec.alpha_channel;
  h.format = from_oiio(spec.format);
  for (const OIIO::TypeDesc& t : spec.channelformats) h.channelformats.push_back(from_oiio(t));
  h.channelnames = spec.channelnames;
  h.extra_attribs = from_oiio(spec.extra_attribs);
  return h;
}

class OiioReader final : public ImageReader {
 public:
  OiioReader(std::string path, std::unique_ptr<OIIO::ImageInput> in)
      : path_(std::move(path)), in_(std::move(in)) {
    spec_ = to_header(in_->spec());
    format_name_ = in_->format_name();
  }
  void read_scanlines(int y0, int y1, int chbegin, int chend, DataType data_type,
                      void* data) override {
    const OIIO::TypeDesc type = to_oiio(data_type);
    const OIIO::ImageSpec& s = in_->spec();
    // The native read gives the same bytes as read_scanlines without the temporary buffer
    // read_scanlines allocates per call (fresh pages, hence page faults, per strip: issue 12).
    const bool native = type == s.format && s.channelformats.empty();
    check(native ? in_->read_native_scanlines(0, 0, s.y + y0, s.y + y1, s.z, chbegin, chend, data)
                 : in_->read_scanlines(0, 0, s.y + y0, s.y + y1, s.z, chbegin, chend, type, data));
  }
  void read_image(DataType type, void* data) override {
    check(in_->read_image(0, 0, 0, in_->spec().nchannels, to_oiio(type), data));
  }

 private:
  void check(bool ok) {
    if (ok && !in_->has_error()) return;
    const std::string msg = in_->geterror();
    throw Error(ErrorCode::corrupt_input,
                path_ + ": cannot decode pixels (" + (msg.empty() ? "truncated?" : msg) + ")");
  }
  std::string path_;
  std::unique_ptr<OIIO::ImageInput> in_;
};

class OiioWriter final : public ImageWriter {
 public:
  explicit OiioWriter(std::unique_ptr<OIIO::ImageOutput> out) : out_(std::move(out)) {
    format_name_ = out_->format_name();
  }
  void open(const std::string& path, const std::string& name, const ImageHeader& h) override {
    name_ = name;
    OIIO::ImageSpec spec(h.width, h.height, h.nchannels, to_oiio(h.format));
    spec.channelnames = h.channelnames;
    for (const DataType& t : h.channelformats) spec.channelformats.push_back(to_oiio(t));
    spec.alpha_channel = h.alpha_channel;
    spec.extra_attribs = to_oiio(h.extra_attribs);
    if (!out_->open(path, spec))
      throw Error(ErrorCode::io, name_ + ": cannot write: " + out_->geterror());
  }
  void write_scanlines(int y0, int y1, DataType type, const void* data) override {
    if (!out_->write_scanlines(y0, y1, 0, to_oiio(type), data))
      throw Error(ErrorCode::io, name_ + ": writing failed: " + out_->geterror());
  }
  void write_image(DataType type, const void* data) override {
    if (!out_->write_image(to_oiio(type), data))
      throw Error(ErrorCode::io, name_ + ": writing failed: " + out_->geterror());
  }
  void close() override {
    if (!out_->close()) throw Error(ErrorCode::io, name_ + ": writing failed: " + out_->geterror());
  }

 private:
  std::string name_;
  std::unique_ptr<OIIO::ImageOutput> out_;
};

ImageReader* open_reader(const std::string& path) {
  auto in = OIIO::ImageInput::open(path);
  if (!in) {
    std::string msg = OIIO::geterror();
    if (msg.empty()) msg = "unknown reason";
    throw Error(ErrorCode::io, path + ": not a readable image (" + msg + ")");
  }
  return new OiioReader(path, std::move(in));
}

ImageWriter* create_writer(const std::string& path) {
  auto out = OIIO::ImageOutput::create(path);
  if (!out) {
    OIIO::geterror();  // cleared: the caller says what is missing
    return nullptr;
  }
  return new OiioWriter(std::move(out));
}

std::string extension_list() {
  return OIIO::get_string_attribute("extension_list");
}

void resize(const float* src, int src_width, int src_height, int channels, float* dst, int width,
            int height, const char* filter) {
  const OIIO::ImageSpec in_spec(src_width, src_height, channels, OIIO::TypeDesc::FLOAT);
  const OIIO::ImageSpec out_spec(width, height, channels, OIIO::TypeDesc::FLOAT);
  // ImageBuf has no const-wrapping constructor; `in` is only read.
  OIIO::ImageBuf in(in_spec, const_cast<float*>(src));
  OIIO::ImageBuf out(out_spec, dst);
  if (!OIIO::ImageBufAlgo::resize(out, in, filter, 0.0f,
                                  OIIO::ROI(0, width, 0, height, 0, 1, 0, channels), 1))
    throw Error(ErrorCode::internal, "resize to " + std::to_string(width) + "x" +
                                         std::to_string(height) + " failed: " + out.geterror());
}

bool decode_texture(const std::string& filename, const void* memory, std::size_t size, int max_side,
                    std::uint64_t max_pixels, std::vector<float>& pixels, int& width, int& height,
                    int& channels, std::string& why) {
  OIIO::Filesystem::IOMemReader reader(memory, memory ? size : 0);
  OIIO::Filesystem::IOProxy* io = memory ? &reader : nullptr;
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);  // base colour keeps its colour where alpha < 1
  // OIIO 2.4's readers take the memory proxy from the configuration hint (the open() argument
  // alone is not passed on to every plugin).
  if (io) config.attribute("oiio:ioproxy", OIIO::TypeDesc::PTR, &io);
  std::unique_ptr<OIIO::ImageInput> in;
  try {
    in = OIIO::ImageInput::open(filename, &config, io);
  } catch (const std::exception& e) {
    why = e.what();
    return false;
  }
  if (!in) {
    why = OIIO::geterror();
    if (why.empty()) why = "cannot be decoded as an image";
    std::replace(why.begin(), why.end(), '\n', ' ');
    return false;
  }
  const OIIO::ImageSpec& spec = in->spec();
  const std::uint64_t w = std::uint64_t(std::max(spec.width, 0));
  const std::uint64_t h = std::uint64_t(std::max(spec.height, 0));
  if (w == 0 || h == 0 || spec.nchannels < 1) {
    why = "an empty image";
    return false;
  }
  if (w > std::uint64_t(max_side) || h > std::uint64_t(max_side) || w * h > max_pixels) {
    why = std::to_string(w) + "x" + std::to_string(h) + " is larger than the texture limit (" +
          std::to_string(max_side) + " pixels a side, " + std::to_string(max_pixels) + " pixels)";
    return false;
  }
  const int stored = std::min(spec.nchannels, 4);
  pixels.assign(w * h * std::uint64_t(stored), 0.0f);
  if (!in->read_image(0, 0, 0, stored, OIIO::TypeDesc::FLOAT, pixels.data())) {
    why = in->geterror();
    if (why.empty()) why = "truncated or corrupt image";
    std::replace(why.begin(), why.end(), '\n', ' ');
    return false;
  }
  width = int(w), height = int(h), channels = stored;
  return true;
}

const OiioModule kModule{open_reader, create_writer, extension_list, resize, decode_texture};

}  // namespace

}  // namespace mr::detail

extern "C" __attribute__((visibility("default"))) const void* mr_oiio_module() {
  return &mr::detail::kModule;
}
