// Issue 11 item 3, "depth that does no harm": the automatic geometry's remaining artifacts, on
// synthetic photos made to fail the way real ones did (gallery/results/geometry_tune.md):
// dark trunks on a snow field seen from above (no sky, no ground plane to the horizon) became
// vertical depth columns from the top of the frame down to each trunk's foot; posts standing on
// the ground under a sky got a staircase of per-column distances; a close-up was placed tens
// of metres away (dense fog erased it, a night look's lamps hung tens of metres into it).
// Every test prints its numbers.
#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
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
#include "photo/geometry.h"
#include "tests/display_luma.h"
#include "tests/gallery_look.h"

namespace mr {
namespace {

constexpr int kW = 640, kH = 480;
const Camera kCamera = Camera::from_horizontal_fov(kW, kH, 60);

// Scene-linear photo of a display-referred [0, 1] CV_32FC3 picture (gamma 2.2).
Image to_photo(const cv::Mat& display) {
  Image out(display.cols, display.rows, 3);
  for (int y = 0; y < display.rows; ++y)
    for (int x = 0; x < display.cols; ++x)
      for (int c = 0; c < 3; ++c)
        out.at(x, y, c) = std::pow(std::clamp(display.at<cv::Vec3f>(y, x)[c], 0.0f, 1.0f), 2.2f);
  return out;
}

// With MR_TEST_IMAGES=<folder>: the photos and depths as PNGs, to look at (a distance map as
// 1 - exp(-d / scale_m), sky blue-white).
void dump(const std::string& name, const Image& image, double scale_m = 10) {
  const char* folder = std::getenv("MR_TEST_IMAGES");
  if (!folder || !*folder) return;
  if (image.channels() == 1) {
    Image v(image.width(), image.height(), 3);
    for (int y = 0; y < image.height(); ++y)
      for (int x = 0; x < image.width(); ++x) {
        const float d = image.at(x, y, 0);
        const float g = std::isfinite(d) ? float(-std::expm1(-d / scale_m)) : 1.0f;
        for (int c = 0; c < 3; ++c)
          v.at(x, y, c) = std::pow(g, 2.2f) * (c == 2 || std::isfinite(d) ? 1.0f : 0.8f);
      }
    write_image(std::string(folder) + "/" + name + ".png", v);
    return;
  }
  write_image(std::string(folder) + "/" + name + ".png", image);
}

using mr::test::display_luma;  // tests/display_luma.h

// Where the photo has an edge: its display luma's largest difference to a neighbour within
// `reach` pixels (a square window) is at least `contrast`.
cv::Mat edge_near(const Image& photo, int reach, float contrast) {
  const cv::Mat l = display_luma(photo);
  cv::Mat hi, lo;
  const cv::Mat k =
      cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * reach + 1, 2 * reach + 1));
  cv::dilate(l, hi, k);
  cv::erode(l, lo, k);
  cv::Mat out = (hi - lo) >= contrast;
  return out;
}

// Depth discontinuities where the photo has no edge: horizontally neighbouring pixels whose
// transmittance in a reference fog differs by more than 0.03, with no photo edge (contrast
// 0.15) within 2 px. The reference fog's extinction length is the scene's own far distance
// (`far_m`: the far billboard's forward distance), so the count does not depend on the
// scene's metres; the sky's transmittance is 0. Writes the seams in red over the photo.
std::size_t vertical_seams_off_edges(const Image& photo, const Image& distance, double far_m,
                                     const std::string& name = "") {
  const cv::Mat edge = edge_near(photo, 2, 0.15f);
  auto t = [&](int x, int y) {
    const float d = distance.at(x, y, 0);
    return std::isfinite(d) ? std::exp(-d / far_m) : 0.0;
  };
  Image map = photo;
  std::size_t n = 0;
  for (int y = 0; y < photo.height(); ++y)
    for (int x = 0; x + 1 < photo.width(); ++x) {
      if (edge.at<std::uint8_t>(y, x)) continue;
      if (std::abs(t(x + 1, y) - t(x, y)) > 0.03) {
        ++n;
        map.at(x, y, 0) = 1, map.at(x, y, 1) = map.at(x, y, 2) = 0;
      }
    }
  if (!name.empty()) dump(name, map);
  return n;
}

double far_billboard_m(const GeometryEstimate& g) {
  return g.pose.position_m.y / std::tan(EstimateOptions{}.billboard_depression_deg * M_PI / 180);
}

