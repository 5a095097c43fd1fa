// A cloud bank on a guessed horizon line (issue 11; photo/clouds.h find_cloud_bank and the bank
// rule of floating_clouds): with no horizon cue the level fall-back guess runs through the
// middle of a sky photo; a grey-blue cloud bank across it and filling the frame below it
// (god_rays in the tuning half) was a structure on the far billboard above the line and the
// ground plane below it: in haze a nearly clear grey shape under the veiled sky, its outline a
// created edge, under a sun a cloud-shaped occluder. The horizon goes below the frame and the
// bank is sky. A bluish, textured mountain range rising from the land across the same line is
// not a bank, and a bank over land is left alone (CloudBankOptions::lower_to_land).
#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "mr/estimate.h"
#include "mr/fog.h"
#include "mr/io.h"
#include "mr/scattering.h"
#include "photo/clouds.h"
#include "tests/gallery_look.h"

namespace mr {
namespace {

float linear(float display) {
  return std::pow(std::clamp(display, 0.0f, 1.0f), 2.2f);
}

// The gallery's created-edge measure and looks (tests/gallery_look.h).
using test::fog_auto_look;
using test::gallery_created_edges;

cv::Mat blurred_noise(int h, int w, std::mt19937& rng, double sigma) {
  std::uniform_real_distribution<float> uniform(0.0f, 1.0f);
  cv::Mat noise(h, w, CV_32F);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) noise.at<float>(y, x) = uniform(rng);
  cv::GaussianBlur(noise, noise, cv::Size(0, 0), sigma);
  cv::normalize(noise, noise, 0, 1, cv::NORM_MINMAX);
  return noise;
}

constexpr int kW = 640, kH = 400;
constexpr int kLand = 300;  // the land's top row, on average (hills of +-14 px: no line cue)

// Blue sky above; a dark textured land from about row kLand down (none for `Kind::bank_only`);
// across the middle either a cloud bank (dim grey-blue, a wavy soft upper outline, a lit rim)
// down to the land or the frame's bottom, or a mountain range (bluish grey, textured rock)
// rising from the land.
enum class Kind { bank_only, bank_over_land, mountain };
struct BankScene {
  Image photo;
  cv::Mat part;  // CV_8U: 1 the bank or the mountain, 2 the land
};
BankScene bank_scene(Kind kind) {
  constexpr int w = kW, h = kH;
  const bool mountain = kind == Kind::mountain;
  std::mt19937 rng(mountain ? 23 : 17);
  const cv::Mat large = blurred_noise(h, w, rng, 14.0);  // the bank's billows
  const cv::Mat medium = blurred_noise(h, w, rng, 4.0);  // and their detail
  const cv::Mat fine = blurred_noise(h, w, rng, 0.8);    // rock, grass
  BankScene s{Image(w, h, 3), cv::Mat(h, w, CV_8U, cv::Scalar(0))};
  cv::Mat display(h, w, CV_32FC3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float t = float(y) / kLand;
      cv::Vec3f c = cv::Vec3f(0.30f, 0.50f, 0.85f) * (1 - t) + cv::Vec3f(0.62f, 0.72f, 0.88f) * t;
      const double land = kind == Kind::bank_only
                              ? 2.0 * h
                              : kLand + 9 * std::sin(x / 61.0) + 5 * std::sin(x / 23.0 + 2.0);
      if (y >= land) {
        const float v = 0.16f + 0.10f * fine.at<float>(y, x) + 0.05f * float(y - land) / h;
        c = cv::Vec3f(v * 0.9f, v * 1.0f, v * 0.7f);  // an olive-brown field
        s.part.at<std::uint8_t>(y, x) = 2;
      } else if (!mountain) {
        // The bank: its top a wavy line through rows 90-150; a soft edge (about 6 px) lit
        // from above; a dim grey-blue body (a storm bank: too dark and grey for the sky mask's
        // blue, too dim for its bright grey), billowed, down to the land.
        const double top = 120 + 22 * std::sin(x / 53.0) + 10 * std::sin(x / 19.0 + 1.0);
        const float k = float(std::clamp((y - top) / 6.0, 0.0, 1.0));
        if (k > 0) {
          const float b = 0.20f + 0.10f * large.at<float>(y, x) + 0.05f * medium.at<float>(y, x);
          const cv::Vec3f body(b * 0.95f, b * 0.98f, b * 1.08f);
          const float rim = 0.45f * std::exp(-float(y - top) / 12.0f);  // lit from behind
          c = c * (1 - k) + (body + cv::Vec3f(rim, rim, rim * 0.95f)) * k;
          if (k >= 1) s.part.at<std::uint8_t>(y, x) = 1;
        }
      } else {
        // The range: peaks up to row 110, bluish grey rock, rough at every scale.
        const double top = 170 - 50 * std::abs(std::sin(x / 90.0)) - 12 * std::sin(x / 23.0);
        if (y >= top) {
          const float v = 0.34f + 0.22f * fine.at<float>(y, x) + 0.06f * large.at<float>(y, x);
          c = cv::Vec3f(v * 0.90f, v * 0.95f, v * 1.08f);
          if (y >= top + 2) s.part.at<std::uint8_t>(y, x) = 1;
        }
      }
      display.at<cv::Vec3f>(y, x) = c;
    }
  cv::GaussianBlur(display, display, cv::Size(0, 0), 0.7);  // a lens
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) s.photo.at(x, y, c) = linear(display.at<cv::Vec3f>(y, x)[c]);
  return s;
}

