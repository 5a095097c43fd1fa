// The sky matte's spill past a sharp edge into the surface (photo/sky_matte.h, trim_matte_spill;
// issue 11, created edges of haze). The tuning half's scenetext06 (a dark tiled roof and
// chimneys under a white sky): the guided filter's ramp ran three or four pixels into the roof
// past the photo's one-pixel edge (alpha 0.07, 0.05, 0.01, 0.01), SkyMask's unmixing kept part
// of it on pixels off the line between the two sides' colours (the roof's hue and texture), and
// the haze's fog mix laid a faint band of the sky's opaque fog over the roof beside the edge: a
// second edge the photo does not have. Drawn display-referred with OpenCV, converted to
// scene-linear (^2.2) as the estimator expects.
#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <random>
#include <vector>

#include "mr/estimate.h"
#include "mr/image.h"
#include "photo/sky_matte.h"
#include "tests/gallery_look.h"

namespace mr {
namespace {

using test::linear;

// A row of gabled roofs of dark, textured, reddish-brown tiles with chimneys, under a white sky
// with pale blue patches, on dark land below an annotated horizon; the roofline a sharp edge (a
// lens of 0.7 px).
constexpr int kW = 640, kH = 400, kHorizon = 300;
struct RoofPhoto {
  Image photo;
  cv::Mat roof_inside;  // the roof's rim, 1 to 4 px inside its outline
};
RoofPhoto roof_photo() {
  cv::Mat m(kH, kW, CV_32FC3);
  std::mt19937 rng(6);
  std::uniform_real_distribution<float> grain(-0.05f, 0.05f);
  // The sky: white, bluish toward the top, with a soft pale-blue patch.
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const float t = float(y) / kHorizon;
      const float patch =
          std::exp(-(std::pow((x - 180.0f) / 120, 2.0f) + std::pow((y - 60.0f) / 50, 2.0f)));
      cv::Vec3f c = cv::Vec3f(0.90f, 0.93f, 0.98f) * (1 - 0.3f * (1 - t)) +
                    cv::Vec3f(0.96f, 0.97f, 0.98f) * 0.3f * (1 - t);
      c = c * (1 - 0.5f * patch) + cv::Vec3f(0.62f, 0.76f, 0.95f) * 0.5f * patch;
      m.at<cv::Vec3f>(y, x) = c;
    }
  // The roofs: a gable line with two slopes per house, and chimneys.
  cv::Mat roof(kH, kW, CV_8U, cv::Scalar(0));
  std::vector<cv::Point> outline{{0, kHorizon + 1}, {0, 170}};
  for (int house = 0; house < 3; ++house) {
    const int x0 = house * 214;
    outline.push_back({x0 + 107, 100 + 15 * house});
    outline.push_back({x0 + 214, 170});
  }
  outline.push_back({kW - 1, kHorizon + 1});
  cv::fillPoly(roof, std::vector<std::vector<cv::Point>>{outline}, cv::Scalar(255));
  // Chimneys of 10-26 px with their pots, and a flat parapet wall between the second and
  // third house (scenetext06's edges were on chimney tops and a wall's top).
  for (int k = 0; k < 9; ++k) {
    const int cx = 20 + 70 * k, cw = 10 + 2 * k, top = 80 + 9 * (k % 4);
    cv::rectangle(roof, cv::Point(cx, top), cv::Point(cx + cw, 200), cv::Scalar(255), cv::FILLED);
    cv::rectangle(roof, cv::Point(cx + 2, top - 8), cv::Point(cx + cw / 2, top), cv::Scalar(255),
                  cv::FILLED);
  }
  cv::rectangle(roof, cv::Point(380, 140), cv::Point(470, 200), cv::Scalar(255), cv::FILLED);
  // A dark rim along the outline (ridge tiles, the fascia's shadow): 2 px darker than the tiles
  // (the real roof's first pixels under the sky are its darkest).
  cv::Mat core;
  cv::erode(roof, core, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(5, 5)));
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      if (!roof.at<std::uint8_t>(y, x) || y >= kHorizon) continue;
      if (!core.at<std::uint8_t>(y, x)) {
        m.at<cv::Vec3f>(y, x) = cv::Vec3f(0.16f, 0.10f, 0.09f) * (1 + 2 * grain(rng));
        continue;
      }
      // Tiles: rows 6 px high, joints darker, each tile's shade its own.
      const int row = y / 6, tile = (x + 7 * row) / 11;
      std::mt19937 tile_rng(unsigned(row * 977 + tile));
      const float shade = 0.8f + 0.4f * std::uniform_real_distribution<float>(0, 1)(tile_rng);
      const float joint = (y % 6 == 0 || (x + 7 * row) % 11 == 0) ? 0.6f : 1.0f;
      const float n = grain(rng);
      m.at<cv::Vec3f>(y, x) = cv::Vec3f(0.46f + n, 0.27f + n, 0.21f + n) * shade * joint;
    }
  // Dark land below the horizon.
  for (int y = kHorizon; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const float v = 0.20f + grain(rng);
      m.at<cv::Vec3f>(y, x) = cv::Vec3f(v + 0.02f, v + 0.03f, v);
    }
  cv::GaussianBlur(m, m, cv::Size(0, 0), 0.7);  // a lens
  RoofPhoto out{test::linear_photo(m), cv::Mat()};
  // The roof's rim: 1 to 4 px inside its outline (the lens mixes the outermost pixel).
  cv::Mat inner, deep;
  cv::erode(roof, inner, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(3, 3)));
  cv::erode(roof, deep, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(9, 9)));
  out.roof_inside = inner & ~deep;
  out.roof_inside.rowRange(kHorizon - 10, kH).setTo(0);
  return out;
}

