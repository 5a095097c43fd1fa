// The automatic sky mask (photo/sky_mask) on synthetic photos of the failure classes found on the
// gallery's tuning half (issue 11): regions that are not sky must not be taken as sky (a grey,
// bluish, textured rock face under the sky; a pale blue flower in a green close-up), without
// losing real sky (soft clouds in a blue sky, blue sky seen beside a tree). Photos are drawn
// display-referred with OpenCV and converted to scene-linear (^2.2) as the estimator expects;
// the horizon is given, so that only the mask is under test. The SkyThroughHaze tests run the
// whole automatic path instead (estimate_scene, fog with the estimate's sky matte, the
// gallery's haze look): a backlit cloud must be seen through the haze layer like the sky
// around it, with no created edge.
#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <string>
#include <vector>

#include "mr/estimate.h"
#include "mr/fog.h"
#include "mr/image.h"
#include "mr/io.h"
#include "mr/scattering.h"
#include "photo/sky_mask.h"
#include "photo/subject.h"
#include "tests/display_luma.h"

namespace mr {
namespace {

constexpr int kW = 640, kH = 480;

Image to_linear(const cv::Mat& display) {  // CV_32FC3 RGB in [0, 1]
  Image img(display.cols, display.rows, 3);
  for (int y = 0; y < display.rows; ++y)
    for (int x = 0; x < display.cols; ++x)
      for (int c = 0; c < 3; ++c)
        img.at(x, y, c) = std::pow(std::clamp(display.at<cv::Vec3f>(y, x)[c], 0.0f, 1.0f), 2.2f);
  return img;
}

// Band-limited luma noise: uniform noise blurred by `sigma_px`, scaled to unit standard
// deviation. Mean gradient of the result ~ amplitude / sigma_px.
cv::Mat smooth_noise(unsigned seed, double sigma_px) {
  cv::Mat n(kH, kW, CV_32F);
  cv::RNG rng(seed);
  rng.fill(n, cv::RNG::UNIFORM, -1.0, 1.0);
  cv::GaussianBlur(n, n, cv::Size(0, 0), sigma_px);
  cv::Scalar mean, sd;
  cv::meanStdDev(n, mean, sd);
  return (n - mean[0]) / sd[0];
}

// Mean display-referred gradient magnitude per pixel (the mask's texture measure, without its
// pre-blur) over a region.
double mean_gradient(const cv::Mat& display, const cv::Mat& region) {
  cv::Mat grey, gx, gy, mag;
  cv::cvtColor(display, grey, cv::COLOR_RGB2GRAY);
  cv::Sobel(grey, gx, CV_32F, 1, 0, 3, 1.0 / 8);
  cv::Sobel(grey, gy, CV_32F, 0, 1, 3, 1.0 / 8);
  cv::magnitude(gx, gy, mag);
  return cv::mean(mag, region)[0];
}

std::array<PixelPoint, 2> level(double row) {
  return {PixelPoint{0.0, row}, PixelPoint{kW - 1.0, row}};
}

double fraction(const std::vector<std::uint8_t>& mask, const cv::Mat& region) {
  std::size_t in = 0, n = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x)
      if (region.at<std::uint8_t>(y, x)) ++n, in += mask[std::size_t(y) * kW + x] != 0;
  return n ? double(in) / double(n) : 0.0;
}

// A blue sky fading to a pale, greyish blue at the horizon (row 330), and above it a mountain
// whose rock has the colour of the sky low down (a bluish grey: B > R, so the mask's colour test
// takes it as blue sky) and a fine texture below the mask's `max_texture` (0.012) but several
// times the sky's. Where its ridge meets the pale sky there is no colour edge, so the rock and
// the sky were one candidate component: the whole face was sky (fog painted it one flat colour;
// aitzgorri in the tuning half). Measured with the core test (roughness): the rock 14.9 % sky
// (2.6 % beyond 16 px of the ridge), the sky 100 %; before it (options off): 99.3 % (100 %).
TEST(SkyMaskClasses, TexturedRockFaceUnderTheSkyIsNotSky) {
  const double horizon = 330;
  cv::Mat img(kH, kW, CV_32FC3), rock(kH, kW, CV_8U, cv::Scalar(0));
  const cv::Vec3f top(0.45f, 0.62f, 0.90f), low(0.60f, 0.64f, 0.72f);
  for (int y = 0; y < kH; ++y) {
    const float t = std::clamp(float(y) / 300.0f, 0.0f, 1.0f);
    for (int x = 0; x < kW; ++x) img.at<cv::Vec3f>(y, x) = top * (1 - t) + low * t;
  }
  // The mountain: a ridge between rows 150 and 220, down to the horizon.
  std::vector<cv::Point> ridge{{0, int(horizon)}};
  for (int x = 0; x <= kW; x += 40)
    ridge.emplace_back(x, int(185 + 35 * std::sin(x * 0.021) + 12 * std::sin(x * 0.09 + 1)));
  ridge.emplace_back(kW, int(horizon));
  cv::fillPoly(rock, std::vector<std::vector<cv::Point>>{ridge}, cv::Scalar(1));
  for (int y = int(horizon) + 1; y < kH; ++y) rock.row(y).setTo(0);  // rock only above
  const cv::Mat grain = smooth_noise(7, 1.2);
  // Below the horizon: a green meadow (textured: not sky either way).
  const cv::Mat grass = smooth_noise(11, 0.8);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      cv::Vec3f& p = img.at<cv::Vec3f>(y, x);
      if (y >= horizon) {
        p = cv::Vec3f(0.35f, 0.55f, 0.2f) + cv::Vec3f(1, 1, 1) * (0.08f * grass.at<float>(y, x));
      } else if (rock.at<std::uint8_t>(y, x)) {
        p = low + cv::Vec3f(1, 1, 1) * (0.016f * grain.at<float>(y, x));
      }
    }
  const double rock_texture = mean_gradient(img, rock);
  std::printf("rock face: mean gradient %.4f per pixel\n", rock_texture);
  ASSERT_GT(rock_texture, 0.006);  // several times the sky's noise ...
  ASSERT_LT(rock_texture, 0.012);  // ... yet below the mask's max_texture (0.012)

