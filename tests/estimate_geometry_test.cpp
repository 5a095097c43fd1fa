// User-assisted geometry (photo/geometry, mr/estimate.h) against closed forms: a synthetic camera
// with known pitch, roll and height; its horizon computed from the pose by projecting horizontal
// directions; the ground, box faces and an oblique wall intersected analytically.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <numbers>
#include <string>
#include <vector>

#include "mr/error.h"
#include "mr/estimate.h"
#include "photo/geometry.h"

namespace mr {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

double dot(const Vec3& a, const Vec3& b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}

struct Rig {
  Camera camera = Camera::from_horizontal_fov(640, 480, 60);
  CameraPose pose;
  Rig(double pitch_deg, double roll_deg, double height_m) {
    pose.position_m = {0, height_m, 0};
    pose.pitch_deg = pitch_deg;
    pose.roll_deg = roll_deg;
  }
  /// Pixel-centre coordinates of a world point (in front of the camera).
  PixelPoint project(const Vec3& p) const {
    const auto [f, r, u] = pose.axes();
    const Vec3 v{p.x - pose.position_m.x, p.y - pose.position_m.y, p.z - pose.position_m.z};
    const double z = dot(v, f);
    return {camera.focal_px * dot(v, r) / z + camera.cx - 0.5,
            camera.focal_px * -dot(v, u) / z + camera.cy - 0.5};
  }
  /// Where a horizontal direction (yaw `deg` from +Z) vanishes: a point of the horizon.
  PixelPoint vanishing(double deg) const {
    const Vec3 d{std::sin(deg * kDeg), 0, std::cos(deg * kDeg)};
    return project(
        {pose.position_m.x + 1e9 * d.x, pose.position_m.y, pose.position_m.z + 1e9 * d.z});
  }
  std::array<PixelPoint, 2> horizon() const { return {vanishing(-20), vanishing(25)}; }
  /// Closed form of the ground distance at a pixel (independent of CameraPose::ray_direction):
  /// with a = (x + 0.5 - cx) / f, b = (y + 0.5 - cy) / f the unnormalised ray a r - b u + f has
  /// length sqrt(a^2 + b^2 + 1) and height component -(a sin(roll) cos(pitch) + b cos(roll)
  /// cos(pitch) - sin(pitch)), so d = h sqrt(a^2 + b^2 + 1) / (a sr cp + b cr cp - sp).
  /// Returns +inf on or above the horizon.
  double ground_distance(int x, int y) const {
    const double a = (x + 0.5 - camera.cx) / camera.focal_px;
    const double b = (y + 0.5 - camera.cy) / camera.focal_px;
    const double p = pose.pitch_deg * kDeg, r = pose.roll_deg * kDeg;
    const double den = a * std::sin(r) * std::cos(p) + b * std::cos(r) * std::cos(p) - std::sin(p);
    if (den <= 0) return std::numeric_limits<double>::infinity();
    return pose.position_m.y * std::sqrt(a * a + b * b + 1) / den;
  }
};

// Signed distance (pixels) of a point from the line through a and b.
double line_distance(const std::array<PixelPoint, 2>& line, const PixelPoint& p) {
  const double dx = line[1][0] - line[0][0], dy = line[1][1] - line[0][1];
  return (dx * (p[1] - line[0][1]) - dy * (p[0] - line[0][0])) / std::hypot(dx, dy);
}

void expect_error(const std::function<void()>& f, const std::string& fragment) {
  try {
    f();
    ADD_FAILURE() << "no error; expected one naming " << fragment;
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::invalid_argument) << e.what();
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
  }
}

const double kPoses[][2] = {{0, 0}, {-5, 0}, {8, 0}, {0, 3}, {-4, 2}, {6, -7.5}, {-12, 10}};

