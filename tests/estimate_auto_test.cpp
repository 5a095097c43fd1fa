// Automatic geometry cues (photo/horizon, photo/sky_mask, mr::estimate_geometry with a photo)
// on synthetic photos rendered with OpenCV from a known camera: a ground grid, building facades
// with windows, a gradient sky. The true horizon comes from projecting far horizontal points
// (not from photo/geometry), the true sky from it.
#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "mr/estimate.h"
#include "photo/horizon.h"
#include "photo/sky_mask.h"

namespace mr {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

double dot(const Vec3& a, const Vec3& b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}

struct Rig {
  Camera camera = Camera::from_horizontal_fov(640, 480, 60);
  CameraPose pose;
  Rig(double pitch_deg, double roll_deg, double yaw_deg, double height_m) {
    pose.position_m = {0, height_m, 0};
    pose.pitch_deg = pitch_deg;
    pose.roll_deg = roll_deg;
    pose.yaw_deg = yaw_deg;
  }
  Vec3 to_camera(const Vec3& p) const {  // (right, down, forward)
    const auto [f, r, u] = pose.axes();
    const Vec3 v{p.x - pose.position_m.x, p.y - pose.position_m.y, p.z - pose.position_m.z};
    return {dot(v, r), -dot(v, u), dot(v, f)};
  }
  /// Continuous image coordinates (pixel edges at integers) of a camera-frame point.
  cv::Point2d image(const Vec3& c) const {
    return {camera.focal_px * c.x / c.z + camera.cx, camera.focal_px * c.y / c.z + camera.cy};
  }
  /// True horizon row (pixel-centre coordinates) at pixel-centre column x: through the
  /// vanishing points of two horizontal directions.
  double horizon_y(double x) const {
    auto vp = [&](double deg) {
      const Vec3 d{std::sin(deg * kDeg), 0, std::cos(deg * kDeg)};
      const Vec3 far{pose.position_m.x + 1e9 * d.x, pose.position_m.y,
                     pose.position_m.z + 1e9 * d.z};
      return image(to_camera(far));
    };
    const cv::Point2d a = vp(pose.yaw_deg - 20), b = vp(pose.yaw_deg + 20);
    return a.y + (x + 0.5 - a.x) * (b.y - a.y) / (b.x - a.x) - 0.5;
  }
};

// Display-referred BGR-free drawing in RGB float [0, 1]; converted to scene-linear at the end.
struct Canvas {
  const Rig& rig;
  cv::Mat img;  // CV_32FC3, RGB display-referred
  static constexpr int kShift = 4;
  explicit Canvas(const Rig& r) : rig(r), img(r.camera.height, r.camera.width, CV_32FC3) {}
  cv::Point fixed(const cv::Point2d& p) const {
    return {int(std::lround(p.x * (1 << kShift) - 0.5 * (1 << kShift))),
            int(std::lround(p.y * (1 << kShift) - 0.5 * (1 << kShift)))};
  }
  /// A world segment, clipped to the camera's near plane (z >= 0.2 m).
  void line(Vec3 a, Vec3 b, const cv::Scalar& colour, int thickness) {
    Vec3 ca = rig.to_camera(a), cb = rig.to_camera(b);
    const double near = 0.2;
    if (ca.z < near && cb.z < near) return;
    if (ca.z < near || cb.z < near) {
      const double t = (near - ca.z) / (cb.z - ca.z);
      const Vec3 m{ca.x + t * (cb.x - ca.x), ca.y + t * (cb.y - ca.y), near};
      (ca.z < near ? ca : cb) = m;
    }
    cv::line(img, fixed(rig.image(ca)), fixed(rig.image(cb)), colour, thickness, cv::LINE_AA,
             kShift);
  }
  /// A planar world polygon, clipped to the camera's near plane (z >= 0.2 m).
  void polygon(const std::vector<Vec3>& pts, const cv::Scalar& colour) {
    const double near = 0.2;
    std::vector<Vec3> cam, clipped;
    for (const auto& w : pts) cam.push_back(rig.to_camera(w));
    for (std::size_t i = 0; i < cam.size(); ++i) {  // Sutherland-Hodgman against z = near
      const Vec3& a = cam[i];
      const Vec3& b = cam[(i + 1) % cam.size()];
      if (a.z >= near) clipped.push_back(a);
      if ((a.z >= near) != (b.z >= near)) {
        const double t = (near - a.z) / (b.z - a.z);
        clipped.push_back({a.x + t * (b.x - a.x), a.y + t * (b.y - a.y), near});
      }
    }
    if (clipped.size() < 3) return;
    std::vector<cv::Point> p;
    for (const auto& c : clipped) p.push_back(fixed(rig.image(c)));
    cv::fillPoly(img, std::vector<std::vector<cv::Point>>{p}, colour, cv::LINE_AA, kShift);
  }
  /// Gradient sky above the true horizon, textured ground (noise, fixed seed) below.
  void sky_and_ground(unsigned seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<float> noise(0, 0.06f);
    for (int y = 0; y < img.rows; ++y)
      for (int x = 0; x < img.cols; ++x) {
        auto& p = img.at<cv::Vec3f>(y, x);
        if (y < rig.horizon_y(x)) {
          const float t = float(y) / img.rows;
          p = cv::Vec3f(0.35f + 0.4f * t, 0.55f + 0.3f * t, 0.9f + 0.05f * t);
        } else {
          const float n = noise(rng);
          p = cv::Vec3f(0.45f + n, 0.38f + n, 0.3f + n);
        }
      }
  }
  Image photo() const {
    Image out(img.cols, img.rows, 3);
    for (int y = 0; y < img.rows; ++y)
      for (int x = 0; x < img.cols; ++x)
        for (int c = 0; c < 3; ++c)
          out.at(x, y, c) = std::pow(std::clamp(img.at<cv::Vec3f>(y, x)[c], 0.0f, 1.0f), 2.2f);
    return out;
  }
};

// Ground grid, 2 m cells, dark lines.
Image ground_grid_photo(const Rig& rig) {
  Canvas c(rig);
  c.sky_and_ground(7);
  const cv::Scalar dark(0.1, 0.1, 0.1);
  // Painted stripes 0.15 m wide (their edges converge exactly, unlike fixed-width lines).
  const double s = 0.075;
  for (int i = -30; i <= 30; ++i)
    c.polygon({{2.0 * i - s, 0, -60},
               {2.0 * i + s, 0, -60},
               {2.0 * i + s, 0, 200},
               {2.0 * i - s, 0, 200}},
              dark);
  for (int k = -30; k <= 100; ++k)
    c.polygon(
        {{-60, 0, 2.0 * k - s}, {60, 0, 2.0 * k - s}, {60, 0, 2.0 * k + s}, {-60, 0, 2.0 * k + s}},
        dark);
  return c.photo();
}

// Two facades (x = -6 along the view, z = 25 across it) with a grid of dark windows.
Image facades_photo(const Rig& rig) {
  Canvas c(rig);
  c.sky_and_ground(11);
  const cv::Scalar wall(0.7, 0.5, 0.4), window(0.12, 0.14, 0.18);
  c.polygon({{-6, 0, 4}, {-6, 0, 25}, {-6, 20, 25}, {-6, 20, 4}}, wall);
  c.polygon({{-6, 0, 25}, {40, 0, 25}, {40, 20, 25}, {-6, 20, 25}}, wall);
  for (int floor = 0; floor < 5; ++floor) {
    const double y0 = 1 + 3.8 * floor, y1 = y0 + 2.4;
    for (double z = 5; z < 23.5; z += 3)
      c.polygon({{-6, y0, z}, {-6, y0, z + 1.5}, {-6, y1, z + 1.5}, {-6, y1, z}}, window);
    for (double x = -4.5; x < 38; x += 3)
      c.polygon({{x, y0, 25}, {x + 1.5, y0, 25}, {x + 1.5, y1, 25}, {x, y1, 25}}, window);
  }
  return c.photo();
}

// Largest vertical distance between the estimated and the true horizon over the image width.
double horizon_error_px(const Rig& rig, const std::array<PixelPoint, 2>& est) {
  double worst = 0;
  const int w = rig.camera.width;
  for (double x : {0.0, w / 2.0, double(w - 1)}) {
    const double y =
        est[0][1] + (x - est[0][0]) * (est[1][1] - est[0][1]) / (est[1][0] - est[0][0]);
    worst = std::max(worst, std::abs(y - rig.horizon_y(x)));
  }
  return worst;
}

// The bar is 3 % of the image height (14.4 px here). Measured (printed): the ground
// grid 0.8-3.8 px, the facades 0.6-6.6 px (their left wall's short window edges fix its
// vanishing point less well). Held at the tighter bars of 1 % (4.8 px) for the grid and 1.5 %
// (7.2 px) for the facades.
constexpr double kGridTolerance = 0.01, kFacadeTolerance = 0.015;

TEST(AutoHorizon, GroundGridWithPitchRollYaw) {
  const double poses[][3] = {{-8, 4, 30}, {-5, -6, -25}, {-12, 2, 40}};
  for (const auto& p : poses) {
    const Rig rig(p[0], p[1], p[2], 1.6);
    const Image photo = ground_grid_photo(rig);
    const photo::AutoHorizon h = photo::estimate_horizon(photo.view(), rig.camera);
    const double err = horizon_error_px(rig, h.points);
    std::printf("grid pitch %g roll %g yaw %g: cue %s, confidence %.2f, error %.2f px (%.2f %%)\n",
                p[0], p[1], p[2], photo::to_string(h.cue), h.confidence, err,
                100 * err / rig.camera.height);
    EXPECT_EQ(h.cue, photo::HorizonCue::horizontal_vps);
    EXPECT_LE(err, kGridTolerance * rig.camera.height);
    EXPECT_GT(h.confidence, 0.3);
  }
}

TEST(AutoHorizon, FacadesWithVerticalLines) {
  const double poses[][3] = {{4, -3, -10}, {8, 2, -15}, {0, 0, -5}, {-3, 5, -12}};
  for (const auto& p : poses) {
    const Rig rig(p[0], p[1], p[2], 1.6);
    const Image photo = facades_photo(rig);
    const photo::AutoHorizon h = photo::estimate_horizon(photo.view(), rig.camera);
    const double err = horizon_error_px(rig, h.points);
    std::printf(
        "facades pitch %g roll %g yaw %g: cue %s, confidence %.2f, error %.2f px (%.2f %%)\n", p[0],
        p[1], p[2], photo::to_string(h.cue), h.confidence, err, 100 * err / rig.camera.height);
    EXPECT_NE(h.cue, photo::HorizonCue::none);
    EXPECT_LE(err, kFacadeTolerance * rig.camera.height);
  }
}

TEST(AutoHorizon, BlankAndNoiseFallBackLevel) {
  const Camera camera = Camera::from_horizontal_fov(640, 480, 60);
  Image blank(640, 480, 3);
  for (int y = 0; y < 480; ++y)
    for (int x = 0; x < 640; ++x)
      for (int c = 0; c < 3; ++c) blank.at(x, y, c) = 0.3f;
  Image noise(640, 480, 3);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0, 1);
  for (int y = 0; y < 480; ++y)
    for (int x = 0; x < 640; ++x)
      for (int c = 0; c < 3; ++c) noise.at(x, y, c) = u(rng);
  for (const Image* img : {&blank, &noise}) {
    const photo::AutoHorizon h = photo::estimate_horizon(img->view(), camera);
    EXPECT_EQ(h.cue, photo::HorizonCue::none);
    EXPECT_LE(h.confidence, 0.1);
    // Level through the principal point: row cy - 0.5 (pixel-centre coordinates).
    EXPECT_NEAR(h.points[0][1], camera.cy - 0.5, 1e-9);
    EXPECT_NEAR(h.points[1][1], camera.cy - 0.5, 1e-9);
    const GeometryEstimate g = estimate_geometry(*img, camera, Annotations{});
    EXPECT_EQ(g.horizon_source, EstimateSource::fallback);
    EXPECT_DOUBLE_EQ(g.confidence, 0.1);
    EXPECT_EQ(g.distance_m.width(), 640);
  }
  // Degenerate sizes do not crash.
  for (auto [w, h] : {std::pair{1, 1}, std::pair{3, 2}, std::pair{2000, 4}}) {
    Image tiny(w, h, 3);
    const Camera c = Camera::from_horizontal_fov(w, h, 60);
    EXPECT_EQ(photo::estimate_horizon(tiny.view(), c).cue, photo::HorizonCue::none);
    EXPECT_NO_THROW(estimate_geometry(tiny, c, Annotations{}));
  }
}