// A snow field seen from above (no sky anywhere): bright textured snow, a few soft drifts,
// dark birch trunks standing in it, each from the top border down to its foot at a different
// row (a real case: the fresh set's description of a snowy birch wood from above).
cv::Mat snow_field_display() {
  cv::Mat m(kH, kW, CV_32FC3);
  std::mt19937 rng(21);
  std::uniform_real_distribution<float> grain(-0.07f, 0.07f);
  // Crust and footprints: blotches a few pixels across (rough at any scale the sky mask reads).
  cv::Mat blotches(kH, kW, CV_32F);
  cv::RNG(5).fill(blotches, cv::RNG::NORMAL, 0, 1);
  cv::GaussianBlur(blotches, blotches, cv::Size(0, 0), 2.5);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const float drift = 0.04f * std::sin(x / 37.0f + y / 53.0f);
      const float v = 0.76f + drift + 0.8f * blotches.at<float>(y, x) + 0.5f * grain(rng);
      m.at<cv::Vec3f>(y, x) = cv::Vec3f(v, v + 0.01f, v + 0.03f);
    }
  const int feet[] = {300, 420, 260, 380, 330, 450, 290, 400};
  for (int i = 0; i < 8; ++i) {
    const int x0 = 40 + i * 76 + (i % 3) * 7, width = 9 + (i % 4) * 3;
    for (int y = 0; y <= feet[i]; ++y)
      for (int x = x0; x < x0 + width; ++x) {
        const float v = 0.12f + 0.05f * grain(rng);
        m.at<cv::Vec3f>(y, x) = cv::Vec3f(v, v, v);
      }
  }
  return m;
}

TEST(GeometryNoHarm, SnowFieldFromAboveHasNoDepthColumns) {
  const Image photo = to_photo(snow_field_display());
  const GeometryEstimate g = estimate_geometry(photo, kCamera, Annotations{});
  dump("snow_photo", photo);
  dump("snow_depth", g.distance_m);
  EXPECT_EQ(g.sky_pixels, 0u);
  EXPECT_EQ(g.contact_pixels, 0u);  // no structure stands on a guessed horizon
  const std::size_t seams =
      vertical_seams_off_edges(photo, g.distance_m, far_billboard_m(g), "snow_seams");
  std::printf(
      "snow field: %zu vertical depth seams (> 5 %%) off the photo's edges; "
      "structures %zu px, scale: %s\n",
      seams, g.contact_pixels, g.scale_cue.c_str());
  // Bar: a few isolated pixels where the ground's confidence ramp meets the far billboard
  // in the grain (0.05 % of the frame; the gallery's created-edge target is 0.02 % of the
  // frame for a whole fogged image), against 2.5 % of the frame in columns before.
  const double frame = double(kW) * kH;
  EXPECT_LT(double(seams), 5e-4 * frame);
  // Also at the outdoor scale (no rescaling): the columns came from the structures' contacts.
  EstimateOptions unscaled;
  unscaled.bounded_scene_depth_m = 1e6;
  const GeometryEstimate u = estimate_geometry(photo, kCamera, Annotations{}, unscaled);
  const std::size_t seams_unscaled =
      vertical_seams_off_edges(photo, u.distance_m, far_billboard_m(u), "snow_seams_unscaled");
  std::printf("snow field, unscaled: %zu seams\n", seams_unscaled);
  EXPECT_LT(double(seams_unscaled), 5e-4 * frame);
  EXPECT_EQ(u.contact_pixels, 0u);
}

// Posts standing on a snow field under a sky, joined at their tops by a textured grey band (a
// fence's top rail, a row of sheds): one structure whose feet are at different rows. Their
// contacts used to be copied column by column into the band between them: a staircase of
// distances with a vertical seam halfway between each two posts, where the photo has none.
cv::Mat posts_display() {
  cv::Mat m(kH, kW, CV_32FC3);
  std::mt19937 rng(4);
  std::uniform_real_distribution<float> grain(-0.05f, 0.05f);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      cv::Vec3f c;
      if (y < 140) {
        const float t = y / 140.0f;
        c = cv::Vec3f(0.36f, 0.55f, 0.86f) * (1 - t) + cv::Vec3f(0.70f, 0.78f, 0.88f) * t;
      } else if (y < 200) {
        const float v = 0.45f + grain(rng);  // the band: textured grey
        c = cv::Vec3f(v, v, v);
      } else {
        const float v = 0.85f + 0.6f * grain(rng);  // the snow
        c = cv::Vec3f(v, v + 0.01f, v + 0.03f);
      }
      m.at<cv::Vec3f>(y, x) = c;
    }
  const int feet[] = {300, 340, 270, 380, 320, 420, 290, 360, 310, 400};
  for (int i = 0; i < 10; ++i) {
    const int x0 = 12 + i * 63;
    for (int y = 200; y <= feet[i]; ++y)
      for (int x = x0; x < x0 + 26; ++x) {
        const float v = 0.40f + grain(rng);
        m.at<cv::Vec3f>(y, x) = cv::Vec3f(v, v, v);
      }
  }
  return m;
}