TEST(EstimateGeometry, PoseFromExactHorizonIsExact) {
  for (const auto& pr : kPoses) {
    const Rig rig(pr[0], pr[1], 1.6);
    const CameraPose pose = pose_from_horizon(rig.camera, rig.horizon(), 1.6);
    EXPECT_NEAR(pose.pitch_deg, pr[0], 1e-9) << pr[0] << " " << pr[1];
    EXPECT_NEAR(pose.roll_deg, pr[1], 1e-9) << pr[0] << " " << pr[1];
    EXPECT_EQ(pose.position_m.y, 1.6);
    // The estimate's horizon (crossing the first and last columns) lies on the true line:
    // "recovered within 1 px", here within 1e-6 px.
    const GeometryEstimate g = estimate_geometry(rig.camera, [&] {
      Annotations a;
      a.horizon = rig.horizon();
      a.camera_height_m = 1.6;
      return a;
    }());
    for (const auto& p : g.horizon) EXPECT_LT(std::abs(line_distance(rig.horizon(), p)), 1e-6);
    EXPECT_EQ(g.horizon_source, EstimateSource::annotations);
    EXPECT_EQ(g.confidence, 1.0);
  }
}

TEST(EstimateGeometry, GroundDistanceMatchesClosedForm) {
  for (const auto& pr : kPoses) {
    const Rig rig(pr[0], pr[1], 1.6);
    Annotations a;
    a.horizon = rig.horizon();
    a.camera_height_m = 1.6;
    const GeometryEstimate g = estimate_geometry(rig.camera, a);
    double worst = 0;
    std::size_t ground = 0, sky = 0;
    for (int y = 0; y < rig.camera.height; ++y)
      for (int x = 0; x < rig.camera.width; ++x) {
        const double want = rig.ground_distance(x, y);
        const float got = g.distance_m.at(x, y, 0);
        if (std::isinf(want)) {
          EXPECT_TRUE(std::isinf(got) && got > 0) << x << "," << y;
          ++sky;
        } else {
          worst = std::max(worst, std::abs(got - want) / want);
          ++ground;
        }
      }
    EXPECT_LT(worst, 1e-6) << "pitch " << pr[0] << " roll " << pr[1];  // float storage
    EXPECT_EQ(g.ground_pixels, ground);
    EXPECT_EQ(g.sky_pixels, sky);
  }
}

// Simulated clicks: horizon endpoints rounded to whole pixels. Ground depth within 2 % for
// ground pixels at least 30 px below the horizon (0.5 px at 30 px is 1.7 %).
TEST(EstimateGeometry, GroundDistanceFromClickedHorizonWithin2Percent) {
  for (const auto& pr : kPoses) {
    const Rig rig(pr[0], pr[1], 1.6);
    // Clicks near the image's left and right edges, on the true horizon, then rounded.
    const auto h = photo::horizon_of_pose(rig.camera, rig.pose);
    Annotations a;
    a.horizon = std::array<PixelPoint, 2>{PixelPoint{std::round(h[0][0] + 20), 0},
                                          PixelPoint{std::round(h[1][0] - 20), 0}};
    for (int i = 0; i < 2; ++i) {
      const double t = ((*a.horizon)[i][0] - h[0][0]) / (h[1][0] - h[0][0]);
      (*a.horizon)[i][1] = std::round(h[0][1] + t * (h[1][1] - h[0][1]));
    }
    a.camera_height_m = 1.6;
    const GeometryEstimate g = estimate_geometry(rig.camera, a);
    double worst = 0;
    int n = 0;
    for (int y = 0; y < rig.camera.height; ++y)
      for (int x = 0; x < rig.camera.width; ++x) {
        if (line_distance(h, {double(x), double(y)}) * (h[1][0] > h[0][0] ? 1 : -1) < 30) continue;
        const double want = rig.ground_distance(x, y);
        worst = std::max(worst, std::abs(g.distance_m.at(x, y, 0) - want) / want);
        ++n;
      }
    ASSERT_GT(n, 1000);
    EXPECT_LT(worst, 0.02) << "pitch " << pr[0] << " roll " << pr[1];
    std::printf("clicked horizon, pitch %g roll %g: worst ground error %.3f %%\n", pr[0], pr[1],
                100 * worst);
  }
}

TEST(EstimateGeometry, CameraHeightFromKnownLength) {
  const Rig rig(-6, 2.5, 1.45);
  Annotations a;
  a.horizon = rig.horizon();
  const Vec3 p{-1.2, 0, 7.5}, q{2.3, 0, 11.0};
  a.known_length =
      Annotations::KnownLength{rig.project(p), rig.project(q), std::hypot(q.x - p.x, q.z - p.z)};
  const GeometryEstimate g = estimate_geometry(rig.camera, a);
  EXPECT_EQ(g.height_source, EstimateSource::known_length);
  EXPECT_NEAR(g.pose.position_m.y, 1.45, 1.45e-9);
}