  const Image photo = to_linear(img);
  const photo::SkyMask mask = photo::estimate_sky_mask(photo.view(), level(horizon));
  cv::Mat sky_truth(kH, kW, CV_8U, cv::Scalar(0));
  for (int y = 0; y < int(horizon); ++y)
    for (int x = 0; x < kW; ++x) sky_truth.at<std::uint8_t>(y, x) = !rock.at<std::uint8_t>(y, x);
  // The sky away from the ridge by 3 px (the matte's edge band may take a pixel or two). The
  // rock beyond 16 px from the ridge: where the ridge has no edge the sky still reaches into the
  // rock by up to `core_grow` texture windows (2 x 5 px here) from its core, plus the texture
  // window's own reach.
  cv::Mat inner_rock, inner_sky;
  cv::erode(rock, inner_rock, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(33, 33)));
  cv::erode(sky_truth, inner_sky, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(7, 7)));
  const double rock_as_sky = fraction(mask.sky, rock);
  const double inner_rock_as_sky = fraction(mask.sky, inner_rock);
  const double sky_as_sky = fraction(mask.sky, inner_sky);
  std::printf("rock taken as sky %.4f (beyond 16 px of the ridge %.4f), sky kept %.4f\n",
              rock_as_sky, inner_rock_as_sky, sky_as_sky);
  EXPECT_LT(inner_rock_as_sky, 0.05);
  EXPECT_LT(rock_as_sky, 0.25);
  EXPECT_GT(sky_as_sky, 0.98);
}

// Soft white clouds (Gaussian blobs, one with a steeper edge) in a blue gradient sky over a
// textured ground: the core test must keep them (their interiors are as smooth as the sky; their
// edges are within reach of it), and the two clouds whose edge is too steep for the texture
// test must stay sky too (the ring rule). Measured: 96.9 % of the cloud pixels kept (the rest:
// the steepest rims), 99.5 % of the sky; before (options off): 73.7 %, 95.6 %.
TEST(SkyMaskClasses, SoftCloudsInABlueSkyStaySky) {
  const double horizon = 300;
  cv::Mat img(kH, kW, CV_32FC3);
  const cv::Mat grass = smooth_noise(3, 0.8);
  struct Cloud {
    double x, y, r, steep;
  };
  const Cloud clouds[] = {{150, 90, 55, 1}, {420, 140, 70, 1}, {560, 60, 40, 3}, {300, 230, 45, 2}};
  cv::Mat cloud_px(kH, kW, CV_8U, cv::Scalar(0));
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      cv::Vec3f& p = img.at<cv::Vec3f>(y, x);
      if (y >= horizon) {
        p = cv::Vec3f(0.4f, 0.35f, 0.25f) + cv::Vec3f(1, 1, 1) * (0.1f * grass.at<float>(y, x));
        continue;
      }
      const float t = float(y) / float(horizon);
      p = cv::Vec3f(0.30f, 0.50f, 0.85f) * (1 - t) + cv::Vec3f(0.62f, 0.72f, 0.88f) * t;
      float cover = 0;
      for (const Cloud& c : clouds) {
        const double d = std::hypot(x - c.x, (y - c.y) * 1.6) / c.r;
        cover = std::max(cover, float(1 / (1 + std::exp(c.steep * 6 * (d - 1)))));
      }
      p = p * (1 - cover) + cv::Vec3f(0.95f, 0.95f, 0.96f) * cover;
      cloud_px.at<std::uint8_t>(y, x) = cover > 0.2f;
    }
  const Image photo = to_linear(img);
  const photo::SkyMask mask = photo::estimate_sky_mask(photo.view(), level(horizon));
  cv::Mat sky_truth(kH, kW, CV_8U, cv::Scalar(0));
  sky_truth.rowRange(0, int(horizon) - 3).setTo(1);
  const double clouds_kept = fraction(mask.sky, cloud_px);
  const double sky_kept = fraction(mask.sky, sky_truth);
  std::printf("clouds kept %.4f, sky kept %.4f\n", clouds_kept, sky_kept);
  EXPECT_GT(clouds_kept, 0.95);
  EXPECT_GT(sky_kept, 0.99);
}

