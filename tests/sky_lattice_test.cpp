// Sky seen through a lattice or between cables is sky, snow seen between branches is not (the
// automatic sky mask, photo/sky_mask.h; issue 11, created edges of haze and dense fog). Synthetic
// photos of the gallery's classes: a launch tower's lattice and a bridge's hanger cables under a
// blue sky (the tuning half's rocket and bridge), birches standing in sunlit, grainy snow under
// a blue sky, and a snow field seen from above with no sky at all (snow_birches, which the
// lattice rule's first version turned into sky). Drawn display-referred with OpenCV, converted
// to scene-linear (^2.2) as the estimator expects.
#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <random>
#include <vector>

#include "mr/estimate.h"
#include "mr/fog.h"
#include "mr/image.h"
#include "mr/io.h"
#include "photo/sky_mask.h"
#include "tests/gallery_look.h"

namespace mr {
namespace {

using test::linear;

// Sky seen through a lattice and between cables (issue 11; the tuning half's launch towers and
// a suspension bridge's hangers): a blue sky with a lattice tower of thin dark members (2 px)
// standing on dark land below an annotated horizon, a pair of hanger cables 14 px apart from the
// top border down to a bridge deck, and a pale blue facade with thick dark windows
// (sky-coloured, but a surface).
// The lattice's openings and the strip between the cables are sky-coloured, but the sky mask's
// texture windows take in the members, so the narrow ones were left out: the top of the tower
// and the strip were surfaces standing on the ground, blue inside a hard outline in haze while
// the open sky around them turned the fog's grey (before: 77.8 % of the openings sky, the
// lower, wider ones; haze created edges 0.058 %, dense 0.003 %). The facade, which the rest of
// the mask takes as sky (a known limit: a smooth wall of the sky's colour), is there to show
// that this rule adds none of it.
constexpr int kLatticeW = 640, kLatticeH = 480, kLatticeHorizon = 330;
struct LatticePhoto {
  Image photo;
  cv::Mat openings, facade;  // where the photo shows sky through the lattice; the facade
};
LatticePhoto lattice_photo() {
  constexpr int w = kLatticeW, h = kLatticeH;
  cv::Mat m(h, w, CV_32FC3), members(h, w, CV_8U, cv::Scalar(0));
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> grain(-0.04f, 0.04f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float t = float(y) / kLatticeHorizon;
      m.at<cv::Vec3f>(y, x) =
          cv::Vec3f(0.30f, 0.50f, 0.84f) * (1 - t) + cv::Vec3f(0.62f, 0.74f, 0.90f) * t;
    }
  // The tower: two legs narrowing upwards, crossed by diagonals and struts every 36 rows.
  auto leg_x = [](int y, bool right) {
    return right ? 250.0 - 40.0 * (h - y) / h : 110.0 + 40.0 * (h - y) / h;
  };
  cv::Mat lattice(h, w, CV_8U, cv::Scalar(0));
  for (const bool right : {false, true})
    cv::line(members, cv::Point2d(leg_x(h - 1, right), h - 1), cv::Point2d(leg_x(20, right), 20),
             cv::Scalar(255), 2, cv::LINE_AA);
  for (int y = 20; y + 36 < h; y += 36) {
    const cv::Point2d a(leg_x(y, false), y), b(leg_x(y, true), y);
    const cv::Point2d c(leg_x(y + 36, false), y + 36), d(leg_x(y + 36, true), y + 36);
    cv::line(members, a, b, cv::Scalar(255), 2, cv::LINE_AA);
    cv::line(members, a, d, cv::Scalar(255), 2, cv::LINE_AA);
    cv::line(members, b, c, cv::Scalar(255), 2, cv::LINE_AA);
  }
  std::vector<cv::Point> outline = {{int(leg_x(20, false)), 20},
                                    {int(leg_x(20, true)), 20},
                                    {int(leg_x(h - 1, true)), h - 1},
                                    {int(leg_x(h - 1, false)), h - 1}};
  cv::fillConvexPoly(lattice, outline, cv::Scalar(255));
  // The hangers: two cables from the top border down to a bridge deck (a thick beam
  // across the right half, above the horizon).
  constexpr int deck_top = 270, deck_bottom = 284;
  for (const int dx : {0, 14})
    cv::line(members, cv::Point(380 + dx, 0), cv::Point(355 + dx, deck_top), cv::Scalar(255), 2,
             cv::LINE_AA);
  cv::rectangle(members, cv::Point(300, deck_top), cv::Point(w - 1, deck_bottom), cv::Scalar(255),
                cv::FILLED);
  for (const int pier : {320, 560})  // the deck stands on piers
    cv::rectangle(members, cv::Point(pier, deck_top), cv::Point(pier + 24, h - 1), cv::Scalar(255),
                  cv::FILLED);
  cv::Mat strip(h, w, CV_8U, cv::Scalar(0));
  std::vector<cv::Point> between = {{383, 0}, {391, 0}, {366, deck_top}, {358, deck_top}};
  cv::fillConvexPoly(strip, between, cv::Scalar(255));
  const cv::Vec3f steel(0.10f, 0.09f, 0.08f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float a = members.at<std::uint8_t>(y, x) / 255.0f;
      cv::Vec3f& c = m.at<cv::Vec3f>(y, x);
      c = c * (1 - a) + steel * a;
    }
  // The facade: a pale blue, rendered wall (the sky's colour near the horizon) on the land in
  // front of the deck, its windows dark and 16 px across.
  cv::Mat facade(h, w, CV_8U, cv::Scalar(0));
  cv::rectangle(facade, cv::Point(470, 150), cv::Point(600, kLatticeHorizon + 20), cv::Scalar(255),
                cv::FILLED);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      if (!facade.at<std::uint8_t>(y, x)) continue;
      const bool window =
          (x - 470) % 32 >= 8 && (x - 470) % 32 < 24 && (y - 200) % 40 >= 12 && (y - 200) % 40 < 30;
      const float n = 0.5f * grain(rng);
      m.at<cv::Vec3f>(y, x) = window ? cv::Vec3f(0.12f + n, 0.13f + n, 0.16f + n)
                                     : cv::Vec3f(0.58f + n, 0.70f + n, 0.88f + n);
    }
  // Dark textured land below the horizon (in front of the tower's and the cables' feet).
  for (int y = kLatticeHorizon; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      if (facade.at<std::uint8_t>(y, x) && y < kLatticeHorizon + 20) continue;
      const float v = 0.16f + 0.04f * float(y - kLatticeHorizon) / h + grain(rng);
      m.at<cv::Vec3f>(y, x) = cv::Vec3f(v + 0.03f, v + 0.04f, v);
    }
  cv::GaussianBlur(m, m, cv::Size(0, 0), 0.7);  // a lens
  LatticePhoto out{Image(w, h, 3), cv::Mat(h, w, CV_8U, cv::Scalar(0)), facade};
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      for (int c = 0; c < 3; ++c)
        out.photo.at(x, y, c) = linear(std::clamp(m.at<cv::Vec3f>(y, x)[c], 0.0f, 1.0f));
      // The openings, 3 px clear of every member, above the horizon's band.
      out.openings.at<std::uint8_t>(y, x) =
          (lattice.at<std::uint8_t>(y, x) || strip.at<std::uint8_t>(y, x)) &&
          y < kLatticeHorizon - 40;
    }
  cv::Mat near_member;
  cv::dilate(members, near_member, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(7, 7)));
  out.openings.setTo(0, near_member);
  return out;
}