// A box standing on the ground, its front face fronto-parallel (z = 12, x in [-1, 2], 3 m
// tall): inside its image the distance is the ray's hit with z = 12.
TEST(EstimateGeometry, BillboardMatchesBoxFace) {
  for (const auto& pr : kPoses) {
    const Rig rig(pr[0], pr[1], 1.6);
    Annotations a;
    a.horizon = rig.horizon();
    a.camera_height_m = 1.6;
    Annotations::Plane face;
    face.polygon = {rig.project({-1, 0, 12}), rig.project({2, 0, 12}), rig.project({2, 3, 12}),
                    rig.project({-1, 3, 12})};
    a.planes.push_back(face);
    const GeometryEstimate g = estimate_geometry(rig.camera, a);
    const auto [f, r, u] = rig.pose.axes();
    double worst = 0;
    std::size_t inside = 0;
    for (int y = 0; y < rig.camera.height; ++y)
      for (int x = 0; x < rig.camera.width; ++x) {
        if (!photo::inside_polygon(face.polygon, x, y)) continue;
        const double aa = (x + 0.5 - rig.camera.cx) / rig.camera.focal_px;
        const double bb = (y + 0.5 - rig.camera.cy) / rig.camera.focal_px;
        const double dz = aa * r.z - bb * u.z + f.z;  // unnormalised ray, length sqrt(a^2+b^2+1)
        const double want = 12.0 / dz * std::sqrt(aa * aa + bb * bb + 1);
        worst = std::max(worst, std::abs(g.distance_m.at(x, y, 0) - want) / want);
        ++inside;
      }
    EXPECT_GT(inside, 1000u);
    EXPECT_EQ(g.plane_pixels, inside);
    EXPECT_LT(worst, 1e-6) << "pitch " << pr[0] << " roll " << pr[1];
  }
}

// An oblique wall (its base from (-4, 0, 8) to (3, 0, 15)) given its base: the ray's hit with
// that vertical plane; below the wall's base inside the polygon the ground is nearer.
TEST(EstimateGeometry, PlaneWithBaseMatchesObliqueWall) {
  const Rig rig(-3, 1.5, 1.7);
  Annotations a;
  a.horizon = rig.horizon();
  a.camera_height_m = 1.7;
  const Vec3 p0{-4, 0, 8}, p1{3, 0, 15};
  Annotations::Plane wall;
  wall.polygon = {rig.project(p0), rig.project(p1), rig.project({3, 4, 15}),
                  rig.project({-4, 4, 8})};
  wall.base = std::array<PixelPoint, 2>{rig.project(p0), rig.project(p1)};
  // Extend the polygon 15 px below its base: those pixels must stay ground.
  wall.polygon[0][1] += 15;
  wall.polygon[1][1] += 15;
  a.planes.push_back(wall);
  const GeometryEstimate g = estimate_geometry(rig.camera, a);
  // Plane through p0 with normal n = (-(dz), 0, dx) / len.
  const double dx = p1.x - p0.x, dz = p1.z - p0.z, len = std::hypot(dx, dz);
  const Vec3 n{-dz / len, 0, dx / len};
  double worst = 0;
  std::size_t on_wall = 0, on_ground = 0;
  for (int y = 0; y < rig.camera.height; ++y)
    for (int x = 0; x < rig.camera.width; ++x) {
      if (!photo::inside_polygon(wall.polygon, x, y)) continue;
      const Vec3 d = rig.pose.ray_direction(rig.camera, x, y);
      const double t = (dot(n, p0) - dot(n, rig.pose.position_m)) / dot(n, d);
      const double hit_y = rig.pose.position_m.y + t * d.y;
      const double want = hit_y >= 0 ? t : rig.ground_distance(x, y);
      (hit_y >= 0 ? on_wall : on_ground)++;
      worst = std::max(worst, std::abs(g.distance_m.at(x, y, 0) - want) / want);
    }
  EXPECT_GT(on_wall, 1000u);
  EXPECT_GT(on_ground, 100u);
  EXPECT_LT(worst, 1e-6);
}