// Lines that lean like a bridge's cable stays (issue 11, gallery/tune/bridge: a zenith 21
// degrees off the image's vertical, so a horizon rolled 21 degrees): a fit rolled beyond
// HorizonOptions::max_roll_deg is not a photo's, and the result is the level fall-back, with
// the rejected roll said. The same lines leaning 5 degrees still give the zenith's horizon.
TEST(AutoHorizon, LinesThatLeanFarFromVerticalAreNotTheZenith) {
  const Rig rig(0, 0, 0, 1.6);
  for (const double lean_deg : {22.0, 5.0}) {
    Canvas c(rig);
    c.sky_and_ground(5);
    // Eight dark cables converging 2000 px away, up the image and leaning lean_deg to the right.
    const cv::Point2d vp{rig.camera.cx + 2000 * std::sin(lean_deg * kDeg),
                         rig.camera.cy - 2000 * std::cos(lean_deg * kDeg)};
    for (int i = 0; i < 8; ++i) {
      const cv::Point2d bottom{40.0 + 80 * i, double(rig.camera.height + 50)};
      const cv::Point2d top = bottom + 0.9 * (vp - bottom) * (600.0 / cv::norm(vp - bottom));
      cv::line(c.img, c.fixed(bottom), c.fixed(top), cv::Scalar(0.08, 0.08, 0.1), 3, cv::LINE_AA,
               Canvas::kShift);
    }
    const Image photo = c.photo();
    const photo::AutoHorizon h = photo::estimate_horizon(photo.view(), rig.camera);
    std::printf("lines leaning %g deg: cue %s, rejected roll %.1f deg\n", lean_deg,
                photo::to_string(h.cue), h.rejected_roll_deg);
    if (lean_deg > 15) {
      EXPECT_EQ(h.cue, photo::HorizonCue::none);
      EXPECT_NEAR(std::abs(h.rejected_roll_deg), lean_deg, 3);  // (leaning right: roll < 0)
      EXPECT_NEAR(h.points[0][1], rig.camera.cy - 0.5, 1e-9);   // level through the centre
      const GeometryEstimate g = estimate_geometry(photo, rig.camera, Annotations{});
      EXPECT_EQ(g.horizon_source, EstimateSource::fallback);
      EXPECT_NEAR(std::abs(g.horizon_rejected_roll_deg), lean_deg, 3);
      EXPECT_NEAR(g.pose.roll_deg, 0, 1e-9);
      // `mr estimate`'s report says why the lines were not used.
      const SceneEstimate est = estimate_scene(photo, rig.camera, Annotations{});
      bool said = false;
      for (const std::string& note : est.notes)
        said |= note.find("the lines' horizon (roll -2") != std::string::npos &&
                note.find("deg) is not a photo's") != std::string::npos;
      EXPECT_TRUE(said);
    } else {
      EXPECT_EQ(h.cue, photo::HorizonCue::zenith);
      EXPECT_TRUE(std::isnan(h.rejected_roll_deg));
    }
  }
}