TEST(GeometryNoHarm, PostsStandingOnTheGroundMakeNoStaircase) {
  const Image photo = to_photo(posts_display());
  Annotations level;
  level.horizon = std::array<PixelPoint, 2>{PixelPoint{0, 239.5}, PixelPoint{kW - 1, 239.5}};
  level.camera_height_m = 1.6;
  const GeometryEstimate g = estimate_geometry(photo, kCamera, level);
  dump("posts_photo", photo);
  dump("posts_depth", g.distance_m, 50);
  const std::size_t seams =
      vertical_seams_off_edges(photo, g.distance_m, far_billboard_m(g), "posts_seams");
  std::printf("posts: %zu vertical depth seams (> 5 %%) off the photo's edges; structures %zu px\n",
              seams, g.contact_pixels);
  EXPECT_GT(g.contact_pixels, 0u);  // the case does stand structures on the ground
  EXPECT_EQ(seams, 0u);
}

// A close-up without sky: a cup (a bright disc) on a wooden table seen from above, as the
// tuning half's coffee photo. A real close-up is centimetres to a few metres away.
cv::Mat closeup_display() {
  cv::Mat m(kH, kW, CV_32FC3);
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> grain(-0.05f, 0.05f);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const float n = grain(rng) + 0.08f * std::sin(y / 2.5f + x / 90.0f);
      m.at<cv::Vec3f>(y, x) = cv::Vec3f(0.45f + n, 0.30f + n, 0.18f + n);
    }
  cv::circle(m, cv::Point(320, 300), 130, cv::Scalar(0.92, 0.9, 0.88), cv::FILLED, cv::LINE_AA);
  cv::circle(m, cv::Point(320, 300), 80, cv::Scalar(0.35, 0.2, 0.1), cv::FILLED, cv::LINE_AA);
  return m;
}

TEST(GeometryNoHarm, CloseUpIsMetresAwayNotTensOfMetres) {
  const Image photo = to_photo(closeup_display());
  const SceneEstimate est = estimate_scene(photo, kCamera, Annotations{});
  const GeometryEstimate& g = est.geometry;
  EXPECT_EQ(g.sky_pixels, 0u);
  std::vector<float> subject, all;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const float d = g.distance_m.at(x, y, 0);
      ASSERT_TRUE(std::isfinite(d));
      all.push_back(d);
      if (std::hypot(x - 320, y - 300) < 120) subject.push_back(d);
    }
  std::sort(subject.begin(), subject.end());
  const float largest = *std::max_element(all.begin(), all.end());
  const float subject_median = subject[subject.size() / 2];
  std::printf("close-up: subject median %.2f m, largest distance %.2f m (%s)\n", subject_median,
              largest, g.scale_cue.c_str());
  // The far billboard 8 m ahead: nothing beyond 8 m / cos(the frame's widest angle), and
  // the subject a few metres away.
  EXPECT_LT(largest, 8.0 / std::cos(std::atan(std::hypot(320.0, 240.0) / kCamera.focal_px)) + 0.01);
  EXPECT_LT(subject_median, 3.0f);
  // Dense fog (the gallery's: visibility 60 m, top 80 m) leaves the subject visible.
  FogScene s = est.scene;
  const float sigma = float(extinction_from_visibility(60));
  s.medium.sigma_t_per_m = {sigma, sigma, sigma};
  s.medium.layer_top_m = 80;
  s.render.backend = Backend::cpu;
  const FogLayers f = fog(photo, g.distance_m, g.sky_alpha, kCamera, s);
  std::vector<float> t;
  for (int y = 0; y < kH; y += 4)
    for (int x = 0; x < kW; x += 4)
      if (std::hypot(x - 320, y - 300) < 120) t.push_back(f.transmittance.at(x, y, 1));
  std::sort(t.begin(), t.end());
  std::printf("close-up, dense fog: subject transmittance median %.3f\n", t[t.size() / 2]);
  EXPECT_GT(t[t.size() / 2], 0.8f);
}

// A small sharp subject in a frame mostly out of focus (gallery/tune ladybird: a ladybird on a
// stem against a blurred meadow): a few sharp blocks, most strongly blurred. Synthetic: green
// and brown blotches blurred by sigma 8 px, and a few small sharp-edged dark shapes.
cv::Mat small_subject_display(bool with_subject) {
  cv::Mat m(kH, kW, CV_32FC3);
  std::mt19937 rng(21);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const float v = u(rng);
      m.at<cv::Vec3f>(y, x) = cv::Vec3f(0.25f + 0.3f * v, 0.45f + 0.3f * v, 0.12f + 0.1f * v);
    }
  cv::GaussianBlur(m, m, cv::Size(0, 0), 3);
  for (int k = 0; k < 600; ++k) {  // blotches: leaves and flowers far behind the subject
    const double v = u(rng);
    cv::circle(m, cv::Point(int(u(rng) * kW), int(u(rng) * kH)), 6 + int(u(rng) * 14),
               cv::Scalar(0.1 + 0.7 * v, 0.2 + 0.7 * v, 0.05 + 0.3 * v), cv::FILLED);
  }
  cv::GaussianBlur(m, m, cv::Size(0, 0), 8);
  if (with_subject) {
    // A stem and the insect on it, sharp.
    cv::line(m, cv::Point(300, 479), cv::Point(420, 230), cv::Scalar(0.35, 0.6, 0.2), 6);
    cv::line(m, cv::Point(360, 355), cv::Point(250, 300), cv::Scalar(0.4, 0.7, 0.25), 5);
    cv::ellipse(m, cv::Point(425, 225), cv::Size(22, 16), 20, 0, 360, cv::Scalar(0.8, 0.1, 0.05),
                cv::FILLED);
    for (const cv::Point& spot : {cv::Point(418, 220), cv::Point(432, 228), cv::Point(424, 234)})
      cv::circle(m, spot, 4, cv::Scalar(0.02, 0.02, 0.02), cv::FILLED);
  }
  return m;
}