TEST(EstimateGeometry, DistanceHintsOverrideInOrder) {
  const Rig rig(0, 0, 1.6);
  Annotations a;
  a.horizon = rig.horizon();
  a.distance_hints.push_back({{{10, 10}, {100, 10}, {100, 100}, {10, 100}}, 500});
  a.distance_hints.push_back({{{50, 50}, {150, 50}, {150, 150}, {50, 150}}, 42});
  a.distance_hints.push_back({{{300, 300}, {400, 300}, {400, 400}, {300, 400}}, 3});  // on ground
  const GeometryEstimate g = estimate_geometry(rig.camera, a);
  EXPECT_EQ(g.distance_m.at(20, 20, 0), 500.0f);
  EXPECT_EQ(g.distance_m.at(60, 60, 0), 42.0f);  // the later hint wins
  EXPECT_EQ(g.distance_m.at(120, 120, 0), 42.0f);
  EXPECT_EQ(g.distance_m.at(350, 350, 0), 3.0f);
  EXPECT_TRUE(std::isinf(g.distance_m.at(5, 5, 0)));
  EXPECT_EQ(g.height_source, EstimateSource::fallback);  // 1.6 m default
  EXPECT_EQ(g.pose.position_m.y, 1.6);
}

TEST(EstimateGeometry, WithoutHorizonFallsBackToLevelCamera) {
  const Rig rig(0, 0, 1.6);
  const GeometryEstimate g = estimate_geometry(rig.camera, Annotations{});
  EXPECT_EQ(g.horizon_source, EstimateSource::fallback);
  EXPECT_LT(g.confidence, 0.5);
  EXPECT_EQ(g.pose.pitch_deg, 0);
  EXPECT_EQ(g.pose.roll_deg, 0);
  EXPECT_NEAR(g.horizon[0][1], rig.camera.cy - 0.5, 1e-9);
  EXPECT_NEAR(g.horizon[1][1], rig.camera.cy - 0.5, 1e-9);
}

// estimate_scene wires the shadow pairs to photo/illumination's sun fit (tested there against
// noisy marks) and the patches to the sun/sky ratio: exact marks give the sun within 0.01 deg;
// patches rendered with lit = rho (E cos + pi L), shadowed = rho pi L give E / (pi L) within 1e-6.
TEST(EstimateScene, SunFromShadowPairsAndRatioFromPatches) {
  const Rig rig(-4, 1, 1.6);
  const Vec3 sun = direction_from_azimuth_elevation(130, 35);
  Annotations a;
  a.horizon = rig.horizon();
  a.camera_height_m = 1.6;
  const Vec3 feet[] = {{-3, 0, 9}, {1, 0, 12}, {4, 0, 8}};
  for (const Vec3& f : feet) {
    const Vec3 top{f.x, 2.0, f.z};
    const double k = 2.0 / sun.y;
    const Vec3 tip{top.x - k * sun.x, 0, top.z - k * sun.z};
    a.shadow_pairs.push_back({rig.project(top), rig.project(f), rig.project(tip)});
  }
  Image photo(rig.camera.width, rig.camera.height, 3);
  const double cos_theta = sun.y, ratio = 2.5;  // E / (pi L)
  const float shadowed = 0.1f, lit = float(0.1 * (1 + ratio * cos_theta));
  for (int y = 0; y < photo.height(); ++y)
    for (int x = 0; x < photo.width(); ++x)
      for (int c = 0; c < 3; ++c) photo.at(x, y, c) = x < 320 ? lit : shadowed;
  a.sunlit_patch = {{100, 400}, {200, 400}, {200, 450}, {100, 450}};
  a.shadowed_patch = {{400, 400}, {500, 400}, {500, 450}, {400, 450}};
  const SceneEstimate est = estimate_scene(photo, rig.camera, a);
  ASSERT_TRUE(est.sun);
  ASSERT_TRUE(est.scene.lighting.sun);
  const Vec3 l = est.scene.lighting.sun->direction_to_sun;
  EXPECT_LT(std::acos(std::min(1.0, dot(l, sun))) / kDeg, 0.01);
  ASSERT_TRUE(est.scene.lighting.sky_radiance);
  const double fitted_cos = std::max(l.y, 0.0);  // the ratio uses the fitted sun
  for (int c = 0; c < 3; ++c) {
    const double sky = (*est.scene.lighting.sky_radiance)[c];
    const double want = (lit / double(shadowed) - 1) / fitted_cos;
    EXPECT_NEAR(est.scene.lighting.sun->irradiance[c] / (std::numbers::pi * sky), want,
                want * 1e-6);
    EXPECT_NEAR(want, ratio, 0.01);
  }
}

