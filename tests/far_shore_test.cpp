// Issue 11 (helper shore14): a thin band of far shore resting on a sea horizon under the sky
// (gallery/tune summer_1am's far shore, camera's skyline, rocket's band of land; rebuilt here
// without looking at the held-out photos). The band stood on the far billboard (46 m from 1.6 m,
// nearly clear in haze: T ~0.9) and the calm water in front of it at the refinement's distance
// (tens of metres), while the sky above it, seen along the haze layer's slant path, turns into
// the fog's light: a step in the fog along the band's outline and its foot where the photo
// shows a faint, low-contrast line. A near post standing in the water keeps its depth.
#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>

#include "mr/estimate.h"
#include "mr/fog.h"
#include "mr/image.h"
#include "mr/io.h"
#include "tests/flat_light_look.h"
#include "tests/gallery_look.h"

namespace mr {
namespace {

using test::gallery_created_edges;
using test::haze_and_dense_looks;
using test::linear;

constexpr int kW = 640, kH = 400, kHorizon = 220;
constexpr int kPointEndX = 330;
constexpr int kPostX = 560, kPostHalfWidth = 3, kPostTop = kHorizon - 60, kPostFoot = kHorizon + 90;

// The band's height above the horizon at column x (px): a low far shore of wooded hills over
// the left two thirds of the width, 3 to 14 px (0.3 to 1.4 degrees with 60 degrees across).
int band_height(int x) {
  if (x >= 430) return 0;
  const double t = x / 430.0;
  return int(std::lround(3 + 7 * std::sin(3.0 * t) * std::sin(3.0 * t) + 4 * std::sin(11.0 * t)));
}

// A dusk sky from a pink glow at the horizon to blue above, calm water its darker mirror image
// with faint ripples, the far shore a dark, slightly textured band on the horizon with its
// reflection, and a near dark post standing in the water (its foot 90 px below the horizon:
// about 10 m from 1.6 m).
Image far_shore_photo(int (*band_height_at)(int) = band_height) {
  Image photo(kW, kH, 3);
  auto sky = [&](double above) {  // display values, above = rows above the horizon
    const double t = std::clamp(above / kHorizon, 0.0, 1.0);
    const double glow = std::exp(-above / 25.0);
    return std::array<double, 3>{0.66 - 0.22 * glow - 0.06 * t, 0.64 - 0.28 * glow - 0.04 * t,
                                 0.78 - 0.30 * glow + 0.04 * t};
  };
  std::mt19937 rng(14);
  std::uniform_real_distribution<float> ripple(-0.006f, 0.006f), leaf(-0.02f, 0.02f);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const double dy = y - kHorizon + 0.5;
      std::array<double, 3> c = dy < 0 ? sky(-dy) : sky(dy);
      const int band = band_height_at(x);
      // The band above the horizon, and its reflection (as tall, darker) below it.
      const bool land = dy < 0 && -dy <= band;
      const bool reflection = dy >= 0 && dy < band;
      if (land || reflection) {
        // Faint: a far shore seen through the evening's air, a little darker than the glow.
        const double k = (land ? 0.78 : 0.82) + leaf(rng);
        for (double& v : c) v *= k;
        c[2] *= 1.05;
      }
      if (dy >= 0)
        for (double& v : c) v = 0.9 * v + ripple(rng);
      if (std::abs(x - kPostX) <= kPostHalfWidth && y >= kPostTop && y <= kPostFoot)
        c = {0.12, 0.10, 0.09};
      for (int k = 0; k < 3; ++k) photo.at(x, y, k) = linear(float(std::clamp(c[k], 0.0, 1.0)));
    }
  cv::Mat m(kH, kW, CV_32FC3, photo.data());
  cv::GaussianBlur(m, m, cv::Size(0, 0), 0.7);  // a lens
  return photo;
}

TEST(FarShore, ThinBandOnASeaHorizonIsFarAndHazeVeilsIt) {
  const Camera camera = Camera::from_horizontal_fov(kW, kH, 60);
  const Image photo = far_shore_photo();
  Annotations horizon;
  horizon.horizon = std::array<PixelPoint, 2>{PixelPoint{0, double(kHorizon)},
                                              PixelPoint{kW - 1.0, double(kHorizon)}};
  EstimateOptions before, with_rule;
  before.far_shore = false;
  with_rule.far_shore = true;
  const SceneEstimate est = estimate_scene(photo, camera, horizon, with_rule);
  const SceneEstimate est_before = estimate_scene(photo, camera, horizon, before);
  const test::GalleryLooks after = haze_and_dense_looks(photo, camera, est, "far_shore");
  const test::GalleryLooks base =
      haze_and_dense_looks(photo, camera, est_before, "far_shore_before");
  // The defect and its mend in haze are measured under the flat sky light (the render before
  // helper haze15): the sky light's brightness scale, on by default since, darkens the sky's
  // fog toward this photo's glow and hides the band's step as well (default render: 0.0023 %
  // before, 0.0090 % with the rule, both within the target, checked below).
  const double flat_after = gallery_created_edges(
      photo, test::fog_auto_look_flat_light(photo, camera, est, 2000, 1500, 0.6).composite);
  const double flat_base = gallery_created_edges(
      photo, test::fog_auto_look_flat_light(photo, camera, est_before, 2000, 1500, 0.6).composite);
  auto d = [](const SceneEstimate& e, int x, int y) { return e.geometry.distance_m.at(x, y, 0); };
  // The band's middle row at its tallest column, the water 4 px below the horizon
  // there, the post 30 px above the horizon and 40 px below it.
  int xb = 0;
  for (int x = 0; x < 430; ++x)
    if (band_height(x) > band_height(xb)) xb = x;
  const int yb = kHorizon - band_height(xb) / 2 - 1;
  std::printf(
      "far shore (column %d, %d px tall): band at %.0f m (before %.0f m), water 4 px below the "
      "horizon %.0f m (before %.0f m); post 30 px above / 40 px below the horizon %.1f / %.1f m "
      "(before %.1f / %.1f m); created-edge pixels haze %.4f %% (before %.4f %%), dense %.4f %% "
      "(before %.4f %%); under the flat sky light haze %.4f %% (before %.4f %%)\n",
      xb, band_height(xb), d(est, xb, yb), d(est_before, xb, yb), d(est, xb, kHorizon + 4),
      d(est_before, xb, kHorizon + 4), d(est, kPostX, kHorizon - 30), d(est, kPostX, kHorizon + 40),
      d(est_before, kPostX, kHorizon - 30), d(est_before, kPostX, kHorizon + 40),
      100 * after.haze_edges, 100 * base.haze_edges, 100 * after.dense_edges,
      100 * base.dense_edges, 100 * flat_after, 100 * flat_base);
  // The defect reproduced: without the rule the band steps out of the haze.
  EXPECT_GT(flat_base, 2e-4);
  // The band is kilometres away, the water in front of it farther than before.
  EXPECT_GT(d(est, xb, yb), 1000.0f);
  EXPECT_GT(d(est, xb, kHorizon + 4), d(est_before, xb, kHorizon + 4));
  // Fewer created edges in haze (flat light): the band and its reflection veiled (0.0070 % with
  // shore15's mirror test and fade, within the 0.02 %; 0.0219 % with shore14's rule);
  // dense fog within it.
  EXPECT_LT(flat_after, 0.75 * flat_base);
  EXPECT_LE(flat_after, 2e-4);
  EXPECT_LE(after.dense_edges, 2e-4);
  // With the default render (the brightness scale on) haze is within the target too.
  EXPECT_LE(after.haze_edges, 2e-4);
  // The near post standing in the water keeps its depth, above and below the horizon.
  for (const int y : {kHorizon - 30, kHorizon - 5, kHorizon + 40})
    EXPECT_NEAR(d(est, kPostX, y), d(est_before, kPostX, y), 0.01 * d(est_before, kPostX, y))
        << "row " << y;
}

}  // namespace
}  // namespace mr