TEST(GeometryNoHarm, SmallSharpSubjectInABlurredFrameIsACloseUp) {
  const Image photo = to_photo(small_subject_display(true));
  const SceneEstimate est = estimate_scene(photo, kCamera, Annotations{});
  const GeometryEstimate& g = est.geometry;
  EstimateOptions before;
  before.closeup_small_subject_defocused = 2;  // off: the close-up rule as it was
  const GeometryEstimate old = estimate_geometry(photo, kCamera, Annotations{}, before);
  std::printf(
      "small subject: %.1f %% blurred, %.1f %% sharp; %s (before: '%s'); insect at %.2f m "
      "(%.2f m)\n",
      100 * g.defocused_fraction, 100 * g.sharp_fraction, g.scale_cue.c_str(),
      old.scale_cue.c_str(), g.distance_m.at(425, 225, 0), old.distance_m.at(425, 225, 0));
  ASSERT_GE(g.defocused_fraction, 0.4);
  ASSERT_LT(g.sharp_fraction, 0.1);  // too few sharp blocks for the first rule
  EXPECT_EQ(old.scale_cue.find("close-up"), std::string::npos);
  EXPECT_NE(g.scale_cue.find("close-up"), std::string::npos);
  EXPECT_LT(g.distance_m.at(425, 225, 0), 3.5f);
  // The same frame without the subject (blurred all over: a missed focus, a shaken camera)
  // shows no sharp subject, and no close-up.
  const GeometryEstimate blurred =
      estimate_geometry(to_photo(small_subject_display(false)), kCamera, Annotations{});
  std::printf("blurred all over: %.0f %% blurred, %.0f %% sharp; '%s'\n",
              100 * blurred.defocused_fraction, 100 * blurred.sharp_fraction,
              blurred.scale_cue.c_str());
  EXPECT_LT(blurred.sharp_fraction, 0.02);
  EXPECT_EQ(blurred.scale_cue.find("close-up"), std::string::npos);
}

#ifdef MR_SOURCE_DIR
// The photo the rule was made on (gallery/tune ladybird, 1280x800): 64 % of the blocks strongly
// blurred, 4 % sharp. Without the rule the meadow stood 46 m away and dense fog erased the
// ladybird; a close-up keeps it.
TEST(GeometryNoHarm, LadybirdIsACloseUp) {
  const Image photo = read_image(std::string(MR_SOURCE_DIR) + "/gallery/tune/ladybird.jpg");
  const Camera camera = Camera::from_horizontal_fov(photo.width(), photo.height(), 60);
  const SceneEstimate est = estimate_scene(photo, camera, Annotations{});
  EstimateOptions before;
  before.closeup_small_subject_defocused = 2;
  // Its blurred meadow's pale patches (3.5 % of the frame "sky") are also a little sky without
  // a clear sky's evidence, which makes the frame a bounded scene (8 m) on its own.
  before.little_sky_evidence = false;
  const SceneEstimate old = estimate_scene(photo, camera, Annotations{}, before);
  auto dense_t = [&](const SceneEstimate& e) {  // the gallery's dense look
    return test::fog_auto_look(photo, camera, e, 60, 80, 0.3).transmittance.at(870, 385, 1);
  };
  const float t = dense_t(est), t_old = dense_t(old);
  std::printf("ladybird: %s; at %.2f m (%.2f m), dense-fog transmittance %.2f (%.2f)\n",
              est.geometry.scale_cue.c_str(), est.geometry.distance_m.at(870, 385, 0),
              old.geometry.distance_m.at(870, 385, 0), t, t_old);
  EXPECT_NE(est.geometry.scale_cue.find("close-up"), std::string::npos);
  EXPECT_LT(t_old, 0.5f);  // the defect reproduced
  EXPECT_GT(t, 0.9f);
}
#endif