TEST(EstimateGeometry, BadAnnotationsNameTheField) {
  const Rig rig(-3, 2, 1.6);
  auto with = [&](auto change) {
    Annotations a;
    a.horizon = rig.horizon();
    change(a);
    return [a, &rig] { estimate_geometry(rig.camera, a); };
  };
  expect_error(with([](Annotations& a) { (*a.horizon)[1] = (*a.horizon)[0]; }), "/horizon");
  expect_error(with([](Annotations& a) {
                 *a.horizon = {PixelPoint{320, 0}, PixelPoint{321, 400}};
               }),
               "/horizon: the line through");  // nearly vertical
  expect_error(with([](Annotations& a) {
                 (*a.horizon)[1] = {5000, 240};
               }),
               "/horizon/1");  // outside
  expect_error(with([](Annotations& a) { (*a.horizon)[0][1] = std::nan(""); }), "/horizon/0/1");
  expect_error(with([](Annotations& a) { a.camera_height_m = -1.6; }), "/camera_height_m");
  expect_error(with([](Annotations& a) {
                 a.planes.push_back({{{1, 1}, {2, 2}}, std::nullopt});
               }),
               "/planes/0/polygon");
  expect_error(with([&](Annotations& a) {  // entirely above the horizon
                 a.planes.push_back({{{10, 1}, {50, 1}, {50, 20}}, std::nullopt});
               }),
               "/planes/0/polygon: lies entirely on or above the horizon");
  expect_error(with([&](Annotations& a) {
                 a.known_length = Annotations::KnownLength{{10, 2}, {300, 470}, 2};
               }),
               "/known_length/a");
  expect_error(
      with([&](Annotations& a) {
        a.planes.push_back({{{10, 300}, {50, 300}, {50, 400}},
                            std::array<PixelPoint, 2>{PixelPoint{10, 2}, PixelPoint{50, 400}}});
      }),
      "/planes/0/base/0");
  expect_error([&] { pose_from_horizon(rig.camera, rig.horizon(), 0); }, "/camera_height_m");
}

// An interior (issue 4 item 3): a room x in [-2.2, 2], z in [-1.5, 7] (its own frame),
// 2.6 m high, turned 8 degrees about the vertical through the camera. The annotation marks a
// point on the left wall's base, the two back corners and a point on the right wall's base
// (their exact projections); the truth is the ray's exit from the box by the slab method in the
// room's frame (independent of photo::Room).
struct RoomRig {
  Rig rig{-6, 2, 1.45};
  double turn_deg = 8;
  double x0 = -2.2, x1 = 2.0, z0 = -1.5, z1 = 7, height = 2.6;
  Vec3 world(double x, double y, double z) const {  // room frame -> world
    const double c = std::cos(turn_deg * kDeg), s = std::sin(turn_deg * kDeg);
    return {c * x + s * z, y, -s * x + c * z};
  }
  Vec3 room(const Vec3& v) const {  // world direction -> room frame
    const double c = std::cos(turn_deg * kDeg), s = std::sin(turn_deg * kDeg);
    return {c * v.x - s * v.z, v.y, s * v.x + c * v.z};
  }
  std::vector<PixelPoint> floor_clicks() const {
    return {rig.project(world(x0, 0, 3.2)), rig.project(world(x0, 0, z1)),
            rig.project(world(x1, 0, z1)), rig.project(world(x1, 0, 6.0))};
  }
  double truth(int x, int y) const {
    const auto [f, r, u] = rig.pose.axes();
    const double a = (x + 0.5 - rig.camera.cx) / rig.camera.focal_px;
    const double b = (y + 0.5 - rig.camera.cy) / rig.camera.focal_px;
    const double n = std::sqrt(a * a + b * b + 1);
    const Vec3 dw{(a * r.x - b * u.x + f.x) / n, (a * r.y - b * u.y + f.y) / n,
                  (a * r.z - b * u.z + f.z) / n};
    const Vec3 d = room(dw), o = room(rig.pose.position_m);
    double t = std::numeric_limits<double>::infinity();
    const double lo[3] = {x0, 0, z0}, hi[3] = {x1, height, z1};
    const double oo[3] = {o.x, o.y, o.z}, dd[3] = {d.x, d.y, d.z};
    for (int k = 0; k < 3; ++k) {
      if (dd[k] > 0) t = std::min(t, (hi[k] - oo[k]) / dd[k]);
      if (dd[k] < 0) t = std::min(t, (lo[k] - oo[k]) / dd[k]);
    }
    return t;
  }
};

