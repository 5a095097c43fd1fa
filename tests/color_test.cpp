#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <random>
#include <vector>

#include "libmr/src/color_tables.h"
#include "mr/color.h"
#include "mr/error.h"
#include "test_support.h"

namespace mr {
namespace {

// IEC 61966-2-1.
std::filesystem::path fs_source() {
  return std::filesystem::path(MR_SOURCE_DIR);
}

double srgb_to_linear(double v) {
  return v <= 0.04045 ? v / 12.92 : std::pow((v + 0.055) / 1.055, 2.4);
}

TEST(Color, BuiltinConfigHasTheRolesAndSpaces) {
  ColorConfig c = ColorConfig::builtin();
  EXPECT_EQ(c.source(), "<builtin>");
  for (const char* name : {colorspace::scene_linear, colorspace::srgb, colorspace::acescg,
                           colorspace::raw, "sRGB", "linear", "data"})
    EXPECT_TRUE(c.has_colorspace(name)) << name;
  EXPECT_TRUE(c.is_data(colorspace::raw));
  EXPECT_FALSE(c.is_data(colorspace::srgb));
  EXPECT_FALSE(c.has_colorspace("no such space"));
}

TEST(Color, SrgbDecodeMatchesTheFormulaAndRoundTrips) {
  ColorConfig c = ColorConfig::builtin();
  const int n = 4096;
  Image im(n, 1, 3);
  for (int i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) im.at(i, 0, k) = float(i) / (n - 1);
  Image lin = im;
  c.convert(lin.view(), colorspace::srgb, colorspace::scene_linear);
  double worst_formula = 0, worst_round_trip = 0;
  Image back = lin;
  c.convert(back.view(), colorspace::scene_linear, colorspace::srgb);
  for (int i = 0; i < n; ++i) {
    const double v = double(i) / (n - 1);
    worst_formula = std::max(worst_formula, std::fabs(lin.at(i, 0, 1) - srgb_to_linear(v)));
    worst_round_trip = std::max(worst_round_trip, std::fabs(double(back.at(i, 0, 2)) - v));
  }
  // Tolerances from the issue: round trip below 1e-5; formula to float precision.
  EXPECT_LT(worst_round_trip, 1e-5);
  EXPECT_LT(worst_formula, 1e-5);
  EXPECT_NEAR(lin.at(n - 1, 0, 0), 1.0, 1e-6);
  EXPECT_EQ(lin.at(0, 0, 0), 0.0f);
}

TEST(Color, AcesCgKeepsWhiteAndRoundTrips) {
  ColorConfig c = ColorConfig::builtin();
  Image im(3, 1, 3);
  const float values[9] = {1, 1, 1, 1, 0, 0, 0.2f, 0.5f, 0.9f};
  std::copy(values, values + 9, im.data());
  Image aces = im;
  c.convert(aces.view(), colorspace::scene_linear, colorspace::acescg);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(aces.at(0, 0, k), 1.0, 1e-5);  // D65 white stays white
  // Pure Rec.709 red in AP1 (first column of the Bradford-adapted matrix).
  EXPECT_NEAR(aces.at(1, 0, 0), 0.6131, 1e-4);
  EXPECT_NEAR(aces.at(1, 0, 1), 0.0702, 1e-4);
  EXPECT_NEAR(aces.at(1, 0, 2), 0.0206, 1e-4);
  c.convert(aces.view(), colorspace::acescg, colorspace::scene_linear);
  EXPECT_LT(test::max_abs_diff(aces, im), 1e-5);
}

TEST(Color, ExtraChannelsAreLeftAlone) {
  ColorConfig c = ColorConfig::builtin();
  Image im(2, 2, 4);
  for (float& v : im.pixels()) v = 0.5f;
  c.convert(im.view(), colorspace::srgb, colorspace::scene_linear);
  EXPECT_NEAR(im.at(1, 1, 0), srgb_to_linear(0.5), 1e-6);
  EXPECT_EQ(im.at(1, 1, 3), 0.5f);
}

TEST(Color, UnknownSpacesAndBadConfigsAreClearErrors) {
  ColorConfig c = ColorConfig::builtin();
  Image im(2, 2, 3);
  try {
    c.convert(im.view(), "nope", colorspace::scene_linear);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::color);
    EXPECT_NE(std::string(e.what()).find("'nope'"), std::string::npos) << e.what();
  }
  test::ScratchDir dir;
  test::write_bytes(dir / "bad.ocio", "this is: [not an ocio config");
  try {
    ColorConfig::from_file(dir / "bad.ocio");
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::color);
    EXPECT_NE(std::string(e.what()).find("bad.ocio"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ColorConfig::from_file(dir / "missing.ocio"), Error);
}

TEST(Color, HonoursTheOcioEnvironmentVariable) {
  test::ScratchDir dir;
  const auto path = dir / "config.ocio";
  // The shipped config file itself, loaded from disk.
  test::write_bytes(
      path, test::read_bytes(std::filesystem::path(MR_SOURCE_DIR) / "libmr/data/config.ocio"));
  ::setenv("OCIO", path.c_str(), 1);
  ColorConfig from_env = ColorConfig::from_environment();
  ::unsetenv("OCIO");
  EXPECT_EQ(from_env.source(), path.string());
  EXPECT_TRUE(from_env.has_colorspace(colorspace::acescg));
  EXPECT_EQ(ColorConfig::from_environment().source(), "<builtin>");
  EXPECT_EQ(ColorConfig::from_environment(path).source(), path.string());
}

// convert_pixels' tables (issue 12) against OCIO's processor on every pixel: integer codes in
// (all 256 / 65536 codes, each channel its own code) and a float sweep out (every exponent,
// both signs, the steps between codes, denormals, inf, NaN). Tolerances from the issue: 0.5
// code values for integer outputs against OCIO's unrounded float result, 1e-5 relative for
// float outputs; the tables reproduce OCIO's own values, so they are also expected equal.
using detail::ConversionPath;

// convert_pixels along `path`; true if the tables converted the pixels.
bool convert_as(const ColorConfig& c, ConversionPath path, const void* src, int src_bits,
                std::ptrdiff_t src_pixel_bytes, void* dst, int dst_bits,
                std::ptrdiff_t dst_pixel_bytes, int width, const std::string& from,
                const std::string& to) {
  const detail::ScopedConversionPath scoped(path);
  c.convert_pixels(src, src_bits, src_pixel_bytes, src_pixel_bytes * width, dst, dst_bits,
                   dst_pixel_bytes, dst_pixel_bytes * width, width, 1, from, to);
  return detail::last_conversion_used_tables();
}

// Codes k, (k * 7 + 3) mod codes, codes - 1 - k: each channel sees every code in another order.
template <class T>
std::vector<T> every_code(int bits) {
  const long codes = 1L << bits;
  std::vector<T> v(std::size_t(codes) * 3);
  for (long k = 0; k < codes; ++k) {
    v[3 * k] = T(k);
    v[3 * k + 1] = T((k * 7 + 3) % codes);
    v[3 * k + 2] = T(codes - 1 - k);
  }
  return v;
}

template <class T>
void expect_codes_to_float_match(const ColorConfig& c, int bits, const char* from, const char* to,
                                 bool expect_tables) {
  std::vector<T> in = every_code<T>(bits);
  const int n = int(in.size() / 3);
  std::vector<float> fast(in.size()), exact(in.size());
  const std::ptrdiff_t ip = 3 * sizeof(T), op = 3 * sizeof(float);
  EXPECT_EQ(
      convert_as(c, ConversionPath::tables, in.data(), bits, ip, fast.data(), 32, op, n, from, to),
      expect_tables)
      << from << " -> " << to;
  convert_as(c, ConversionPath::ocio, in.data(), bits, ip, exact.data(), 32, op, n, from, to);
  double worst = 0;
  std::size_t differ = 0;
  for (std::size_t i = 0; i < in.size(); ++i) {
    worst = std::max(worst, std::fabs(double(fast[i]) - exact[i]) /
                                std::max(std::fabs(double(exact[i])), 1e-30));
    differ += !(fast[i] == exact[i]);
  }
  EXPECT_LE(worst, 1e-5) << bits << "-bit " << from << " -> " << to;
  EXPECT_EQ(differ, 0u) << bits << "-bit " << from << " -> " << to;
}

// Floats over the whole range: 64 values per binade of both signs, a dense walk over [0, 1.2],
// random values, the specials.
std::vector<float> float_sweep() {
  std::vector<float> v;
  for (int e = -149; e <= 127; ++e)
    for (int m = 0; m < 64; ++m) {
      const float x = std::ldexp(1.0f + m / 64.0f, e);
      if (std::isfinite(x)) v.insert(v.end(), {x, -x});
    }
  for (int i = 0; i <= 1200000; ++i) v.push_back(float(i) * 1e-6f);
  std::mt19937 rng(12);
  std::uniform_real_distribution<float> u(-0.5f, 20.0f);
  for (int i = 0; i < 200000; ++i) v.push_back(u(rng));
  const float inf = std::numeric_limits<float>::infinity();
  v.insert(v.end(),
           {0.0f, -0.0f, inf, -inf, std::nanf(""), std::numeric_limits<float>::denorm_min(),
            std::numeric_limits<float>::max(), 1.0f, 0.0031308f, 0.8f});
  while (v.size() % 3) v.push_back(0.5f);
  return v;
}

template <class T>
void expect_float_to_codes_match(const ColorConfig& c, int bits, const char* to) {
  const std::vector<float> in = float_sweep();
  const int n = int(in.size() / 3);
  std::vector<T> fast(in.size()), exact(in.size());
  std::vector<float> unrounded(in.size());
  const std::ptrdiff_t ip = 3 * sizeof(float), op = 3 * sizeof(T);
  EXPECT_TRUE(convert_as(c, ConversionPath::tables, in.data(), 32, ip, fast.data(), bits, op, n,
                         colorspace::scene_linear, to))
      << to;
  convert_as(c, ConversionPath::ocio, in.data(), 32, ip, exact.data(), bits, op, n,
             colorspace::scene_linear, to);
  convert_as(c, ConversionPath::ocio, in.data(), 32, ip, unrounded.data(), 32, ip, n,
             colorspace::scene_linear, to);
  const double max_code = double((1L << bits) - 1);
  double worst = 0;
  std::size_t differ = 0;
  for (std::size_t i = 0; i < in.size(); ++i) {
    differ += fast[i] != exact[i];
    if (std::isnan(unrounded[i])) continue;
    const double target = std::clamp(double(unrounded[i]), 0.0, 1.0) * max_code;
    worst = std::max(worst, std::fabs(double(fast[i]) - target));
  }
  // Half a code, plus four float ulps of 1.0 in codes (OCIO's float and integer outputs are
  // computed separately: 0.0019 codes apart at most at 16 bits, measured).
  std::printf("%d-bit %s: worst %.6f codes from OCIO's float output\n", bits, to, worst);
  EXPECT_LE(worst, 0.5 + 4 * 0x1p-23 * max_code) << bits << "-bit " << to;
  EXPECT_EQ(differ, 0u) << bits << "-bit " << to;
}

TEST(Color, FastConversionsMatchOcio) {
  const ColorConfig c = ColorConfig::builtin();
  expect_codes_to_float_match<std::uint8_t>(c, 8, colorspace::srgb, colorspace::scene_linear, true);
  expect_codes_to_float_match<std::uint16_t>(c, 16, colorspace::srgb, colorspace::scene_linear,
                                             true);
  // A matrix mixes the channels: no tables, OCIO on every pixel.
  expect_codes_to_float_match<std::uint8_t>(c, 8, colorspace::srgb, colorspace::acescg, false);
  for (const char* to : {colorspace::srgb, colorspace::srgb_rolloff}) {
    expect_float_to_codes_match<std::uint8_t>(c, 8, to);
    expect_float_to_codes_match<std::uint16_t>(c, 16, to);
  }
}

TEST(Color, FastConversionsAreLeftToOcioWhereTheyWouldDiffer) {
  // x -> 1 - x per channel: no crosstalk, but decreasing, which the float tables cannot hold.
  test::ScratchDir dir;
  std::string config = test::read_bytes(fs_source() / "libmr/data/config.ocio");
  config += R"(
  - !<ColorSpace>
    name: Negative
    family: Test
    bitdepth: 32f
    isdata: false
    to_scene_reference: !<MatrixTransform> {matrix: [-1, 0, 0, 0, 0, -1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1], offset: [1, 1, 1, 0]}
)";
  test::write_bytes(dir / "negative.ocio", config);
  const ColorConfig c = ColorConfig::from_file(dir / "negative.ocio");
  std::vector<float> in = float_sweep();
  const int n = int(in.size() / 3);
  std::vector<std::uint8_t> fast(in.size()), exact(in.size());
  EXPECT_FALSE(convert_as(c, ConversionPath::tables, in.data(), 32, 12, fast.data(), 8, 3, n,
                          colorspace::scene_linear, "Negative"));
  convert_as(c, ConversionPath::ocio, in.data(), 32, 12, exact.data(), 8, 3, n,
             colorspace::scene_linear, "Negative");
  EXPECT_EQ(fast, exact);
  float zero[3] = {0, 0, 0};
  std::uint8_t white[3] = {0, 0, 0};
  c.convert_pixels(zero, 32, 12, 12, white, 8, 3, 3, 1, 1, colorspace::scene_linear, "Negative");
  EXPECT_EQ(white[1], 255);  // 0 -> 1: the transform did run
  // Integer codes in: a table per code is exact for any per-channel function.
  expect_codes_to_float_match<std::uint8_t>(c, 8, "Negative", colorspace::scene_linear, true);
}

}  // namespace
}  // namespace mr