struct SpillRun {
  double spill = 0;            // the matte's mean alpha over the roof's rim
  std::size_t spilled = 0;     // of those pixels, how many have alpha > 0.005
  double haze = 0, dense = 0;  // created-edge fractions
};
SpillRun run(const RoofPhoto& p, bool trim, const char* name) {
  const Camera camera = Camera::from_horizontal_fov(kW, kH, 60);
  Annotations horizon;
  horizon.horizon = std::array<PixelPoint, 2>{PixelPoint{0, kHorizon - 0.5},
                                              PixelPoint{kW - 1.0, kHorizon - 0.5}};
  EstimateOptions options;
  options.trim_matte_spill = trim;
  const SceneEstimate est = estimate_scene(p.photo, camera, horizon, options);
  SpillRun r;
  std::size_t count = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      if (!p.roof_inside.at<std::uint8_t>(y, x)) continue;
      const float a = est.geometry.sky_alpha.at(x, y, 0);
      r.spill += a, r.spilled += a > 0.005f, ++count;
    }
  r.spill /= double(std::max<std::size_t>(1, count));
  const auto looks = test::haze_and_dense_looks(p.photo, camera, est, name);
  r.haze = looks.haze_edges, r.dense = looks.dense_edges;
  return r;
}

TEST(SkyMatteSpill, DarkRoofUnderAWhiteSkyGetsNoSkyFog) {
  const RoofPhoto p = roof_photo();
  const SpillRun before = run(p, false, "roof_untrimmed");
  const SpillRun after = run(p, true, "roof_trimmed");
  std::printf(
      "roof: matte over the roof's rim (1-4 px inside its edge), mean %.5f (%zu pixels > 0.005) "
      "untrimmed, "
      "%.5f (%zu) trimmed; created-edge pixels haze %.4f %% -> %.4f %%, dense %.4f %% -> "
      "%.4f %%\n",
      before.spill, before.spilled, after.spill, after.spilled, 100 * before.haze, 100 * after.haze,
      100 * before.dense, 100 * after.dense);
  // The defect, reproduced: the untrimmed matte lays sky on the roof's rim (measured: 2043 rim
  // pixels above 0.005, mean 0.0089), and haze draws a second edge there (0.156 %).
  EXPECT_GT(before.spilled, 1000u);
  EXPECT_GT(before.haze, 2e-4);
  // Trimmed (measured: 81 pixels, mean 0.0002; haze 0.036 %, the rest spots where the dark rim
  // meets the tiles inside the narrow chimneys, not the matte's spill): a tenth of the spill
  // at most, the haze's created edges a third at most; dense fog within the target.
  EXPECT_LT(after.spilled, before.spilled / 10);
  EXPECT_LT(after.haze, before.haze / 3);
  EXPECT_LE(after.dense, 2e-4);
}