struct Counts {
  std::size_t part = 0, part_sky = 0, land = 0, land_finite = 0;
};
Counts count(const BankScene& s, const Image& d) {
  Counts k;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const bool sky = !std::isfinite(d.at(x, y, 0));
      if (s.part.at<std::uint8_t>(y, x) == 1) ++k.part, k.part_sky += sky;
      if (s.part.at<std::uint8_t>(y, x) == 2) ++k.land, k.land_finite += !sky;
    }
  return k;
}

void write_to_look_at(const std::string& name, const Image& photo, const Image& haze,
                      const Image& d) {
  const char* folder = std::getenv("MR_TEST_IMAGES");
  if (!folder || !*folder) return;
  const std::string f(folder);
  write_image(f + "/" + name + "_photo.png", photo);
  write_image(f + "/" + name + "_haze.png", haze);
  write_image(f + "/" + name + "_depth.png", test::depth_picture(d));
}

double percent(std::size_t a, std::size_t b) {
  return b > 0 ? 100.0 * double(a) / double(b) : 0;
}

// One scene through the automatic estimate and the gallery's haze (and dense) looks.
struct BankRun {
  SceneEstimate est;
  Counts k;
  double e_haze = 0, e_dense = 0;
};
BankRun run_bank(Kind kind, const std::string& name, bool dense = true) {
  const BankScene s = bank_scene(kind);
  const Camera camera = Camera::from_horizontal_fov(kW, kH, 60);
  BankRun r;
  r.est = estimate_scene(s.photo, camera, Annotations{});
  const Image& d = r.est.geometry.distance_m;
  r.k = count(s, d);
  const FogLayers haze = fog_auto_look(s.photo, camera, r.est, 2000, 1500, 0.6);
  r.e_haze = gallery_created_edges(s.photo, haze.composite);
  if (dense)
    r.e_dense = gallery_created_edges(s.photo,
                                      fog_auto_look(s.photo, camera, r.est, 60, 80, 0.3).composite);
  write_to_look_at(name, s.photo, haze.composite, d);
  return r;
}

