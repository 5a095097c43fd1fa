#include "mr/color.h"

#include <OpenColorIO/OpenColorIO.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <sstream>

#include "mr/error.h"

namespace OCIO = OCIO_NAMESPACE;

namespace mr {

namespace detail {
extern const char* const kBuiltinOcioConfig;
}

struct ColorConfig::Impl {
  OCIO::ConstConfigRcPtr config;
  std::string source;
};

ColorConfig::ColorConfig(std::shared_ptr<const Impl> impl) : impl_(std::move(impl)) {}

double highlight_rolloff(double x, double knee) {
  if (!(x > knee)) return x;  // NaN passes through
  if (std::isinf(x)) return 1.0;
  const double u = (x - knee) / (1 - knee);
  return knee + (1 - knee) * u / (1 + u);
}

double highlight_rolloff_inverse(double y, double knee) {
  if (!(y > knee)) return y;
  if (y >= 1) return std::numeric_limits<double>::infinity();
  const double t = (y - knee) / (1 - knee);  // = u / (1 + u)
  return knee + (1 - knee) * t / (1 - t);
}

namespace {

float half_bits_to_float(std::uint16_t h) {
  const std::uint32_t sign = std::uint32_t(h & 0x8000u) << 16;
  const int exponent = (h >> 10) & 0x1f;
  std::uint32_t mantissa = h & 0x3ffu;
  std::uint32_t bits;
  if (exponent == 0) {
    if (mantissa == 0) {
      bits = sign;
    } else {  // subnormal: renormalise
      int e = -1;
      do {
        ++e;
        mantissa <<= 1;
      } while ((mantissa & 0x400u) == 0);
      bits = sign | std::uint32_t(127 - 15 - e) << 23 | (mantissa & 0x3ffu) << 13;
    }
  } else if (exponent == 31) {
    bits = sign | 0x7f800000u | mantissa << 13;
  } else {
    bits = sign | std::uint32_t(exponent - 15 + 127) << 23 | mantissa << 13;
  }
  float f;
  std::memcpy(&f, &bits, sizeof f);
  return f;
}

// The srgb_rolloff colour space: a half-domain 1D LUT (65536 entries, one per half-float code,
// so it covers every value without a shaper; OCIO interpolates between neighbouring codes, which
// is exact on the identity part) with highlight_rolloff, then the sRGB encoding. A LUT cannot be
// written in an OCIO 2.1 config file without a LUT file beside it, so it is built here.
OCIO::ColorSpaceRcPtr make_rolloff_colorspace() {
  auto lut = OCIO::Lut1DTransform::Create(65536, true);
  for (std::uint32_t i = 0; i < 65536; ++i) {
    const float x = half_bits_to_float(std::uint16_t(i));
    const float y = std::isnan(x) ? 0.0f : float(highlight_rolloff(x));
    lut->setValue(i, y, y, y);
  }
  auto encode = OCIO::ExponentWithLinearTransform::Create();
  encode->setGamma({2.4, 2.4, 2.4, 1.0});
  encode->setOffset({0.055, 0.055, 0.055, 0.0});
  encode->setDirection(OCIO::TRANSFORM_DIR_INVERSE);
  auto group = OCIO::GroupTransform::Create();
  group->appendTransform(lut);
  group->appendTransform(encode);
  auto cs = OCIO::ColorSpace::Create(OCIO::REFERENCE_SPACE_SCENE);
  cs->setName("sRGB - Roll-off");
  cs->addAlias(colorspace::srgb_rolloff);
  cs->setFamily("Display-encoded");
  cs->setBitDepth(OCIO::BIT_DEPTH_UINT8);
  cs->setDescription(
      "sRGB encoding after a highlight roll-off: identity up to 0.8 scene-linear, then "
      "0.8 + 0.2 u / (1 + u), u = (x - 0.8) / 0.2 (libmr, mr/color.h highlight_rolloff)");
  cs->setTransform(group, OCIO::COLORSPACE_DIR_FROM_REFERENCE);
  return cs;
}

}  // namespace

ColorConfig ColorConfig::builtin() {
  // Parsed once; OCIO configs are immutable and thread-safe once loaded.
  static const std::shared_ptr<const Impl> impl = [] {
    std::istringstream text(detail::kBuiltinOcioConfig);
    try {
      OCIO::ConfigRcPtr config = OCIO::Config::CreateFromStream(text)->createEditableCopy();
      config->addColorSpace(make_rolloff_colorspace());
      config->addDisplayView("sRGB", "Roll-off", "sRGB - Roll-off", "");
      config->setActiveViews("sRGB, Roll-off, Raw");
      config->validate();
      return std::make_shared<const Impl>(Impl{config, "<builtin>"});
    } catch (const OCIO::Exception& e) {
      throw Error(ErrorCode::internal, std::string("builtin OCIO config: ") + e.what());
    }
  }();
  return ColorConfig(impl);
}

ColorConfig ColorConfig::from_file(const std::filesystem::path& path) {
  try {
    auto config = OCIO::Config::CreateFromFile(path.c_str());
    config->validate();
    return ColorConfig(std::make_shared<const Impl>(Impl{config, path.string()}));
  } catch (const OCIO::Exception& e) {
    throw Error(ErrorCode::color, path.string() + ": cannot load OCIO config: " + e.what());
  }
}

ColorConfig ColorConfig::from_environment(const std::filesystem::path& explicit_path) {
  if (!explicit_path.empty()) return from_file(explicit_path);
  if (const char* env = std::getenv("OCIO"); env && *env) return from_file(env);
  return builtin();
}

const std::string& ColorConfig::source() const { return impl_->source; }

std::vector<std::string> ColorConfig::colorspace_names() const {
  std::vector<std::string> names;
  const auto& c = *impl_->config;
  for (int i = 0; i < c.getNumColorSpaces(); ++i) names.emplace_back(c.getColorSpaceNameByIndex(i));
  return names;
}

bool ColorConfig::has_colorspace(const std::string& name) const {
  return !name.empty() && impl_->config->getColorSpace(name.c_str()) != nullptr;
}

bool ColorConfig::is_data(const std::string& name) const {
  auto cs = impl_->config->getColorSpace(name.c_str());
  return cs && cs->isData();
}

const char* ColorConfig::display_colorspace() const {
  return has_colorspace(colorspace::srgb_rolloff) ? colorspace::srgb_rolloff : colorspace::srgb;
}

namespace {

OCIO::BitDepth ocio_bit_depth(int bits) {
  switch (bits) {
    case 8: return OCIO::BIT_DEPTH_UINT8;
    case 16: return OCIO::BIT_DEPTH_UINT16;
    case 32: return OCIO::BIT_DEPTH_F32;
  }
  throw Error(ErrorCode::internal, "colour conversion: unsupported bit depth " + std::to_string(bits));
}

}  // namespace

void ColorConfig::convert(ImageView rgb, const std::string& from, const std::string& to) const {
  if (rgb.channels < 3)
    throw Error(ErrorCode::color, "colour conversion " + from + " -> " + to +
                                      " needs 3 channels, image has " + std::to_string(rgb.channels));
  const std::ptrdiff_t px = std::ptrdiff_t(rgb.channels) * sizeof(float);
  const std::ptrdiff_t row = rgb.row_stride * std::ptrdiff_t(sizeof(float));
  convert_pixels(rgb.data, 32, px, row, rgb.data, 32, px, row, rgb.width, rgb.height, from, to);
}

void ColorConfig::convert_pixels(const void* src, int src_bits, std::ptrdiff_t src_pixel_bytes,
                                 std::ptrdiff_t src_row_bytes, void* dst, int dst_bits,
                                 std::ptrdiff_t dst_pixel_bytes, std::ptrdiff_t dst_row_bytes,
                                 int width, int height, const std::string& from,
                                 const std::string& to) const {
  for (const std::string* name : {&from, &to})
    if (!has_colorspace(*name))
      throw Error(ErrorCode::color,
                  "unknown colour space '" + *name + "' in OCIO config " + source());
  if (width <= 0 || height <= 0) return;
  const OCIO::BitDepth in_depth = ocio_bit_depth(src_bits), out_depth = ocio_bit_depth(dst_bits);
  OCIO::ConstCPUProcessorRcPtr cpu;
  try {
    auto processor = impl_->config->getProcessor(from.c_str(), to.c_str());
    if (processor->isNoOp() && src == dst && src_bits == dst_bits) return;
    // For integer input OCIO bakes the whole transform into a lookup table.
    cpu = processor->getOptimizedCPUProcessor(in_depth, out_depth, OCIO::OPTIMIZATION_DEFAULT);
  } catch (const OCIO::Exception& e) {
    throw Error(ErrorCode::color, "colour conversion " + from + " -> " + to + ": " + e.what());
  }
  const std::ptrdiff_t in_chan = src_bits / 8, out_chan = dst_bits / 8;
  tbb::parallel_for(tbb::blocked_range<int>(0, height, 16), [&](const tbb::blocked_range<int>& r) {
    const long rows = long(r.size());
    auto* in_row = static_cast<const char*>(src) + r.begin() * src_row_bytes;
    auto* out_row = static_cast<char*>(dst) + r.begin() * dst_row_bytes;
    OCIO::PackedImageDesc in(const_cast<char*>(in_row), width, rows, 3, in_depth, in_chan,
                             src_pixel_bytes, src_row_bytes);
    OCIO::PackedImageDesc out(out_row, width, rows, 3, out_depth, out_chan, dst_pixel_bytes,
                              dst_row_bytes);
    cpu->apply(in, out);
  });
}

}  // namespace mr
