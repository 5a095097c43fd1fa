#include "mr/color.h"

#include <OpenColorIO/OpenColorIO.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <map>
#include <mutex>
#include <sstream>
#include <tuple>
#include <type_traits>

#include "color_tables.h"
#include "mr/error.h"

namespace OCIO = OCIO_NAMESPACE;

namespace mr {

namespace detail {
extern const char* const kBuiltinOcioConfig;
}

namespace detail::conversion {
struct Conversion;
}

struct ColorConfig::Impl {
  OCIO::ConstConfigRcPtr config;
  std::string source;
  // convert_pixels' processors and tables, per (from, to, source bits, destination bits).
  mutable std::mutex conversions_mutex;
  mutable std::map<std::tuple<std::string, std::string, int, int>,
                   std::shared_ptr<detail::conversion::Conversion>>
      conversions;
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
      auto impl = std::make_shared<Impl>();
      impl->config = config;
      impl->source = "<builtin>";
      return std::shared_ptr<const Impl>(std::move(impl));
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
    auto impl = std::make_shared<Impl>();
    impl->config = config;
    impl->source = path.string();
    return ColorConfig(std::shared_ptr<const Impl>(std::move(impl)));
  } catch (const OCIO::Exception& e) {
    throw Error(ErrorCode::color, path.string() + ": cannot load OCIO config: " + e.what());
  }
}

ColorConfig ColorConfig::from_environment(const std::filesystem::path& explicit_path) {
  if (!explicit_path.empty()) return from_file(explicit_path);
  if (const char* env = std::getenv("OCIO"); env && *env) return from_file(env);
  return builtin();
}

const std::string& ColorConfig::source() const {
  return impl_->source;
}

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

// Names of their own (not anonymous: ColorConfig::Impl holds a Conversion).
namespace detail::conversion {

OCIO::BitDepth ocio_bit_depth(int bits) {
  switch (bits) {
    case 8:
      return OCIO::BIT_DEPTH_UINT8;
    case 16:
      return OCIO::BIT_DEPTH_UINT16;
    case 32:
      return OCIO::BIT_DEPTH_F32;
  }
  throw Error(ErrorCode::internal,
              "colour conversion: unsupported bit depth " + std::to_string(bits));
}

// A float's bits as a key in the floats' order (-inf < ... < -0 < +0 < ... < +inf), NaNs beyond
// both ends, so that a table can be indexed and searched by the bits.
std::uint32_t order_key(float v) {
  std::uint32_t bits;
  std::memcpy(&bits, &v, sizeof bits);
  return bits & 0x80000000u ? ~bits : bits | 0x80000000u;
}

float key_float(std::uint32_t key) {
  const std::uint32_t bits = key & 0x80000000u ? key & 0x7fffffffu : ~key;
  float v;
  std::memcpy(&v, &bits, sizeof v);
  return v;
}

// Tables that give OCIO's own results for a conversion without running its per-value
// arithmetic (for the sRGB encodings a powf per value, the half-domain LUT of srgb_rolloff per
// value: 35 % of a 2 MP batch's CPU, issue 12). Only for transforms without channel
// crosstalk (each output channel a function of its own input channel), where they are exact:
//  - integer input: OCIO's output for every code, per channel (256 or 65536 entries);
//  - float input, integer output: for a non-decreasing channel function the output code of x is
//    the lowest code plus the number of code steps at or below x. The steps (the smallest float
//    that reaches each code) are found by bisection on the floats' order with OCIO's processor
//    itself, so that every rounding and clamping is OCIO's; a bucket table on the float's upper
//    16 bits finds the first candidate step. Whether the function is non-decreasing is checked
//    when the tables are built, against OCIO on 2^17 floats spread over the whole range and on
//    both sides of every step; where it is not, the conversion stays with OCIO.
// Float to float conversions stay with OCIO (they are not on the 8/16-bit file paths).
struct Tables {
  int src_bits = 0, dst_bits = 0;
  std::array<std::vector<float>, 3> codes_to_float;          // integer in, float out
  std::array<std::vector<std::uint16_t>, 3> codes_to_codes;  // integer in, integer out
  // Float in: per channel the sorted step keys, padded with most_steps + 4 keys above every
  // float; per bucket (key >> 16) the index of its first step; at most `most_steps` steps lie
  // in one bucket (1 or 2 for 8-bit sRGB outputs), so a fixed number of comparisons counts them.
  std::array<std::vector<std::uint32_t>, 3> steps;
  std::array<std::vector<std::uint32_t>, 3> first_step;
  std::array<std::uint16_t, 3> lowest_code{}, nan_code{};
  std::uint32_t most_steps = 0;