// A close-up: green foliage fills the frame (textured), a pale blue flower (smooth petals) sits
// above the (fall-back, mid-frame) horizon, one touching the left border. Blue, smooth and large
// enough, both were sky before (a flat fog-coloured blob in the haze look). With no blue sky at
// the top border they are not. Measured: 0 sky pixels (before: 9497, both flowers, 3 % of the
// frame).
TEST(SkyMaskClasses, PaleBlueFlowerInAGreenCloseUpIsNotSky) {
  cv::Mat img(kH, kW, CV_32FC3);
  const cv::Mat leaves = smooth_noise(5, 1.0);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x)
      img.at<cv::Vec3f>(y, x) =
          cv::Vec3f(0.25f, 0.45f, 0.15f) + cv::Vec3f(1, 1, 1) * (0.12f * leaves.at<float>(y, x));
  const cv::Vec3f petal(0.68f, 0.76f, 0.95f);
  cv::circle(img, {260, 140}, 45, cv::Scalar(petal[0], petal[1], petal[2]), cv::FILLED,
             cv::LINE_AA);
  cv::ellipse(img, {20, 90}, {40, 30}, 0, 0, 360, cv::Scalar(petal[0], petal[1], petal[2]),
              cv::FILLED, cv::LINE_AA);
  const Image photo = to_linear(img);
  const photo::SkyMask mask = photo::estimate_sky_mask(photo.view(), level(kH / 2.0 - 0.5));
  std::printf("close-up: %zu sky pixels\n", mask.pixels);
  EXPECT_EQ(mask.pixels, 0u);
}

// The same rule keeps real sky that does not reach the top border: blue sky at the top and
// a patch of the same sky beside a tree trunk (cut off from the top by the canopy) at the right
// border. Measured: 100 % of both kept (as before the rule).
TEST(SkyMaskClasses, DetachedSkyUnderABlueSkyStaysSky) {
  const double horizon = 330;
  cv::Mat img(kH, kW, CV_32FC3);
  const cv::Mat leaves = smooth_noise(9, 1.0);
  cv::Mat open_sky(kH, kW, CV_8U, cv::Scalar(0)), side_sky(kH, kW, CV_8U, cv::Scalar(0));
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      cv::Vec3f& p = img.at<cv::Vec3f>(y, x);
      const bool canopy = y >= 100 && y < 160 && x >= 300;  // the canopy's lower edge
      const bool trunk = x >= 300 && x < 360 && y >= 100;
      const bool ground = y >= horizon;
      if (canopy || trunk || ground) {
        p = cv::Vec3f(0.3f, 0.38f, 0.18f) + cv::Vec3f(1, 1, 1) * (0.12f * leaves.at<float>(y, x));
      } else {
        const float t = float(y) / float(horizon);
        p = cv::Vec3f(0.35f, 0.55f, 0.88f) * (1 - t) + cv::Vec3f(0.55f, 0.68f, 0.90f) * t;
        (x >= 360 && y >= 160 ? side_sky : open_sky).at<std::uint8_t>(y, x) = 1;
      }
    }
  cv::Mat inner_open, inner_side;
  const cv::Mat k = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(9, 9));
  cv::erode(open_sky, inner_open, k);
  cv::erode(side_sky, inner_side, k);
  const Image photo = to_linear(img);
  const photo::SkyMask mask = photo::estimate_sky_mask(photo.view(), level(horizon));
  const double open_kept = fraction(mask.sky, inner_open);
  const double side_kept = fraction(mask.sky, inner_side);
  std::printf("open sky kept %.4f, detached sky kept %.4f\n", open_kept, side_kept);
  EXPECT_GT(open_kept, 0.99);
  EXPECT_GT(side_kept, 0.99);
}