TEST(SkyLight, SkyThroughALatticeIsSky) {
  const LatticePhoto p = lattice_photo();
  constexpr int kW = kLatticeW, kH = kLatticeH;
  const Camera camera = Camera::from_horizontal_fov(kW, kH, 60);
  Annotations horizon;
  horizon.horizon = std::array<PixelPoint, 2>{PixelPoint{0, kLatticeHorizon - 0.5},
                                              PixelPoint{kW - 1.0, kLatticeHorizon - 0.5}};
  // The sky mask with and without the rule: the openings, and the facade (what the rest of the
  // mask makes of a sky-coloured wall touching the sky is not this rule's business; the rule
  // must add none of it).
  photo::SkyMaskOptions off;
  off.thin_member_width = 0;
  const photo::SkyMask with = photo::estimate_sky_mask(p.photo.view(), *horizon.horizon);
  const photo::SkyMask without = photo::estimate_sky_mask(p.photo.view(), *horizon.horizon, off);
  std::size_t openings = 0, open_with = 0, open_without = 0, facade_with = 0, facade_without = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const std::size_t i = std::size_t(y) * kW + x;
      if (p.openings.at<std::uint8_t>(y, x))
        ++openings, open_with += with.sky[i], open_without += without.sky[i];
      if (p.facade.at<std::uint8_t>(y, x))
        facade_with += with.sky[i], facade_without += without.sky[i];
    }
  const SceneEstimate est = estimate_scene(p.photo, camera, horizon);
  std::size_t open_sky = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x)
      open_sky +=
          p.openings.at<std::uint8_t>(y, x) && std::isinf(est.geometry.distance_m.at(x, y, 0));
  const auto [e_haze, e_dense] = test::haze_and_dense_looks(p.photo, camera, est, "lattice");
  std::printf(
      "lattice: openings sky in the mask %.1f %% (without the rule %.1f %%), in the estimate "
      "%.1f %%; facade pixels made sky %zu (without the rule %zu); created-edge pixels haze "
      "%.4f %%, dense %.4f %%\n",
      100.0 * double(open_with) / double(openings), 100.0 * double(open_without) / double(openings),
      100.0 * double(open_sky) / double(openings), facade_with, facade_without, 100 * e_haze,
      100 * e_dense);
  EXPECT_GE(double(open_with), 0.95 * double(openings));
  EXPECT_GE(double(open_sky), 0.95 * double(openings));
  EXPECT_EQ(facade_with, facade_without);
  // The target for dense fog and haze: at most 0.02 % of the pixels.
  EXPECT_LE(e_haze, 2e-4);
  EXPECT_LE(e_dense, 2e-4);
}

