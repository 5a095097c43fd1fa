// Issue 11: backlit land (a sunset's black silhouette) gives the horizon of a level camera
// (photo/horizon.h, find_silhouette): gallery/tune after_the_rain's storm cumulus stood on the
// ground plane 8 m away under the level fall-back through the frame's middle, clear under the
// haze's veil over the sky around it.
#include <gtest/gtest.h>

#include <opencv2/core.hpp>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <random>

#include "mr/estimate.h"
#include "mr/io.h"
#include "photo/horizon.h"
#include "tests/gallery_look.h"

namespace mr {
namespace {

constexpr int kW = 400, kH = 300;

// The land's skyline at column x: hills around row 225.
int skyline(int x) {
  return 225 + int(std::lround(6 * std::sin(x / 37.0)));
}

// A display-referred sunset: an orange glow under a blue-grey sky, a grey-brown cumulus across
// the middle (rows 90-200, columns 60-340) and black land under the skyline, with a tree
// (columns 300-315) rising to row 190 and a few lit windows in the land.
cv::Mat backlit_sunset(float land = 0.02f) {
  cv::Mat p(kH, kW, CV_32FC3);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> grain(-0.01f, 0.01f);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const float t = float(y) / kH;
      cv::Vec3f c(0.45f + 0.5f * t, 0.5f + 0.2f * t, 0.7f - 0.4f * t);  // R, G, B
      const double cx = (x - 200) / 140.0, cy = (y - 145) / 55.0;
      if (cx * cx + cy * cy < 1) c = cv::Vec3f(0.2f, 0.2f, 0.24f) + cv::Vec3f::all(grain(rng));
      if (y >= skyline(x) || (x >= 300 && x < 315 && y >= 190))
        c = cv::Vec3f::all(land + 0.3f * grain(rng));
      p.at<cv::Vec3f>(y, x) = c;
    }
  p(cv::Rect(100, 260, 3, 2)).setTo(cv::Scalar(0.6, 0.8, 0.9));  // a lit window
  return p;
}

TEST(Silhouette, ABacklitLandsSkylineAndWhatIsSkyAboveIt) {
  const Image photo = test::linear_photo(backlit_sunset());
  std::vector<std::uint8_t> sky(std::size_t(kW) * kH, 0);
  for (int y = 0; y < 60; ++y)
    for (int x = 0; x < kW; ++x) sky[std::size_t(y) * kW + x] = 1;
  const photo::Silhouette s = photo::find_silhouette(photo.view(), sky);
  ASSERT_TRUE(std::isfinite(s.skyline_row));
  EXPECT_NEAR(s.skyline_row, 225, 4);
  EXPECT_GT(s.contrast, 4);
  ASSERT_EQ(s.land.size(), sky.size());
  ASSERT_EQ(s.sky_alpha.size(), sky.size());
  auto at = [&](int x, int y) { return std::size_t(y) * kW + x; };
  EXPECT_EQ(s.land[at(50, 280)], 1);   // the land
  EXPECT_EQ(s.land[at(307, 195)], 1);  // the tree standing on it
  EXPECT_EQ(s.sky_alpha[at(307, 195)], 0.0f);
  EXPECT_EQ(s.sky_alpha[at(101, 261)], 0.0f);  // a lit window in the land is not sky
  EXPECT_EQ(s.sky_alpha[at(200, 145)], 1.0f);  // the cumulus
  EXPECT_EQ(s.sky_alpha[at(20, 215)], 1.0f);   // the glow down to the land
  EXPECT_EQ(s.sky_alpha[at(200, 20)], 1.0f);
}

TEST(Silhouette, NoneWithoutABacklitLand) {
  std::vector<std::uint8_t> sky(std::size_t(kW) * kH, 0);  // the sky's rows under a letterbox
  for (std::size_t i = std::size_t(kW) * 35; i < std::size_t(kW) * 60; ++i) sky[i] = 1;
  // Frontlit land (brighter than a silhouette), a night (all dark), a dark strip at the
  // bottom only 2 % of the height, noise; below, a letterboxed still and a night-dark sky.
  cv::Mat frontlit = backlit_sunset(0.3f);
  cv::Mat night(kH, kW, CV_32FC3, cv::Scalar(0.03, 0.03, 0.04));
  cv::Mat strip = backlit_sunset();
  strip.rowRange(200, 294).setTo(cv::Scalar(0.35, 0.4, 0.3));
  cv::Mat noise(kH, kW, CV_32FC3);
  cv::randu(noise, cv::Scalar::all(0), cv::Scalar::all(1));
  // A letterboxed still: black bars along the top and the bottom (10 % each) around a
  // landscape; and the sunset under a night-dark sky.
  cv::Mat letterbox = backlit_sunset(0.3f);
  letterbox.rowRange(0, 30).setTo(cv::Scalar::all(0));
  letterbox.rowRange(270, 300).setTo(cv::Scalar::all(0));
  cv::Mat dark_sky = backlit_sunset(0.0f);
  dark_sky.rowRange(0, 220).setTo(cv::Scalar(0.03, 0.03, 0.06));
  for (const cv::Mat& p : {frontlit, night, strip, noise, letterbox, dark_sky}) {
    const photo::Silhouette s = photo::find_silhouette(test::linear_photo(p).view(), sky);
    EXPECT_TRUE(std::isnan(s.skyline_row)) << s.skyline_row;
    EXPECT_TRUE(s.sky_alpha.empty());
  }
}

TEST(Silhouette, NeverThrowsForAnyImageContent) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  for (const int size : {1, 7, 8, 40})
    for (const int channels : {1, 3, 4})
      for (const float fill : {0.0f, 1.0f, nan, inf, -inf}) {
        Image photo(size, size, channels);
        for (float& v : photo.pixels()) v = fill;
        const std::vector<std::uint8_t> sky(std::size_t(size) * size, 0);
        EXPECT_NO_THROW(photo::find_silhouette(photo.view(), sky));
        EXPECT_NO_THROW(photo::find_silhouette(photo.view(), {}));  // a wrong sky size
      }
}