  // OCIO's code for v in channel c; kSteps: most_steps when small and known (0: search).
  template <int kSteps>
  std::uint16_t encode(int c, float v) const {
    if (v != v) return nan_code[c];
    std::uint32_t bits;
    std::memcpy(&bits, &v, sizeof bits);
    const std::uint32_t key = bits ^ (std::uint32_t(std::int32_t(bits) >> 31) | 0x80000000u);
    const std::uint32_t* s = steps[c].data();
    const std::uint32_t first = first_step[c][key >> 16];
    std::uint32_t count = 0;
    if constexpr (kSteps > 0) {
      for (int j = 0; j < kSteps; ++j) count += s[first + j] <= key;
    } else {
      count = std::uint32_t(std::upper_bound(s + first, s + first + most_steps, key) - (s + first));
    }
    return std::uint16_t(lowest_code[c] + first + count);
  }
};

// One conversion: OCIO's processor, and the tables once enough pixels went through it to pay
// for building them (they give the same values, so when they start does not matter).
struct Conversion {
  OCIO::ConstCPUProcessorRcPtr cpu;
  bool no_op = false;
  bool tables_apply = false;  // no channel crosstalk, and a table kind exists for the bit depths
  std::size_t build_after_pixels = 0;
  std::atomic<std::size_t> pixels_seen{0};
  std::mutex build_mutex;
  std::atomic<bool> tables_tried{false};
  std::shared_ptr<const Tables> tables;  // set under build_mutex before tables_tried
};

}  // namespace detail::conversion