double iou(const std::vector<std::uint8_t>& a, const std::vector<std::uint8_t>& b) {
  std::size_t inter = 0, uni = 0;
  for (std::size_t i = 0; i < a.size(); ++i) inter += a[i] && b[i], uni += a[i] || b[i];
  return uni ? double(inter) / double(uni) : 1.0;
}

// The true sky: pixel centres above the true horizon not covered by a facade.
std::vector<std::uint8_t> true_sky(const Rig& rig, const Image& photo) {
  std::vector<std::uint8_t> sky(std::size_t(photo.width()) * photo.height());
  for (int y = 0; y < photo.height(); ++y)
    for (int x = 0; x < photo.width(); ++x) {
      // Sky pixels are the gradient's blue (B > R + 0.3 in display terms) above the horizon.
      const bool above = y < rig.horizon_y(x);
      const float r = std::pow(photo.at(x, y, 0), 1 / 2.2f),
                  b = std::pow(photo.at(x, y, 2), 1 / 2.2f);
      sky[std::size_t(y) * photo.width() + x] = above && b > r + 0.1f;
    }
  return sky;
}

// IoU bars: measured 0.9999-1.0000 (printed); held at 0.97 for the grid scene, 0.95 for the facades
// (anti-aliased silhouettes against the sky; edge pixels are mixtures).
TEST(AutoSkyMask, GradientSkyOverTexturedGround) {
  const Rig rig(-6, 3, 30, 1.6);
  const Image photo = ground_grid_photo(rig);
  const auto truth = true_sky(rig, photo);
  const std::array<PixelPoint, 2> horizon{PixelPoint{0.0, rig.horizon_y(0)},
                                          PixelPoint{639.0, rig.horizon_y(639)}};
  const photo::SkyMask mask = photo::estimate_sky_mask(photo.view(), horizon);
  const double with_true = iou(mask.sky, truth);
  // Through estimate_geometry: the automatic horizon, then the mask; the sky is +inf.
  const GeometryEstimate g = estimate_geometry(photo, rig.camera, Annotations{});
  std::vector<std::uint8_t> inf(truth.size());
  for (int y = 0; y < 480; ++y)
    for (int x = 0; x < 640; ++x)
      inf[std::size_t(y) * 640 + x] = !std::isfinite(g.distance_m.at(x, y, 0));
  const double with_auto = iou(inf, truth);
  std::printf("sky IoU: %.4f with the true horizon, %.4f through estimate_geometry\n", with_true,
              with_auto);
  EXPECT_GE(with_true, 0.97);
  EXPECT_GE(with_auto, 0.97);
  EXPECT_TRUE(g.sky_from_mask);
}