// Before: the level fall-back (row 200) ran through the bank; its part above was on the far
// billboard, 46 m away, below it the ground plane.
TEST(CloudBank, BankFillingTheFrameBelowAGuessedHorizonIsSky) {
  const auto [est, k, e_haze, e_dense] = run_bank(Kind::bank_only, "cloud_bank");
  std::printf(
      "cloud bank: %s; lowered %.0f px (horizon row %.1f); bank %.1f %% sky; created-edge "
      "pixels haze %.4f %%, dense %.4f %%\n",
      est.notes.front().c_str(), est.geometry.horizon_lowered_px, est.geometry.horizon[0][1],
      percent(k.part_sky, k.part), 100 * e_haze, 100 * e_dense);
  ASSERT_EQ(est.geometry.horizon_source, EstimateSource::fallback);
  EXPECT_GE(est.geometry.horizon[0][1], kH - 1.0);  // below the bank: the frame's bottom
  EXPECT_GE(double(k.part_sky), 0.98 * double(k.part));
  EXPECT_LE(e_haze, 2e-4);  // the target for created edges, 0.02 %
  EXPECT_LE(e_dense, 2e-4);
}

// The same bank over hilly land: left as it was (CloudBankOptions::lower_to_land is off; with
// it on, the horizon went to the land's line and the bank became sky, but the land stayed
// nearly clear under the veil: haze created edges 0.90 % along the skyline).
TEST(CloudBank, BankOverLandIsLeftAlone) {
  const auto [est, k, e_haze, e_dense] = run_bank(Kind::bank_over_land, "bank_over_land");
  std::printf(
      "bank over land: %s; lowered %.0f px; bank %.1f %% sky, land %.1f %% surface; "
      "created-edge pixels haze %.4f %%, dense %.4f %%\n",
      est.notes.front().c_str(), est.geometry.horizon_lowered_px, percent(k.part_sky, k.part),
      percent(k.land_finite, k.land), 100 * e_haze, 100 * e_dense);
  ASSERT_EQ(est.geometry.horizon_source, EstimateSource::fallback);
  EXPECT_EQ(est.geometry.horizon_lowered_px, 0.0);
  EXPECT_GE(double(k.land_finite), 0.99 * double(k.land));
  EXPECT_LE(e_haze, 2e-4);
  EXPECT_LE(e_dense, 2e-4);
}

// The counter-case: a bluish grey mountain range rising from the land across the guessed line
// is textured rock, not a bank: the guess is not lowered, the range stays a surface.
TEST(CloudBank, TexturedMountainOnAGuessedHorizonStaysASurface) {
  const BankRun r = run_bank(Kind::mountain, "mountain", /*dense=*/false);
  const SceneEstimate& est = r.est;
  const Counts& k = r.k;
  std::printf("mountain: %s; lowered %.0f px; range %.1f %% sky, land %.1f %% surface\n",
              est.notes.front().c_str(), est.geometry.horizon_lowered_px,
              percent(k.part_sky, k.part), percent(k.land_finite, k.land));
  ASSERT_EQ(est.geometry.horizon_source, EstimateSource::fallback);
  EXPECT_EQ(est.geometry.horizon_lowered_px, 0.0);
  EXPECT_LE(double(k.part_sky), 0.01 * double(k.part));
  EXPECT_GE(double(k.land_finite), 0.99 * double(k.land));
}

