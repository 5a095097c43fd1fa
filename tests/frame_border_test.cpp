// Issue 11: the frame around a picture (a scanned print's border) is not the scene
// (photo/frame_border.h): found where it is, nowhere else, and veiled as the picture's edge
// beside it (the canyon couple's dark top edge had lent its darkness to the sky's matte under
// it: a dark line in haze).
#include <gtest/gtest.h>

#include <opencv2/core.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <random>

#include "mr/estimate.h"
#include "mr/io.h"
#include "photo/frame_border.h"
#include "tests/gallery_look.h"

namespace mr {
namespace {

// A display-referred picture: a clear sky over land, h x w.
cv::Mat sky_over_land(int w, int h) {
  cv::Mat p(h, w, CV_32FC3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float t = float(y) / h;
      p.at<cv::Vec3f>(y, x) = y < h / 2 ? cv::Vec3f(0.55f + 0.2f * t, 0.72f + 0.1f * t, 0.9f)
                                        : cv::Vec3f(0.35f, 0.3f + 0.1f * float(x % 7) / 7, 0.2f);
    }
  return p;
}

// A scanned print's top edge: `lines` rows of uneven dark grey (a curled print's shadow, 0.18 to
// 0.42, and the scanner's grain), then a blurred row between it and the picture.
void scan_edge_on_top(cv::Mat& p, int lines, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> grain(-0.03f, 0.03f);
  for (int y = 0; y < lines; ++y)
    for (int x = 0; x < p.cols; ++x) {
      const float v = 0.3f + 0.09f * std::sin(x / 23.0f) + grain(rng);
      p.at<cv::Vec3f>(y, x) = cv::Vec3f(v, v + 0.01f, v + 0.03f);
    }
  for (int x = 0; x < p.cols; ++x)
    p.at<cv::Vec3f>(lines, x) =
        0.5f * (p.at<cv::Vec3f>(lines - 1, x) + p.at<cv::Vec3f>(lines + 1, x));
}

// The gallery's haze look over an estimate: its created-edge pixels in the top 12 rows (under a
// print's top edge).
std::size_t haze_created_in_top_rows(const Image& photo, const Camera& camera,
                                     const SceneEstimate& est) {
  const FogLayers haze = test::fog_auto_look(photo, camera, est, 2000, 1500, 0.6);
  Image created;
  test::gallery_created_edges(photo, haze.composite, &created);
  std::size_t band = 0;
  for (int y = 0; y < 12; ++y)
    for (int x = 0; x < photo.width(); ++x) band += created.at(x, y, 0) == 1.0f;
  return band;
}

TEST(FrameBorder, AScannedPrintsUnevenTopEdgeIsFoundAndNothingElse) {
  cv::Mat p = sky_over_land(400, 300);
  scan_edge_on_top(p, 3, 7);
  const photo::FrameBorder b = photo::find_frame_border(test::linear_photo(p).view());
  EXPECT_GE(b.top, 3);
  EXPECT_LE(b.top, 5);
  EXPECT_EQ(b.bottom, 0);
  EXPECT_EQ(b.left, 0);
  EXPECT_EQ(b.right, 0);
}

TEST(FrameBorder, PicturesWithoutAFrameHaveNone) {
  // A clear sky to the top edge; a dark night sky over dark land; a white product shot; noise.
  cv::Mat night(300, 400, CV_32FC3, cv::Scalar(0.04, 0.04, 0.06));
  night.rowRange(200, 300).setTo(cv::Scalar(0.08, 0.07, 0.05));
  cv::Mat white(300, 400, CV_32FC3, cv::Scalar(0.97, 0.97, 0.97));
  cv::rectangle(white, cv::Rect(150, 100, 100, 120), cv::Scalar(0.6, 0.2, 0.1), cv::FILLED);
  cv::Mat noise(300, 400, CV_32FC3);
  cv::randu(noise, cv::Scalar::all(0), cv::Scalar::all(1));
  for (const cv::Mat& p : {sky_over_land(400, 300), night, white, noise}) {
    const photo::FrameBorder b = photo::find_frame_border(test::linear_photo(p).view());
    EXPECT_FALSE(b.any()) << b.top << " " << b.bottom << " " << b.left << " " << b.right;
  }
  // A dark band thicker than a border (3 % of the height) is the picture's.
  cv::Mat thick = sky_over_land(400, 300);
  thick.rowRange(0, 20).setTo(cv::Scalar(0.3, 0.3, 0.31));
  EXPECT_FALSE(photo::find_frame_border(test::linear_photo(thick).view()).any());
}

TEST(FrameBorder, NeverThrowsForAnyImageContent) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  for (const int size : {1, 15, 16, 40})
    for (const int channels : {1, 3, 4})
      for (const float fill : {0.0f, 1.0f, nan, inf, -inf}) {
        Image photo(size, size, channels);
        for (float& v : photo.pixels()) v = fill;
        EXPECT_NO_THROW(photo::find_frame_border(photo.view()));
      }
}

// The estimate veils the border as the picture's edge beside it, and the sky under it keeps
// its own fog: before, the dark rows were sky, the sky's matte under them mixed their darkness
// in, and the haze drew a dark line under the edge (canyon_couple: 0.18 % created edges, most
// of them in the top 8 rows).
TEST(FrameBorder, TheSkyUnderAScannedEdgeIsVeiledAsTheRestOfTheSky) {
  cv::Mat p = sky_over_land(400, 300);
  scan_edge_on_top(p, 3, 11);
  const Image photo = test::linear_photo(p);
  const Camera camera = Camera::from_horizontal_fov(photo.width(), photo.height(), 60);
  const SceneEstimate est = estimate_scene(photo, camera, Annotations{});
  const int top = photo::find_frame_border(photo.view()).top;
  EXPECT_EQ(est.geometry.frame_border_pixels, std::size_t(photo.width()) * std::size_t(top));
  EXPECT_GT(est.geometry.sky_pixels, std::size_t(photo.width()) * 100);
  for (int x = 0; x < photo.width(); x += 37)  // sky, as the picture's top row
    EXPECT_TRUE(std::isinf(est.geometry.distance_m.at(x, 0, 0))) << x;
  EXPECT_EQ(haze_created_in_top_rows(photo, camera, est), 0u);
}

// The photo the border was found on (gallery/tune canyon_couple: a scanned print, an uneven dark
// edge along the top and a grey strip down the left). Haze created edges in its top 12 rows:
// the dark line under the edge.
TEST(FrameBorder, TheCanyonPrintsTopEdgeDrawsNoLineInHaze) {
  const Image photo =
      read_image(std::filesystem::path(MR_SOURCE_DIR) / "gallery" / "tune" / "canyon_couple.jpg");
  const Camera camera = Camera::from_horizontal_fov(photo.width(), photo.height(), 60);
  auto top_band_created = [&](bool frame_border) {
    EstimateOptions options;
    options.frame_border = frame_border;
    const SceneEstimate est = estimate_scene(photo, camera, Annotations{}, options);
    EXPECT_EQ(est.geometry.frame_border_pixels > 0, frame_border);
    return haze_created_in_top_rows(photo, camera, est);
  };
  const std::size_t with = top_band_created(true), without = top_band_created(false);
  RecordProperty("top_band_created_with", int(with));
  RecordProperty("top_band_created_without", int(without));
  EXPECT_GT(without, 400u);  // 0.1 % of the frame
  EXPECT_LT(with, without / 3);
}

}  // namespace
}  // namespace mr
