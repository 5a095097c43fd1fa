#include "mr/io.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <cctype>
#include <cmath>
#include <map>
#include <mutex>
#include <set>

#include "atomic_file.h"
#include "mr/error.h"
#include "core/metadata_impl.h"
#include "image_files.h"
#include "oiio_formats.h"

namespace mr {

namespace {

using detail::automatic_pixel_type;
using detail::drop_encoding_attributes;
using detail::format_supports;
using detail::ImageHeader;
using detail::ImageReader;
using detail::ImageWriter;
using detail::stored_type;

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

PixelType from_oiio(detail::DataType t) {
  switch (t.basetype) {
    case detail::DataType::kUInt8:
    case detail::DataType::kInt8: return PixelType::uint8;
    case detail::DataType::kUInt16:
    case detail::DataType::kInt16: return PixelType::uint16;
    case detail::DataType::kHalf: return PixelType::half;
    default: return PixelType::float32;
  }
}


bool is_integer(PixelType t) { return t == PixelType::uint8 || t == PixelType::uint16; }

const ColorConfig& config_or_default(const ColorConfig* given, ColorConfig& storage) {
  if (given) return *given;
  storage = ColorConfig::from_environment();
  return storage;
}

std::atomic<std::uint64_t> g_max_decoded_pixels{kDefaultMaxDecodedPixels};

std::unique_ptr<ImageReader> open_input(const std::filesystem::path& path) {
  // Only regular files: a FIFO or /dev/zero would block or stream for ever.
  detail::check_regular_input(path, "an image");
  auto in = detail::open_image_reader(path);
  const auto& spec = in->spec();
  if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0 || spec.depth > 1)
    throw Error(ErrorCode::corrupt_input,
                path.string() + ": unsupported image shape " + std::to_string(spec.width) + "x" +
                    std::to_string(spec.height) + "x" + std::to_string(spec.nchannels) +
                    " (depth " + std::to_string(spec.depth) + ")");
  if (spec.nchannels > 64)
    throw Error(ErrorCode::corrupt_input, path.string() + ": " + std::to_string(spec.nchannels) +
                                              " channels (at most 64 are read)");
  return in;
}

// The decoded size is known from the header: a small file that would decode to gigabytes is
// refused before any pixel is allocated.
void check_decoded_size(const std::filesystem::path& path, const ImageHeader& spec) {
  const std::uint64_t pixels = std::uint64_t(spec.width) * std::uint64_t(spec.height);
  const std::uint64_t limit = max_decoded_pixels();
  if (pixels > limit) {
    char text[160];
    std::snprintf(text, sizeof text,
                  "%dx%d is %.1f megapixels, more than the limit of %.1f (raise it with "
                  "--max-megapixels)",
                  spec.width, spec.height, double(pixels) / 1e6, double(limit) / 1e6);
    throw Error(ErrorCode::corrupt_input, path.string() + ": " + text);
  }
}

std::size_t count_non_finite(const Image& image) {
  const auto px = image.pixels();
  return tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, px.size(), 1 << 16), std::size_t(0),
      [&](const tbb::blocked_range<std::size_t>& r, std::size_t n) {
        for (std::size_t i = r.begin(); i < r.end(); ++i) n += !std::isfinite(px[i]);
        return n;
      },
      std::plus<>());
}

// Grey images become RGB (alpha kept) so that colour code downstream sees three channels.
Image expand_grey(const Image& grey) {
  const bool alpha = grey.channels() == 2;
  Image rgb = Image::uninitialized(grey.width(), grey.height(), alpha ? 4 : 3);
  for (std::size_t i = 0; i < grey.pixel_count(); ++i) {
    const float* s = grey.data() + i * grey.channels();
    float* d = rgb.data() + i * rgb.channels();
    d[0] = d[1] = d[2] = s[0];
    if (alpha) d[3] = s[1];
  }
  rgb.metadata() = grey.metadata();
  return rgb;
}

