// Issue 11 item 5, light that matches the photo: the fog colour's neutral prior and chroma bound
// (photo/airlight.h), the exposure-relative sun (photo/illumination.h), and the highlight
// roll-off output transform (mr/color.h, colour space srgb_rolloff).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <vector>

#include "mr/mr.h"
#include "photo/airlight.h"
#include "photo/illumination.h"
#include "scattering_scenes.h"
#include "test_support.h"

namespace mr {
namespace {

constexpr double kPi = std::numbers::pi;

double luminance(const std::array<float, 3>& c) {
  return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
}

// u'v' of a linear Rec.709 colour, written out independently of photo/airlight.cpp.
std::array<double, 2> uv(const std::array<float, 3>& c) {
  const double X = 0.4124 * c[0] + 0.3576 * c[1] + 0.1805 * c[2];
  const double Y = 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
  const double Z = 0.0193 * c[0] + 0.1192 * c[1] + 0.9505 * c[2];
  const double d = X + 15 * Y + 3 * Z;
  return {4 * X / d, 9 * Y / d};
}
std::array<double, 2> uv_xy(double x, double y) {
  const double d = -2 * x + 12 * y + 3;
  return {4 * x / d, 9 * y / d};
}

// The bound checked on its own terms: along the daylight locus toward 4000 K (warm) or
// 10000 K (cool) within 0.043 / 0.029 of D65, and within 0.01 across it (u'v').
struct LocusOffset {
  double along, across;
  bool warm;
};
LocusOffset locus_offset(const std::array<float, 3>& c) {
  const auto d65 = uv_xy(0.3127, 0.3290), k4000 = uv_xy(0.3805, 0.3768),
             k10000 = uv_xy(0.2807, 0.2884);
  const auto p = uv(c);
  const double du = p[0] - d65[0], dv = p[1] - d65[1];
  auto unit = [&](std::array<double, 2> q) {
    const double x = q[0] - d65[0], y = q[1] - d65[1], n = std::hypot(x, y);
    return std::array<double, 2>{x / n, y / n};
  };
  const auto w = unit(k4000), k = unit(k10000);
  const bool warm = du * w[0] + dv * w[1] > 0;
  const auto& dir = warm ? w : k;
  const double along = std::max(0.0, du * dir[0] + dv * dir[1]);
  return {along, std::hypot(du - along * dir[0], dv - along * dir[1]), warm};
}

// --- fog colour: neutral prior and chroma bound --------------------------------------------

TEST(FogColour, PlausibleDaylightColoursPassUnchanged) {
  for (const std::array<float, 3> c : {std::array<float, 3>{0.5f, 0.5f, 0.5f},
                                      {0.7f, 0.75f, 0.8f},      // bluish haze
                                      {0.16f, 0.17f, 0.2f},     // the README's example sky
                                      {0.9f, 0.85f, 0.78f}}) {  // warm white
    const auto out = photo::neutral_fog_colour(c);
    for (int k = 0; k < 3; ++k) EXPECT_EQ(out[k], c[k]) << c[0] << " " << c[1] << " " << c[2];
  }
}

TEST(FogColour, SaturatedEstimatesAreBoundedAndKeepTheirLuminanceAndLean) {
  // Lemon yellow, slate blue, a sunset orange, a clear-sky blue, a foliage green, pure primaries.
  const std::vector<std::array<float, 3>> colours = {
      {1.0f, 1.0f, 0.1f}, {0.2f, 0.3f, 0.5f}, {1.0f, 0.5f, 0.2f}, {0.25f, 0.45f, 0.9f},
      {0.3f, 0.6f, 0.2f}, {1.0f, 0.0f, 0.0f}, {0.0f, 1.0f, 0.0f},  {0.0f, 0.0f, 1.0f}};
  for (const auto& c : colours) {
    const LocusOffset before = locus_offset(c);
    const auto out = photo::neutral_fog_colour(c);
    const LocusOffset after = locus_offset(out);
    std::printf("  (%.2f %.2f %.2f) along %.4f across %.4f C* %.1f -> (%.3f %.3f %.3f) along "
                "%.4f across %.4f C* %.1f\n",
                c[0], c[1], c[2], before.along, before.across, photo::chroma_ab(c), out[0],
                out[1], out[2], after.along, after.across, photo::chroma_ab(out));
    // The independent u'v' matrices above are rounded to 4 digits: 2e-4 of slack.
    EXPECT_LE(after.along, (before.warm ? 0.043 : 0.029) + 2e-4);
    EXPECT_LE(after.across, 0.01 + 2e-4);
    EXPECT_LE(photo::chroma_ab(out), 33.6 + 1e-3);  // C*ab of the Planckian 4000 K
    EXPECT_LE(after.along, before.along + 2e-4);  // only ever toward neutral
    if (before.along > 0.01) { EXPECT_EQ(after.warm, before.warm); }  // keeps its lean
    // Luminance kept: the test's coefficients are rounded to 4 digits (3e-4 relative for blue).
    EXPECT_NEAR(luminance(out), luminance(c), 3e-4 * luminance(c));
    for (float v : out) EXPECT_GE(v, 0.0f);
  }
  // The raw colours were far outside (the test can fail): lemon 0.061 along, 0.043 across.
  EXPECT_GT(locus_offset(colours[0]).across, 0.03);
  EXPECT_GT(locus_offset(colours[1]).along, 0.04);
}

TEST(FogColour, CompressionIsMonotonicInSaturation) {
  // Mixing grey with lemon yellow in steps: the bounded offset never decreases, never jumps.
  double last = -1;
  for (int i = 0; i <= 200; ++i) {
    const float t = float(i) / 200;
    const std::array<float, 3> c{0.6f + 0.4f * t, 0.6f + 0.4f * t, 0.6f - 0.5f * t};
    const auto out = photo::neutral_fog_colour(c);
    const double d = photo::delta_uv_from_d65(out);
    EXPECT_GE(d, last - 1e-7) << t;
    if (last >= 0) { EXPECT_LT(d - last, 2e-3) << t; }
    last = d;
  }
}

// A synthetic photo: a dark textured ground below, a sky of one colour above (the dark channel
// picks the sky), as the saturated sunset / lemon sky cases.
Image sky_photo(const std::array<float, 3>& sky) {
  Image im(240, 160, 3);
  for (int y = 0; y < 160; ++y)
    for (int x = 0; x < 240; ++x)
      for (int c = 0; c < 3; ++c)
        im.at(x, y, c) = y < 60 ? sky[c] : 0.05f + 0.04f * float((x * 7 + y * 3 + c) % 5);
  return im;
}

TEST(FogColour, AutomaticAirlightOfSaturatedSkiesIsBoundedAndNeutralFogStaysNeutral) {
  for (const std::array<float, 3> sky : {std::array<float, 3>{0.9f, 0.85f, 0.08f},  // lemon
                                        {0.22f, 0.3f, 0.55f},                       // slate
                                        {0.95f, 0.45f, 0.15f}}) {                   // sunset
    const Image photo = sky_photo(sky);
    photo::DarkChannelOptions raw;
    raw.apply_neutral_prior = false;
    const auto before = photo::estimate_airlight_dark_channel(photo.view(), raw);
    const Rgb after = estimate_airlight(photo);
    const LocusOffset b = locus_offset(before), a = locus_offset(after);
    std::printf("  sky (%.2f %.2f %.2f): raw airlight du'v' %.4f C* %.1f -> du'v' %.4f C* %.1f\n",
                sky[0], sky[1], sky[2], photo::delta_uv_from_d65(before), photo::chroma_ab(before),
                photo::delta_uv_from_d65(after), photo::chroma_ab(after));
    EXPECT_TRUE(b.along > (b.warm ? 0.043 : 0.029) || b.across > 0.01);  // raw: out of bounds
    EXPECT_LE(a.along, (a.warm ? 0.043 : 0.029) + 2e-4);
    EXPECT_LE(a.across, 0.01 + 2e-4);
    EXPECT_LE(photo::chroma_ab(after), 33.6 + 1e-3);
    EXPECT_NEAR(luminance(after), luminance(before), 3e-4 * luminance(before));
  }
  // Neutral fog: a grey haze sky gives a grey airlight (the prior adds no colour).
  const Rgb grey = estimate_airlight(sky_photo({0.8f, 0.8f, 0.8f}));
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(grey[c], 0.8f, 1e-6);
  EXPECT_LT(photo::delta_uv_from_d65(grey), 1e-6);
}

// --- exposure-relative sun ------------------------------------------------------------------

TEST(ExposureRelativeSun, IsPiTimesTheBrightSurfaceLuminanceAndScalesWithExposure) {
  // Surfaces of luminance 0.1..0.5 (99th percentile known), a sky far brighter that must not
  // count, a sky radiance that does not bind (ratio within [1, 10]).
  const int w = 200, h = 100;
  Image photo(w, h, 3), depth(w, h, 1, {"Z"});
  std::vector<float> surface;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const bool sky = y < 20;
      const float v = sky ? 5.0f : 0.1f + 0.4f * float(x) / float(w - 1);
      for (int c = 0; c < 3; ++c) photo.at(x, y, c) = v;
      depth.at(x, y, 0) = sky ? test::kInf : 10.0f;
      if (!sky) surface.push_back(v);
    }
  std::sort(surface.begin(), surface.end());
  const double p99 = surface[std::size_t(0.99 * double(surface.size() - 1))];
  for (const float exposure : {0.25f, 1.0f, 4.0f}) {
    Image scaled = photo;
    for (float& v : scaled.pixels()) v *= exposure;
    const Rgb sky{0.1f * exposure, 0.1f * exposure, 0.1f * exposure};
    const Rgb e = exposure_relative_sun_irradiance(scaled, depth, sky);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(e[c], kPi * p99 * exposure, 1e-5 * kPi * p99 * exposure);
  }
  // Kept within 1 <= E / (pi L_sky) <= 10 of the sky.
  const Rgb dim = exposure_relative_sun_irradiance(photo, depth, {0.001f, 0.001f, 0.001f});
  EXPECT_NEAR(dim[0], 10 * kPi * 0.001, 1e-6);
  const Rgb bright = exposure_relative_sun_irradiance(photo, depth, {2.0f, 2.0f, 2.0f});
  EXPECT_NEAR(bright[0], kPi * 2.0, 1e-5);
  // Without a distance map every pixel counts (here: the sky's 5.0 is in the top 20 %).
  const Rgb all = exposure_relative_sun_irradiance(photo, Image(), {1.0f, 1.0f, 1.0f});
  EXPECT_NEAR(all[0], kPi * 5.0, 1e-4);
  EXPECT_THROW(exposure_relative_sun_irradiance(photo, Image(10, 10, 1), {1, 1, 1}), Error);
}

// A sunlit fog-bank look on one scene at three exposures: the share of pixels that turn white
// (all three 8-bit codes >= 250, the gallery's measure) and were not must stay <= 2 %, with the default light
// (exposure-relative sun, automatic airlight) and the default display encoding (roll-off).
// The old defaults (sun irradiance 3, plain sRGB) are measured beside it.
struct WhiteShare {
  double rolloff, old;
};
WhiteShare sunlit_new_white(float exposure) {
  const Camera cam = Camera::from_horizontal_fov(192, 128, 70);
  CameraPose pose;
  pose.position_m = {0, 1.6, 0};
  pose.pitch_deg = 3;
  const Image depth = test::street_depth(cam, pose);
  // The photo: a bright sky, lit walls and ground, clipped to [0, 1] as an 8-bit photo is.
  Image photo(cam.width, cam.height, 3);
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const float d = depth.at(x, y, 0);
      const float base[3] = {0.55f, 0.62f, 0.75f};
      const float ground = 0.18f + 0.1f * float((x / 8 + y / 8) % 2);
      for (int c = 0; c < 3; ++c)
        photo.at(x, y, c) =
            std::min(1.0f, exposure * (std::isinf(d) ? base[c] : ground * (1.0f + 0.2f * c)));
    }
  FogScene scene;
  scene.pose = pose;
  const float sigma = float(extinction_from_visibility(120));
  scene.medium.sigma_t_per_m = {sigma, sigma, sigma};
  scene.medium.layer_bottom_m = -10;
  scene.medium.layer_top_m = 20;
  scene.medium.g = 0.6;
  scene.render.quality = Quality::draft;
  scene.render.backend = Backend::cpu;
  const Rgb sky = estimate_airlight(photo);
  scene.lighting.sky_radiance = sky;
  Sun sun;
  sun.direction_to_sun = direction_from_azimuth_elevation(25, 15);  // in front, low: the glare case
  const ColorConfig config = ColorConfig::builtin();
  auto white_share = [&](const Image& composite, const char* space) {
    std::vector<unsigned char> out(composite.pixel_count() * 3), in(photo.pixel_count() * 3);
    const std::ptrdiff_t px = 3 * sizeof(float);
    config.convert_pixels(composite.data(), 32, px, px * cam.width, out.data(), 8, 3, 3 * cam.width,
                          cam.width, cam.height, colorspace::scene_linear, space);
    config.convert_pixels(photo.data(), 32, px, px * cam.width, in.data(), 8, 3, 3 * cam.width,
                          cam.width, cam.height, colorspace::scene_linear, colorspace::srgb);
    // "White" as the gallery's measure has it (gallery/measures.py): all three codes >= 250.
    auto white = [](const unsigned char* p) { return p[0] >= 250 && p[1] >= 250 && p[2] >= 250; };
    std::size_t n = 0;
    for (std::size_t i = 0; i < photo.pixel_count(); ++i) n += white(&out[3 * i]) && !white(&in[3 * i]);
    return double(n) / double(photo.pixel_count());
  };
  sun.irradiance = exposure_relative_sun_irradiance(photo, depth, sky);
  scene.lighting.sun = sun;
  const double now = white_share(fog(photo, depth, cam, scene).composite, colorspace::srgb_rolloff);
  sun.irradiance = {3, 3, 3};
  scene.lighting.sun = sun;
  const double old = white_share(fog(photo, depth, cam, scene).composite, colorspace::srgb);
  std::printf("  exposure x%.2f: sky (%.3f %.3f %.3f), E_sun %.3f; new pure white %.2f %% "
              "(old defaults: %.2f %%)\n",
              exposure, sky[0], sky[1], sky[2],
              exposure_relative_sun_irradiance(photo, depth, sky)[0], 100 * now, 100 * old);
  return {now, old};
}