// The tower's foot (issue 11, helper haze16; the tuning half's rocket, whose slender middle
// tower stands on a dark cloud bank at the horizon): a lattice tower 30 px across of 1 px members,
// its bays 24 rows tall, standing on dark land below an annotated horizon, under a blue sky. Its
// openings are too narrow for the mask's texture windows, so the lattice rule finds them, and it
// used to refuse every opening that reached the horizon (the mask ends there: an opening going on
// below would end in a line across the lattice). The lowest bay's opening ends where the photo's
// does, on the land, and refused it stayed a surface: the lattice's blue inside a hard outline
// at the tower's foot while the sky around it took the haze's grey.
// Before (the old rule: thin_max_ground_sky < 0): the foot's openings 0.0 % sky in the mask and
// the estimate (haze created edges 0.0059 %); after: 100 % (0.0000 %). The lens blur comes before
// the land is drawn: a soft land edge makes thick structure along the horizon that refuses the
// lowest bay on its own (thin_max_thick), which this test is not about.
constexpr int kTowerW = 640, kTowerH = 480, kTowerHorizon = 330;
struct TowerPhoto {
  Image photo;
  cv::Mat foot_openings;  // the lowest bay's openings above the horizon, 3 px clear of steel
};
TowerPhoto slender_tower_photo(int horizon_y) {
  constexpr int w = kTowerW, h = kTowerH;
  cv::Mat m(h, w, CV_32FC3), members(h, w, CV_8U, cv::Scalar(0));
  cv::Mat inside(h, w, CV_8U, cv::Scalar(0));
  std::mt19937 rng(23);
  std::uniform_real_distribution<float> grain(-0.04f, 0.04f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float t = float(y) / kTowerHorizon;
      m.at<cv::Vec3f>(y, x) =
          cv::Vec3f(0.30f, 0.50f, 0.84f) * (1 - t) + cv::Vec3f(0.40f, 0.58f, 0.88f) * t;
    }
  auto leg_x = [](int y, bool right) {
    return right ? 330.0 - 6.0 * (h - y) / h : 300.0 + 6.0 * (h - y) / h;
  };
  constexpr int top = 42, bay = 24;  // the last strut on the horizon
  for (const bool right : {false, true})
    cv::line(members, cv::Point2d(leg_x(h - 1, right), h - 1), cv::Point2d(leg_x(top, right), top),
             cv::Scalar(255), 1, cv::LINE_AA);
  for (int y = top; y < h; y += bay) {
    const cv::Point2d a(leg_x(y, false), y), b(leg_x(y, true), y);
    const cv::Point2d d(leg_x(y + bay, true), y + bay);
    cv::line(members, a, b, cv::Scalar(255), 1, cv::LINE_AA);
    cv::line(members, a, d, cv::Scalar(255), 1, cv::LINE_AA);
  }
  std::vector<cv::Point> outline = {{int(leg_x(top, false)), top},
                                    {int(leg_x(top, true)), top},
                                    {int(leg_x(h - 1, true)), h - 1},
                                    {int(leg_x(h - 1, false)), h - 1}};
  cv::fillConvexPoly(inside, outline, cv::Scalar(255));
  const cv::Vec3f steel(0.10f, 0.09f, 0.08f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float a = members.at<std::uint8_t>(y, x) / 255.0f;
      cv::Vec3f& c = m.at<cv::Vec3f>(y, x);
      c = c * (1 - a) + steel * a;
    }
  cv::GaussianBlur(m, m, cv::Size(0, 0), 0.7);  // a lens (the land's edge is crisp)
  // Dark textured land below the photo's horizon, in front of the tower's foot.
  for (int y = kTowerHorizon; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float v = 0.16f + 0.04f * float(y - kTowerHorizon) / h + grain(rng);
      m.at<cv::Vec3f>(y, x) = cv::Vec3f(v + 0.03f, v + 0.04f, v);
    }
  TowerPhoto out{Image(w, h, 3), cv::Mat(h, w, CV_8U, cv::Scalar(0))};
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      for (int c = 0; c < 3; ++c)
        out.photo.at(x, y, c) = linear(std::clamp(m.at<cv::Vec3f>(y, x)[c], 0.0f, 1.0f));
      out.foot_openings.at<std::uint8_t>(y, x) =
          inside.at<std::uint8_t>(y, x) && y >= horizon_y - 22 && y < horizon_y - 2;
    }
  cv::Mat near_member;
  cv::dilate(members, near_member, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(7, 7)));
  out.foot_openings.setTo(0, near_member);
  return out;
}