// The stored pixels turned as EXIF Orientation `orientation` (2..8) says they are displayed:
// each displayed pixel (dx, dy) is the stored pixel (sx, sy) of the stored W x H image below.
// 2 mirrored left-right, 3 turned 180 degrees, 4 mirrored top-bottom, 5 transposed, 6 turned 90
// degrees clockwise, 7 transversed, 8 turned 90 degrees counter-clockwise (the same as
// OIIO::ImageBufAlgo::reorient). Exact: pixels are moved, never resampled.
Image reorient(const Image& stored, int orientation) {
  const int w = stored.width(), h = stored.height(), n = stored.channels();
  const bool swapped = orientation >= 5;
  const int dw = swapped ? h : w, dh = swapped ? w : h;
  Image out = Image::uninitialized(dw, dh, n, stored.channel_names());
  tbb::parallel_for(tbb::blocked_range<int>(0, dh), [&](const tbb::blocked_range<int>& rows) {
    for (int dy = rows.begin(); dy < rows.end(); ++dy)
      for (int dx = 0; dx < dw; ++dx) {
        int sx = dx, sy = dy;
        switch (orientation) {
          case 2: sx = w - 1 - dx, sy = dy; break;
          case 3: sx = w - 1 - dx, sy = h - 1 - dy; break;
          case 4: sx = dx, sy = h - 1 - dy; break;
          case 5: sx = dy, sy = dx; break;
          case 6: sx = dy, sy = h - 1 - dx; break;
          case 7: sx = w - 1 - dy, sy = h - 1 - dx; break;
          case 8: sx = w - 1 - dy, sy = dx; break;
          default: break;
        }
        std::copy_n(stored.pixel(sx, sy), n, out.pixel(dx, dy));
      }
  });
  out.metadata() = stored.metadata();
  return out;
}


void write_buf(const std::filesystem::path& path, ImageWriter& out, const ImageHeader& spec,
               detail::DataType data_type, const void* data, bool overwrite) {
  std::error_code ec;
  const auto folder = path.parent_path().empty() ? std::filesystem::path(".") : path.parent_path();
  if (!std::filesystem::is_directory(folder, ec))
    throw Error(ErrorCode::io, path.string() + ": output folder " + folder.string() +
                                   " does not exist");
  if (!overwrite && std::filesystem::exists(path, ec))
    throw Error(ErrorCode::io, path.string() + ": exists already (not overwriting)");
  detail::AtomicFile file(path);
  out.open(file.temp_path().string(), path.string(), spec);
  out.write_image(data_type, data);
  out.close();
  file.commit(overwrite);
}

}  // namespace

PixelType parse_pixel_type(const std::string& text) {
  const std::string t = lower(text);
  if (t == "8" || t == "uint8") return PixelType::uint8;
  if (t == "16" || t == "uint16") return PixelType::uint16;
  if (t == "half" || t == "f16") return PixelType::half;
  if (t == "float" || t == "32" || t == "f32" || t == "float32") return PixelType::float32;
  if (t == "auto" || t == "automatic") return PixelType::automatic;
  throw Error(ErrorCode::invalid_argument,
              "bit depth '" + text + "': expected 8, 16, half or float");
}

const char* to_string(PixelType type) noexcept {
  switch (type) {
    case PixelType::automatic: return "auto";
    case PixelType::uint8: return "8";
    case PixelType::uint16: return "16";
    case PixelType::half: return "half";
    case PixelType::float32: return "float";
  }
  return "?";
}

ImageFileInfo probe_image(const std::filesystem::path& path) {
  auto in = open_input(path);
  const auto& spec = in->spec();
  const int orientation = spec.get_int_attribute("Orientation", 1);
  ImageFileInfo info;
  info.width = spec.width;
  info.height = spec.height;
  info.channels = spec.nchannels;
  info.pixel_type = from_oiio(spec.format);
  info.format = in->format_name();
  info.orientation = orientation >= 1 && orientation <= 8 ? orientation : 1;
  info.software = spec.get_string_attribute("Software");
  return info;
}

std::uint64_t max_decoded_pixels() noexcept { return g_max_decoded_pixels.load(); }

void set_max_decoded_pixels(std::uint64_t pixels) noexcept {
  g_max_decoded_pixels.store(pixels > 0 ? pixels : kDefaultMaxDecodedPixels);
}