TEST(AutoSkyMask, FacadesAgainstSky) {
  const Rig rig(6, -2, -10, 1.6);
  const Image photo = facades_photo(rig);
  const auto truth = true_sky(rig, photo);
  // The facades fill the frame above the horizon here: the true sky is empty, so the IoU is 1
  // only when no pixel is taken as sky (a dark window or a wall taken as sky makes it 0).
  ASSERT_EQ(std::count(truth.begin(), truth.end(), 1), 0);
  const GeometryEstimate g = estimate_geometry(photo, rig.camera, Annotations{});
  std::vector<std::uint8_t> inf(truth.size());
  std::size_t finite_above = 0;
  for (int y = 0; y < 480; ++y)
    for (int x = 0; x < 640; ++x) {
      const float d = g.distance_m.at(x, y, 0);
      inf[std::size_t(y) * 640 + x] = !std::isfinite(d);
      finite_above += std::isfinite(d) && y < rig.horizon_y(x);
    }
  const double v = iou(inf, truth);
  std::printf("facades sky IoU %.4f, billboard pixels %zu\n", v, g.billboard_pixels);
  EXPECT_GE(v, 0.95);
  // The facades above the horizon are not sky: they stand where they meet the ground, or on
  // the far billboard.
  EXPECT_GT(g.billboard_pixels + g.contact_pixels, 0u);
  EXPECT_GT(finite_above, 0u);
}