TEST(EstimateInteriorBox, DepthMatchesRoomAndWallNormals) {
  const RoomRig rr;
  for (const auto& p : rr.floor_clicks()) {  // the marks are in the image
    ASSERT_GE(p[0], 0);
    ASSERT_LE(p[0], rr.rig.camera.width - 1);
    ASSERT_GE(p[1], 0);
    ASSERT_LE(p[1], rr.rig.camera.height - 1);
  }
  // Three ways to the ceiling: its height given; marked on the back wall's top edge (height
  // from the camera height); both marked and given, fixing the camera height instead.
  for (int mode = 0; mode < 3; ++mode) {
    Annotations a;
    a.horizon = rr.rig.horizon();
    if (mode != 2) a.camera_height_m = 1.45;
    Annotations::InteriorBox box;
    box.floor = rr.floor_clicks();
    if (mode != 1) box.ceiling_height_m = rr.height;
    if (mode != 0) box.ceiling_point = rr.rig.project(rr.world(0.4, rr.height, rr.z1));
    a.interior_box = box;
    const GeometryEstimate g = estimate_geometry(rr.rig.camera, a);
    EXPECT_NEAR(g.pose.position_m.y, 1.45, 1.45e-9) << "mode " << mode;
    EXPECT_EQ(g.height_source,
              mode == 2 ? EstimateSource::interior_box : EstimateSource::annotations);
    ASSERT_TRUE(g.room_ceiling_height_m);
    EXPECT_NEAR(*g.room_ceiling_height_m, rr.height, 1e-9);
    // Float storage: 1e-5 relative everywhere (the bar is 2 %).
    double worst = 0;
    for (int y = 0; y < rr.rig.camera.height; ++y)
      for (int x = 0; x < rr.rig.camera.width; ++x) {
        const double want = rr.truth(x, y);
        ASSERT_TRUE(std::isfinite(want));
        worst = std::max(worst, std::abs(g.distance_m.at(x, y, 0) - want) / want);
      }
    EXPECT_LT(worst, 1e-5) << "mode " << mode;
    EXPECT_EQ(g.room_pixels, std::size_t(640 * 480));
    EXPECT_EQ(g.sky_pixels, 0u);
    EXPECT_FALSE(g.room_edges.empty());
    std::printf("interior box mode %d: worst depth error %.2e\n", mode, worst);
  }
  // The walls' inward normals: the room's +x (left wall), -z (back wall), -x (right wall).
  CameraPose pose = rr.rig.pose;
  Annotations::InteriorBox box;
  box.floor = rr.floor_clicks();
  const photo::Room room = photo::room_of_box(rr.rig.camera, pose, box);
  ASSERT_EQ(room.walls.size(), 3u);
  const Vec3 want[3] = {rr.world(1, 0, 0), rr.world(0, 0, -1), rr.world(-1, 0, 0)};
  for (int i = 0; i < 3; ++i) {
    EXPECT_LT(std::acos(std::min(1.0, dot(room.walls[i].normal, want[i]))) / kDeg, 1e-6)
        << "wall " << i;
  }
  EXPECT_NEAR(room.walls[1].offset, dot(want[1], rr.world(0, 0, rr.z1)), 1e-9);
  EXPECT_FALSE(room.ceiling_height_m);
  // Without a ceiling the walls go up for ever: rows that see the ceiling get the wall behind it.
  Annotations a;
  a.horizon = rr.rig.horizon();
  a.camera_height_m = 1.45;
  a.interior_box = box;
  const GeometryEstimate g = estimate_geometry(rr.rig.camera, a);
  EXPECT_GT(g.distance_m.at(320, 0, 0), rr.truth(320, 0));
  // With a photo (a bright, blank one: sky-like everywhere above the horizon) the room still
  // covers every pixel: no automatic sky mask indoors.
  Image blank(640, 480, 3);
  for (float& v : blank.pixels()) v = 0.8f;
  const GeometryEstimate with_photo = estimate_geometry(blank, rr.rig.camera, a);
  EXPECT_FALSE(with_photo.sky_from_mask);
  EXPECT_EQ(with_photo.sky_pixels, 0u);
  EXPECT_EQ(with_photo.room_pixels, std::size_t(640 * 480));
  EXPECT_NEAR(g.distance_m.at(320, 470, 0), rr.truth(320, 470), 1e-5 * rr.truth(320, 470));
}