Image read_image(const std::filesystem::path& path, const ReadOptions& options) {
  auto in = open_input(path);
  const ImageHeader spec = in->spec();
  check_decoded_size(path, spec);
  const PixelType stored = from_oiio(spec.format);

  ColorConfig storage = ColorConfig::builtin();
  const ColorConfig& config = config_or_default(options.color, storage);
  std::string from = options.colorspace;
  if (options.to_scene_linear) {
    if (from.empty()) {
      const std::string tag = spec.get_string_attribute("oiio:ColorSpace");
      if (config.has_colorspace(tag) && !config.is_data(tag))
        from = tag;
      else
        from = is_integer(stored) ? colorspace::srgb : colorspace::scene_linear;
    } else if (!config.has_colorspace(from)) {
      throw Error(ErrorCode::color, path.string() + ": unknown input colour space '" + from +
                                        "' in OCIO config " + config.source());
    }
  }
  auto read_pixels = [&](detail::DataType type, void* data) { in->read_image(type, data); };

  Image image = Image::uninitialized(spec.width, spec.height, spec.nchannels, spec.channelnames);
  const int n = spec.nchannels;
  if (options.to_scene_linear && is_integer(stored) && n >= 3) {
    // Integer codes go through OCIO's lookup table straight into floats: no pow per value.
    // Scanline files are read strip by strip into the float image (issue 13: a 12000 x 12000
    // PNG or JPEG peaked at 1.25x its float image with a whole-frame copy of its codes, now
    // at the float image plus one strip); tiled ones whole.
    const int bits = stored == PixelType::uint8 ? 8 : 16;
    const std::size_t bytes = std::size_t(bits / 8);
    const detail::DataType code_type = bits == 8 ? detail::kTypeUInt8 : detail::kTypeUInt16;
    const std::size_t row_codes = std::size_t(spec.width) * std::size_t(n) * bytes;
    constexpr std::size_t kStripBytes = std::size_t(4) << 20;
    const int strip_rows =
        spec.tile_width > 0
            ? spec.height
            : int(std::clamp<std::size_t>(kStripBytes / row_codes, 16, std::size_t(spec.height)));
    std::vector<unsigned char> codes(std::size_t(strip_rows) * row_codes);
    const std::ptrdiff_t in_px = std::ptrdiff_t(n * bytes),
                         out_px = std::ptrdiff_t(n * sizeof(float));
    for (int y0 = 0; y0 < spec.height; y0 += strip_rows) {
      const int rows = std::min(strip_rows, spec.height - y0);
      if (strip_rows == spec.height) {
        read_pixels(code_type, codes.data());
      } else {
        in->read_scanlines(y0, y0 + rows, 0, n, code_type, codes.data());
      }
      float* out = image.data() + std::size_t(y0) * std::size_t(spec.width) * std::size_t(n);
      config.convert_pixels(codes.data(), bits, in_px, in_px * spec.width, out, 32, out_px,
                            out_px * spec.width, spec.width, rows, from, colorspace::scene_linear);
      if (n > 3) {  // alpha and other extra channels: normalised codes
        const double scale = 1.0 / (bits == 8 ? 255.0 : 65535.0);
        const auto* c8 = codes.data();
        const auto* c16 = reinterpret_cast<const std::uint16_t*>(codes.data());
        for (std::size_t i = 0; i < std::size_t(rows) * std::size_t(spec.width); ++i)
          for (int c = 3; c < n; ++c) {
            const std::size_t k = i * n + c;
            out[k] = float((bits == 8 ? c8[k] : c16[k]) * scale);
          }
      }
    }
  } else {
    read_pixels(detail::kTypeFloat, image.data());
    if (options.reject_non_finite)
      if (std::size_t bad = count_non_finite(image))
        throw Error(ErrorCode::corrupt_input, path.string() + ": " + std::to_string(bad) +
                                                  " pixel values are NaN or infinite");
    if (options.to_scene_linear) {
      if (n < 3) image = expand_grey(image);
      config.convert(image.view(), from, colorspace::scene_linear);
    }
  }
  in.reset();
  image.metadata().impl().attributes = spec.extra_attribs;
  if (options.to_scene_linear) drop_encoding_attributes(image.metadata().impl().attributes);
  const int orientation = spec.get_int_attribute("Orientation", 1);
  if (options.apply_orientation && orientation >= 2 && orientation <= 8) {
    image = reorient(image, orientation);
    auto& attrs = image.metadata().impl().attributes;
    // The pixels are now as displayed: a written copy must not be turned again.
    attrs.attribute("Orientation", 1);
    if (orientation >= 5) {
      const int px = spec.get_int_attribute("Exif:PixelXDimension", 0);
      const int py = spec.get_int_attribute("Exif:PixelYDimension", 0);
      if (px > 0 && py > 0) {
        attrs.attribute("Exif:PixelXDimension", py);
        attrs.attribute("Exif:PixelYDimension", px);
      }
    }
  }
  return image;
}