TEST(GeometryNoHarm, RobustInverseLine) {
  // One vertical plane: inverse forward distance exactly linear in the column.
  std::vector<double> f(100, 0.0);
  for (int k = 0; k < 100; k += 3) f[std::size_t(k)] = 1 / (0.05 + 0.001 * k);
  // Two columns reaching a foreground object do not pull the line.
  f[30] = 1.0, f[60] = 2.0;
  const std::vector<double> fit = photo::robust_inverse_line(f, 100);
  double worst = 0;
  for (int k = 0; k < 100; ++k)
    worst = std::max(worst, std::abs(fit[std::size_t(k)] * (0.05 + 0.001 * k) - 1));
  std::printf("robust line: worst relative error %.2e\n", worst);
  EXPECT_LT(worst, 1e-3);
  // A box's two faces meeting at column 50 (inverse distance linear on each, continuous at
  // the corner): local lines follow both faces better than one line, with no jump anywhere.
  std::vector<double> box(100, 0.0);
  auto q_box = [](int k) { return k < 50 ? 0.05 + 0.001 * k : 0.1 - 0.0008 * (k - 50); };
  for (int k = 0; k < 100; k += 2) box[std::size_t(k)] = 1 / q_box(k);
  const std::vector<double> local = photo::robust_inverse_line(box, 100, 8);
  const std::vector<double> global = photo::robust_inverse_line(box, 100);
  double local_face = 0, global_face = 0, worst_step = 0;
  for (int k = 0; k < 100; ++k) {
    if (std::abs(k - 50) > 9) {
      local_face = std::max(local_face, std::abs(local[std::size_t(k)] * q_box(k) - 1));
      global_face = std::max(global_face, std::abs(global[std::size_t(k)] * q_box(k) - 1));
    }
    if (k > 0)
      worst_step =
          std::max(worst_step, std::abs(local[std::size_t(k)] / local[std::size_t(k - 1)] - 1));
  }
  std::printf("two faces: worst face error local %.3f, one line %.3f; largest step %.4f\n",
              local_face, global_face, worst_step);
  EXPECT_LT(local_face, 0.75 * global_face);  // measured 0.181 vs 0.298
  EXPECT_LT(worst_step, 0.03);                // the faces' own slope is up to 2 % per column
  // One measured column: its value everywhere; none: +inf.
  std::vector<double> one(10, 0.0);
  one[4] = 7;
  for (const double v : photo::robust_inverse_line(one, 10)) EXPECT_NEAR(v, 7, 1e-12);
  for (const double v : photo::robust_inverse_line(std::vector<double>(5, 0.0), 5))
    EXPECT_TRUE(std::isinf(v));
}

// A portrait's person (mask > 0) in its estimated depth and in dense fog (visibility 60 m, a
// layer 80 m deep): the person's distances and transmittances sorted, and the bottom row's
// ground distance (1.6 m / tan(the bottom edge's angle below the horizon)).
struct PortraitInFog {
  std::vector<float> distance_m, transmittance;
  double bottom_row_ground_m = 0;
};

PortraitInFog portrait_in_dense_fog(const Image& photo, const cv::Mat& person,
                                    const SceneEstimate& est, const std::string& name) {
  const GeometryEstimate& g = est.geometry;
  dump(name + "_depth", g.distance_m);
  PortraitInFog r;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x)
      if (person.at<std::uint8_t>(y, x)) r.distance_m.push_back(g.distance_m.at(x, y, 0));
  std::sort(r.distance_m.begin(), r.distance_m.end());
  r.bottom_row_ground_m = g.pose.position_m.y / (0.5 * kH / kCamera.focal_px);
  FogScene s = est.scene;
  const float sigma = float(extinction_from_visibility(60));
  s.medium.sigma_t_per_m = {sigma, sigma, sigma};
  s.medium.layer_top_m = 80;
  s.render.backend = Backend::cpu;
  const FogLayers f = fog(photo, g.distance_m, g.sky_alpha, kCamera, s);
  dump(name + "_dense", f.composite);
  for (int y = 0; y < kH; y += 2)
    for (int x = 0; x < kW; x += 2)
      if (person.at<std::uint8_t>(y, x)) r.transmittance.push_back(f.transmittance.at(x, y, 1));
  std::sort(r.transmittance.begin(), r.transmittance.end());
  return r;
}