namespace mr {
namespace {

// Helper shore15: a horizon found a few pixels above the waterline (gallery/tune summer_1am:
// 5-6 px). The same far shore and its reflection, the annotated horizon 5 px too high: the
// reflection starts at the waterline, so the waterline is found from the mirror itself and the
// reflection's rows (below the horizon as annotated, and below where a reflection measured
// from that horizon would end) are as far as the band. Fails before (shore14's rule: 0 of
// 792 such rows far).
TEST(FarShore, ReflectionStartsAtTheWaterlineNotAtAHorizonFoundTooHigh) {
  const Camera camera = Camera::from_horizontal_fov(kW, kH, 60);
  const Image photo = far_shore_photo();
  constexpr int kTooHighPx = 5;
  Annotations horizon;
  horizon.horizon = std::array<PixelPoint, 2>{PixelPoint{0, double(kHorizon - kTooHighPx)},
                                              PixelPoint{kW - 1.0, double(kHorizon - kTooHighPx)}};
  EstimateOptions before, with_rule;
  before.far_shore = false;
  with_rule.far_shore = true;
  const SceneEstimate est = estimate_scene(photo, camera, horizon, with_rule);
  const SceneEstimate est_before = estimate_scene(photo, camera, horizon, before);
  const test::GalleryLooks after = haze_and_dense_looks(photo, camera, est, "waterline");
  const test::GalleryLooks base =
      haze_and_dense_looks(photo, camera, est_before, "waterline_before");
  auto d = [](const SceneEstimate& e, int x, int y) { return e.geometry.distance_m.at(x, y, 0); };
  // In the band's tall columns, its reflection's last rows (within the reflection, but below
  // where a reflection mirrored about the annotated horizon would end) are kilometres away.
  int far_rows = 0, rows = 0;
  for (int x = 20; x < 400; ++x) {
    const int band = band_height(x);
    if (band < 8) continue;
    for (int y = kHorizon + band - kTooHighPx; y < kHorizon + band - 1; ++y, ++rows)
      if (d(est, x, y) > 1000.0f) ++far_rows;
  }
  std::printf(
      "waterline (horizon %d px high): reflection rows far %d of %d; created-edge "
      "pixels haze %.4f %% (before %.4f %%), dense %.4f %% (before %.4f %%)\n",
      kTooHighPx, far_rows, rows, 100 * after.haze_edges, 100 * base.haze_edges,
      100 * after.dense_edges, 100 * base.dense_edges);
  ASSERT_GT(rows, 0);
  EXPECT_GT(far_rows, rows * 9 / 10);
  EXPECT_LE(after.dense_edges, 2e-4);
  // Not barred: haze's created edges, fewer than without the rule with the horizon 2 px too
  // high (0.027 -> 0.014 %), more with 3 and 5 px (0.028 -> 0.038 %, 0.169 -> 0.257 %): where
  // the band is lower than the horizon's error nothing of it stands above the horizon, so those
  // columns are no band and stay clear beside veiled ones (gallery/results/shore15_tune.md).
}

// Helper shore15 (gallery/tune storm_pano): a dark ridge on the horizon under a dark storm sky,
// and in front of it a dark ploughed field as bright as the ridge and the sky's lower edge, but
// no mirror: the field's rows do not repeat the ridge's outline upside down. The ridge is no
// far shore across water, and neither it nor the field moves.
Image dark_field_photo() {
  Image photo(kW, kH, 3);
  std::mt19937 rng(15);
  std::uniform_real_distribution<float> clod(-0.01f, 0.01f);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const double dy = y - kHorizon + 0.5;
      const double t = std::clamp(-dy / kHorizon, 0.0, 1.0);
      // A dark blue-grey storm sky, lighter near the horizon.
      std::array<double, 3> c{0.30 - 0.12 * t, 0.33 - 0.12 * t, 0.40 - 0.12 * t};
      const int band = band_height(x);
      if (dy < 0 && -dy <= band) c = {0.22 + clod(rng), 0.25 + clod(rng), 0.25 + clod(rng)};
      if (dy >= 0) {
        // The field: dark brown furrows running to the horizon, a little lighter nearer.
        const double near = std::clamp(dy / (kH - kHorizon), 0.0, 1.0);
        const double furrow = 0.02 * std::sin(0.35 * x + 40.0 / (dy + 2.0));
        const double v = 0.24 + 0.04 * near + furrow + clod(rng);
        c = {v * 1.05, v * 0.92, v * 0.80};
      }
      for (int k = 0; k < 3; ++k) photo.at(x, y, k) = linear(float(std::clamp(c[k], 0.0, 1.0)));
    }
  cv::Mat m(kH, kW, CV_32FC3, photo.data());
  cv::GaussianBlur(m, m, cv::Size(0, 0), 0.7);
  return photo;
}

TEST(FarShore, DarkFieldUnderADarkRidgeIsNoWater) {
  const Camera camera = Camera::from_horizontal_fov(kW, kH, 60);
  const Image photo = dark_field_photo();
  Annotations horizon;
  horizon.horizon = std::array<PixelPoint, 2>{PixelPoint{0, double(kHorizon)},
                                              PixelPoint{kW - 1.0, double(kHorizon)}};
  EstimateOptions before, with_rule;
  before.far_shore = false;
  with_rule.far_shore = true;
  const SceneEstimate est = estimate_scene(photo, camera, horizon, with_rule);
  const SceneEstimate est_before = estimate_scene(photo, camera, horizon, before);
  const Image& da = est.geometry.distance_m;
  const Image& db = est_before.geometry.distance_m;
  int moved = 0, checked = 0;
  for (int x = 0; x < 430; ++x)
    for (int y = kHorizon - 14; y < kHorizon + 40; ++y, ++checked) {
      const float a = da.at(x, y, 0), b = db.at(x, y, 0);
      if (std::isfinite(b) && !(std::abs(a - b) <= 0.01f * b)) ++moved;
    }
  std::printf("dark field: %d of %d pixels of the ridge and the field moved\n", moved, checked);
  EXPECT_LE(moved, checked / 100);
}

}  // namespace
}  // namespace mr