void write_image(const std::filesystem::path& path, const Image& image,
                 const WriteOptions& options) {
  if (image.empty()) throw Error(ErrorCode::invalid_argument, path.string() + ": image is empty");
  if (image.channels() > 4)
    throw Error(ErrorCode::invalid_argument,
                path.string() + ": write_image takes 1 to 4 channels, image has " +
                    std::to_string(image.channels()) + " (use write_exr_layers)");
  if (options.jpeg_quality < 1 || options.jpeg_quality > 100)
    throw Error(ErrorCode::invalid_argument,
                "jpeg quality " + std::to_string(options.jpeg_quality) + " is not in 1..100");
  const std::unique_ptr<ImageWriter> out = detail::create_image_writer(path);
  if (!out)
    throw Error(ErrorCode::invalid_argument,
                path.string() + ": no image format for extension '" + path.extension().string() + "'");
  const std::string format = out->format_name();

  const PixelType type = options.pixel_type == PixelType::automatic ? automatic_pixel_type(format)
                                                                    : options.pixel_type;
  if (!format_supports(format, type))
    throw Error(ErrorCode::invalid_argument, path.string() + ": " + format + " files cannot store " +
                                                 to_string(type) + "-bit pixels");

  ColorConfig storage = ColorConfig::builtin();
  const ColorConfig& config = config_or_default(options.color, storage);
  const std::string to =
      !options.colorspace.empty() ? options.colorspace
                                  : (is_integer(type) ? colorspace::srgb : colorspace::scene_linear);
  if (!config.has_colorspace(to))
    throw Error(ErrorCode::color, path.string() + ": unknown output colour space '" + to +
                                      "' in OCIO config " + config.source());

  // Encode: integer files get OCIO's clamped, rounded integer output directly.
  const int n = image.channels();
  const float* pixels = image.data();
  detail::DataType data_type = detail::kTypeFloat;
  const void* data = pixels;
  Image encoded;
  std::vector<unsigned char> codes;
  if (n >= 3 && is_integer(type)) {
    const int bits = type == PixelType::uint8 ? 8 : 16;
    const std::size_t bytes = std::size_t(bits / 8);
    codes.resize(image.pixels().size() * bytes);
    const std::ptrdiff_t in_px = std::ptrdiff_t(n * sizeof(float)), out_px = std::ptrdiff_t(n * bytes);
    config.convert_pixels(pixels, 32, in_px, in_px * image.width(), codes.data(), bits, out_px,
                          out_px * image.width(), image.width(), image.height(),
                          colorspace::scene_linear, to);
    const double max_code = bits == 8 ? 255.0 : 65535.0;
    auto* c16 = reinterpret_cast<std::uint16_t*>(codes.data());
    for (std::size_t i = 0; i < image.pixel_count(); ++i)
      for (int c = 3; c < n; ++c) {
        const std::size_t k = i * n + c;
        const double v = std::lround(std::clamp(double(pixels[k]), 0.0, 1.0) * max_code);
        if (bits == 8) codes[k] = static_cast<unsigned char>(v);
        else c16[k] = static_cast<std::uint16_t>(v);
      }
    data_type = bits == 8 ? detail::kTypeUInt8 : detail::kTypeUInt16;
    data = codes.data();
  } else if (n >= 3) {
    encoded = image;
    config.convert(encoded.view(), colorspace::scene_linear, to);
    data = encoded.data();
  }

  ImageHeader spec;
  spec.width = image.width(), spec.height = image.height(), spec.nchannels = image.channels();
  spec.format = stored_type(type);
  spec.channelnames = image.channel_names();
  if (image.channels() == 4) spec.alpha_channel = 3;
  spec.extra_attribs = image.metadata().impl().attributes;
  drop_encoding_attributes(spec.extra_attribs);
  spec.attribute("oiio:ColorSpace", to);
  if (format == "jpeg") {
    spec.attribute("Compression", "jpeg:" + std::to_string(options.jpeg_quality));
    // Full-resolution chroma: fog changes colour smoothly and 4:2:0 smears hue edges.
    spec.attribute("jpeg:subsampling", "4:4:4");
  }
  if (format == "openexr") spec.attribute("Compression", "zip");
  if (format == "tiff") spec.attribute("Compression", "zip");
  write_buf(path, *out, spec, data_type, data, options.overwrite);
}