// A portrait with sky (the tuning half's cameraman, a person in front of the sky on a lawn):
// a dark coat and a head rising from the bottom of the frame far above the horizon, a pale blue
// sky, a sharp lawn running to a level horizon (the image's middle row, given). The person's
// feet are out of the frame: no contact with the ground, so before, the person stood on the far
// billboard and faded in dense fog (person median 11 m, transmittance 0.49). What covers the
// bottom row hides the ground there: it is no farther than that ground.
TEST(GeometryNoHarm, PersonInFrontOfTheSkyIsNearNotOnTheFarBillboard) {
  cv::Mat m(kH, kW, CV_32FC3);
  std::mt19937 rng(17);
  std::uniform_real_distribution<float> grain(-0.06f, 0.06f);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      if (y < kH / 2) {
        const float t = float(y) / (kH / 2);
        m.at<cv::Vec3f>(y, x) =
            cv::Vec3f(0.45f, 0.62f, 0.88f) * (1 - t) + cv::Vec3f(0.72f, 0.78f, 0.86f) * t;
      } else {
        const float n = grain(rng);
        m.at<cv::Vec3f>(y, x) = cv::Vec3f(0.30f + n, 0.45f + n, 0.20f + n);
      }
    }
  cv::Mat person(kH, kW, CV_8U, cv::Scalar(0));
  // (Its foot stays left of the middle half of the bottom band, where the ground's colour is
  // modelled: a dark subject covering much of it makes the mean-started model take it as
  // ground; see gallery/results/skymask_tune.md.)
  std::vector<cv::Point> coat = {{10, 479},  {40, 210},  {90, 155},
                                 {190, 150}, {230, 210}, {150, 479}};
  cv::fillPoly(person, std::vector<std::vector<cv::Point>>{coat}, cv::Scalar(255));
  cv::circle(person, cv::Point(140, 95), 50, cv::Scalar(128), cv::FILLED);
  cv::rectangle(person, cv::Point(125, 135), cv::Point(155, 155), cv::Scalar(128), cv::FILLED);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const std::uint8_t p = person.at<std::uint8_t>(y, x);
      const float n = 0.5f * grain(rng);
      if (p == 255) m.at<cv::Vec3f>(y, x) = cv::Vec3f(0.10f + n, 0.10f + n, 0.12f + n);
      if (p == 128) m.at<cv::Vec3f>(y, x) = cv::Vec3f(0.70f + n, 0.52f + n, 0.42f + n);
    }
  cv::GaussianBlur(m, m, cv::Size(0, 0), 0.7);  // a lens: edges a pixel wide
  const Image photo = to_photo(m);
  dump("portrait_photo", photo);
  // The horizon is given (in a real photo: found from its lines, the cameraman's buildings);
  // under the level fall-back the bottom row is not known to be below the horizon.
  Annotations horizon;
  horizon.horizon = std::array<PixelPoint, 2>{PixelPoint{0, kH / 2.0 - 0.5},
                                              PixelPoint{kW - 1.0, kH / 2.0 - 0.5}};
  const SceneEstimate est = estimate_scene(photo, kCamera, horizon);
  const PortraitInFog r = portrait_in_dense_fog(photo, person, est, "portrait");
  const std::vector<float>&d = r.distance_m, &t = r.transmittance;
  const double bottom_m = r.bottom_row_ground_m;
  std::printf(
      "portrait: person distance median %.2f m, 90th percentile %.2f m (bottom row's ground "
      "%.2f m forward); dense fog transmittance median %.3f\n",
      d[d.size() / 2], d[d.size() * 9 / 10], bottom_m, t[t.size() / 2]);
  // No farther than the bottom row's ground along the most oblique ray (head, 1.2x), with room
  // for the refinement's mixing at the silhouette.
  EXPECT_LT(d[d.size() / 2], 1.3 * bottom_m);
  EXPECT_GT(t[t.size() / 2], 0.6f);  // visible in dense fog (before: about 0.05)
}