TEST(SkyLight, SkyThroughALatticeReachesATowersFootOnDarkLand) {
  const TowerPhoto p = slender_tower_photo(kTowerHorizon);
  constexpr int kW = kTowerW, kH = kTowerH;
  const Camera camera = Camera::from_horizontal_fov(kW, kH, 60);
  Annotations horizon;
  horizon.horizon = std::array<PixelPoint, 2>{PixelPoint{0, kTowerHorizon - 0.5},
                                              PixelPoint{kW - 1.0, kTowerHorizon - 0.5}};
  photo::SkyMaskOptions before;
  before.thin_max_ground_sky = -1;  // every opening that reaches the horizon refused
  const photo::SkyMask with = photo::estimate_sky_mask(p.photo.view(), *horizon.horizon);
  const photo::SkyMask without = photo::estimate_sky_mask(p.photo.view(), *horizon.horizon, before);
  const SceneEstimate est = estimate_scene(p.photo, camera, horizon);
  std::size_t foot = 0, foot_with = 0, foot_without = 0, foot_estimate = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      if (!p.foot_openings.at<std::uint8_t>(y, x)) continue;
      const std::size_t i = std::size_t(y) * kW + x;
      ++foot, foot_with += with.sky[i], foot_without += without.sky[i];
      foot_estimate += std::isinf(est.geometry.distance_m.at(x, y, 0));
    }
  const auto [e_haze, e_dense] = test::haze_and_dense_looks(p.photo, camera, est, "tower foot");
  std::printf(
      "tower foot: openings sky in the mask %.1f %% (refusing every opening at the horizon "
      "%.1f %%), in the estimate %.1f %%; created-edge pixels haze %.4f %%, dense %.4f %%\n",
      100.0 * double(foot_with) / double(foot), 100.0 * double(foot_without) / double(foot),
      100.0 * double(foot_estimate) / double(foot), 100 * e_haze, 100 * e_dense);
  ASSERT_GT(foot, 0u);
  EXPECT_LT(double(foot_without), 0.95 * double(foot));  // the defect, as before
  EXPECT_GE(double(foot_with), 0.95 * double(foot));
  EXPECT_GE(double(foot_estimate), 0.95 * double(foot));
  EXPECT_LE(e_haze, 2e-4);
  EXPECT_LE(e_dense, 2e-4);
}

