#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <fstream>

#include "mr/color.h"
#include "mr/error.h"
#include "test_support.h"

namespace mr {
namespace {

// IEC 61966-2-1.
double srgb_to_linear(double v) { return v <= 0.04045 ? v / 12.92 : std::pow((v + 0.055) / 1.055, 2.4); }

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
  test::write_bytes(path, test::read_bytes(std::filesystem::path(MR_SOURCE_DIR) / "libmr/data/config.ocio"));
  ::setenv("OCIO", path.c_str(), 1);
  ColorConfig from_env = ColorConfig::from_environment();
  ::unsetenv("OCIO");
  EXPECT_EQ(from_env.source(), path.string());
  EXPECT_TRUE(from_env.has_colorspace(colorspace::acescg));
  EXPECT_EQ(ColorConfig::from_environment().source(), "<builtin>");
  EXPECT_EQ(ColorConfig::from_environment(path).source(), path.string());
}

}  // namespace
}  // namespace mr
