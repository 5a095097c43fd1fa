// photo/lamps: interior lamps lifted with the distance map and their intensities fitted with
// Ceres, against a synthetic room: a floor (y = 0) and a back wall (z = 6 m) seen from a known
// camera, two lamps of known position and intensity, and a photo rendered with the closed-form
// direct-light model of photo/lamps.h (known albedo per surface, known ambient term), using the
// analytic normals (not the fit's finite differences). Also the annotations keys and the
// estimate_scene wiring.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "mr/annotations.h"
#include "mr/error.h"
#include "mr/estimate.h"
#include "photo/lamps.h"

namespace mr::photo {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kWallZ = 6.0;

double dot(const Vec3& a, const Vec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
Vec3 sub(const Vec3& a, const Vec3& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
double norm(const Vec3& a) { return std::sqrt(dot(a, a)); }

struct TrueLamp {
  Vec3 position;
  std::array<double, 3> intensity;
};

/// 320x240, 70 degrees across, 1.5 m above the floor, pitched 10 degrees down.
struct Room {
  Camera camera = Camera::from_horizontal_fov(320, 240, 70);
  CameraPose pose;
  Image distance{320, 240, 1};
  std::vector<int> surface;  // per pixel: 0 floor, 1 wall
  std::vector<TrueLamp> lamps = {{{-1.0, 2.2, 4.0}, {20, 15, 10}}, {{1.2, 1.0, 5.0}, {5, 8, 12}}};
  std::array<std::array<double, 3>, 2> albedo = {{{0.6, 0.5, 0.4}, {0.7, 0.7, 0.7}}};
  std::array<std::array<double, 3>, 2> ambient = {{{0.02, 0.025, 0.03}, {0.03, 0.03, 0.03}}};
  // Pixel rectangles on the floor (rows 170..235) and on the wall (rows 5..80).
  std::vector<PixelPoint> floor_patch = {{20, 170}, {300, 170}, {300, 235}, {20, 235}};
  std::vector<PixelPoint> wall_patch = {{20, 5}, {300, 5}, {300, 80}, {20, 80}};

  Room() {
    pose.position_m = {0, 1.5, 0};
    pose.pitch_deg = -10;
    surface.resize(std::size_t(320) * 240);
    for (int y = 0; y < 240; ++y)
      for (int x = 0; x < 320; ++x) {
        const Vec3 d = pose.ray_direction(camera, x, y);
        const double t_floor = d.y < 0 ? -pose.position_m.y / d.y : INFINITY;
        const double t_wall = d.z > 0 ? kWallZ / d.z : INFINITY;
        distance.at(x, y, 0) = float(std::min(t_floor, t_wall));
        surface[std::size_t(y) * 320 + x] = t_wall < t_floor;
      }
  }
  bool project(const Vec3& p, std::array<double, 2>& px) const {
    const auto [f, r, u] = pose.axes();
    const Vec3 d = sub(p, pose.position_m);
    const double zf = dot(d, f);
    if (zf <= 1e-6) return false;
    px[0] = dot(d, r) / zf * camera.focal_px + camera.cx - 0.5;
    px[1] = -dot(d, u) / zf * camera.focal_px + camera.cy - 0.5;
    return true;
  }
  /// The photo of the room under `lamps` (closed-form model, analytic normals), with
  /// multiplicative Gaussian noise of relative standard deviation `noise`.
  Image render(const std::vector<TrueLamp>& ls, double noise = 0, unsigned seed = 1) const {
    std::mt19937 rng(seed);
    std::normal_distribution<double> gauss(0, 1);
    Image photo(320, 240, 3);
    for (int y = 0; y < 240; ++y)
      for (int x = 0; x < 320; ++x) {
        const int s = surface[std::size_t(y) * 320 + x];
        const Vec3 d = pose.ray_direction(camera, x, y);
        const double t = distance.at(x, y, 0);
        const Vec3 X{pose.position_m.x + t * d.x, pose.position_m.y + t * d.y,
                     pose.position_m.z + t * d.z};
        const Vec3 n = s ? Vec3{0, 0, -1} : Vec3{0, 1, 0};
        for (int c = 0; c < 3; ++c) {
          double v = ambient[s][c];
          for (const auto& l : ls) {
            const Vec3 to = sub(l.position, X);
            const double r = norm(to);
            v += albedo[s][c] / kPi * l.intensity[c] * std::max(0.0, dot(n, to) / r) / (r * r);
          }
          photo.at(x, y, c) = float(v * (1 + noise * gauss(rng)));
        }
      }
    return photo;
  }
  std::vector<LampMark> marks() const {
    std::vector<LampMark> out;
    for (const auto& l : lamps) {
      LampMark m;
      EXPECT_TRUE(project(l.position, m.pixel));
      const Vec3 d = pose.ray_direction(camera, m.pixel[0], m.pixel[1]);
      m.offset_m = kWallZ / d.z - norm(sub(l.position, pose.position_m));  // both on the wall
      out.push_back(m);
    }
    return out;
  }
  std::vector<LampPatch> patches() const {
    return {{floor_patch, albedo[0]}, {wall_patch, albedo[1]}};
  }
};

double max_relative_error(const LampFit& fit, const std::vector<TrueLamp>& truth) {
  double worst = 0;
  for (std::size_t i = 0; i < truth.size(); ++i)
    for (int c = 0; c < 3; ++c)
      worst = std::max(worst, std::abs(fit.intensity_per_sr[i][c] / truth[i].intensity[c] - 1));
  return worst;
}

TEST(Lamps, RoomIsAsDesigned) {
  const Room room;
  // The patches lie on one surface each and the lamps' pixels show the wall.
  for (int y = 170; y <= 235; ++y) EXPECT_EQ(room.surface[std::size_t(y) * 320 + 160], 0) << y;
  for (int y = 5; y <= 80; ++y) EXPECT_EQ(room.surface[std::size_t(y) * 320 + 160], 1) << y;
  for (const auto& m : room.marks()) {
    EXPECT_GT(m.offset_m, 0.5);
    EXPECT_EQ(room.surface[std::size_t(std::lround(m.pixel[1])) * 320 + std::lround(m.pixel[0])], 1);
  }
}

TEST(Lamps, LiftsPositionsWithinOnePercentOfDepth) {
  const Room room;
  const auto marks = room.marks();
  for (std::size_t i = 0; i < marks.size(); ++i) {
    const Vec3 p = lift_lamp(room.distance, room.camera, room.pose, marks[i], i);
    const double depth = norm(sub(room.lamps[i].position, room.pose.position_m));
    const double err = norm(sub(p, room.lamps[i].position));
    std::printf("lamp %zu lifted %.2e m off (%.4f %% of its depth %.2f m)\n", i, err,
                100 * err / depth, depth);
    EXPECT_LT(err, 0.01 * depth);
  }
}

TEST(Lamps, NormalsFromTheDistanceMapMatchTheRoom) {
  const Room room;
  Vec3 X, n;
  ASSERT_TRUE(surface_point(room.distance, room.camera, room.pose, 160, 200, X, n));
  EXPECT_NEAR(n.y, 1, 1e-4);
  ASSERT_TRUE(surface_point(room.distance, room.camera, room.pose, 160, 40, X, n));
  EXPECT_NEAR(n.z, -1, 1e-4);
}

// Noise-free: the fit recovers the intensities within 0.5 % (float photo and depth, normals from
// finite differences of the depth map).
TEST(Lamps, RecoversIntensitiesExactData) {
  const Room room;
  const LampFit fit = fit_lamps(room.render(room.lamps), room.distance, room.camera, room.pose,
                                room.marks(), room.patches());
  const double err = max_relative_error(fit, room.lamps);
  std::printf("exact data: max intensity error %.4f %%, residual %.4f %% RMS, %zu pixels, %d its\n",
              100 * err, 100 * fit.rms_residual, fit.pixels_used, fit.iterations);
  EXPECT_LT(err, 0.005);
  EXPECT_LT(fit.rms_residual, 1e-3);
  EXPECT_TRUE(fit.converged);
  for (int k = 0; k < 2; ++k)
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(fit.ambient[k][c], room.ambient[k][c], 0.01 * room.ambient[k][c]);
}

// 1 % multiplicative pixel noise: intensities within 5 %.
TEST(Lamps, RecoversIntensitiesWithOnePercentNoise) {
  const Room room;
  const LampFit fit = fit_lamps(room.render(room.lamps, 0.01, 7), room.distance, room.camera,
                                room.pose, room.marks(), room.patches());
  const double err = max_relative_error(fit, room.lamps);
  std::printf("1 %% noise: max intensity error %.3f %%, residual %.3f %% RMS (%.3f %% median)\n",
              100 * err, 100 * fit.rms_residual, 100 * fit.median_abs_residual);
  EXPECT_LT(err, 0.05);
  EXPECT_LT(fit.rms_residual, 0.03);
}

// Robust loss: a bright object covering about 10 % of the floor patch (3x the radiance) barely
// moves the fit (intensities within 5 %).
TEST(Lamps, RobustToAnObjectOnThePatch) {
  const Room room;
  Image photo = room.render(room.lamps);
  for (int y = 190; y < 220; ++y)
    for (int x = 100; x < 160; ++x)
      for (int c = 0; c < 3; ++c) photo.at(x, y, c) *= 3;
  const LampFit fit = fit_lamps(photo, room.distance, room.camera, room.pose, room.marks(),
                                room.patches());
  const double err = max_relative_error(fit, room.lamps);
  std::printf("bright object on 10 %% of the floor patch: max intensity error %.3f %%, floor "
              "residual %.1f %% RMS\n", 100 * err, 100 * fit.patch_rms_residual[0]);
  EXPECT_LT(err, 0.05);
}

// Bad starts: every intensity 0.01x and 100x the truth.
TEST(Lamps, ConvergesFromBadStarts) {
  const Room room;
  const Image photo = room.render(room.lamps);
  for (const double factor : {0.01, 100.0}) {
    LampFitOptions o;
    for (const auto& l : room.lamps)
      o.initial_intensity.push_back({l.intensity[0] * factor, l.intensity[1] * factor,
                                     l.intensity[2] * factor});
    const LampFit fit =
        fit_lamps(photo, room.distance, room.camera, room.pose, room.marks(), room.patches(), o);
    const double err = max_relative_error(fit, room.lamps);
    std::printf("start x%g: max intensity error %.4f %% after %d iterations\n", factor, 100 * err,
                fit.iterations);
    EXPECT_LT(err, 0.005) << factor;
  }
}

// A lamp with a given colour: one unknown, the same answer.
TEST(Lamps, ColouredLampKeepsItsChromaticity) {
  const Room room;
  auto marks = room.marks();
  marks[1].color = std::array<double, 3>{0.5, 0.8, 1.2};  // the truth's (5, 8, 12), scaled
  const LampFit fit = fit_lamps(room.render(room.lamps), room.distance, room.camera, room.pose,
                                marks, room.patches());
  EXPECT_LT(max_relative_error(fit, room.lamps), 0.005);
}

TEST(Lamps, ContradictoryShadingIsACleanError) {
  Room room;
  // The photo needs the second lamp to take light away.
  auto truth = room.lamps;
  truth[1].intensity = {-4, -4, -4};
  room.ambient = {{{0.2, 0.2, 0.2}, {0.2, 0.2, 0.2}}};
  try {
    fit_lamps(room.render(truth), room.distance, room.camera, room.pose, room.marks(),
              room.patches());
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::invalid_argument);
    const std::string what = e.what();
    EXPECT_NE(what.find("lamp 1"), std::string::npos) << what;
    EXPECT_NE(what.find("negative intensity"), std::string::npos) << what;
  }
}

std::string fit_error(const Room& room, const Image& distance, const std::vector<LampMark>& marks,
                      const std::vector<LampPatch>& patches) {
  try {
    fit_lamps(room.render(room.lamps), distance, room.camera, room.pose, marks, patches);
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::invalid_argument);
    return e.what();
  }
  return "no error";
}

TEST(Lamps, BadMarksAreCleanErrorsNamingTheLamp) {
  const Room room;
  auto marks = room.marks();
  marks[1].pixel = {400, 10};
  EXPECT_NE(fit_error(room, room.distance, marks, room.patches()).find("lamp 1: pixel (400, 10) is outside the 320x240 image"),
            std::string::npos);
  marks = room.marks();
  marks[0].offset_m = 50;
  EXPECT_NE(fit_error(room, room.distance, marks, room.patches()).find("lamp 0: offset_m (50 m)"),
            std::string::npos);
  EXPECT_NE(fit_error(room, room.distance, marks, room.patches()).find("behind the camera"),
            std::string::npos);
  Image sky = room.distance;
  marks = room.marks();
  const int lx = int(std::lround(marks[1].pixel[0])), ly = int(std::lround(marks[1].pixel[1]));
  for (int y = ly - 2; y <= ly + 2; ++y)
    for (int x = lx - 2; x <= lx + 2; ++x) sky.at(x, y, 0) = INFINITY;
  EXPECT_NE(fit_error(room, sky, marks, room.patches()).find("lamp 1: "), std::string::npos);
  EXPECT_NE(fit_error(room, sky, marks, room.patches()).find("sky"), std::string::npos);
  EXPECT_NE(fit_error(room, room.distance, marks, {}).find("no lamp patches"), std::string::npos);
  // A patch entirely outside the image has no pixels.
  std::vector<LampPatch> outside = {{{{-50, -50}, {-10, -50}, {-10, -10}}, {0.5, 0.5, 0.5}}};
  EXPECT_NE(fit_error(room, room.distance, marks, outside).find("lamp patch 0: no pixel"),
            std::string::npos);
}

// The annotations document carries lamps and lamp patches; estimate_scene fits them.
TEST(Lamps, AnnotationsAndEstimateScene) {
  const Room room;
  std::array<double, 2> h0, h1, crease;
  ASSERT_TRUE(room.project({-1e6, 1.5, 1e7}, h0));
  ASSERT_TRUE(room.project({1e6, 1.5, 1e7}, h1));
  ASSERT_TRUE(room.project({0, 0, kWallZ}, crease));
  Annotations a;
  a.horizon = {{{h0[0], h0[1]}, {h1[0], h1[1]}}};
  a.camera_height_m = 1.5;
  // The back wall: a plane facing the camera standing on the crease.
  a.planes.push_back({{{-0.5, -0.5}, {319.5, -0.5}, {319.5, crease[1]}, {-0.5, crease[1]}}, {}});
  for (const auto& m : room.marks()) a.lamps.push_back({m.pixel, m.offset_m, {}});
  a.lamp_patches.push_back({room.floor_patch, room.albedo[0]});
  a.lamp_patches.push_back({room.wall_patch, room.albedo[1]});
  const Annotations back = annotations_from_json(annotations_to_json(a), "a.json");
  ASSERT_EQ(back.lamps.size(), 2u);
  EXPECT_EQ(back.lamps[1].offset_m, a.lamps[1].offset_m);
  EXPECT_EQ(back.lamp_patches[0].albedo, a.lamp_patches[0].albedo);

  EstimateOptions o;
  o.automatic = false;
  const SceneEstimate est = estimate_scene(room.render(room.lamps), room.camera, back, o);
  ASSERT_EQ(est.scene.lighting.lamps.size(), 2u);
  for (std::size_t i = 0; i < 2; ++i) {
    const auto& l = est.scene.lighting.lamps[i];
    const double depth = norm(sub(room.lamps[i].position, room.pose.position_m));
    EXPECT_LT(norm(sub(l.position_m, room.lamps[i].position)), 0.01 * depth);
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(l.intensity_per_sr[c], room.lamps[i].intensity[c], 0.02 * room.lamps[i].intensity[c]);
  }
  bool noted = false;
  for (const auto& n : est.notes) noted = noted || n.rfind("lamps: 2 lamp(s) fitted", 0) == 0;
  EXPECT_TRUE(noted);
  const Image overlay = render_estimate_overlay(room.render(room.lamps), est, back);  // lamps drawn
  EXPECT_EQ(overlay.width(), 320);

  // Errors keep the lamp's index and the pointer prefix.
  Annotations bad = back;
  bad.lamps[0].pixel = {-20, 5};
  try {
    estimate_scene(room.render(room.lamps), room.camera, bad, o);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("/lamps, /lamp_patches: lamp 0: pixel (-20, 5) is outside"),
              std::string::npos)
        << e.what();
  }
}