// ... and the guard: the same tower under a horizon drawn 12 rows too high (a guessed horizon),
// so the lowest bay's opening goes on below it in the sky's colour (the tuning half's rocket's
// left tower). Made sky, its sky would end in a line across the lattice at the horizon; the
// mask stays exactly what refusing every opening at the horizon gives.
TEST(SkyLight, LatticeOpeningGoingOnBelowTheHorizonIsNotCutThere) {
  const TowerPhoto p = slender_tower_photo(kTowerHorizon - 12);
  const std::array<PixelPoint, 2> high{PixelPoint{0, kTowerHorizon - 12.5},
                                       PixelPoint{kTowerW - 1.0, kTowerHorizon - 12.5}};
  photo::SkyMaskOptions before;
  before.thin_max_ground_sky = -1;
  const photo::SkyMask with = photo::estimate_sky_mask(p.photo.view(), high);
  const photo::SkyMask without = photo::estimate_sky_mask(p.photo.view(), high, before);
  std::size_t differ = 0, foot = 0, foot_sky = 0;
  for (std::size_t i = 0; i < with.sky.size(); ++i) differ += with.sky[i] != without.sky[i];
  for (int y = 0; y < kTowerH; ++y)
    for (int x = 0; x < kTowerW; ++x)
      if (p.foot_openings.at<std::uint8_t>(y, x))
        ++foot, foot_sky += with.sky[std::size_t(y) * kTowerW + x];
  std::printf(
      "tower under a high horizon: %zu mask pixels differ; the foot's openings sky %.1f %%\n",
      differ, 100.0 * double(foot_sky) / double(std::max<std::size_t>(foot, 1)));
  EXPECT_EQ(differ, 0u);
}

// A photo of the gallery's tuning half, at the size the test's pixel coordinates are for.
Image tuning_photo(const char* name, int width, int height) {
  Image photo = read_image(std::filesystem::path(MR_SOURCE_DIR) / "gallery" / "tune" / name);
  EXPECT_EQ(photo.width(), width) << name;
  EXPECT_EQ(photo.height(), height) << name;
  return photo;
}

// Sky between cables down to a horizon drawn in the haze band (the tuning half's bridge; a
// drawn photo would have to copy its clouds and noise to reach this rule): its guessed horizon
// is lowered to just below the sky it cut (row 596.5, in the pale band over the far shore), and
// the cable stays cut a triangle of sky off the rest, its base on the horizon (2.3 % of the
// frame). The band below the horizon has the sky's colour all along, so the rule for openings
// that go on below it (the lattice's, above) refused the triangle: it stood as a wall at the far
// billboard, 46 m away, a grey triangle in the night look (lamp light did not reach into it). No
// member goes on below it (0.4 % of its ring there is not sky-coloured; rocket's left tower,
// which that rule is for, 14 %), so it is not an opening cut across: it is sky.
TEST(SkyLight, SkyBetweenCablesDownToAHorizonInTheHazeBandIsSky) {
  const Image photo = tuning_photo("bridge.jpg", 1280, 720);
  const std::array<PixelPoint, 2> horizon{PixelPoint{0, 596.5}, PixelPoint{1279, 596.5}};
  photo::SkyMaskOptions before;
  before.thin_min_ground_members = 0;  // every opening whose ground ring is sky-coloured refused
  const photo::SkyMask with = photo::estimate_sky_mask(photo.view(), horizon);
  const photo::SkyMask without = photo::estimate_sky_mask(photo.view(), horizon, before);
  // The triangle's inside, 15-20 px clear of the cables and 12 rows clear of the horizon.
  cv::Mat triangle(photo.height(), photo.width(), CV_8U, cv::Scalar(0));
  const std::vector<cv::Point> inside = {{790, 485}, {610, 585}, {855, 585}};
  cv::fillConvexPoly(triangle, inside, cv::Scalar(1));
  std::size_t pixels = 0, sky_with = 0, sky_without = 0;
  for (int y = 0; y < photo.height(); ++y)
    for (int x = 0; x < photo.width(); ++x)
      if (triangle.at<std::uint8_t>(y, x)) {
        const std::size_t i = std::size_t(y) * photo.width() + x;
        ++pixels, sky_with += with.sky[i], sky_without += without.sky[i];
      }
  std::printf(
      "bridge's triangle between cables: %zu px, sky in the mask %.1f %% (before %.1f %%)\n",
      pixels, 100.0 * double(sky_with) / double(pixels),
      100.0 * double(sky_without) / double(pixels));
  ASSERT_GT(pixels, 5000u);
  EXPECT_GE(double(sky_with), 0.95 * double(pixels));
  EXPECT_LE(double(sky_without), 0.05 * double(pixels));  // the case the rule is for
}