namespace {

using detail::conversion::Conversion;
using detail::conversion::key_float;
using detail::conversion::ocio_bit_depth;
using detail::conversion::order_key;
using detail::conversion::Tables;

// OCIO on a row of RGB pixels (packed, no alpha).
void apply_row(const OCIO::CPUProcessor& cpu, void* in, int in_bits, void* out, int out_bits,
               long pixels) {
  OCIO::PackedImageDesc in_desc(in, pixels, 1, 3, ocio_bit_depth(in_bits), in_bits / 8,
                                3 * (in_bits / 8), 3 * (in_bits / 8) * pixels);
  OCIO::PackedImageDesc out_desc(out, pixels, 1, 3, ocio_bit_depth(out_bits), out_bits / 8,
                                 3 * (out_bits / 8), 3 * (out_bits / 8) * pixels);
  cpu.apply(in_desc, out_desc);
}

std::shared_ptr<const Tables> build_tables(const OCIO::CPUProcessor& cpu, int src_bits,
                                           int dst_bits) {
  auto t = std::make_shared<Tables>();
  t->src_bits = src_bits;
  t->dst_bits = dst_bits;
  if (src_bits != 32) {
    const long codes = 1L << src_bits;
    std::vector<std::uint16_t> in(std::size_t(codes) * 3);
    for (long k = 0; k < codes; ++k)
      for (int c = 0; c < 3; ++c) in[std::size_t(k) * 3 + c] = std::uint16_t(k);
    std::vector<unsigned char> in8(in.begin(), in.end());
    void* in_data = src_bits == 8 ? static_cast<void*>(in8.data()) : in.data();
    if (dst_bits == 32) {
      std::vector<float> out(std::size_t(codes) * 3);
      apply_row(cpu, in_data, src_bits, out.data(), 32, codes);
      for (int c = 0; c < 3; ++c) {
        t->codes_to_float[c].resize(std::size_t(codes));
        for (long k = 0; k < codes; ++k) t->codes_to_float[c][k] = out[std::size_t(k) * 3 + c];
      }
    } else {
      std::vector<std::uint16_t> out16(std::size_t(codes) * 3);
      std::vector<unsigned char> out8(std::size_t(codes) * 3);
      apply_row(cpu, in_data, src_bits,
                dst_bits == 8 ? static_cast<void*>(out8.data()) : out16.data(), dst_bits, codes);
      for (int c = 0; c < 3; ++c) {
        t->codes_to_codes[c].resize(std::size_t(codes));
        for (long k = 0; k < codes; ++k) {
          const std::size_t i = std::size_t(k) * 3 + c;
          t->codes_to_codes[c][k] = dst_bits == 8 ? out8[i] : out16[i];
        }
      }
    }
    return t;
  }

  // Float in, integer out. OCIO's code for keys (one per channel lane; n pixels).
  const int out_bytes = dst_bits / 8;
  auto codes_of = [&](const std::vector<float>& values, std::vector<std::uint16_t>& codes) {
    const long n = long(values.size() / 3);
    std::vector<unsigned char> out(values.size() * std::size_t(out_bytes));
    std::vector<float> in = values;  // OCIO's descriptor is not const
    apply_row(cpu, in.data(), 32, out.data(), dst_bits, n);
    codes.resize(values.size());
    for (std::size_t i = 0; i < values.size(); ++i) {
      if (dst_bits == 8) {
        codes[i] = out[i];
      } else {
        std::uint16_t v;
        std::memcpy(&v, out.data() + 2 * i, 2);
        codes[i] = v;
      }
    }
  };
  const float inf = std::numeric_limits<float>::infinity();
  const std::uint32_t key_lo = order_key(-inf), key_hi = order_key(inf);
  std::vector<std::uint16_t> ends;
  codes_of({-inf, -inf, -inf, inf, inf, inf, std::nanf(""), std::nanf(""), std::nanf("")}, ends);
  std::array<int, 3> steps_of{};
  for (int c = 0; c < 3; ++c) {
    t->lowest_code[c] = ends[c];
    t->nan_code[c] = ends[6 + c];
    if (ends[3 + c] < ends[c]) return nullptr;  // decreasing: not for these tables
    steps_of[c] = ends[3 + c] - ends[c];
  }
  // Bisection for every step of every channel at once: step k of channel c is the smallest key
  // whose code is above lowest + k. Invariant: code(lo) <= lowest + k < code(hi).
  const int n = *std::max_element(steps_of.begin(), steps_of.end());
  std::vector<std::uint32_t> lo(std::size_t(n) * 3, key_lo), hi(std::size_t(n) * 3, key_hi);
  std::vector<float> probe(std::size_t(n) * 3);
  std::vector<std::uint16_t> codes;
  for (int iteration = 0; iteration < 33; ++iteration) {
    bool open = false;
    for (std::size_t i = 0; i < probe.size(); ++i) {
      const std::uint32_t mid = lo[i] + (hi[i] - lo[i]) / 2;
      open |= hi[i] - lo[i] > 1;
      probe[i] = key_float(mid);
    }
    if (!open) break;
    codes_of(probe, codes);
    for (std::size_t i = 0; i < probe.size(); ++i) {
      if (hi[i] - lo[i] <= 1) continue;
      const std::size_t k = i / 3;
      const int c = int(i % 3);
      const std::uint32_t mid = lo[i] + (hi[i] - lo[i]) / 2;
      (codes[i] > t->lowest_code[c] + k ? hi[i] : lo[i]) = mid;
    }
  }
  for (int c = 0; c < 3; ++c) {
    std::vector<std::uint32_t>& s = t->steps[c];
    for (int k = 0; k < steps_of[c]; ++k) s.push_back(hi[std::size_t(k) * 3 + c]);
    if (!std::is_sorted(s.begin(), s.end())) return nullptr;
    t->first_step[c].resize(65536);
    for (std::uint32_t b = 0; b < 65536; ++b) {
      t->first_step[c][b] =
          std::uint32_t(std::lower_bound(s.begin(), s.end(), b << 16) - s.begin());
      if (b > 0)
        t->most_steps = std::max(t->most_steps, t->first_step[c][b] - t->first_step[c][b - 1]);
    }
    t->most_steps = std::max(t->most_steps, std::uint32_t(s.size()) - t->first_step[c][65535]);
  }
  // Keys above every float (and above NaN's keys, which never reach the tables) end each list,
  // so that the comparisons past a channel's last step read a key and count nothing.
  for (int c = 0; c < 3; ++c)
    t->steps[c].resize(t->steps[c].size() + t->most_steps + 4, 0xffffffffu);
  // The check that the channel functions are non-decreasing, where the steps alone cannot
  // tell: OCIO against the tables at two keys per bucket and on both sides of every step.
  std::vector<float> check;
  auto add = [&](std::uint32_t key) {
    if (key < key_lo || key > key_hi) return;
    const float v = key_float(key);
    check.insert(check.end(), {v, v, v});
  };
  for (std::uint32_t b = 0; b < 65536; ++b) add(b << 16), add(b << 16 | 0x8000u);
  for (int c = 0; c < 3; ++c)
    for (std::size_t k = 0; k < std::size_t(steps_of[c]); ++k)
      add(t->steps[c][k]), add(t->steps[c][k] - 1);
  codes_of(check, codes);
  for (std::size_t i = 0; i < check.size(); ++i)
    if (t->encode<0>(int(i % 3), check[i]) != codes[i]) return nullptr;
  return t;
}

// The tables on rows [y0, y1): one loop per kind, so that the compiler sees the types.
template <class In, class Out, class Convert>
void table_rows(const void* src, std::ptrdiff_t src_pixel_bytes, std::ptrdiff_t src_row_bytes,
                void* dst, std::ptrdiff_t dst_pixel_bytes, std::ptrdiff_t dst_row_bytes, int width,
                int y0, int y1, Convert convert) {
  for (int y = y0; y < y1; ++y) {
    const char* in = static_cast<const char*>(src) + y * src_row_bytes;
    char* out = static_cast<char*>(dst) + y * dst_row_bytes;
    for (int x = 0; x < width; ++x, in += src_pixel_bytes, out += dst_pixel_bytes) {
      In v[3];
      std::memcpy(v, in, sizeof v);
      const Out o[3] = {convert(0, v[0]), convert(1, v[1]), convert(2, v[2])};
      std::memcpy(out, o, sizeof o);
    }
  }
}

template <class Out>
void encode_rows(const Tables& t, const void* src, std::ptrdiff_t sp, std::ptrdiff_t sr, void* dst,
                 std::ptrdiff_t dp, std::ptrdiff_t dr, int width, int y0, int y1) {
  auto rows = [&](auto steps) {
    constexpr int kSteps = decltype(steps)::value;
    table_rows<float, Out>(src, sp, sr, dst, dp, dr, width, y0, y1,
                           [&](int c, float v) { return Out(t.encode<kSteps>(c, v)); });
  };
  switch (t.most_steps) {
    case 0:
    case 1:
      rows(std::integral_constant<int, 1>());
      break;
    case 2:
      rows(std::integral_constant<int, 2>());
      break;
    case 3:
    case 4:
      rows(std::integral_constant<int, 4>());
      break;
    default:
      rows(std::integral_constant<int, 0>());
  }
}

template <class In>
void decode_rows(const Tables& t, const void* src, std::ptrdiff_t sp, std::ptrdiff_t sr, void* dst,
                 std::ptrdiff_t dp, std::ptrdiff_t dr, int width, int y0, int y1) {
  if (t.dst_bits == 32) {
    const float* lut[3] = {t.codes_to_float[0].data(), t.codes_to_float[1].data(),
                           t.codes_to_float[2].data()};
    table_rows<In, float>(src, sp, sr, dst, dp, dr, width, y0, y1,
                          [&](int c, In k) { return lut[c][k]; });
  } else {
    const std::uint16_t* lut[3] = {t.codes_to_codes[0].data(), t.codes_to_codes[1].data(),
                                   t.codes_to_codes[2].data()};
    if (t.dst_bits == 8)
      table_rows<In, std::uint8_t>(src, sp, sr, dst, dp, dr, width, y0, y1,
                                   [&](int c, In k) { return std::uint8_t(lut[c][k]); });
    else
      table_rows<In, std::uint16_t>(src, sp, sr, dst, dp, dr, width, y0, y1,
                                    [&](int c, In k) { return lut[c][k]; });
  }
}

void apply_tables(const Tables& t, const void* src, std::ptrdiff_t sp, std::ptrdiff_t sr, void* dst,
                  std::ptrdiff_t dp, std::ptrdiff_t dr, int width, int y0, int y1) {
  if (t.src_bits == 32 && t.dst_bits == 8)
    encode_rows<std::uint8_t>(t, src, sp, sr, dst, dp, dr, width, y0, y1);
  else if (t.src_bits == 32)
    encode_rows<std::uint16_t>(t, src, sp, sr, dst, dp, dr, width, y0, y1);
  else if (t.src_bits == 8)
    decode_rows<std::uint8_t>(t, src, sp, sr, dst, dp, dr, width, y0, y1);
  else
    decode_rows<std::uint16_t>(t, src, sp, sr, dst, dp, dr, width, y0, y1);
}

}  // namespace