TEST(AutoSkyMask, CarvesAnnotatedPlaneReachingIntoTheSky) {
  const Rig rig(-6, 0, 30, 1.6);
  const Image photo = ground_grid_photo(rig);
  const double yh = rig.horizon_y(320);
  Annotations a;
  a.horizon = std::array<PixelPoint, 2>{PixelPoint{0, rig.horizon_y(0)},
                                        PixelPoint{639, rig.horizon_y(639)}};
  a.camera_height_m = 1.6;
  Annotations::Plane plane;
  plane.polygon = {{200, yh - 80}, {440, yh - 80}, {440, yh + 60}, {200, yh + 60}};
  a.planes.push_back(plane);
  const GeometryEstimate without = estimate_geometry(rig.camera, a);
  const GeometryEstimate with = estimate_geometry(photo, rig.camera, a);
  const int x = 320, y_sky = int(yh - 40), y_plane = int(yh + 30);
  EXPECT_TRUE(std::isfinite(without.distance_m.at(x, y_sky, 0)));  // the plane, without the mask
  EXPECT_TRUE(std::isinf(with.distance_m.at(x, y_sky, 0)));        // carved: sky
  EXPECT_FLOAT_EQ(with.distance_m.at(x, y_plane, 0), without.distance_m.at(x, y_plane, 0));
  EXPECT_EQ(with.horizon_source, EstimateSource::annotations);
}

// Overcast fall-back (issue 4 item 5): no shadow pairs, so no sun; the sky light is the median
// of the sky pixels. The horizon is annotated so that only the sky mask is under test.
Annotations level_horizon(const Rig& rig) {
  Annotations a;
  a.horizon = std::array<PixelPoint, 2>{PixelPoint{0, rig.horizon_y(0)},
                                        PixelPoint{639, rig.horizon_y(639)}};
  a.camera_height_m = 1.6;
  return a;
}