// ... but not a pale wall taken for sky whose colour goes on far below the horizon (gallery/tune
// friends, moved there from heldout/ for this: dogs at a window of a white wooden house, no
// sky; the mask takes a white downpipe for sky, and the white siding beside it, bounded by its
// thin grooves, for an opening). Its ground ring is sky-coloured with no member in it, as
// bridge's; the siding goes on 10 % of the height below the horizon, the haze band under
// bridge's triangle 2.8 %. Without the band limit the false sky grew by 39 k pixels in the mask
// (46 k more infinite distances in the estimate).
TEST(SkyLight, APaleWallGoingOnBelowTheHorizonIsNoOpeningBetweenCables) {
  const Image photo = tuning_photo("friends.jpg", 852, 1280);
  // The estimate's horizon (a horizontal and the vertical vanishing point).
  const std::array<PixelPoint, 2> horizon{PixelPoint{0, 596.8}, PixelPoint{851, 595.6}};
  photo::SkyMaskOptions no_limit;
  no_limit.thin_max_band_fraction = 1;
  photo::SkyMaskOptions before;
  before.thin_min_ground_members = 0;
  const photo::SkyMask with = photo::estimate_sky_mask(photo.view(), horizon);
  const photo::SkyMask without_limit = photo::estimate_sky_mask(photo.view(), horizon, no_limit);
  const photo::SkyMask refused = photo::estimate_sky_mask(photo.view(), horizon, before);
  std::printf("friends' sky pixels: %zu (without the band limit %zu, refusing as before %zu)\n",
              with.pixels, without_limit.pixels, refused.pixels);
  EXPECT_EQ(with.sky, refused.sky);
  EXPECT_GT(without_limit.pixels, with.pixels + 20000);  // the case the limit is for
}

// Snow's grain: white noise blurred to grains of about 1.5 px, scaled to a standard deviation of
// `amplitude` (display units).
cv::Mat snow_grain(int w, int h, float amplitude, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> normal(0.0f, 1.0f);
  cv::Mat g(h, w, CV_32F);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) g.at<float>(y, x) = normal(rng);
  cv::GaussianBlur(g, g, cv::Size(0, 0), 0.8);
  cv::Scalar mean, sd;
  cv::meanStdDev(g, mean, sd);
  return g * (amplitude / sd[0]);
}

// Birches standing in sunlit snow on a slope that rises above the horizon to a ridge, under a
// blue sky (the held-out snow_birches' class, and any snowy hillside seen through a tree). The
// birches' crowns are a mesh of thin dark twigs (1-2 px, as a lattice's members) reaching from
// the snow up into the sky. The snow is bluish white, within the sky's colour bounds, and
// grainy; the lattice rule saw its openings between the twigs as sky: bounded by thin
// structure, next to the sky openings of the crowns' upper part across a twig, above the
// horizon.
constexpr int kSnowW = 640, kSnowH = 480, kSnowHorizon = 330;
struct SnowPhoto {
  Image photo;
  cv::Mat snow_openings, sky_openings;  // 2 px clear of every twig, inside the crowns
};
SnowPhoto birches_in_snow() {
  constexpr int w = kSnowW, h = kSnowH;
  auto ridge = [](int x) { return 190.0 + 12.0 * std::sin(x / 90.0); };
  const cv::Mat grain = snow_grain(w, h, 0.035f, 5);
  cv::Mat m(h, w, CV_32FC3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      if (y < ridge(x)) {
        const float t = float(y / ridge(x));
        m.at<cv::Vec3f>(y, x) =
            cv::Vec3f(0.30f, 0.50f, 0.84f) * (1 - t) + cv::Vec3f(0.62f, 0.74f, 0.90f) * t;
      } else {
        // Drifts: a slow shading across the slope, and the grain.
        const float v = 0.025f * float(std::sin(x / 37.0 + y / 23.0)) + grain.at<float>(y, x);
        m.at<cv::Vec3f>(y, x) = cv::Vec3f(0.68f + v, 0.78f + v, 0.92f + v);
      }
    }
  // The birches: a trunk from below the horizon up into the sky, main branches up and out from
  // it, twigs from those.
  cv::Mat twigs(h, w, CV_8U, cv::Scalar(0)), crowns(h, w, CV_8U, cv::Scalar(0));
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (const int x0 : {110, 250, 400, 540}) {
    const int base = 400 + int(30 * u(rng)), top = 60 + int(20 * u(rng));
    cv::line(twigs, cv::Point(x0, base), cv::Point(x0 + 2, top), cv::Scalar(255), 3, cv::LINE_AA);
    const cv::Point2d centre(x0, 180);
    const cv::Size2d axes(60, 100);
    for (int k = 0; k < 8; ++k) {  // main branches, up and out
      const double y = 110 + 150 * u(rng), a = (0.3 + 0.5 * u(rng)) * (k % 2 ? 1 : -1);
      const cv::Point2d p(x0 + 1, y), q(p.x + 55 * std::sin(a), p.y - 55 * std::cos(a));
      cv::line(twigs, p, q, cv::Scalar(255), 2, cv::LINE_AA);
    }
    for (int k = 0; k < 200; ++k) {  // the crown's net of twigs, every way
      double dx, dy;
      do dx = 2 * u(rng) - 1, dy = 2 * u(rng) - 1;
      while (dx * dx + dy * dy > 1);
      const cv::Point2d p(centre.x + axes.width * dx, centre.y + axes.height * dy);
      const double a = 2 * 3.14159265 * u(rng), l = 14 + 26 * u(rng);
      cv::line(twigs, p, p + cv::Point2d(l * std::cos(a), l * std::sin(a)), cv::Scalar(255), 1,
               cv::LINE_AA);
    }
    cv::ellipse(crowns, centre, cv::Size(int(axes.width) - 8, int(axes.height) - 8), 0, 0, 360,
                cv::Scalar(255), cv::FILLED);
  }
  const cv::Vec3f bark(0.20f, 0.18f, 0.16f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float a = twigs.at<std::uint8_t>(y, x) / 255.0f;
      cv::Vec3f& c = m.at<cv::Vec3f>(y, x);
      c = c * (1 - a) + bark * a;
    }
  cv::GaussianBlur(m, m, cv::Size(0, 0), 0.7);  // a lens
  SnowPhoto out{Image(w, h, 3), cv::Mat(h, w, CV_8U, cv::Scalar(0)),
                cv::Mat(h, w, CV_8U, cv::Scalar(0))};
  cv::Mat near_twig;
  cv::dilate(twigs, near_twig, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(5, 5)));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      for (int c = 0; c < 3; ++c)
        out.photo.at(x, y, c) = linear(std::clamp(m.at<cv::Vec3f>(y, x)[c], 0.0f, 1.0f));
      if (!crowns.at<std::uint8_t>(y, x) || near_twig.at<std::uint8_t>(y, x)) continue;
      if (y > ridge(x) + 4 && y < kSnowHorizon) out.snow_openings.at<std::uint8_t>(y, x) = 1;
      if (y < ridge(x) - 4) out.sky_openings.at<std::uint8_t>(y, x) = 1;
    }
  return out;
}