// A portrait in the middle of the frame (class (b) of the held-out set at the end of the last
// session, rebuilt here without looking at it): a person in a dark coat fills the middle of the
// bottom of the frame and rises far into a pale sky; a meadow beside the coat, a low treeline on
// the horizon; round shapes, so only a weak horizon (a level one through a horizontal vanishing
// point, confidence 0.15). The coat covers the middle of the bottom band, where the ground's
// colour is modelled: before, the coat was taken as the ground (its part below the horizon a
// ground plane running to the horizon, its head and shoulders on the far billboard) and the
// person faded in dense fog (measured with the two changes switched off: distance median 10.1 m,
// 90th percentile 47 m, transmittance median 0.52, 10th percentile 0.05).
TEST(GeometryNoHarm, PortraitFillingTheBottomBandStaysNear) {
  cv::Mat m(kH, kW, CV_32FC3);
  std::mt19937 rng(23);
  std::uniform_real_distribution<float> grain(-0.05f, 0.05f);
  const int treeline = 262;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      if (y < treeline - 8 - 4 * std::sin(x / 23.0)) {
        const float t = float(y) / treeline;
        m.at<cv::Vec3f>(y, x) =
            cv::Vec3f(0.52f, 0.66f, 0.88f) * (1 - t) + cv::Vec3f(0.78f, 0.82f, 0.88f) * t;
      } else if (y < treeline) {
        const float n = grain(rng);
        m.at<cv::Vec3f>(y, x) = cv::Vec3f(0.16f + n, 0.24f + n, 0.14f + n);  // far trees
      } else {
        const float n = grain(rng);
        m.at<cv::Vec3f>(y, x) = cv::Vec3f(0.36f + n, 0.50f + n, 0.22f + n);  // a meadow
      }
    }
  cv::Mat person(kH, kW, CV_8U, cv::Scalar(0));
  // Round shapes (shoulders, a head): no straight lines to measure a horizon from.
  cv::ellipse(person, cv::Point(320, 520), cv::Size(175, 320), 0, 0, 360, cv::Scalar(255),
              cv::FILLED);
  cv::ellipse(person, cv::Point(320, 130), cv::Size(48, 60), 0, 0, 360, cv::Scalar(128),
              cv::FILLED);
  cv::ellipse(person, cv::Point(320, 200), cv::Size(22, 20), 0, 0, 360, cv::Scalar(128),
              cv::FILLED);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const std::uint8_t p = person.at<std::uint8_t>(y, x);
      const float n = 0.5f * grain(rng);
      if (p == 255) m.at<cv::Vec3f>(y, x) = cv::Vec3f(0.20f + n, 0.18f + n, 0.17f + n);
      if (p == 128) m.at<cv::Vec3f>(y, x) = cv::Vec3f(0.72f + n, 0.55f + n, 0.45f + n);
    }
  cv::GaussianBlur(m, m, cv::Size(0, 0), 0.7);  // a lens
  const Image photo = to_photo(m);
  dump("portrait_mid_photo", photo);
  const SceneEstimate est = estimate_scene(photo, kCamera, Annotations{});
  std::printf("horizon: %s, pitch %.2f deg\n", to_string(est.geometry.horizon_source),
              est.geometry.pose.pitch_deg);
  const PortraitInFog r = portrait_in_dense_fog(photo, person, est, "portrait_mid");
  const std::vector<float>&d = r.distance_m, &t = r.transmittance;
  const double bottom_m = r.bottom_row_ground_m;
  std::printf(
      "portrait (middle of the bottom band): person distance median %.2f m, 90th percentile %.2f m "
      "(bottom row's ground %.2f m forward); dense fog transmittance median %.3f, 10th "
      "percentile %.3f\n",
      d[d.size() / 2], d[d.size() * 9 / 10], bottom_m, t[t.size() / 2], t[t.size() / 10]);
  // As the portrait above: no farther than the bottom row's ground (with room for the
  // refinement at the silhouette), visible in dense fog.
  EXPECT_LT(d[d.size() / 2], 1.3 * bottom_m);
  EXPECT_GT(t[t.size() / 2], 0.6f);
}

