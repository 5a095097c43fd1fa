// Issue 13, section 1: blockers the photo does not show. The scattering core against the
// independent Monte Carlo reference (tests/mc_reference.*), which traces the FULL geometry,
// including what lies outside the frame, on synthetic scenes whose blockers leave the frame at
// the top and at the sides.
//
// Bars: mean relative error of R over all pixels (reference R > 1e-4) below 3 % at normal
// quality with the completion of cut structures on (or with the scene's blockers given); the
// error without them is printed and must be above the bar, so each test fails without what it
// tests. The reference's own noise is checked to be well below the bar.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "mc_reference.h"
#include "mr/error.h"
#include "mr/scattering.h"
#include "mr/scene_json.h"
#include "render/blockers.h"
#include "render/occluder_mesh.h"
#include "test_support.h"

namespace mr {
namespace {

#if defined(__SANITIZE_ADDRESS__) || !defined(__OPTIMIZE__)
constexpr bool kSlowBuild = true;
#else
constexpr bool kSlowBuild = false;
#endif

constexpr double kBar = 0.03;

// Mean relative error of R against the reference, over values where the reference is > 1e-4.
double mean_relative_error(const Image& core, const Image& ref) {
  double sum = 0;
  std::size_t n = 0;
  for (int y = 0; y < ref.height(); ++y)
    for (int x = 0; x < ref.width(); ++x)
      for (int c = 0; c < 3; ++c) {
        const double want = ref.at(x, y, c);
        if (!(want > 1e-4)) continue;
        const double got = core.at(x, y, c);
        sum += std::isfinite(got) ? std::fabs(got - want) / want : 1e9;
        ++n;
      }
  return n ? sum / double(n) : 0;
}

// A fog bank of 60 m visibility, 10 m deep, a little sky light, a sun the caller places: sunlit
// fog with shafts, as in the scenes (R mostly the sun's, so the shadows matter).
FogScene sunny_fog(double azimuth, double elevation) {
  FogScene s;
  s.pose.position_m = {0, 1.6, 0};
  const float sigma = float(3.912 / 60.0);
  s.medium.sigma_t_per_m = {sigma, sigma, sigma};
  s.medium.albedo = {0.9f, 0.9f, 0.9f};
  s.medium.g = 0.5;
  s.medium.layer_top_m = 10.0;
  s.lighting.sun = Sun{direction_from_azimuth_elevation(azimuth, elevation), {3, 3, 3}, 0.27};
  s.lighting.sky_radiance = Rgb{0.05f, 0.05f, 0.05f};
  s.render.quality = Quality::normal;
  s.render.backend = Backend::cpu;
  s.render.seed = 1;
  return s;
}

mcref::Result reference(const Image& distance, const Camera& cam, const FogScene& s,
                        const mcref::Geometry& g) {
  mcref::Settings st;
  st.batches = kSlowBuild ? 8 : 16;
  st.medium_samples = kSlowBuild ? 48 : 128;
  st.lamp_samples = 8;
  st.seed = 777;
  mcref::Result r = mcref::render(distance, cam, s, g, st);
  // Well below the 3 % bar (the sharp shafts of the pillar scene make it 0.27 %).
  EXPECT_LT(r.mean_relative_standard_error, kSlowBuild ? 8e-3 : 5e-3);
  return r;
}

struct Errors {
  double with = 0, without = 0;
  std::size_t triangles_with = 0;
  std::vector<CompletedBlocker> completed;  // what the render with the blockers continued
};

// The core with the scene as given and with completion off and no explicit blockers.
Errors compare(const Image& distance, const Camera& cam, const FogScene& s,
               const mcref::Result& ref, const std::string& tag) {
  Errors e;
  const ScatteringLayers with = render_scattering(Image(), distance, cam, s);
  FogScene bare = s;
  bare.blockers = Blockers{};
  bare.blockers.completion.enabled = false;
  const ScatteringLayers without = render_scattering(Image(), distance, cam, bare);
  e.with = mean_relative_error(with.inscatter, ref.inscatter);
  e.completed = with.completed_blockers;
  e.without = mean_relative_error(without.inscatter, ref.inscatter);
  std::printf("[ OffFrame ] %s: mean relative error of R %.4f with the blockers, %.4f without; "
              "reference standard error %.5f\n",
              tag.c_str(), e.with, e.without, ref.mean_relative_standard_error);
  return e;
}

// A colonnade in front of the camera: five square pillars 1.2 m wide, 25 m tall, 14 m away,
// cut by the top of the frame at about 7 m; the sun behind them and to the right, so their
// parts above the frame cast the shafts that cross the fog in front of the camera, and their
// sides (which the photo does not show) widen the shadows (with only their front faces, all
// the way up, R was 48 % off). Measured 2026-12-01: 79 % without completion; 5.0 % with prisms
// as deep as wide behind every outline point (a side seen at a grazing angle doubled the
// depth), 1.8 % with boxes aligned to the widest face; with the pillars' true boxes given as
// polygons the core is within 1.0 % (the rest: their width quantised to whole pixels, 8 px for
// 7.1).
TEST(OffFrame, PillarsCutByTheTopMatchReferenceWithCompletion) {
  const Camera cam = Camera::from_horizontal_fov(96, 64, 60);
  FogScene s = sunny_fog(20, 35);
  mcref::Geometry g;
  g.ground = true;
  for (double cx : {-6.0, -3.0, 0.0, 3.0, 6.0})
    g.boxes.push_back({{cx - 0.6, 0, 14}, {cx + 0.6, 25, 15.2}});
  const Image distance = mcref::distance_map(cam, s.pose, g);
  // The pillars do leave the frame at the top.
  int cut = 0;
  for (int x = 0; x < cam.width; ++x) cut += std::isfinite(distance.at(x, 0, 0));
  ASSERT_GT(cut, 10);
  const mcref::Result ref = reference(distance, cam, s, g);
  const Errors e = compare(distance, cam, s, ref, "pillars cut by the top");
  EXPECT_LT(e.with, kBar);
  EXPECT_GT(e.without, kBar);
  // The API says what it guessed: five boxes cut by the top, continued to the scene's maximum
  // height (no pillar top is visible), so with the low confidence of a guessed height and depth.
  ASSERT_EQ(e.completed.size(), 5u);
  for (const CompletedBlocker& b : e.completed) {
    EXPECT_EQ(b.edge, CompletedBlocker::Edge::top);
    EXPECT_TRUE(b.vertical && b.prism);
    EXPECT_EQ(b.top_m, s.blockers.completion.max_height_m);
    EXPECT_NEAR(b.confidence, 0.2, 1e-12);
    EXPECT_GE(b.last_px - b.first_px + 1, 6);  // 7-9 px wide
    EXPECT_LE(b.last_px - b.first_px + 1, 10);
  }
}

// Square posts turned 45 degrees to the view (two faces seen, neither facing the camera), at
// four distances, 20 m tall, cut by the top; a sun from the front right at 30 degrees throws
// their shadows across the fog towards the camera. Measured 2026-12-01: 1.7 % with completion
// (1.1 % with the earlier prisms), 15 % without.
TEST(OffFrame, TurnedPostsCutByTheTopMatchReferenceWithCompletion) {
  const Camera cam = Camera::from_horizontal_fov(96, 64, 60);
  FogScene s = sunny_fog(-25, 25);
  mcref::Geometry g;
  g.ground = true;
  const double half = 0.5 / std::sqrt(2.0) * 2;  // 1 m sides: corners 0.707 m from the axis
  const double posts[4][2] = {{-4.5, 12}, {-1.5, 15}, {1.5, 18}, {4.5, 21}};
  for (const auto& c : posts) {
    const Vec3 p0{c[0], 0, c[1] - half}, p1{c[0] + half, 0, c[1]}, p2{c[0], 0, c[1] + half},
        p3{c[0] - half, 0, c[1]};
    const Vec3 up{0, 20, 0};
    for (const auto& [a, b] : {std::pair{p0, p1}, {p1, p2}, {p2, p3}, {p3, p0}})
      g.quads.push_back({a, {b.x - a.x, 0, b.z - a.z}, up});
  }
  const Image distance = mcref::distance_map(cam, s.pose, g);
  int cut = 0;
  for (int x = 0; x < cam.width; ++x) cut += std::isfinite(distance.at(x, 0, 0));
  ASSERT_GT(cut, 10);
  const mcref::Result ref = reference(distance, cam, s, g);
  const Errors e = compare(distance, cam, s, ref, "turned posts cut by the top");
  EXPECT_LT(e.with, kBar);
  EXPECT_GT(e.without, kBar);
}

// A long wall on the left (x in [-5, -4], 10 m tall, z from -30 to 40): the frame's left edge
// cuts it 7 m ahead and the top cuts it nearer than 22 m; the low sun from the left puts the
// fog in front of the camera in the shadow of the wall's parts beside and behind the frame.
TEST(OffFrame, WallCutByTheLeftEdgeMatchesReferenceWithCompletion) {
  const Camera cam = Camera::from_horizontal_fov(96, 64, 60);
  FogScene s = sunny_fog(-70, 30);
  mcref::Geometry g;
  g.ground = true;
  g.boxes.push_back({{-5, 0, -30}, {-4, 10, 40}});
  const Image distance = mcref::distance_map(cam, s.pose, g);
  int cut = 0;
  for (int y = 0; y < cam.height; ++y) cut += std::isfinite(distance.at(0, y, 0)) && y < 40;
  ASSERT_GT(cut, 10);
  const mcref::Result ref = reference(distance, cam, s, g);
  const Errors e = compare(distance, cam, s, ref, "wall cut by the left edge");
  EXPECT_LT(e.with, kBar);
  EXPECT_GT(e.without, kBar);
}

// The same wall's completion is a few large quads, not one 30 m sliver per pixel row: slivers
// stacked along the wall overlap each other's bounding boxes along their whole length, and every
// shadow ray passing them tested hundreds of triangles (at 1080p the render's CPU time doubled).
TEST(OffFrame, CompletedPlanarWallIsAFewLargeQuads) {
  const Camera cam = Camera::from_horizontal_fov(96, 64, 60);
  const FogScene s = sunny_fog(-70, 30);
  mcref::Geometry g;
  g.ground = true;
  g.boxes.push_back({{-5, 0, -30}, {-4, 10, 40}});
  const Image distance = mcref::distance_map(cam, s.pose, g);
  const Image normals = render::estimate_normals(distance.view(), cam, s.pose);
  int rows_cut = 0;  // wall pixels along the left edge: one sliver each before
  for (int y = 0; y < cam.height; ++y) rows_cut += std::isfinite(distance.at(0, y, 0)) && y < 40;
  ASSERT_GT(rows_cut, 10);
  render::TriangleMesh mesh;
  const render::BlockerReport report =
      render::append_blockers(mesh, distance.view(), normals.view(), cam, s.pose, s.blockers);
  std::printf("[ OffFrame ] completed wall: %zu triangles for %d cut rows\n", report.triangles,
              rows_cut);
  ASSERT_FALSE(report.completed.empty());
  EXPECT_GT(report.triangles, 0u);
  EXPECT_LT(report.triangles, std::size_t(rows_cut));
}

// Blockers the photo cannot show at all, given in the scene: the camera sees only ground and
// sky; behind it, in the way of a sun low behind-left, stand a wall (a polygon, 15 m tall, 8 m to
// the left) and a skyline (35 m tall, 45 m away, azimuth 160..220). The reference holds the same
// surfaces as quads (the skyline's wall pieces 5 degrees wide, as docs/scene.md defines them).
TEST(OffFrame, SkylineAndPolygonMatchReference) {
  const Camera cam = Camera::from_horizontal_fov(96, 64, 60);
  FogScene s = sunny_fog(-150, 25);
  s.pose.pitch_deg = -5;
  mcref::Geometry g;
  g.ground = true;
  const Image distance = mcref::distance_map(cam, s.pose, g);  // ground and sky only
  Blockers::Polygon wall;
  wall.corners_m = {{-8, 0, -14}, {-8, 0, 2}, {-8, 15, 2}, {-8, 15, -14}};
  s.blockers.polygons.push_back(wall);
  g.quads.push_back({{-8, 0, -14}, {0, 0, 16}, {0, 15, 0}});
  Blockers::Skyline sky;
  sky.distance_m = 45;
  sky.samples = {{160, 35}, {220, 35}};
  s.blockers.skyline = sky;
  constexpr double kPi = 3.14159265358979323846;
  for (double az = 160; az < 220 - 1e-9; az += 5) {
    const double a0 = az * kPi / 180, a1 = (az + 5) * kPi / 180;
    const Vec3 p0{45 * std::sin(a0), 0, 45 * std::cos(a0)};
    const Vec3 p1{45 * std::sin(a1), 0, 45 * std::cos(a1)};
    g.quads.push_back({{s.pose.position_m.x + p0.x, 0, s.pose.position_m.z + p0.z},
                       {p1.x - p0.x, 0, p1.z - p0.z},
                       {0, 35, 0}});
  }
  const mcref::Result ref = reference(distance, cam, s, g);
  const Errors e = compare(distance, cam, s, ref, "skyline and polygon");
  EXPECT_LT(e.with, kBar);
  EXPECT_GT(e.without, kBar);
}

// A canopy 6 m up over flat ground with 30 % gaps, seen from 5 m looking straight down (about
// 1600 cells of 0.25 m in view, so the fraction of gaps seen is within ~0.01 of 0.3): the mean
// sun visibility on the ground (sun at 50 degrees) is the gap fraction within 0.05. At final
// quality: at normal, the gradient acceleration's sparse samples (every 3 px) miss shadows of
// cells this small (README, simplifications).
TEST(OffFrame, CanopyLetsItsGapFractionThrough) {
  const Camera cam = Camera::from_horizontal_fov(128, 128, 90);
  FogScene s = sunny_fog(30, 50);
  s.render.quality = Quality::final;
  s.pose.position_m = {0, 5, 0};
  s.pose.pitch_deg = -90;
  Blockers::Canopy c;
  c.height_m = 6;
  c.gap_fraction = 0.3;
  c.radius_m = 20;
  c.cell_m = 0.25;
  s.blockers.canopy = c;
  mcref::Geometry g;
  g.ground = true;
  const Image distance = mcref::distance_map(cam, s.pose, g);
  const ScatteringLayers out = render_scattering(Image(), distance, cam, s);
  double sum = 0;
  int n = 0;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const double d = distance.at(x, y, 0);
      if (!std::isfinite(d)) continue;
      sum += out.sun_visibility.at(x, y, 0);
      ++n;
    }
  ASSERT_GT(n, 3000);
  std::printf("[ OffFrame ] canopy with 30 %% gaps: mean sun visibility on the ground %.3f\n",
              sum / n);
  EXPECT_NEAR(sum / n, 0.3, 0.05);
}

TEST(OffFrame, BlockersReadWriteAndValidate) {
  FogScene s;
  s.blockers.completion.max_height_m = 22;
  s.blockers.completion.prism_max_width_m = 1.5;
  s.blockers.skyline = Blockers::Skyline{40, {{-30, 12}, {30, 18.5}}};
  s.blockers.polygons.push_back({{{1, 0, 2}, {3, 0, 2}, {3, 5, 2}}});
  s.blockers.canopy = Blockers::Canopy{7, 0.25, 20, 0.75, 9};
  const std::string text = scene_to_json(s);
  // Written as the current format (blockers came with version 3; objects made it 4).
  EXPECT_NE(text.find("\"version\": " + std::to_string(kSceneFormatVersion)), std::string::npos);
  const FogScene t = scene_from_json(text, "b.json");
  EXPECT_EQ(scene_to_json(t), text);
  EXPECT_EQ(t.blockers.completion.max_height_m, 22);
  ASSERT_TRUE(t.blockers.skyline);
  EXPECT_EQ(t.blockers.skyline->samples[1].height_m, 18.5);
  ASSERT_EQ(t.blockers.polygons.size(), 1u);
  EXPECT_EQ(t.blockers.polygons[0].corners_m[2].y, 5);
  ASSERT_TRUE(t.blockers.canopy);
  EXPECT_EQ(t.blockers.canopy->seed, 9u);

  // Older documents render as before: completion off. Version 3 without blockers: on.
  EXPECT_FALSE(scene_from_json("{\"format\": \"libmr-scene\", \"version\": 2}").blockers
                   .completion.enabled);
  EXPECT_TRUE(scene_from_json("{\"format\": \"libmr-scene\", \"version\": 3}").blockers
                  .completion.enabled);
  auto error_of = [](const std::string& doc) {
    try {
      scene_from_json(doc, "b.json");
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  const std::string head = "{\"format\": \"libmr-scene\", \"version\": 3, \"blockers\": ";
  EXPECT_NE(error_of("{\"format\": \"libmr-scene\", \"version\": 2, \"blockers\": {}}")
                .find("/blockers: blockers are part of the format from version 3 on"),
            std::string::npos);
  EXPECT_NE(error_of(head + "{\"canopy\": {\"gap_fraction\": 1.5}}}")
                .find("b.json: /blockers/canopy/gap_fraction"),
            std::string::npos)
      << error_of(head + "{\"canopy\": {\"gap_fraction\": 1.5}}}");
  EXPECT_NE(error_of(head + "{\"skyline\": {\"samples\": [[0, 5]]}}}")
                .find("/blockers/skyline/samples"),
            std::string::npos);
  EXPECT_NE(error_of(head + "{\"polygons\": [{\"corners_m\": [[0, 0, 0], [1, 0, 0]]}]}}")
                .find("/blockers/polygons/0/corners_m"),
            std::string::npos);
  EXPECT_NE(error_of(head + "{\"completion\": {\"max_height_m\": -1}}}")
                .find("/blockers/completion/max_height_m"),
            std::string::npos);
  EXPECT_NE(error_of(head + "{\"completion\": {\"enable\": false}}}").find("enable"),
            std::string::npos);
}

}  // namespace
}  // namespace mr