TEST(AutoSkyLight, OvercastSkyRadianceIsTheSkyColour) {
  const Rig rig(-6, 2, 0, 1.6);
  Canvas c(rig);
  c.sky_and_ground(5);
  const cv::Vec3f sky_display(0.62f, 0.68f, 0.78f);  // uniform grey-blue overcast sky
  for (int y = 0; y < c.img.rows; ++y)
    for (int x = 0; x < c.img.cols; ++x)
      if (y < rig.horizon_y(x)) c.img.at<cv::Vec3f>(y, x) = sky_display;
  const Image photo = c.photo();
  const SceneEstimate est = estimate_scene(photo, rig.camera, level_horizon(rig));
  EXPECT_FALSE(est.scene.lighting.sun);
  ASSERT_TRUE(est.geometry.sky_from_mask);
  ASSERT_TRUE(est.scene.lighting.sky_radiance);
  // Every sky pixel holds exactly the colour (scene-linear: display ^ 2.2) and the mask's few
  // edge pixels cannot move a median: equal to float rounding, held at 1e-4 relative.
  for (int k = 0; k < 3; ++k) {
    const float expected = std::pow(sky_display[k], 2.2f);
    EXPECT_NEAR((*est.scene.lighting.sky_radiance)[k], expected, 1e-4f * expected)
        << "channel " << k;
  }
  bool noted = false;
  for (const std::string& n : est.notes) {
    std::printf("%s\n", n.c_str());
    noted |= n.find("sky: radiance from " + std::to_string(est.geometry.sky_pixels) +
                    " sky pixels (overcast)") == 0;
  }
  EXPECT_TRUE(noted);
}

TEST(AutoSkyLight, WithoutSkyTheRadianceIsLeftToTheDarkChannelPrior) {
  const Rig rig(-6, 2, 0, 1.6);
  // Textured ground colours everywhere, above the horizon too (a hedge up to the top border).
  Image photo(640, 480, 3);
  std::mt19937 rng(13);
  std::normal_distribution<float> noise(0, 0.06f);
  for (int y = 0; y < 480; ++y)
    for (int x = 0; x < 640; ++x) {
      const float n = noise(rng);
      const float display[3] = {0.30f + n, 0.38f + n, 0.22f + n};
      for (int k = 0; k < 3; ++k)
        photo.at(x, y, k) = std::pow(std::clamp(display[k], 0.0f, 1.0f), 2.2f);
    }
  const SceneEstimate est = estimate_scene(photo, rig.camera, level_horizon(rig));
  EXPECT_EQ(est.geometry.sky_pixels, 0u);
  EXPECT_FALSE(est.scene.lighting.sky_radiance);
  bool noted = false;
  for (const std::string& n : est.notes) {
    std::printf("%s\n", n.c_str());
    noted |= n.rfind("sky: ", 0) == 0 && n.find("dark channel prior") != std::string::npos;
  }
  EXPECT_TRUE(noted);
}

// Structures standing on the ground (issue 4 item 2, automatic): boxes taller than the camera
// on a textured ground, none behind another in the image. The truth is the nearest ray hit of
// the boxes (slab method) and the ground; scored on pixel centres whose 5x5 neighbourhood sees
// one and the same box face (silhouette and contact pixels are colour mixtures).
struct Box {
  double x0, x1, z0, z1, top;
  cv::Scalar front, side;
};
const std::vector<Box> kBoxes = {
    {-7.0, -4.0, 13.0, 16.0, 3.0, {0.65, 0.2, 0.15}, {0.5, 0.15, 0.1}},
    {-1.0, 1.5, 22.0, 24.0, 4.0, {0.25, 0.5, 0.2}, {0.2, 0.4, 0.15}},
    {3.0, 5.5, 9.0, 11.0, 2.5, {0.8, 0.6, 0.1}, {0.65, 0.45, 0.08}},
};

Image boxes_photo(const Rig& rig) {
  Canvas c(rig);
  c.sky_and_ground(17);
  for (const Box& b : kBoxes) {                // no box hides another: any order
    const double sx = b.x1 < 0 ? b.x1 : b.x0;  // the side facing the camera
    c.polygon({{sx, 0, b.z0}, {sx, 0, b.z1}, {sx, b.top, b.z1}, {sx, b.top, b.z0}}, b.side);
    c.polygon({{b.x0, 0, b.z0}, {b.x1, 0, b.z0}, {b.x1, b.top, b.z0}, {b.x0, b.top, b.z0}},
              b.front);
  }
  return c.photo();
}