// Under a canopy (the tuning photo scenetext01: a sign under trees, no sky in the frame): the
// shaded foliage in a corner is blurred (out of focus) into a dim, barely bluish grey (display
// RGB 0.29, 0.28, 0.34: B > R, smooth), which the colour test took as blue sky touching the
// top border; the sky's distance then spread over the foliage around it (in haze a white blob
// with a blocky edge, 0.34 % created edges). Real blue sky seen through the same canopy, in
// gaps reaching the top border, stays sky. Measured: shade taken as sky 0 (before: 1.0), sky
// gaps kept 1.0.
TEST(SkyMaskClasses, DimBluishShadeUnderACanopyIsNotSkyGapsAre) {
  const double horizon = 330;
  cv::Mat img(kH, kW, CV_32FC3);
  const cv::Mat leaves = smooth_noise(31, 1.0);
  cv::Mat shade(kH, kW, CV_32F, cv::Scalar(0)), gaps(kH, kW, CV_8U, cv::Scalar(0));
  cv::circle(shade, {kW - 1, 0}, 120, cv::Scalar(1), cv::FILLED);
  cv::GaussianBlur(shade, shade, cv::Size(0, 0), 12.0);
  const cv::Point holes[] = {{120, 0}, {230, 20}, {330, 0}};
  for (const cv::Point& c : holes) cv::circle(gaps, c, 34, cv::Scalar(1), cv::FILLED);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      cv::Vec3f& p = img.at<cv::Vec3f>(y, x);
      const cv::Vec3f leaf =
          cv::Vec3f(0.22f, 0.36f, 0.16f) + cv::Vec3f(1, 1, 1) * (0.1f * leaves.at<float>(y, x));
      const float a = shade.at<float>(y, x);
      p = leaf * (1 - a) + cv::Vec3f(0.29f, 0.28f, 0.34f) * a;
      if (gaps.at<std::uint8_t>(y, x) && y < horizon) p = cv::Vec3f(0.42f, 0.60f, 0.90f);
    }
  cv::Mat shade_core = shade > 0.9f, inner_gaps;
  cv::erode(gaps, inner_gaps, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(9, 9)));
  const Image photo = to_linear(img);
  const photo::SkyMask mask = photo::estimate_sky_mask(photo.view(), level(horizon));
  const double shade_as_sky = fraction(mask.sky, shade_core);
  const double gaps_kept = fraction(mask.sky, inner_gaps);
  std::printf("dim bluish shade taken as sky %.4f, sky gaps kept %.4f\n", shade_as_sky, gaps_kept);
  EXPECT_LT(shade_as_sky, 0.01);
  EXPECT_GT(gaps_kept, 0.99);
}

// ---- Issue 11 item 4 through the whole automatic path (estimate, fog with the matte) ----------

// With MR_TEST_IMAGES=<folder>: the photos and fogged results as PNGs, to look at.
void dump(const std::string& name, const Image& image) {
  const char* folder = std::getenv("MR_TEST_IMAGES");
  if (!folder || !*folder) return;
  write_image(std::string(folder) + "/" + name + ".png", image);
}

// The gallery's haze look (2 km visibility, 1.5 km layer top, sky light only) on the automatic
// estimate, with its sky matte, as `mr fog --depth auto --scene gallery/looks/haze.json` does.
FogLayers haze(const Image& photo, const Camera& camera, SceneEstimate* est_out = nullptr) {
  const SceneEstimate est = estimate_scene(photo, camera, Annotations{});
  FogScene s = est.scene;
  const float sigma = float(extinction_from_visibility(2000));
  s.medium.sigma_t_per_m = {sigma, sigma, sigma};
  s.medium.layer_top_m = 1500;
  s.render.backend = Backend::cpu;
  FogLayers out = fog(photo, est.geometry.distance_m, est.geometry.sky_alpha, camera, s);
  if (est_out) *est_out = est;
  return out;
}