TEST(SkyLight, SnowBetweenBranchesStaysGround) {
  const SnowPhoto p = birches_in_snow();
  constexpr int kW = kSnowW, kH = kSnowH;
  const std::array<PixelPoint, 2> horizon{PixelPoint{0, kSnowHorizon - 0.5},
                                          PixelPoint{kW - 1.0, kSnowHorizon - 0.5}};
  photo::SkyMaskOptions off, unguarded;
  off.thin_member_width = 0;
  unguarded.opening_max_texture_ratio = 0;
  const photo::SkyMask with = photo::estimate_sky_mask(p.photo.view(), horizon);
  const photo::SkyMask without = photo::estimate_sky_mask(p.photo.view(), horizon, off);
  const photo::SkyMask first = photo::estimate_sky_mask(p.photo.view(), horizon, unguarded);
  std::size_t snow = 0, sky = 0, snow_with = 0, snow_without = 0, snow_first = 0, sky_with = 0,
              sky_without = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const std::size_t i = std::size_t(y) * kW + x;
      if (p.snow_openings.at<std::uint8_t>(y, x))
        ++snow, snow_with += with.sky[i], snow_without += without.sky[i],
            snow_first += first.sky[i];
      if (p.sky_openings.at<std::uint8_t>(y, x))
        ++sky, sky_with += with.sky[i], sky_without += without.sky[i];
    }
  Annotations annotations;
  annotations.horizon = horizon;
  const Camera camera = Camera::from_horizontal_fov(kW, kH, 60);
  const SceneEstimate est = estimate_scene(p.photo, camera, annotations);
  std::size_t snow_est = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x)
      snow_est +=
          p.snow_openings.at<std::uint8_t>(y, x) && std::isinf(est.geometry.distance_m.at(x, y, 0));
  const auto [e_haze, e_dense] = test::haze_and_dense_looks(p.photo, camera, est, "snow_birches");
  auto pct = [](std::size_t a, std::size_t b) { return 100.0 * double(a) / double(b); };
  std::printf(
      "snow between the twigs made sky: %.1f %% (the lattice rule off %.1f %%, unguarded "
      "%.1f %%), in the estimate %.1f %%; sky between the twigs %.1f %% (the rule off "
      "%.1f %%); created-edge pixels haze %.4f %%, dense %.4f %%\n",
      pct(snow_with, snow), pct(snow_without, snow), pct(snow_first, snow), pct(snow_est, snow),
      pct(sky_with, sky), pct(sky_without, sky), 100 * e_haze, 100 * e_dense);
  // Before the guard (37.1 %) the scene shows the failure; with it (0.3 %: an opening across
  // the ridge) the snow stays ground, in the mask and in the estimate, while the sky seen
  // through the crowns keeps the rule (0.7 % -> 36.5 %). Haze's created edges (0.055 %) lie at
  // the twigs' tips against the sky and around the crowns' sky openings the rule leaves out
  // (bounded by more open sky than twigs), none in the snow: not checked here.
  EXPECT_GE(double(snow_first), 0.3 * double(snow));
  EXPECT_LE(double(snow_with), 0.01 * double(snow));
  EXPECT_LE(double(snow_est), 0.01 * double(snow));
  EXPECT_GE(double(sky_with), double(sky_without) + 0.2 * double(sky));
  EXPECT_LE(e_dense, 2e-4);
}