TEST(ExposureRelativeSun, SunlitLookMakesAtMostTwoPercentNewWhiteAtAnyExposure) {
  for (const float exposure : {0.3f, 1.0f, 1.6f}) {
    const WhiteShare s = sunlit_new_white(exposure);
    EXPECT_LE(s.rolloff, 0.02) << "exposure " << exposure;
  }
}

// --- highlight roll-off ---------------------------------------------------------------------

TEST(HighlightRolloff, IdentityBelowTheKneeMonotonicContinuousAndNeverOne) {
  const double k = kHighlightRolloffKnee;
  for (double x = -1; x <= k; x += 1e-3) EXPECT_EQ(highlight_rolloff(x), x);
  double last = highlight_rolloff(k), last_x = k;
  for (double x = k + 1e-4; x < 1e4; x *= 1.0 + 1e-4) {
    const double y = highlight_rolloff(x);
    EXPECT_GT(y, last) << x;  // strictly increasing
    EXPECT_LT(y, 1.0) << x;   // never clips
    EXPECT_LE(y - last, (x - last_x) * (1 + 1e-9)) << x;  // slope <= 1: continuous, no jump
    last_x = x;
    EXPECT_NEAR(highlight_rolloff_inverse(y), x, 1e-7 * x) << x;
    last = y;
    if (x > 1e3) x *= 1.01;
  }
  // Slope 1 at the knee from above (C1): (f(k + h) - k) / h -> 1.
  EXPECT_NEAR((highlight_rolloff(k + 1e-7) - k) / 1e-7, 1.0, 1e-5);
  EXPECT_NEAR(highlight_rolloff(1.0), 0.9, 1e-12);
  EXPECT_EQ(highlight_rolloff(std::numeric_limits<double>::infinity()), 1.0);
}