TEST(Lamps, AnnotationsAreStrict) {
  const std::string head = R"({"format": "libmr-annotations", "version": 1, )";
  auto error = [&](const std::string& body) {
    try {
      annotations_from_json(head + body + "}", "a.json");
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  const std::string patches = R"("lamp_patches": [{"polygon": [[0, 0], [9, 0], [9, 9]]}])";
  EXPECT_EQ(error(R"("lamps": [{"pixel": [1, 2], "ofset_m": 1}], )" + patches),
            "a.json: /lamps/0/ofset_m: unknown key; did you mean \"offset_m\"?");
  EXPECT_EQ(error(R"("lamps": [{"pixel": [1, 2], "offset_m": -1}], )" + patches),
            "a.json: /lamps/0/offset_m: must be >= 0, found -1.000000");
  EXPECT_EQ(error(R"("lamps": [{"pixel": [1, 2]}])"),
            "a.json: /lamp_patches: missing: lamps are fitted to the shading of lamp_patches; "
            "mark both or neither");
  EXPECT_EQ(error(R"("lamps": [{"pixel": [1, 2], "color": [0, 0, 0]}], )" + patches),
            "a.json: /lamps/0/color: must not be black");
  EXPECT_EQ(error(R"("lamps": [{"pixel": [1, 2]}], "lamp_patches": [{"polygon": [[0, 0], [9, 0], [9, 9]], "albedo": 1.5}])"),
            "a.json: /lamp_patches/0/albedo/0: must be in (0, 1], found 1.500000");
  EXPECT_EQ(error(R"("lamps": [{"pixel": [1, 2], "color": [1, 2]}], )" + patches),
            "a.json: /lamps/0/color: expected a number or [r, g, b] (3 numbers), found an array of 2 elements");
  const Annotations a = annotations_from_json(
      head + R"("lamps": [{"pixel": [1, 2], "offset_m": 0.25, "color": 0.5}], )" + patches + "}");
  ASSERT_EQ(a.lamps.size(), 1u);
  EXPECT_EQ(a.lamps[0].offset_m, 0.25);
  EXPECT_EQ(*a.lamps[0].color, (std::array<double, 3>{0.5, 0.5, 0.5}));
  EXPECT_FALSE(a.lamp_patches[0].albedo);
}

}  // namespace
}  // namespace mr::photo