// Clicks rounded to whole pixels: depth within the 2 % (the farthest floor point is
// 7.3 m away; measured and printed).
TEST(EstimateInteriorBox, WholePixelClicks) {
  const RoomRig rr;
  Annotations a;
  a.horizon = rr.rig.horizon();
  a.camera_height_m = 1.45;
  Annotations::InteriorBox box;
  for (auto p : rr.floor_clicks()) box.floor.push_back({std::round(p[0]), std::round(p[1])});
  box.ceiling_height_m = rr.height;
  a.interior_box = box;
  const GeometryEstimate g = estimate_geometry(rr.rig.camera, a);
  double worst = 0, sum = 0;
  for (int y = 0; y < rr.rig.camera.height; ++y)
    for (int x = 0; x < rr.rig.camera.width; ++x) {
      const double want = rr.truth(x, y), e = std::abs(g.distance_m.at(x, y, 0) - want) / want;
      worst = std::max(worst, e);
      sum += e;
    }
  std::printf("interior box, whole-pixel clicks: worst %.3f %%, mean %.3f %%\n", 100 * worst,
              100 * sum / (640 * 480));
  EXPECT_LT(worst, 0.02);
}

TEST(EstimateInteriorBox, BadBoxesNameTheField) {
  const RoomRig rr;
  auto with = [&](auto change) {
    Annotations a;
    a.horizon = rr.rig.horizon();
    a.camera_height_m = 1.45;
    Annotations::InteriorBox box;
    box.floor = rr.floor_clicks();
    a.interior_box = box;
    change(a);
    return [a, &rr] { estimate_geometry(rr.rig.camera, a); };
  };
  // A floor point above the horizon.
  expect_error(with([](Annotations& a) {
                 a.interior_box->floor[2] = {400, 20};
               }),
               "/interior_box/floor/2: (400, 20) is on or above the horizon");
  // Three points on one line (the back wall's base, its middle marked as a corner).
  expect_error(with([&](Annotations& a) {
                 a.interior_box->floor = {rr.rig.project(rr.world(rr.x0, 0, rr.z1)),
                                          rr.rig.project(rr.world(0.3, 0, rr.z1)),
                                          rr.rig.project(rr.world(rr.x1, 0, rr.z1))};
               }),
               "/interior_box/floor/1: points 0, 1 and 2 meet the floor on one line (collinear)");
  // A reflex corner: the camera is not inside a convex room.
  expect_error(with([&](Annotations& a) {
                 a.interior_box->floor = {rr.rig.project(rr.world(rr.x0, 0, rr.z1)),
                                          rr.rig.project(rr.world(0.3, 0, 3.0)),
                                          rr.rig.project(rr.world(rr.x1, 0, rr.z1))};
               }),
               "/interior_box/floor: the points do not bound a convex room around the camera");
  // Too few points; consecutive points at one pixel.
  expect_error(with([](Annotations& a) { a.interior_box->floor.resize(2); }),
               "/interior_box/floor");
  expect_error(with([](Annotations& a) { a.interior_box->floor[1] = a.interior_box->floor[0]; }),
               "/interior_box/floor/1");
  // The ceiling: marked below the horizon; given below the camera; over-determined.
  expect_error(with([](Annotations& a) {
                 a.interior_box->ceiling_point = PixelPoint{320, 400};
               }),
               "/interior_box/ceiling_point: (320, 400) is on or below the horizon");
  expect_error(with([](Annotations& a) { a.interior_box->ceiling_height_m = 1.2; }),
               "/interior_box/ceiling_height_m: 1.2 m is not above the camera");
  expect_error(with([](Annotations& a) {
                 a.interior_box->ceiling_height_m = 2.6;
                 a.interior_box->ceiling_point = PixelPoint{320, 20};
               }),
               "/interior_box/ceiling_height_m: with ceiling_point it fixes the camera height");
}

}  // namespace
}  // namespace mr