// The rule on a hand-made matte, one column of pixels (closed form): sky B above, surface F
// below, the photo's edge between rows 9 and 10.
TEST(SkyMatteSpill, TrimsOnlyTheSurfaceSideOfASharpEdge) {
  constexpr int w = 8, h = 24;
  const std::array<float, 3> B{0.9f, 0.9f, 0.95f}, F{0.10f, 0.05f, 0.04f};
  auto photo_of = [&](const std::vector<float>& sky_share) {
    Image img(w, h, 3);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        for (int c = 0; c < 3; ++c)
          img.at(x, y, c) = sky_share[std::size_t(y)] * B[std::size_t(c)] +
                            (1 - sky_share[std::size_t(y)]) * F[std::size_t(c)];
    return img;
  };
  auto matte_of = [&](const std::vector<float>& column) {
    std::vector<float> a(std::size_t(w) * h);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) a[std::size_t(y) * w + x] = column[std::size_t(y)];
    return a;
  };
  // A sharp edge: the photo all sky to row 9, all surface from row 10; the matte runs on.
  std::vector<float> share(h, 0.0f), column(h, 0.0f);
  for (int y = 0; y < 10; ++y) share[std::size_t(y)] = 1.0f;
  for (int y = 0; y < 8; ++y) column[std::size_t(y)] = 1.0f;
  const float ramp[] = {0.95f, 0.8f, 0.3f, 0.07f, 0.05f, 0.01f};
  for (int k = 0; k < 6; ++k) column[std::size_t(8 + k)] = ramp[k];
  {
    std::vector<float> a = matte_of(column);
    photo::trim_matte_spill(photo_of(share).view(), a);
    // Rows 10-11 (alpha 0.3, 0.07: within 2.5 px of the binary sky and 3.5 px of alpha >= 0.9,
    // the photo's pure surface colour there) fall to 0, and the ramp's tail beyond them (rows
    // 12-13, 0.05 and 0.01) with them; the sky side (rows 8-9) is untouched.
    EXPECT_FLOAT_EQ(a[std::size_t(8) * w + 3], 0.95f);
    EXPECT_FLOAT_EQ(a[std::size_t(9) * w + 3], 0.8f);
    for (int y = 10; y < 14; ++y) EXPECT_FLOAT_EQ(a[std::size_t(y) * w + 3], 0.0f) << "row " << y;
  }
  // The same photo with the ramp starting 4 px below the binary sky's edge (an alpha-0 gap in
  // between): no seed near a sharp edge, nothing trimmed.
  {
    std::vector<float> gapped = column;
    gapped[10] = gapped[11] = gapped[12] = 0.0f;
    gapped[13] = 0.2f, gapped[14] = 0.1f;
    std::vector<float> a = matte_of(gapped);
    photo::trim_matte_spill(photo_of(share).view(), a);
    EXPECT_FLOAT_EQ(a[std::size_t(13) * w + 3], 0.2f);
    EXPECT_FLOAT_EQ(a[std::size_t(14) * w + 3], 0.1f);
  }
  // The same matte over a photo whose edge is as soft as the matte (each pixel the matte's mix
  // of B and F): every projection is the pixel's own alpha, above 0.1 where alpha is: kept.
  {
    std::vector<float> a = matte_of(column);
    photo::trim_matte_spill(photo_of(column).view(), a);
    EXPECT_FLOAT_EQ(a[std::size_t(10) * w + 3], 0.3f);
    // Alpha 0.07: its projection (<= 0.1) is its own value, up to the 3x3 means' blur of B
    // and F: nearly unchanged.
    EXPECT_NEAR(a[std::size_t(11) * w + 3], 0.07f, 0.005f);
  }
  // A hue edge with (nearly) no step in luma: a brown leg against a dark blue dusk sky, display
  // luma 0.246 and 0.254 (rocket's towers): kept, the photo's luma is smooth across it.
  {
    const std::array<float, 3> sky{0.15f, 0.25f, 0.60f}, steel{0.40f, 0.21f, 0.15f};
    Image img(w, h, 3);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        for (int c = 0; c < 3; ++c)
          img.at(x, y, c) = linear(y < 10 ? sky[std::size_t(c)] : steel[std::size_t(c)]);
    std::vector<float> a = matte_of(column);
    photo::trim_matte_spill(img.view(), a);
    EXPECT_FLOAT_EQ(a[std::size_t(10) * w + 3], 0.3f);
    EXPECT_FLOAT_EQ(a[std::size_t(11) * w + 3], 0.07f);
  }
  // A thin member (rows 10-12) with sky on both sides, its nearest plain surface 8 px away
  // (beyond 4.5 px): its colour is not compared with some other structure's: kept.
  {
    std::vector<float> member(h, 1.0f), thin_share(h, 1.0f);
    const float ramp2[] = {0.95f, 0.8f, 0.3f, 0.2f, 0.3f, 0.8f, 0.95f};
    for (int k = 0; k < 7; ++k) member[std::size_t(8 + k)] = ramp2[k];
    for (int y = 20; y < h; ++y) member[std::size_t(y)] = 0.0f, thin_share[std::size_t(y)] = 0.0f;
    for (int y = 10; y < 13; ++y) thin_share[std::size_t(y)] = 0.0f;
    std::vector<float> a = matte_of(member);
    photo::trim_matte_spill(photo_of(thin_share).view(), a);
    EXPECT_FLOAT_EQ(a[std::size_t(10) * w + 3], 0.3f);
    EXPECT_FLOAT_EQ(a[std::size_t(11) * w + 3], 0.2f);
  }
  // A sharp edge the photo hardly shows (sides 0.02 apart, display-referred): kept.
  {
    const std::array<float, 3> b{0.50f, 0.50f, 0.50f};
    Image img(w, h, 3);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        for (int c = 0; c < 3; ++c)
          img.at(x, y, c) =
              y < 10 ? b[std::size_t(c)] : std::pow(std::pow(0.5f, 1 / 2.2f) - 0.02f, 2.2f);
    std::vector<float> a = matte_of(column);
    photo::trim_matte_spill(img.view(), a);
    EXPECT_FLOAT_EQ(a[std::size_t(10) * w + 3], 0.3f);
  }
}

}  // namespace
}  // namespace mr