// Display-referred luma blurred by 1 px and its gradient magnitude (central differences), as
// gallery/measures.py's created-edge measure takes them.
cv::Mat edge_strength(const Image& img) {
  cv::Mat l = mr::test::display_luma(img);
  cv::GaussianBlur(l, l, cv::Size(7, 7), 1.0, 1.0, cv::BORDER_REPLICATE);
  cv::Mat gx, gy, g;
  cv::Sobel(l, gx, CV_32F, 1, 0, 1, 0.5, 0, cv::BORDER_REPLICATE);
  cv::Sobel(l, gy, CV_32F, 0, 1, 1, 0.5, 0, cv::BORDER_REPLICATE);
  cv::magnitude(gx, gy, g);
  return g;
}

// The measure: pixels where the fogged image's gradient is more than twice the photo's
// and above 0.01 luma per pixel; counted inside `region` (or everywhere when empty), as a
// fraction of the whole image (the gallery's unit).
double created_edges(const Image& photo, const Image& fogged, const cv::Mat& region,
                     const std::string& name = "") {
  const cv::Mat gp = edge_strength(photo), gf = edge_strength(fogged);
  std::size_t n = 0;
  Image map(photo.width(), photo.height(), 3);
  for (int y = 0; y < gp.rows; ++y)
    for (int x = 0; x < gp.cols; ++x) {
      const bool c = gf.at<float>(y, x) > 2 * gp.at<float>(y, x) && gf.at<float>(y, x) > 0.01f &&
                     (region.empty() || region.at<std::uint8_t>(y, x));
      n += c;
      for (int k = 0; k < 3; ++k) map.at(x, y, k) = c ? float(k == 0) : 0.3f * fogged.at(x, y, k);
    }
  if (!name.empty()) dump(name, map);
  return double(n) / double(gp.total());
}

// A backlit cloud (the held-out failure: part of such a cloud taken as clear sky, and in haze a
// flat, hard-edged patch of sky colour cut into it): a blue sky over a textured meadow, and in it
// a large cloud whose thin rim is lit bright silver by the sun behind it and whose thick body is
// dark grey, with a faint texture; no hard edge anywhere inside it. The fogged result must not
// have an edge the photo does not have, inside the cloud or along its rim.
cv::Mat backlit_cloud_display(cv::Mat* cloud_region) {
  const double horizon = 360;
  cv::Mat img(kH, kW, CV_32FC3);
  const cv::Mat grass = smooth_noise(21, 0.8), puff = smooth_noise(23, 9.0),
                grain = smooth_noise(25, 2.5);
  cv::Mat density(kH, kW, CV_32F);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      // Thickness: two overlapping lobes with a wavy outline, fading out over ~25 px.
      const double d1 = std::hypot((x - 250.0) / 190.0, (y - 150.0) / 95.0),
                   d2 = std::hypot((x - 440.0) / 130.0, (y - 120.0) / 80.0);
      const double d = std::min(d1, d2) + 0.08 * puff.at<float>(y, x);
      density.at<float>(y, x) = float(std::clamp((1.0 - d) / 0.3, 0.0, 1.0));
    }
  if (cloud_region) *cloud_region = density > 0.0f;
  const cv::Vec3f zenith(0.16f, 0.36f, 0.78f), low(0.55f, 0.68f, 0.88f);
  const cv::Vec3f lit(0.96f, 0.94f, 0.91f), body(0.30f, 0.31f, 0.35f);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      cv::Vec3f& p = img.at<cv::Vec3f>(y, x);
      if (y >= horizon) {
        p = cv::Vec3f(0.3f, 0.45f, 0.18f) + cv::Vec3f(1, 1, 1) * (0.08f * grass.at<float>(y, x));
        continue;
      }
      const float t = float(y / horizon);
      const cv::Vec3f sky = zenith * (1 - t) + low * t;
      const float dn = density.at<float>(y, x);
      const float cover = std::min(1.0f, 2.5f * dn * dn * (3 - 2 * dn));
      // The sun is behind the cloud's upper left: its thin upper-left part glows silver, its
      // thick body is dark; the light fades across the cloud over ~150 px, with no edge.
      const float shade = std::clamp(float((x - 120) + 1.6 * (y - 60)) / 260.0f, 0.0f, 1.0f);
      const float dark = shade * shade * (3 - 2 * shade);
      const cv::Vec3f cloud =
          lit * (1 - dark) + body * dark + cv::Vec3f(1, 1, 1) * (0.03f * grain.at<float>(y, x));
      p = sky * (1 - cover) + cloud * cover;
    }
  return img;
}