// Per pixel: the distance to the nearest hit and what it hits (-1 ground or nothing, else
// 2 * box + (0 front, 1 side)).
struct Truth {
  std::vector<double> distance;
  std::vector<int> face;
};
Truth boxes_truth(const Rig& rig) {
  const int w = rig.camera.width, h = rig.camera.height;
  Truth t{std::vector<double>(std::size_t(w) * h), std::vector<int>(std::size_t(w) * h, -1)};
  const auto [f, r, u] = rig.pose.axes();
  const Vec3 o = rig.pose.position_m;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const double a = (x + 0.5 - rig.camera.cx) / rig.camera.focal_px;
      const double b = (y + 0.5 - rig.camera.cy) / rig.camera.focal_px;
      const double n = std::sqrt(a * a + b * b + 1);
      const Vec3 d{(a * r.x - b * u.x + f.x) / n, (a * r.y - b * u.y + f.y) / n,
                   (a * r.z - b * u.z + f.z) / n};
      double best = d.y < 0 ? o.y / -d.y : std::numeric_limits<double>::infinity();
      int face = -1;
      for (std::size_t k = 0; k < kBoxes.size(); ++k) {
        const Box& bx = kBoxes[k];
        const double lo[3] = {bx.x0, 0, bx.z0}, hi[3] = {bx.x1, bx.top, bx.z1};
        const double oo[3] = {o.x, o.y, o.z}, dd[3] = {d.x, d.y, d.z};
        double tin = 0, tout = std::numeric_limits<double>::infinity();
        int axis = -1;
        for (int j = 0; j < 3; ++j) {
          if (dd[j] == 0) {
            if (oo[j] < lo[j] || oo[j] > hi[j]) tin = tout + 1;
            continue;
          }
          double t0 = (lo[j] - oo[j]) / dd[j], t1 = (hi[j] - oo[j]) / dd[j];
          if (t0 > t1) std::swap(t0, t1);
          if (t0 > tin) tin = t0, axis = j;
          tout = std::min(tout, t1);
        }
        if (tin <= tout && tin > 0 && tin < best)
          best = tin, face = int(2 * k) + (axis == 2 ? 0 : 1);
      }
      t.distance[std::size_t(y) * w + x] = best;
      t.face[std::size_t(y) * w + x] = face;
    }
  return t;
}

struct BoxScore {
  double abs_rel = 0, median = 0, p90 = 0;
  std::size_t pixels = 0;
};
BoxScore score(const Truth& t, const Image& distance, int w, int h) {
  std::vector<double> errors;
  double sum = 0;
  for (int y = 2; y < h - 2; ++y)
    for (int x = 2; x < w - 2; ++x) {
      const int face = t.face[std::size_t(y) * w + x];
      if (face < 0) continue;
      bool interior = true;
      for (int dy = -2; dy <= 2 && interior; ++dy)
        for (int dx = -2; dx <= 2; ++dx)
          interior &= t.face[std::size_t(y + dy) * w + x + dx] == face;
      if (!interior) continue;
      const double want = t.distance[std::size_t(y) * w + x];
      const double e = std::abs(distance.at(x, y, 0) - want) / want;
      errors.push_back(e);
      sum += e;
    }
  BoxScore s;
  s.pixels = errors.size();
  if (errors.empty()) return s;
  s.abs_rel = sum / double(errors.size());
  std::sort(errors.begin(), errors.end());
  s.median = errors[errors.size() / 2];
  s.p90 = errors[errors.size() * 9 / 10];
  return s;
}

// Bars: the box faces' AbsRel <= 5 % and 90 % of their pixels within 5 %; and at most a fifth of
// the far billboard's AbsRel. Measured (printed) for three camera poses.
TEST(AutoStructures, BoxesStandWhereTheyMeetTheGround) {
  const double poses[][3] = {{0, 0, 0}, {-3, 2, 5}, {2, -1.5, -4}};
  for (const auto& p : poses) {
    const Rig rig(p[0], p[1], p[2], 1.6);
    const Image photo = boxes_photo(rig);
    const Truth truth = boxes_truth(rig);
    Annotations a;
    a.horizon = std::array<PixelPoint, 2>{PixelPoint{0, rig.horizon_y(0)},
                                          PixelPoint{639, rig.horizon_y(639)}};
    a.camera_height_m = 1.6;
    const GeometryEstimate g = estimate_geometry(photo, rig.camera, a);
    EstimateOptions far_only;
    far_only.ground_contact = false;
    const GeometryEstimate far = estimate_geometry(photo, rig.camera, a, far_only);
    const BoxScore sc = score(truth, g.distance_m, 640, 480),
                   sf = score(truth, far.distance_m, 640, 480);
    std::printf(
        "boxes pitch %g roll %g yaw %g: %zu face pixels; contact: AbsRel %.2f %%, median %.2f %%, "
        "p90 %.2f %%; far billboard: AbsRel %.1f %%; %zu contact, %zu far pixels\n",
        p[0], p[1], p[2], sc.pixels, 100 * sc.abs_rel, 100 * sc.median, 100 * sc.p90,
        100 * sf.abs_rel, g.contact_pixels, g.billboard_pixels);
    ASSERT_GT(sc.pixels, 5000u);
    EXPECT_LT(sc.abs_rel, 0.05);
    EXPECT_LT(sc.p90, 0.05);
    EXPECT_LT(sc.abs_rel, 0.2 * sf.abs_rel);
    EXPECT_GT(g.contact_pixels, 0u);
    EXPECT_EQ(far.contact_pixels, 0u);
  }
}