namespace mr {
namespace {

// The far shore's reflection returns to the water's distance gradually below it (over twice
// the band's height), and the water beyond 4 degrees below the horizon (the ground's full
// confidence, kept exactly by the refinement) was written back as the ground plane over that
// return: a step in distance (2x there, 3.2x here) along the row where the confidence is 1, a
// straight seam across calm water the photo does not have (gallery/tune summer_1am's lake at
// 4 degrees: 47 m over 23 m in one row, plain in the night look's 70 m fog). The distance down
// a column of water changes from row to row only as the bounds' ramps do: from kilometres to
// tens of metres over some 20-40 rows, at most 1.26x per row here (the ground plane itself
// changes by ~3 % per row there), against the step's 3.2x before. The sky fold is off here: this
// synthetic water meets the open sky right of the shore, so its fold stays just under 1 down to the
// frame's bottom and every water pixel was written back anyway, hiding the step; summer_1am's
// water, cut off from the sky by its shore, has a fold of exactly 1 (the default's case).
TEST(FarShore, WaterReturnsToItsPlaneWithoutAStepWhereTheGroundIsKeptExactly) {
  const Camera camera = Camera::from_horizontal_fov(kW, kH, 60);
  const Image photo = far_shore_photo();
  Annotations horizon;
  horizon.horizon = std::array<PixelPoint, 2>{PixelPoint{0, double(kHorizon)},
                                              PixelPoint{kW - 1.0, double(kHorizon)}};
  EstimateOptions options;
  options.sky_fold = false;
  const SceneEstimate est = estimate_scene(photo, camera, horizon, options);
  double worst = 1;
  int worst_x = -1, worst_y = -1;
  for (int x = 0; x < 430; ++x) {
    if (band_height(x) < 8) continue;
    for (int y = kHorizon + 2 * band_height(x) + 8; y + 1 < kH; ++y) {
      const double a = est.geometry.distance_m.at(x, y, 0),
                   b = est.geometry.distance_m.at(x, y + 1, 0);
      if (!(std::isfinite(a) && std::isfinite(b) && b > 0)) continue;
      if (a / b > worst) worst = a / b, worst_x = x, worst_y = y;
    }
  }
  std::printf(
      "water below the far shore: largest row-to-row distance ratio %.3f (column %d, row %d)\n",
      worst, worst_x, worst_y);
  EXPECT_LT(worst, 1.5);
}

// Where the far shore ends, its water goes on beside it under the open sky (a wooded point
// ending at a column). The band's columns bound their water's distance by the band's rule, the
// columns beside it by the open water's only, and the two met in one column: the water in front
// stepped from kilometres to tens of metres there (gallery/tune summer_1am: a vertical seam
// through the reflection in dense fog, a pale block in the night look). Across the band's end
// the water's distance changes gradually from column to column.
int point_height(int x) {
  return x < kPointEndX ? 10 : 0;
}

TEST(FarShore, WaterBesideTheBandsEndHasNoSeamAcrossColumns) {
  const Camera camera = Camera::from_horizontal_fov(kW, kH, 60);
  const Image photo = far_shore_photo(point_height);
  Annotations horizon;
  horizon.horizon = std::array<PixelPoint, 2>{PixelPoint{0, double(kHorizon)},
                                              PixelPoint{kW - 1.0, double(kHorizon)}};
  const SceneEstimate est = estimate_scene(photo, camera, horizon, EstimateOptions{});
  // Beyond the haze look's visibility both sides are as good as opaque, in every look.
  constexpr double kVisibleM = 2000;
  double worst = 1;
  int worst_x = -1, worst_y = -1;
  // The water's first rows (the reflection and as much again), from well inside the band to
  // well past its end, short of the post.
  for (int y = kHorizon + 1; y < kHorizon + 40; ++y)
    for (int x = kPointEndX - 150; x + 1 < kPostX - 20; ++x) {
      const double a = est.geometry.distance_m.at(x, y, 0),
                   b = est.geometry.distance_m.at(x + 1, y, 0);
      if (!(std::isfinite(a) && std::isfinite(b) && a > 0 && b > 0) || std::min(a, b) > kVisibleM)
        continue;
      const double ratio = std::max(a / b, b / a);
      if (ratio > worst) worst = ratio, worst_x = x, worst_y = y;
    }
  std::printf(
      "water beside the band's end: largest column-to-column distance ratio %.3f (column %d, "
      "row %d)\n",
      worst, worst_x, worst_y);
  EXPECT_LT(worst, 1.5);
}

}  // namespace
}  // namespace mr

