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
#include <vector>

#include "mr/estimate.h"
#include "photo/horizon.h"
#include "photo/sky_mask.h"

namespace mr {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

double dot(const Vec3& a, const Vec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }

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
      const Vec3 far{pose.position_m.x + 1e9 * d.x, pose.position_m.y, pose.position_m.z + 1e9 * d.z};
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
    cv::line(img, fixed(rig.image(ca)), fixed(rig.image(cb)), colour, thickness, cv::LINE_AA, kShift);
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
    c.polygon({{2.0 * i - s, 0, -60}, {2.0 * i + s, 0, -60}, {2.0 * i + s, 0, 200}, {2.0 * i - s, 0, 200}}, dark);
  for (int k = -30; k <= 100; ++k)
    c.polygon({{-60, 0, 2.0 * k - s}, {60, 0, 2.0 * k - s}, {60, 0, 2.0 * k + s}, {-60, 0, 2.0 * k + s}}, dark);
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
    const double y = est[0][1] + (x - est[0][0]) * (est[1][1] - est[0][1]) / (est[1][0] - est[0][0]);
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
    std::printf("facades pitch %g roll %g yaw %g: cue %s, confidence %.2f, error %.2f px (%.2f %%)\n",
                p[0], p[1], p[2], photo::to_string(h.cue), h.confidence, err,
                100 * err / rig.camera.height);
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
      const float r = std::pow(photo.at(x, y, 0), 1 / 2.2f), b = std::pow(photo.at(x, y, 2), 1 / 2.2f);
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
    for (int x = 0; x < 640; ++x) inf[std::size_t(y) * 640 + x] = !std::isfinite(g.distance_m.at(x, y, 0));
  const double with_auto = iou(inf, truth);
  std::printf("sky IoU: %.4f with the true horizon, %.4f through estimate_geometry\n", with_true, with_auto);
  EXPECT_GE(with_true, 0.97);
  EXPECT_GE(with_auto, 0.97);
  EXPECT_TRUE(g.sky_from_mask);
}

TEST(AutoSkyMask, FacadesAgainstSky) {
  const Rig rig(6, -2, -10, 1.6);
  const Image photo = facades_photo(rig);
  const auto truth = true_sky(rig, photo);
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
  // The facades above the horizon are not sky: they are on the far billboard.
  EXPECT_GT(g.billboard_pixels, 0u);
  EXPECT_GT(finite_above, 0u);
}

TEST(AutoSkyMask, CarvesAnnotatedPlaneReachingIntoTheSky) {
  const Rig rig(-6, 0, 30, 1.6);
  const Image photo = ground_grid_photo(rig);
  const double yh = rig.horizon_y(320);
  Annotations a;
  a.horizon = std::array<PixelPoint, 2>{PixelPoint{0, rig.horizon_y(0)}, PixelPoint{639, rig.horizon_y(639)}};
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
  a.horizon = std::array<PixelPoint, 2>{PixelPoint{0, rig.horizon_y(0)}, PixelPoint{639, rig.horizon_y(639)}};
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
    EXPECT_NEAR((*est.scene.lighting.sky_radiance)[k], expected, 1e-4f * expected) << "channel " << k;
  }
  bool noted = false;
  for (const std::string& n : est.notes) {
    std::printf("%s\n", n.c_str());
    noted |= n.find("sky: radiance from " + std::to_string(est.geometry.sky_pixels) + " sky pixels (overcast)") == 0;
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
      for (int k = 0; k < 3; ++k) photo.at(x, y, k) = std::pow(std::clamp(display[k], 0.0f, 1.0f), 2.2f);
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

}  // namespace
}  // namespace mr