TEST(Silhouette, TheRecedingSkylineIgnoresSpikesAndHasNoSteps) {
  // Land everywhere at row 200 but a post (columns 50-52, up to row 120) and a column broken
  // by a lamp (60: its land starts at row 280); columns 0-9 have no land.
  std::vector<int> top(400, 200);
  for (int x = 50; x < 53; ++x) top[std::size_t(x)] = 120;
  top[60] = 280;
  for (int x = 0; x < 10; ++x) top[std::size_t(x)] = -1;
  const std::vector<double> s = photo::receding_skyline(top);
  ASSERT_EQ(s.size(), top.size());
  for (std::size_t x = 0; x < s.size(); ++x) EXPECT_NEAR(s[x], 200, 1e-9) << x;
  // A slope: the running mean keeps it (away from the ends), column to column within its step.
  std::vector<int> slope(400);
  for (int x = 0; x < 400; ++x) slope[std::size_t(x)] = 150 + x / 4;
  const std::vector<double> t = photo::receding_skyline(slope);
  for (int x = 20; x < 380; ++x) EXPECT_NEAR(t[std::size_t(x)], 150 + x / 4.0, 1.0) << x;
  for (int x = 1; x < 400; ++x) EXPECT_LE(std::abs(t[std::size_t(x)] - t[std::size_t(x - 1)]), 0.5);
  EXPECT_TRUE(photo::receding_skyline({}).empty());
  EXPECT_TRUE(photo::receding_skyline(std::vector<int>(5, -1)).empty());
}