namespace mr {
namespace {

// Issue 11 (gallery/tune darkesthour: a lake at blue hour, no line to find the horizon from).
// The level fall-back cuts through the sky 20 px above the waterline; the calm water mirrors
// the sky as smoothly as the sky itself, so the sky "went on" below the guess down to the
// frame's bottom and the horizon was lowered out of the frame: the lake was sky, veiled flat by
// any fog. The horizon goes down only to the water's mirror line; with the rule off it goes
// past it (the defect, reproduced).
TEST(FarShore, MirroringWaterStopsAWeakHorizonAtItsWaterline) {
  const Camera camera = Camera::from_horizontal_fov(kW, kH, 60);
  // No far shore: nothing but the glow's gradient and its mirror image gives the horizon away.
  const Image photo = far_shore_photo([](int) { return 0; });
  EstimateOptions with_rule, without;
  without.water_mirror = false;
  const SceneEstimate est = estimate_scene(photo, camera, Annotations{}, with_rule);
  const SceneEstimate est_before = estimate_scene(photo, camera, Annotations{}, without);
  auto horizon_row = [](const SceneEstimate& e) {
    return 0.5 * (e.geometry.horizon[0][1] + e.geometry.horizon[1][1]);
  };
  // Pixels of open water (away from the post and the band's reflection) that are sky.
  auto water_sky = [&](const SceneEstimate& e) {
    std::size_t sky = 0, all = 0;
    for (int y = kHorizon + 20; y < kH; ++y)
      for (int x = 440; x < kW; ++x) {
        if (std::abs(x - kPostX) <= kPostHalfWidth + 4) continue;
        ++all;
        sky += std::isinf(e.geometry.distance_m.at(x, y, 0));
      }
    return double(sky) / double(all);
  };
  const test::GalleryLooks looks = haze_and_dense_looks(photo, camera, est, "water_mirror");
  std::printf(
      "mirroring water under the level fall-back: %s; horizon row %.1f (waterline %d; without "
      "the rule %.1f); open water that is sky %.1f %% (without %.1f %%); created-edge pixels "
      "haze %.4f %%, dense %.4f %%\n",
      est.notes.front().c_str(), horizon_row(est), kHorizon, horizon_row(est_before),
      100 * water_sky(est), 100 * water_sky(est_before), 100 * looks.haze_edges,
      100 * looks.dense_edges);
  ASSERT_GT(est_before.geometry.horizon_lowered_px, 0.0);  // the case: a weak guess lowered
  EXPECT_FALSE(est_before.geometry.lowered_to_water);
  EXPECT_GT(horizon_row(est_before), kHorizon + 20.0);
  EXPECT_GT(water_sky(est_before), 0.5);
  EXPECT_TRUE(est.geometry.lowered_to_water);
  EXPECT_NEAR(horizon_row(est), kHorizon, 3.0);
  EXPECT_EQ(water_sky(est), 0.0);
  EXPECT_LE(looks.haze_edges, 2e-4);
  EXPECT_LE(looks.dense_edges, 2e-4);
}

// The photo the rule was made on (gallery/tune darkesthour, 1280x800: a lake at blue hour, the
// far shore's trees on its waterline near row 530). Without the rule the horizon went out of
// the frame and 99.9 % of it was sky, the lake veiled flat in every look.
TEST(FarShore, DarkestHoursLakeIsWaterUnderItsWaterline) {
  const Image photo = test::tuning_photo("darkesthour.jpg");
  EstimateOptions without;
  without.water_mirror = false;
  const test::WithAndWithout e = test::estimate_with_and_without(photo, without);
  const Camera& camera = e.camera;
  const SceneEstimate &est = e.with, &before = e.without;
  const double n = double(photo.width()) * photo.height();
  std::size_t lake_sky = 0;
  for (int y = 560; y < photo.height(); ++y)
    for (int x = 0; x < photo.width(); ++x)
      lake_sky += std::isinf(est.geometry.distance_m.at(x, y, 0));
  const test::GalleryLooks looks = haze_and_dense_looks(photo, camera, est, "darkesthour");
  std::printf(
      "darkesthour: %s; sky %.1f %% (without the rule %.1f %%), sky below row 560: %zu px; "
      "created-edge pixels haze %.4f %%, dense %.4f %%\n",
      est.notes.front().c_str(), 100 * est.geometry.sky_pixels / n,
      100 * before.geometry.sky_pixels / n, lake_sky, 100 * looks.haze_edges,
      100 * looks.dense_edges);
  ASSERT_GT(double(before.geometry.sky_pixels), 0.99 * n);  // the defect reproduced
  EXPECT_TRUE(est.geometry.lowered_to_water);
  for (const auto& end : est.geometry.horizon) {
    EXPECT_GE(end[1], 520.0);
    EXPECT_LE(end[1], 540.0);
  }
  EXPECT_EQ(lake_sky, 0u);
  EXPECT_LE(looks.haze_edges, 2e-4);
  EXPECT_LE(looks.dense_edges, 2e-4);
}

}  // namespace
}  // namespace mr