TEST(SkyThroughHaze, BacklitDarkCloudIsSeenThroughTheLayerWithNoCreatedEdge) {
  cv::Mat cloud;
  const cv::Mat display = backlit_cloud_display(&cloud);
  const Image photo = to_linear(display);
  const Camera camera = Camera::from_horizontal_fov(kW, kH, 60);
  SceneEstimate est;
  const FogLayers fogged = haze(photo, camera, &est);
  dump("backlit_cloud_photo", photo);
  dump("backlit_cloud_haze", fogged.composite);
  Image alpha_view(kW, kH, 3);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x)
      for (int c = 0; c < 3; ++c) alpha_view.at(x, y, c) = est.geometry.sky_alpha.at(x, y, 0);
  dump("backlit_cloud_alpha", alpha_view);
  // A cloud is far above a 1.5 km haze layer: it is seen through the whole layer, like the
  // sky around it. Bar: no pixel of the cloud's body (1 px in from its visible edge) lets more
  // light through than the most transparent pixel of the open sky (the top row) plus 0.002.
  // Before: the dark body and the part of the lit rim beyond the core test's reach were a
  // surface 46 m away (transmittance ~0.91), the rest of the cloud sky (~0.01).
  float sky_t = 0;
  for (int x = 0; x < kW; ++x)
    if (!cloud.at<std::uint8_t>(0, x)) sky_t = std::max(sky_t, fogged.transmittance.at(x, 0, 1));
  cv::Mat body;
  cv::erode(cloud, body, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(3, 3)));
  float worst = 0;
  std::size_t clear = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x)
      if (body.at<std::uint8_t>(y, x)) {
        const float t = fogged.transmittance.at(x, y, 1);
        worst = std::max(worst, t);
        clear += t > sky_t + 0.002f;
      }
  cv::Mat around;  // the cloud and a margin of 8 px around it
  cv::dilate(cloud, around, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(17, 17)));
  const double inside = created_edges(photo, fogged.composite, around, "backlit_cloud_edges");
  const double all = created_edges(photo, fogged.composite, cv::Mat());
  std::printf(
      "backlit cloud, haze: open sky transmittance <= %.4f; cloud body: largest %.4f, %zu of "
      "%d pixels clearer than the sky; created-edge pixels in and around the cloud %.4f %%, "
      "whole image %.4f %%\n",
      sky_t, worst, clear, cv::countNonZero(body), 100 * inside, 100 * all);
  EXPECT_EQ(clear, 0u);
  EXPECT_LE(inside, 2e-4);
  EXPECT_LE(all, 2e-4);
}

// ---- Issue 11: a close-up's blurred background is not sky ------------------------------------

// A close-up (a flower head on its stem, sharp, with fine texture) against a background blurred
// smooth by the shallow depth of field: lavender at the top (bokeh of flowers: B > R, saturated,
// no texture: the mask's tests take it as sky), running with no edge into a muted green-grey
// and, lower down, out-of-focus foliage. The real failure (honey_bee, kleiber): the lavender was
// sky, seen through the whole haze layer, while the rest of the background and the subject
// stood a few metres away: a flat patch of fog colour whose edge cuts the smooth bokeh.
cv::Mat lavender_closeup_display(cv::Mat* subject_region) {
  cv::Mat img(kH, kW, CV_32FC3);
  const cv::Mat blobs = smooth_noise(31, 30.0), leaves = smooth_noise(33, 5.0),
                petals = smooth_noise(35, 0.7);
  const cv::Vec3f lavender(0.74f, 0.64f, 0.90f), sage(0.50f, 0.56f, 0.44f),
      foliage(0.30f, 0.42f, 0.22f);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      // Lavender down to row ~170, a smooth ramp to sage by ~300, foliage below.
      const float t = std::clamp(float(y - 170) / 130.0f, 0.0f, 1.0f);
      const float u = std::clamp(float(y - 300) / 80.0f, 0.0f, 1.0f);
      const float ts = t * t * (3 - 2 * t), us = u * u * (3 - 2 * u);
      cv::Vec3f p = lavender * (1 - ts) + sage * ts;
      p = p * (1 - us) + foliage * us;
      p += cv::Vec3f(1, 1, 1) *
           (0.03f * blobs.at<float>(y, x) + 0.10f * us * leaves.at<float>(y, x));
      img.at<cv::Vec3f>(y, x) = p;
    }
  // The subject: a sharp flower head with fine texture on a stem reaching the bottom.
  cv::Mat subject(kH, kW, CV_8U, cv::Scalar(0));
  cv::circle(subject, cv::Point(250, 190), 115, cv::Scalar(255), cv::FILLED, cv::LINE_8);
  std::vector<cv::Point> stem = {{238, 300}, {262, 300}, {280, 479}, {256, 479}};
  cv::fillConvexPoly(subject, stem, cv::Scalar(255), cv::LINE_8);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x)
      if (subject.at<std::uint8_t>(y, x)) {
        const float n = 0.10f * petals.at<float>(y, x);
        const bool head = std::hypot(x - 250.0, y - 190.0) <= 115;
        img.at<cv::Vec3f>(y, x) = head ? cv::Vec3f(0.95f + n, 0.72f + n, 0.18f + n)
                                       : cv::Vec3f(0.22f + n, 0.40f + n, 0.12f + n);
      }
  if (subject_region) *subject_region = subject;
  return img;
}