void ColorConfig::convert(ImageView rgb, const std::string& from, const std::string& to) const {
  if (rgb.channels < 3)
    throw Error(ErrorCode::color, "colour conversion " + from + " -> " + to +
                                      " needs 3 channels, image has " +
                                      std::to_string(rgb.channels));
  const std::ptrdiff_t px = std::ptrdiff_t(rgb.channels) * sizeof(float);
  const std::ptrdiff_t row = rgb.row_stride * std::ptrdiff_t(sizeof(float));
  convert_pixels(rgb.data, 32, px, row, rgb.data, 32, px, row, rgb.width, rgb.height, from, to);
}

namespace {

std::shared_ptr<Conversion> find_conversion(const ColorConfig::Impl& impl, const std::string& from,
                                            const std::string& to, int src_bits, int dst_bits) {
  std::lock_guard lock(impl.conversions_mutex);
  auto& slot = impl.conversions[{from, to, src_bits, dst_bits}];
  if (slot) return slot;
  auto conversion = std::make_shared<Conversion>();
  try {
    auto processor = impl.config->getProcessor(from.c_str(), to.c_str());
    conversion->no_op = processor->isNoOp();
    // For integer input OCIO bakes the whole transform into a lookup table.
    conversion->cpu = processor->getOptimizedCPUProcessor(
        ocio_bit_depth(src_bits), ocio_bit_depth(dst_bits), OCIO::OPTIMIZATION_DEFAULT);
    conversion->tables_apply =
        !processor->hasChannelCrosstalk() && !(src_bits == 32 && dst_bits == 32);
  } catch (const OCIO::Exception& e) {
    throw Error(ErrorCode::color, "colour conversion " + from + " -> " + to + ": " + e.what());
  }
  // Building costs about as many OCIO evaluations as this many pixels (a few ms at most).
  conversion->build_after_pixels = src_bits == 8    ? 1024
                                   : src_bits == 16 ? 65536
                                   : dst_bits == 8  ? 65536
                                                    : 2 * 65536 * 33;
  slot = conversion;
  return slot;
}

// The tables for `conversion` once it has converted enough pixels, else nullptr (use OCIO).
std::shared_ptr<const Tables> tables_for(Conversion& conversion, std::size_t pixels, int src_bits,
                                         int dst_bits, bool force) {
  if (!conversion.tables_apply) return nullptr;
  const std::size_t seen = conversion.pixels_seen.fetch_add(pixels) + pixels;
  if (!force && seen < conversion.build_after_pixels) return nullptr;
  if (!conversion.tables_tried.load(std::memory_order_acquire)) {
    std::lock_guard lock(conversion.build_mutex);
    if (!conversion.tables_tried.load(std::memory_order_relaxed)) {
      try {
        conversion.tables = build_tables(*conversion.cpu, src_bits, dst_bits);
      } catch (const OCIO::Exception&) {
        conversion.tables = nullptr;  // OCIO will report it on the pixels themselves
      }
      conversion.tables_tried.store(true, std::memory_order_release);
    }
  }
  return conversion.tables;
}

}  // namespace