// Focal length from orthogonal vanishing points (issue 4 item 1, no EXIF): the ground grid's two
// line families and the facades' (each pair at right angles), rendered with a 60 degree camera
// (f = 554.3 px) and estimated starting from wrong focal lengths (40 and 90 degrees): the
// estimate does not depend on the start. Bar 3 % (measured, printed).
TEST(AutoFocal, FromOrthogonalVanishingPoints) {
  struct Case {
    const char* scene;
    double pitch, roll, yaw;
  };
  const Case cases[] = {
      {"grid", -8, 4, 30}, {"grid", -12, 2, 40}, {"facades", 4, -3, -25}, {"facades", 8, 2, -15}};
  for (const Case& c : cases) {
    const Rig rig(c.pitch, c.roll, c.yaw, 1.6);
    const Image photo =
        std::string(c.scene) == "grid" ? ground_grid_photo(rig) : facades_photo(rig);
    for (double start_fov : {40.0, 90.0}) {
      const Camera start = Camera::from_horizontal_fov(640, 480, start_fov);
      const auto f = photo::estimate_focal_px(photo.view(), start);
      ASSERT_TRUE(f) << c.scene << " yaw " << c.yaw;
      const double err = std::abs(f->focal_px - rig.camera.focal_px) / rig.camera.focal_px;
      std::printf(
          "%s pitch %g roll %g yaw %g, start %g deg: focal %.1f px (true %.1f), error %.2f %%, "
          "%d vanishing points, confidence %.2f\n",
          c.scene, c.pitch, c.roll, c.yaw, start_fov, f->focal_px, rig.camera.focal_px, 100 * err,
          f->vanishing_points, f->confidence);
      EXPECT_LT(err, 0.03);
      EXPECT_GE(f->confidence, 0.3);
    }
  }
}

TEST(AutoFocal, NoLinesNoFocal) {
  // A level camera seeing one horizontal line family and the verticals: the vertical vanishing
  // point is at infinity and one horizontal point fixes nothing; no estimate.
  {
    const Rig rig(0, 2, -35, 1.6);
    EXPECT_FALSE(photo::estimate_focal_px(facades_photo(rig).view(), rig.camera));
  }
  const Camera camera = Camera::from_horizontal_fov(640, 480, 60);
  Image noise(640, 480, 3);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0, 1);
  for (int y = 0; y < 480; ++y)
    for (int x = 0; x < 640; ++x)
      for (int k = 0; k < 3; ++k) noise.at(x, y, k) = u(rng);
  EXPECT_FALSE(photo::estimate_focal_px(noise.view(), camera));
  EXPECT_FALSE(photo::estimate_focal_px(Image(640, 480, 3).view(), camera));
  // Through camera_for_photo: no EXIF and no lines -> the default field of view.
  const PhotoCamera pc = camera_for_photo(noise);
  EXPECT_EQ(pc.source, "default");
  EXPECT_NEAR(pc.camera.horizontal_fov_deg(), 60, 1e-9);
  // A grid photo without EXIF gets the vanishing points' focal length.
  const Rig rig(-8, 4, 30, 1.6);
  const PhotoCamera grid = camera_for_photo(ground_grid_photo(rig));
  EXPECT_EQ(grid.source, "vanishing points");
  EXPECT_NEAR(grid.camera.focal_px, rig.camera.focal_px, 0.03 * rig.camera.focal_px);
}

}  // namespace
}  // namespace mr