void write_exr_layers(const std::filesystem::path& path, std::span<const ExrLayer> layers,
                      const Metadata& metadata, PixelType pixel_type) {
  if (layers.empty()) throw Error(ErrorCode::invalid_argument, path.string() + ": no layers");
  if (pixel_type != PixelType::half && pixel_type != PixelType::float32)
    throw Error(ErrorCode::invalid_argument,
                path.string() + ": EXR layers are half or float, not " + std::string(to_string(pixel_type)));
  const int width = layers[0].image->width(), height = layers[0].image->height();
  std::vector<std::string> names;
  for (const ExrLayer& layer : layers) {
    const Image& im = *layer.image;
    if (im.width() != width || im.height() != height)
      throw Error(ErrorCode::size_mismatch,
                  path.string() + ": layer '" + layer.name + "' is " + std::to_string(im.width()) +
                      "x" + std::to_string(im.height()) + ", expected " + std::to_string(width) +
                      "x" + std::to_string(height));
    for (const std::string& c : im.channel_names())
      names.push_back(layer.name.empty() ? c : layer.name + "." + c);
  }
  const int total = int(names.size());
  std::vector<float> interleaved(std::size_t(width) * height * total);
  int offset = 0;
  for (const ExrLayer& layer : layers) {
    const Image& im = *layer.image;
    const int n = im.channels();
    for (std::size_t i = 0; i < im.pixel_count(); ++i)
      for (int c = 0; c < n; ++c) interleaved[i * total + offset + c] = im.data()[i * n + c];
    offset += n;
  }
  ImageHeader spec;
  spec.width = width, spec.height = height, spec.nchannels = total;
  spec.format = stored_type(pixel_type);
  spec.channelnames = names;
  // Data layers (depth) must not be rounded to half: keep them float.
  spec.channelformats.assign(total, stored_type(pixel_type));
  offset = 0;
  for (const ExrLayer& layer : layers) {
    if (layer.is_data)
      for (int c = 0; c < layer.image->channels(); ++c)
        spec.channelformats[offset + c] = detail::kTypeFloat;
    offset += layer.image->channels();
  }
  spec.extra_attribs = metadata.impl().attributes;
  drop_encoding_attributes(spec.extra_attribs);
  spec.attribute("oiio:ColorSpace", "Linear");  // OIIO's tag for scene-linear Rec.709
  spec.attribute("Compression", "zip");
  if (path.extension() != ".exr" && path.extension() != ".EXR")
    throw Error(ErrorCode::invalid_argument, path.string() + ": layered output must be .exr");
  const std::unique_ptr<ImageWriter> out = detail::create_image_writer(path);
  write_buf(path, *out, spec, detail::kTypeFloat, interleaved.data(), true);
}

bool is_readable_image_extension(const std::filesystem::path& path) {
  return detail::is_readable_extension(path);
}

void check_output_path(const std::filesystem::path& path) { detail::check_output_target(path); }

void remove_unfinished_outputs() noexcept { detail::remove_temporaries_now(); }

bool is_writable_image_extension(const std::filesystem::path& path) {
  if (!is_readable_image_extension(path)) return false;
  return detail::create_image_writer(path) != nullptr;
}

}  // namespace mr