TEST(HighlightRolloff, OcioColourSpaceIsTheCurveThenSrgb) {
  const ColorConfig config = ColorConfig::builtin();
  ASSERT_TRUE(config.has_colorspace(colorspace::srgb_rolloff));
  EXPECT_STREQ(config.display_colorspace(), colorspace::srgb_rolloff);
  const int n = 4000;
  Image ramp(n, 1, 3), plain(n, 1, 3);
  std::vector<double> xs(n);
  for (int i = 0; i < n; ++i) {
    xs[i] = i < n / 2 ? double(i) / (n / 2) : std::pow(1000.0, double(i - n / 2) / (n / 2));
    for (int c = 0; c < 3; ++c) ramp.at(i, 0, c) = plain.at(i, 0, c) = float(xs[i]);
  }
  config.convert(ramp.view(), colorspace::scene_linear, colorspace::srgb_rolloff);
  config.convert(plain.view(), colorspace::scene_linear, colorspace::srgb);
  auto srgb = [](double v) { return v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1 / 2.4) - 0.055; };
  double worst_identity = 0, worst_curve = 0;
  for (int i = 0; i < n; ++i) {
    const double got = ramp.at(i, 0, 0);
    if (xs[i] <= kHighlightRolloffKnee)
      worst_identity = std::max(worst_identity, std::fabs(got - plain.at(i, 0, 0)));
    worst_curve = std::max(worst_curve, std::fabs(got - srgb(highlight_rolloff(xs[i]))));
    EXPECT_LT(got, 1.0f) << xs[i];
    if (i > 0) { EXPECT_GE(got, ramp.at(i - 1, 0, 0)) << xs[i]; }
  }
  std::printf("  OCIO roll-off vs plain sRGB below the knee: %.3g; vs the curve: %.3g\n",
              worst_identity, worst_curve);
  // Below the knee the LUT interpolates between half codes of an identity: float rounding only.
  EXPECT_LE(worst_identity, 1e-6);
  // Above it, linear interpolation between half codes (relative spacing 2^-11) of a smooth curve.
  EXPECT_LE(worst_curve, 2e-4);
  // 8-bit codes: 255 (pure white) only beyond ~9.7 x the photo's white.
  const float probe[6] = {1.0f, 1.0f, 1.0f, 8.0f, 8.0f, 8.0f};
  unsigned char codes[6];
  config.convert_pixels(probe, 32, 12, 24, codes, 8, 3, 6, 2, 1, colorspace::scene_linear,
                        colorspace::srgb_rolloff);
  EXPECT_EQ(codes[0], 243);  // the photo's white, 0.9 after the roll-off
  EXPECT_LT(codes[3], 255);
}