namespace detail {

namespace {
thread_local ConversionPath this_thread_path = ConversionPath::automatic;
thread_local bool this_thread_used_tables = false;
}  // namespace

ScopedConversionPath::ScopedConversionPath(ConversionPath path) : previous_(this_thread_path) {
  this_thread_path = path;
}
ScopedConversionPath::~ScopedConversionPath() {
  this_thread_path = previous_;
}
bool last_conversion_used_tables() {
  return this_thread_used_tables;
}

}  // namespace detail

void ColorConfig::convert_pixels(const void* src, int src_bits, std::ptrdiff_t src_pixel_bytes,
                                 std::ptrdiff_t src_row_bytes, void* dst, int dst_bits,
                                 std::ptrdiff_t dst_pixel_bytes, std::ptrdiff_t dst_row_bytes,
                                 int width, int height, const std::string& from,
                                 const std::string& to) const {
  using detail::ConversionPath;
  const ConversionPath path = detail::this_thread_path;
  detail::this_thread_used_tables = false;
  for (const std::string* name : {&from, &to})
    if (!has_colorspace(*name))
      throw Error(ErrorCode::color,
                  "unknown colour space '" + *name + "' in OCIO config " + source());
  const OCIO::BitDepth in_depth = ocio_bit_depth(src_bits), out_depth = ocio_bit_depth(dst_bits);
  if (width <= 0 || height <= 0) return;
  const std::shared_ptr<Conversion> conversion =
      find_conversion(*impl_, from, to, src_bits, dst_bits);
  if (conversion->no_op && src == dst && src_bits == dst_bits) return;
  const std::shared_ptr<const Tables> tables =
      path == ConversionPath::ocio
          ? nullptr
          : tables_for(*conversion, std::size_t(width) * std::size_t(height), src_bits, dst_bits,
                       path == ConversionPath::tables);
  const OCIO::CPUProcessor& cpu = *conversion->cpu;
  const std::ptrdiff_t in_chan = src_bits / 8, out_chan = dst_bits / 8;
  tbb::parallel_for(tbb::blocked_range<int>(0, height, 16), [&](const tbb::blocked_range<int>& r) {
    if (tables) {
      apply_tables(*tables, src, src_pixel_bytes, src_row_bytes, dst, dst_pixel_bytes,
                   dst_row_bytes, width, r.begin(), r.end());
      return;
    }
    const long rows = long(r.size());
    auto* in_row = static_cast<const char*>(src) + r.begin() * src_row_bytes;
    auto* out_row = static_cast<char*>(dst) + r.begin() * dst_row_bytes;
    OCIO::PackedImageDesc in(const_cast<char*>(in_row), width, rows, 3, in_depth, in_chan,
                             src_pixel_bytes, src_row_bytes);
    OCIO::PackedImageDesc out(out_row, width, rows, 3, out_depth, out_chan, dst_pixel_bytes,
                              dst_row_bytes);
    cpu.apply(in, out);
  });
  detail::this_thread_used_tables = tables != nullptr;
}

}  // namespace mr