TEST(SkyThroughHaze, BlurredLavenderBackgroundOfACloseUpIsNotSky) {
  cv::Mat subject;
  const cv::Mat display = lavender_closeup_display(&subject);
  const Image photo = to_linear(display);
  const Camera camera = Camera::from_horizontal_fov(kW, kH, 60);
  // The mask alone (level horizon through the middle) takes the lavender as sky: the case.
  const photo::SkyMask raw = photo::estimate_sky_mask(photo.view(), level(kH / 2.0 - 0.5));
  cv::Mat lavender_core(kH, kW, CV_8U, cv::Scalar(0));
  lavender_core(cv::Rect(0, 0, kW, 150)).setTo(255);
  lavender_core.setTo(0, subject);
  const double raw_sky = fraction(raw.sky, lavender_core);
  SceneEstimate est;
  const FogLayers hazed = haze(photo, camera, &est);
  std::size_t sky = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) sky += est.geometry.sky_alpha.at(x, y, 0) > 0;
  // Dense fog (the gallery's: 60 m visibility, 80 m top) on the same estimate.
  FogScene s = est.scene;
  const float sigma = float(extinction_from_visibility(60));
  s.medium.sigma_t_per_m = {sigma, sigma, sigma};
  s.medium.layer_top_m = 80;
  s.render.backend = Backend::cpu;
  const FogLayers dense = fog(photo, est.geometry.distance_m, est.geometry.sky_alpha, camera, s);
  dump("lavender_closeup_photo", photo);
  dump("lavender_closeup_haze", hazed.composite);
  dump("lavender_closeup_dense", dense.composite);
  const double haze_edges = created_edges(photo, hazed.composite, cv::Mat(), "lavender_haze_edges");
  const double dense_edges =
      created_edges(photo, dense.composite, cv::Mat(), "lavender_dense_edges");
  // In dense fog the lavender stands with the subject, a few metres away, like the sage below
  // it: before, it was sky, opaque (seen through the whole layer: transmittance 0) next to the
  // clear sage. Created edges before (the same photo through mr fog --depth auto of the branch
  // base, gallery/measures.py): haze 0.49 %, dense 0.007 %.
  auto mean_t = [&](const FogLayers& f, int y0, int y1) {
    double sum = 0;
    int count = 0;
    for (int y = y0; y < y1; ++y)
      for (int x = 400; x < kW; ++x) sum += f.transmittance.at(x, y, 1), ++count;
    return sum / count;
  };
  const double t_lavender = mean_t(dense, 10, 60), t_sage = mean_t(dense, 330, 380);
  std::printf(
      "lavender close-up (%s; %.2f of the frame blurred, %.2f sharp): mask alone takes %.3f of the "
      "lavender as sky; estimate: %zu "
      "pixels of sky matte; dense fog transmittance lavender %.3f, sage %.3f; created-edge "
      "pixels haze %.4f %%, dense %.4f %%\n",
      est.geometry.scale_cue.c_str(), est.geometry.defocused_fraction, est.geometry.sharp_fraction,
      raw_sky, sky, t_lavender, t_sage, 100 * haze_edges, 100 * dense_edges);
  EXPECT_GT(raw_sky, 0.9);  // the failure class is present
  EXPECT_EQ(sky, 0u);
  EXPECT_GT(t_lavender, 0.6);
  EXPECT_GT(t_sage, 0.6);
  EXPECT_LE(haze_edges, 2e-4);
  EXPECT_LE(dense_edges, 2e-4);
}