// sigma_t = 0 gives back the photo: exactly in scene-linear; through the default display
// encoding, codes up to the knee (231) unchanged and the highlights above it within 12 codes.
TEST(HighlightRolloff, NoFogGivesBackThePhoto) {
  test::ScratchDir dir;
  const Image photo8 = test::make_test_photo(96, 64);
  write_image(dir / "photo.png", photo8);
  const Image photo = read_image(dir / "photo.png");
  const Camera cam = Camera::from_horizontal_fov(96, 64, 60);
  FogScene scene;
  scene.pose.position_m = {0, 1.6, 0};
  scene.medium.sigma_t_per_m = {0, 0, 0};
  scene.lighting.sun = Sun{direction_from_azimuth_elevation(10, 20), {3, 3, 3}, 0.27};
  scene.render.backend = Backend::cpu;
  const Image depth = test::ground_depth(cam, scene.pose);
  const FogLayers f = fog(photo, depth, cam, scene);
  for (std::size_t i = 0; i < photo.pixels().size(); ++i)
    ASSERT_EQ(f.composite.pixels()[i], photo.pixels()[i]) << i;
  WriteOptions w;
  w.colorspace = colorspace::srgb_rolloff;
  write_image(dir / "out.png", f.composite, w);
  ReadOptions raw;
  raw.to_scene_linear = false;
  const Image a = read_image(dir / "photo.png", raw), b = read_image(dir / "out.png", raw);
  int worst_low = 0, worst_high = 0, high = 0;
  for (std::size_t i = 0; i < a.pixels().size(); ++i) {
    const int ca = int(std::lround(a.pixels()[i] * 255)), cb = int(std::lround(b.pixels()[i] * 255));
    if (ca <= 231) {
      worst_low = std::max(worst_low, std::abs(ca - cb));
    } else {
      worst_high = std::max(worst_high, std::abs(ca - cb));
      ++high;
    }
  }
  std::printf("  no fog: codes <= 231 differ by <= %d; %d values above differ by <= %d\n",
              worst_low, high, worst_high);
  EXPECT_EQ(worst_low, 0);
  EXPECT_LE(worst_high, 12);
}

}  // namespace
}  // namespace mr