// find_cloud_bank on hand-made maps: the rule's guards one at a time.
TEST(CloudBank, FindCloudBankGuards) {
  constexpr int w = 200, h = 100, guess = 50, land = 80;
  auto make = [&](Rgb bank, Rgb ground, bool textured_bank, bool textured_land = true) {
    Image photo(w, h, 3);
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> grain(-0.15f, 0.15f);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        Rgb c{0.1f, 0.25f, 0.7f};                      // blue sky
        const int top = 22 + (x * 7) % 17;             // a ragged upper outline
        if (y >= top && x >= 20 && x < 190) c = bank;  // the bank, down to the land
        if (y >= land) c = ground;                     // the land
        const bool grain_here = (textured_land && y >= land) ||
                                (textured_bank && y >= top && x >= 20 && x < 190 && y < land);
        const float gr = grain_here ? grain(rng) : 0.0f;  // texture
        for (int k = 0; k < 3; ++k) photo.at(x, y, k) = std::max(0.0f, c[k] * (1 + gr));
      }
    return photo;
  };
  auto sky_of = [&](const Image& photo) {
    std::vector<std::uint8_t> sky(std::size_t(w) * h, 0);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) sky[std::size_t(y) * w + x] = photo.at(x, y, 2) == 0.7f;
    return sky;
  };
  const std::array<PixelPoint, 2> line{PixelPoint{0, guess}, PixelPoint{w - 1.0, guess}};
  const Rgb grey_blue{0.35f, 0.38f, 0.45f}, field{0.15f, 0.12f, 0.05f};
  {
    const Image p = make(grey_blue, field, false);
    // A bank over land: not by default (CloudBankOptions::lower_to_land).
    EXPECT_EQ(photo::find_cloud_bank(p.view(), line, sky_of(p)).drop_px, 0.0);
    photo::CloudBankOptions to_land;
    to_land.lower_to_land = true;
    const photo::CloudBank b = photo::find_cloud_bank(p.view(), line, sky_of(p), to_land);
    // The last bank row, less the texture window's reach into it (4 rows).
    EXPECT_GE(b.drop_px, land - 1 - guess - 5);
    EXPECT_LE(b.drop_px, land - 1 - guess);
    ASSERT_EQ(b.bank.size(), std::size_t(w) * h);
    EXPECT_EQ(b.bank[std::size_t(40) * w + 100], 1);
    EXPECT_EQ(b.bank[std::size_t(90) * w + 100], 0);  // the land
    EXPECT_EQ(b.bank[std::size_t(10) * w + 100], 0);  // the sky
  }
  // Each guard alone, in a frame the "bank" fills below the guess (no land):
  // textured (rock, a facade): not a bank.
  {
    const Image p = make(grey_blue, grey_blue, true);
    EXPECT_EQ(photo::find_cloud_bank(p.view(), line, sky_of(p)).drop_px, 0.0);
  }
  // Green (a hillside of trees, a lawn): not a bank.
  {
    const Image p = make(Rgb{0.2f, 0.35f, 0.15f}, Rgb{0.2f, 0.35f, 0.15f}, false, false);
    EXPECT_EQ(photo::find_cloud_bank(p.view(), line, sky_of(p)).drop_px, 0.0);
  }
  // Saturated orange (a sunlit wall): not a bank.
  {
    const Image p = make(Rgb{0.8f, 0.35f, 0.1f}, Rgb{0.8f, 0.35f, 0.1f}, false, false);
    EXPECT_EQ(photo::find_cloud_bank(p.view(), line, sky_of(p)).drop_px, 0.0);
  }
  // No land under it, the bank filling the frame below the guess: lowered to the bottom row.
  {
    const Image p = make(grey_blue, grey_blue, false, false);
    EXPECT_EQ(photo::find_cloud_bank(p.view(), line, sky_of(p)).drop_px, h - 1 - guess);
  }
  // A calm grey-blue sea from a straight horizon at row 30 to the frame's bottom: its outline
  // under the sky is a line, not a bank's ragged one.
  {
    Image p = make(grey_blue, grey_blue, false, false);
    const Rgb blue{0.1f, 0.25f, 0.7f};
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        for (int k = 0; k < 3; ++k) p.at(x, y, k) = y < 30 ? blue[k] : grey_blue[k];
    EXPECT_EQ(photo::find_cloud_bank(p.view(), line, sky_of(p)).drop_px, 0.0);
  }
  // No sky above the guess (an overcast grey frame, a wall): nothing rings the bank.
  {
    Image p = make(grey_blue, grey_blue, false, false);
    for (int y = 0; y < 30; ++y)
      for (int x = 0; x < w; ++x)
        for (int k = 0; k < 3; ++k) p.at(x, y, k) = grey_blue[k];
    EXPECT_EQ(photo::find_cloud_bank(p.view(), line, std::vector<std::uint8_t>(std::size_t(w) * h))
                  .drop_px,
              0.0);
  }
}

}  // namespace
}  // namespace mr