// Issue 11 (tuning cold_water: people wading in a sea under an overcast sky, no line cue). The
// level fall-back put the horizon through the frame's middle, 36 px under the sea line: the
// sea's far band stood as a wall above the horizon, and the sea under the guess ran to 14-30
// m where it is kilometres away (dense fog left the far sea and the people along the line
// plain). A sea line is the horizon: where the sky ends along a straight, level line above a
// weak guess, the guess is raised to it (EstimateOptions::level_sky_line). A land's skyline
// (a wooded ridge) is not straight, and stays where the guess puts it.
namespace mr {
namespace {

using test::linear;

constexpr int kSeaW = 640, kSeaH = 427, kSeaLine = 170;  // the fall-back's row: 213

// An overcast sky over a sea (or, `ragged`, a wooded ridge whose top wanders by up to 14 px),
// two dark figures wading in front, their heads over the line: the negative case's photo.
Image sea_photo(bool ragged) {
  Image photo(kSeaW, kSeaH, 3);
  std::mt19937 rng(33);
  std::uniform_real_distribution<float> ripple(-0.04f, 0.04f);
  auto top = [&](int x) {
    return ragged ? kSeaLine - int(std::lround(7 + 5 * std::sin(x / 23.0) + 2 * std::sin(x / 5.0)))
                  : kSeaLine;
  };
  for (int y = 0; y < kSeaH; ++y)
    for (int x = 0; x < kSeaW; ++x) {
      std::array<double, 3> c;
      if (y < top(x)) {  // overcast: pale grey-blue, a little darker up
        const double t = double(y) / kSeaLine;
        c = {0.70 + 0.08 * t, 0.73 + 0.08 * t, 0.80 + 0.05 * t};
      } else if (ragged) {
        const double k = ripple(rng);
        c = {0.16 + k, 0.22 + k, 0.12 + k};
      } else {
        const double k = ripple(rng) * std::min(1.0, (y - kSeaLine + 2) / 40.0);
        c = {0.36 + k, 0.40 + k, 0.38 + k};  // a grey-green sea, darker than the sky
      }
      // Round figures (no straight edges for a line cue): a head over the line, a body below.
      auto blob = [&](double cx, double cy, double rx, double ry) {
        return std::pow((x - cx) / rx, 2) + std::pow((y - cy) / ry, 2) <= 1;
      };
      if (blob(170, kSeaLine - 20, 11, 13) || blob(170, kSeaLine + 60, 30, 75) ||
          blob(450, kSeaLine - 30, 13, 15) || blob(450, kSeaLine + 70, 38, 95))
        c = {0.08, 0.08, 0.10};
      for (int k = 0; k < 3; ++k) photo.at(x, y, k) = linear(float(std::clamp(c[k], 0.0, 1.0)));
    }
  cv::Mat m(kSeaH, kSeaW, CV_32FC3, photo.data());
  cv::GaussianBlur(m, m, cv::Size(0, 0), 0.7);  // a lens
  return photo;
}

TEST(FarShore, ASeaLineAboveTheLevelGuessIsTheHorizon) {
  const Image photo = test::tuning_photo("cold_water.jpg");
  const Camera camera = Camera::from_horizontal_fov(photo.width(), photo.height(), 60);
  const SceneEstimate est = estimate_scene(photo, camera, Annotations{});
  EstimateOptions off;
  off.level_sky_line = false;
  const SceneEstimate before = estimate_scene(photo, camera, Annotations{}, off);
  const auto& g = est.geometry;
  const double centre = 0.5 * (photo.width() - 1);
  auto row_at_centre = [&](const std::array<PixelPoint, 2>& line) {
    return line[0][1] +
           (centre - line[0][0]) * (line[1][1] - line[0][1]) / (line[1][0] - line[0][0]);
  };
  // The sea line, read off the photo: the sky's last row is 229 and the sea's first 230 in
  // every clear column (the grey steps from ~190 to ~150 there).
  const double sea_line = 229.5;
  const int far_x = 700, far_y = 232;  // clear sea, 2 rows under the line
  std::printf(
      "cold_water: %s; horizon at the centre row %.1f (without the rule %.1f), raised %.1f px; "
      "the sea 2 rows under its line at %.0f m (%.1f m)\n",
      est.notes.empty() ? "" : est.notes.front().c_str(), row_at_centre(g.horizon),
      row_at_centre(before.geometry.horizon), g.horizon_raised_px, g.distance_m.at(far_x, far_y, 0),
      before.geometry.distance_m.at(far_x, far_y, 0));
  ASSERT_EQ(before.geometry.horizon_source, EstimateSource::fallback);  // no line cue
  EXPECT_NEAR(row_at_centre(before.geometry.horizon), 0.5 * photo.height(), 1.0);
  EXPECT_EQ(before.geometry.horizon_raised_px, 0);
  EXPECT_GT(g.horizon_raised_px, 0);
  EXPECT_NEAR(row_at_centre(g.horizon), sea_line, 1.5);
  // The ground plane 2 rows under a horizon 1.6 m up is ~550 m away (the refinement against
  // the sea's ripples brings it nearer); under the guess the sea there stood at ~15 m.
  EXPECT_GT(g.distance_m.at(far_x, far_y, 0), 40.0f);
  EXPECT_LT(before.geometry.distance_m.at(far_x, far_y, 0), 25.0f);
}

TEST(FarShore, ARaggedSkylineAboveTheLevelGuessIsNoSeaLine) {
  const Image photo = sea_photo(true);
  const Camera camera = Camera::from_horizontal_fov(kSeaW, kSeaH, 60);
  const SceneEstimate est = estimate_scene(photo, camera, Annotations{});
  std::printf("ridge: %s\n", est.notes.empty() ? "" : est.notes.front().c_str());
  ASSERT_EQ(est.geometry.horizon_source, EstimateSource::fallback);
  EXPECT_EQ(est.geometry.horizon_raised_px, 0);
}

}  // namespace
}  // namespace mr