// A person sitting on a beach (the tuning half's anne_helene, rebuilt here): a dark shirt fills
// the middle of the bottom band and rises a little above a horizon guessed too low (through her
// chin), her head and blonde hair rise above a far band of dunes that her hair touches, and
// the far beach between the dunes and the guessed horizon is above that horizon too. The
// person, the dunes and the far beach were one structure, which rose too little above the
// horizon for its foot at the bottom of the frame to count (min_rise_ratio): the person stood
// on the far billboard above the horizon and on the ground plane below it, her head veiled in
// dense fog and a line across her shirt at the horizon's row. The subject standing in the band
// (photo/subject.h) stands at the bottom row's ground, and the dunes beside her head stay far.
// `head_y` and `head_half_height`: the head's (and hair's) centre row and half height in pixels.
void expect_person_on_a_beach_whole_and_near(const std::string& name, int head_y,
                                             int head_half_height) {
  cv::Mat m(kH, kW, CV_32FC3);
  std::mt19937 rng(29);
  std::uniform_real_distribution<float> grain(-0.05f, 0.05f);
  constexpr int kDunesTop = 165, kSandTop = 190, kGuess = 240;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const float n = grain(rng);
      if (y < kDunesTop - 3 * std::sin(x / 31.0)) {
        const float t = float(y) / kDunesTop;
        m.at<cv::Vec3f>(y, x) =
            cv::Vec3f(0.74f, 0.77f, 0.81f) * (1 - t) + cv::Vec3f(0.82f, 0.84f, 0.86f) * t;
      } else if (y < kSandTop) {
        m.at<cv::Vec3f>(y, x) = cv::Vec3f(0.34f + n, 0.38f + n, 0.30f + n);  // dunes, far
      } else {
        m.at<cv::Vec3f>(y, x) = cv::Vec3f(0.80f + n, 0.72f + n, 0.58f + n);  // sand
      }
    }
  cv::Mat person(kH, kW, CV_8U, cv::Scalar(0));
  // A broad shirt (shoulders above the guessed horizon), a head, hair touching the dunes.
  const std::vector<cv::Point> shirt = {{100, 479}, {120, 232}, {200, 205},
                                        {440, 205}, {520, 232}, {540, 479}};
  cv::fillPoly(person, std::vector<std::vector<cv::Point>>{shirt}, cv::Scalar(255));
  cv::ellipse(person, cv::Point(320, head_y - 5), cv::Size(62, head_half_height + 2), 0, 0, 360,
              cv::Scalar(100), cv::FILLED);  // hair
  cv::ellipse(person, cv::Point(320, head_y), cv::Size(38, head_half_height), 0, 0, 360,
              cv::Scalar(170), cv::FILLED);  // face
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const std::uint8_t p = person.at<std::uint8_t>(y, x);
      const float n = 0.4f * grain(rng);
      if (p == 255) m.at<cv::Vec3f>(y, x) = cv::Vec3f(0.05f + n, 0.05f + n, 0.06f + n);
      if (p == 100) m.at<cv::Vec3f>(y, x) = cv::Vec3f(0.86f + n, 0.74f + n, 0.45f + n);
      if (p == 170) m.at<cv::Vec3f>(y, x) = cv::Vec3f(0.85f + n, 0.62f + n, 0.52f + n);
    }
  cv::GaussianBlur(m, m, cv::Size(0, 0), 0.7);  // a lens
  const Image photo = to_photo(m);
  dump(name + "_photo", photo);
  Annotations guess;  // the horizon guessed too low, through her chin
  guess.horizon =
      std::array<PixelPoint, 2>{PixelPoint{0, kGuess - 0.5}, PixelPoint{kW - 1.0, kGuess - 0.5}};
  const SceneEstimate est = estimate_scene(photo, kCamera, guess);
  const PortraitInFog r = portrait_in_dense_fog(photo, person, est, name);
  const std::vector<float>&d = r.distance_m, &t = r.transmittance;
  const double bottom_m = r.bottom_row_ground_m;
  // The dunes beside her head, and her shirt just above and just below the guessed horizon.
  std::vector<float> dunes;
  for (int y = kDunesTop + 6; y < kSandTop - 4; ++y)
    for (int x = 150; x < 240; ++x)
      if (!person.at<std::uint8_t>(y, x)) dunes.push_back(est.geometry.distance_m.at(x, y, 0));
  std::sort(dunes.begin(), dunes.end());
  std::vector<float> far_sand;  // the far beach beside her head, above the guessed horizon
  for (int y = kSandTop + 4; y < kGuess - 4; ++y)
    for (int x = 180; x < 250; ++x)
      if (!person.at<std::uint8_t>(y, x)) far_sand.push_back(est.geometry.distance_m.at(x, y, 0));
  std::sort(far_sand.begin(), far_sand.end());
  double above = 0, below = 0;
  for (int x = 200; x < 440; ++x) {
    above += est.geometry.distance_m.at(x, kGuess - 4, 0);
    below += est.geometry.distance_m.at(x, kGuess + 4, 0);
  }
  above /= 240, below /= 240;
  std::printf(
      "%s: distance median %.2f m, 90th percentile %.2f m (bottom row's ground "
      "%.2f m); dense fog transmittance median %.3f, 10th percentile %.3f; shirt 4 rows above / "
      "below the guessed horizon %.2f / %.2f m; dunes beside the head: 10th percentile %.1f m; "
      "far beach beside the head: 10th percentile %.1f m\n",
      name.c_str(), d[d.size() / 2], d[d.size() * 9 / 10], bottom_m, t[t.size() / 2],
      t[t.size() / 10], above, below, dunes[dunes.size() / 10], far_sand[far_sand.size() / 10]);
  EXPECT_LT(d[d.size() * 9 / 10], 1.3 * bottom_m);  // all of her, the head included
  EXPECT_GT(t[t.size() / 10], 0.6f);                // visible in dense fog, the head included
  EXPECT_LT(std::abs(above - below), 0.1 * below);  // no line across her at the horizon
  EXPECT_GT(dunes[dunes.size() / 10], 20.0f);       // the far land she touches stays far
  // ... and the far beach beside her head, whose colour is close to her hair's: her nearness
  // does not spread into it in the refinement (before: 5.1 m).
  EXPECT_GT(far_sand[far_sand.size() / 10], 20.0f);
}

TEST(GeometryNoHarm, SeatedPersonJoinedToTheFarLandStaysWholeAndNear) {
  expect_person_on_a_beach_whole_and_near("seated", 200, 40);
}

// The same with her head rising high above the horizon (a person standing in front of the beach,
// photographed from below eye level): the structure joined through her head rose enough for the
// foot at the frame's bottom to count, and that foot, hers, was lent to the dunes and the far
// beach: all of them a few metres away, unfogged (before: 3.8 m). Her foot is her own now.
TEST(GeometryNoHarm, HighHeadLendsTheFarLandItTouchesNoFoot) {
  expect_person_on_a_beach_whole_and_near("high_head", 150, 60);
}

}  // namespace
}  // namespace mr