// The counterpart: a close-up whose background is a clear blue sky across the top (a flower
// photographed from below against the sky) keeps its sky.
TEST(SkyThroughHaze, ClearBlueSkyBehindACloseUpStaysSky) {
  cv::Mat subject;
  cv::Mat display = lavender_closeup_display(&subject);
  const cv::Mat blobs = smooth_noise(37, 30.0);
  for (int y = 0; y < 230; ++y)
    for (int x = 0; x < kW; ++x) {
      if (subject.at<std::uint8_t>(y, x)) continue;
      const float t = float(y) / 230.0f, u = std::clamp(float(y - 170) / 60.0f, 0.0f, 1.0f);
      const cv::Vec3f sky =
          cv::Vec3f(0.25f, 0.50f, 0.88f) * (1 - t) + cv::Vec3f(0.55f, 0.70f, 0.92f) * t;
      cv::Vec3f& p = display.at<cv::Vec3f>(y, x);
      p = sky * (1 - u) + p * u + cv::Vec3f(1, 1, 1) * (0.01f * blobs.at<float>(y, x));
    }
  const Image photo = to_linear(display);
  const Camera camera = Camera::from_horizontal_fov(kW, kH, 60);
  SceneEstimate est;
  haze(photo, camera, &est);
  cv::Mat sky_core(kH, kW, CV_8U, cv::Scalar(0));
  sky_core(cv::Rect(0, 0, kW, 120)).setTo(255);
  sky_core.setTo(0, subject);
  std::size_t in = 0, total = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x)
      if (sky_core.at<std::uint8_t>(y, x))
        ++total, in += est.geometry.sky_alpha.at(x, y, 0) >= 0.5f;
  std::printf("blue sky behind a close-up (%s): %.3f of the open sky kept\n",
              est.geometry.scale_cue.c_str(), double(in) / double(total));
  EXPECT_GT(double(in) / double(total), 0.95);
}

// The standing subject's search (photo/subject.h) never throws for any image content: tiny
// frames, all subject, nearly no background for GrabCut's colour models (which need several
// pixels of each), one channel, NaN and infinite pixels. What it returns is the photo's size or
// empty, and only where the ground mask found a standing subject.
TEST(StandingSubject, NeverThrowsForAnyImageContent) {
  const std::array<PixelPoint, 2> horizon{PixelPoint{0, 3.5}, PixelPoint{15, 3.5}};
  for (const int size : {8, 9, 16, 40}) {
    for (const int background : {0, 1, 2, 3, 7}) {  // pixels neither subject nor sky
      for (const int channels : {1, 3})
        for (const bool with_sky : {true, false}) {
          Image photo(size, size, channels);
          const std::size_t n = std::size_t(size) * size;
          photo::GroundMask ground;
          ground.valid = true;
          ground.standing_subject = true;
          ground.width = ground.height = size;
          ground.ground.assign(n, 0);
          ground.coloured.assign(n, 0);
          std::vector<std::uint8_t> sky(n, 0);
          for (int y = 0; y < size; ++y)
            for (int x = 0; x < size; ++x) {
              const std::size_t i = std::size_t(y) * size + x;
              for (int c = 0; c < channels; ++c)
                photo.at(x, y, c) = (x * 7 + y * 3 + c) % 5 == 0 ? 0.9f : 0.05f;
              if (with_sky && y == 0 && x >= background) sky[i] = 1;  // the top row: sky
              if (y == 0 && x < background) ground.coloured[i] = 1;
            }
          photo.at(1, size - 1, 0) = std::numeric_limits<float>::quiet_NaN();
          photo.at(2, size - 1, 0) = std::numeric_limits<float>::infinity();
          photo::StandingSubject s;
          EXPECT_NO_THROW(s = photo::find_standing_subject(photo.view(), horizon, sky, ground))
              << size << " px, " << background << " background pixels, " << channels << " channels";
          EXPECT_TRUE(s.pixels.empty() || s.pixels.size() == n);
          for (std::size_t i = 0; i < s.pixels.size(); ++i) EXPECT_FALSE(s.pixels[i] && sky[i]);
        }
    }
  }
  // No standing subject found by the ground mask, or a mask of another size: nothing.
  Image photo(16, 16, 3);
  photo::GroundMask ground;
  ground.valid = true;
  ground.coloured.assign(256, 0);
  EXPECT_TRUE(
      photo::find_standing_subject(photo.view(), horizon, std::vector<std::uint8_t>(256, 0), ground)
          .pixels.empty());
  ground.standing_subject = true;
  EXPECT_TRUE(
      photo::find_standing_subject(photo.view(), horizon, std::vector<std::uint8_t>(10, 0), ground)
          .pixels.empty());
}

}  // namespace
}  // namespace mr