// A snow field seen from above (snow_birches): no sky in the frame, the horizon guessed level
// through its middle. Sunlit snow is grainy and white; the shade of a wood and of the trees,
// lit by the blue sky alone, is the sky's own blue, smoother (less light, less grain) and wide,
// and touches the frame's top: the mask took it as sky, a dark cut-out at night and a flat
// bright patch in the sun bank. Its grain keeps it rougher than any sky's core.
TEST(SkyLight, SnowFieldSeenFromAboveIsNotSky) {
  constexpr int w = kSnowW, h = kSnowH;
  const cv::Mat lit_grain = snow_grain(w, h, 0.06f, 7), shade_grain = snow_grain(w, h, 0.03f, 8);
  cv::Mat shade(h, w, CV_32F, cv::Scalar(0));
  cv::ellipse(shade, cv::Point(60, -40), cv::Size(300, 150), -12, 0, 360, cv::Scalar(1),
              cv::FILLED);
  for (const int x0 : {250, 420, 560})  // the trees' shadows, long and diagonal
    cv::line(shade, cv::Point(x0, 40), cv::Point(x0 - 220, 440), cv::Scalar(1), 14, cv::LINE_AA);
  cv::GaussianBlur(shade, shade, cv::Size(0, 0), 4);
  cv::Mat m(h, w, CV_32FC3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float s = shade.at<float>(y, x);
      const cv::Vec3f lit =
          cv::Vec3f(0.86f, 0.89f, 0.94f) + cv::Vec3f(1, 1, 1) * lit_grain.at<float>(y, x);
      const cv::Vec3f dim =
          cv::Vec3f(0.42f, 0.55f, 0.80f) + cv::Vec3f(1, 1, 1) * shade_grain.at<float>(y, x);
      m.at<cv::Vec3f>(y, x) = lit * (1 - s) + dim * s;
    }
  cv::GaussianBlur(m, m, cv::Size(0, 0), 0.7);  // a lens
  Image photo(w, h, 3);
  std::size_t shaded_top = 0;  // the shade above the guessed horizon
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      for (int c = 0; c < 3; ++c)
        photo.at(x, y, c) = linear(std::clamp(m.at<cv::Vec3f>(y, x)[c], 0.0f, 1.0f));
      shaded_top += y < h / 2 && shade.at<float>(y, x) > 0.5f;
    }
  const std::array<PixelPoint, 2> level{PixelPoint{0, h / 2 - 0.5},
                                        PixelPoint{w - 1.0, h / 2 - 0.5}};
  photo::SkyMaskOptions before;
  before.max_core_floor = 0;
  const photo::SkyMask mask = photo::estimate_sky_mask(photo.view(), level);
  const photo::SkyMask old = photo::estimate_sky_mask(photo.view(), level, before);
  const Camera camera = Camera::from_horizontal_fov(w, h, 60);
  const SceneEstimate est = estimate_scene(photo, camera, Annotations{});
  std::printf(
      "snow field from above: sky pixels %zu (without the noise floor %zu of %zu shaded above "
      "the horizon), in the estimate %zu\n",
      mask.pixels, old.pixels, shaded_top, est.geometry.sky_pixels);
  EXPECT_GE(double(old.pixels), 0.3 * double(shaded_top));  // the scene shows the failure ...
  EXPECT_EQ(mask.pixels, 0u);                               // ... and the floor prevents it
  EXPECT_EQ(est.geometry.sky_pixels, 0u);
}

}  // namespace
}  // namespace mr
