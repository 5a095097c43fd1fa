#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "mr/error.h"
#include "mr/fog.h"
#include "test_support.h"

namespace mr {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

TEST(Fog, KoschmiederExtinction) {
  EXPECT_NEAR(extinction_from_visibility(100.0), 0.03912, 1e-12);
  // At the visibility distance a black object keeps 2 % contrast: T(V) = 0.02 (to 1e-4).
  EXPECT_NEAR(std::exp(-extinction_from_visibility(250.0) * 250.0), 0.02, 1e-4);
  EXPECT_THROW(extinction_from_visibility(0.0), Error);
  EXPECT_THROW(extinction_from_visibility(-5.0), Error);
  EXPECT_THROW(extinction_from_visibility(std::nan("")), Error);
  // The inverse: T(V) = 0.02 at the visibility it gives, and a round trip.
  EXPECT_NEAR(std::exp(-0.01 * visibility_from_extinction(0.01)), 0.02, 1e-4);
  EXPECT_NEAR(visibility_from_extinction(extinction_from_visibility(1234.5)), 1234.5, 1e-9);
  EXPECT_THROW(visibility_from_extinction(0.0), Error);
  EXPECT_THROW(visibility_from_extinction(std::numeric_limits<double>::infinity()), Error);
}

TEST(Fog, CompositeIsExactlyItPlusAirlightTimesOneMinusT) {
  const int w = 61, h = 17;
  Image photo = test::make_test_photo(w, h);
  Image dist(w, h, 1, {"Z"});
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0.1f, 500.0f);
  for (float& d : dist.pixels()) d = u(rng);
  dist.at(5, 5, 0) = kInf;  // sky
  FogParams p;
  p.sigma_t_per_m = {0.01f, 0.02f, 0.005f};
  p.airlight = Rgb{0.8f, 0.85f, 0.9f};
  const FogLayers f = fog(photo, dist, p);
  EXPECT_EQ(f.airlight, *p.airlight);
  double worst = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) {
        const double t = std::exp(-double(p.sigma_t_per_m[c]) * dist.at(x, y, 0));
        const double want = photo.at(x, y, c) * t + (*p.airlight)[c] * (1 - t);
        worst = std::max(worst, std::fabs(f.composite.at(x, y, c) - want));
        EXPECT_NEAR(f.transmittance.at(x, y, c), t, 1e-6);
        EXPECT_NEAR(f.inscatter.at(x, y, c), (*p.airlight)[c] * (1 - t), 1e-6);
      }
  EXPECT_LT(worst, 1e-6);  // float arithmetic only
  for (int c = 0; c < 3; ++c) {
    EXPECT_EQ(f.transmittance.at(5, 5, c), 0.0f);
    EXPECT_EQ(f.composite.at(5, 5, c), (*p.airlight)[c]);  // sky takes the airlight
  }
}

TEST(Fog, FarIsFoggierThanNear) {
  Image photo(3, 1, 3);
  Image dist(3, 1, 1);
  dist.at(0, 0, 0) = 10;
  dist.at(1, 0, 0) = 100;
  dist.at(2, 0, 0) = 1000;
  FogParams p;
  p.airlight = Rgb{1, 1, 1};
  const FogLayers f = fog(photo, dist, p);  // black photo: composite = 1 - T
  EXPECT_LT(f.composite.at(0, 0, 0), f.composite.at(1, 0, 0));
  EXPECT_LT(f.composite.at(1, 0, 0), f.composite.at(2, 0, 0));
}

TEST(Fog, ZeroDensityLeavesThePhotoAlone) {
  Image photo = test::make_test_photo(9, 9);
  Image dist(9, 9, 1);
  for (float& d : dist.pixels()) d = kInf;
  FogParams p;
  p.sigma_t_per_m = {0, 0, 0};
  p.airlight = Rgb{1, 1, 1};
  EXPECT_EQ(test::max_abs_diff(fog(photo, dist, p).composite, photo), 0.0);
}

TEST(Fog, AlphaIsCarried) {
  Image photo(2, 2, 4);
  for (std::size_t i = 0; i < 4; ++i) photo.pixels()[i * 4 + 3] = 0.3f;
  Image dist(2, 2, 1);
  for (float& d : dist.pixels()) d = 50;
  FogParams p;
  p.airlight = Rgb{1, 1, 1};
  const FogLayers f = fog(photo, dist, p);
  EXPECT_EQ(f.composite.channels(), 4);
  EXPECT_EQ(f.composite.at(1, 1, 3), 0.3f);
}

TEST(Fog, BadInputIsAClearError) {
  Image photo(4, 4, 3), dist(4, 4, 1);
  FogParams p;
  p.airlight = Rgb{1, 1, 1};
  try {
    fog(photo, Image(5, 4, 1), p);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::size_mismatch);
    EXPECT_NE(std::string(e.what()).find("5x4"), std::string::npos);
  }
  FogParams neg = p;
  neg.sigma_t_per_m = {-1, 0, 0};
  EXPECT_THROW(fog(photo, dist, neg), Error);
  FogParams nan = p;
  nan.airlight = Rgb{std::nanf(""), 1, 1};
  EXPECT_THROW(fog(photo, dist, nan), Error);
  Image nan_dist = dist;
  nan_dist.at(1, 1, 0) = std::nanf("");
  EXPECT_THROW(fog(photo, nan_dist, p), Error);
  EXPECT_THROW(fog(Image(4, 4, 1), dist, p), Error);
}

TEST(Airlight, DarkChannelFindsTheHazeColour) {
  // Dark, saturated foreground (low dark channel) and a hazy region of known colour.
  const int w = 200, h = 150;
  Image photo(w, h, 3);
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      float* p = photo.pixel(x, y);
      // Saturated colours: one channel near zero keeps the dark channel low.
      p[0] = u(rng);
      p[1] = u(rng) * 0.05f;
      p[2] = u(rng);
    }
  const Rgb haze{0.7f, 0.75f, 0.8f};
  for (int y = 10; y < 40; ++y)
    for (int x = 120; x < 180; ++x)
      for (int c = 0; c < 3; ++c) photo.at(x, y, c) = haze[c];
  // A single white pixel (a specular highlight) must not win: the min filter removes it.
  for (int c = 0; c < 3; ++c) photo.at(20, 100, c) = 10.0f;
  const Rgb a = estimate_airlight(photo);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(a[c], haze[c], 1e-6) << c;
}

}  // namespace
}  // namespace mr