// The estimate: the horizon at the skyline, the cumulus sky; without the rule the level
// fall-back through the middle row, the cumulus standing on the ground.
TEST(Silhouette, TheEstimatePutsTheHorizonAtTheSkylineAndTheCloudInTheSky) {
  const Image photo = test::linear_photo(backlit_sunset());
  const Camera camera = Camera::from_horizontal_fov(kW, kH, 60);
  auto estimate = [&](bool backlit_land) {
    EstimateOptions options;
    options.backlit_land = backlit_land;
    return estimate_scene(photo, camera, Annotations{}, options);
  };
  const SceneEstimate with = estimate(true), without = estimate(false);
  EXPECT_TRUE(with.geometry.backlit_land);
  EXPECT_FALSE(without.geometry.backlit_land);
  EXPECT_NEAR(with.geometry.horizon[0][1], 225, 5);
  EXPECT_NEAR(without.geometry.horizon[0][1], 149.5, 1);
  EXPECT_TRUE(std::isinf(with.geometry.distance_m.at(200, 145, 0)));
  EXPECT_TRUE(std::isfinite(without.geometry.distance_m.at(200, 145, 0)));
  EXPECT_TRUE(std::isfinite(with.geometry.distance_m.at(50, 280, 0)));
  // The land recedes to its skyline in every column (farther up), without steps between
  // neighbouring columns (a lit window at column 100 breaks no column's land).
  const Image& d = with.geometry.distance_m;
  for (int x = 0; x < kW; x += 7) {
    if (x >= 280 && x <= 336) continue;              // the tree and the skyline it raises
    EXPECT_GT(d.at(x, skyline(x) + 2, 0), 60) << x;  // the land's top: far
    EXPECT_LT(d.at(x, kH - 1, 0), 12) << x;          // its bottom: the ground's nearest
    for (int y = skyline(x) + 3; y < kH; ++y) EXPECT_LE(d.at(x, y, 0), d.at(x, y - 1, 0)) << x;
  }
  for (int y = 240; y < kH; y += 5)
    for (int x = 1; x < kW; ++x) {
      if (x >= 280 && x <= 336) continue;  // the tree and the skyline it raises
      const float a = d.at(x - 1, y, 0), b = d.at(x, y, 0);
      if (!std::isfinite(a) || !std::isfinite(b)) continue;
      EXPECT_LT(std::abs(a - b), 0.02 * std::max(a, b)) << x << "," << y;
    }
}

// The photo the rule was made on (gallery/tune after_the_rain): its horizon at the land's
// skyline (rows 640-655), the cumulus' body sky; haze's created edges within the gallery's target.
TEST(Silhouette, AfterTheRainsCumulusIsSkyAndHazeCreatesFewerEdges) {
  const Image photo =
      read_image(std::filesystem::path(MR_SOURCE_DIR) / "gallery" / "tune" / "after_the_rain.jpg");
  const Camera camera = Camera::from_horizontal_fov(photo.width(), photo.height(), 61.9);
  auto haze_edges = [&](bool backlit_land, SceneEstimate& est) {
    EstimateOptions options;
    options.backlit_land = backlit_land;
    est = estimate_scene(photo, camera, Annotations{}, options);
    const FogLayers haze = test::fog_auto_look(photo, camera, est, 2000, 1500, 0.6);
    return test::gallery_created_edges(photo, haze.composite);
  };
  SceneEstimate with, without;
  const double edges_with = haze_edges(true, with), edges_without = haze_edges(false, without);
  RecordProperty("haze_created_pct_with", std::to_string(100 * edges_with));
  RecordProperty("haze_created_pct_without", std::to_string(100 * edges_without));
  EXPECT_TRUE(with.geometry.backlit_land);
  EXPECT_GE(with.geometry.horizon[0][1], 640);
  EXPECT_LE(with.geometry.horizon[0][1], 655);
  for (const auto& [x, y] : {std::pair{640, 500}, std::pair{300, 450}, std::pair{1000, 400}}) {
    EXPECT_TRUE(std::isinf(with.geometry.distance_m.at(x, y, 0))) << x << "," << y;
    EXPECT_TRUE(std::isfinite(without.geometry.distance_m.at(x, y, 0))) << x << "," << y;
  }
  EXPECT_GT(edges_without, 0.0005);  // 0.05 % of the frame
  EXPECT_LT(edges_with, 0.0002);     // the gallery's target, 0.02 %
}

}  // namespace
}  // namespace mr
