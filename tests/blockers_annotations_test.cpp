// Blockers the photo does not show, stated in the annotations document (issue 13 section 1): the
// same "blockers" schema and rules as the scene document, errors naming the field, the estimate
// copying them into its scene; and the library's rules for blocker polygons (planar, convex,
// with an area), which mr-studio's blockers panel relies on instead of checking them itself.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>
#include <string>
#include <vector>

#include "mr/annotations.h"
#include "mr/error.h"
#include "mr/estimate.h"
#include "mr/scattering.h"
#include "mr/scene_json.h"
#include "test_support.h"

namespace mr {
namespace {

const std::string kHead = R"({"format": "libmr-annotations", "version": 1)";

// A message containing every fragment, or "no error".
std::string annotations_error(const std::string& text) {
  try {
    annotations_from_json(text, "a.json");
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::invalid_argument);
    return e.what();
  }
  return "no error";
}

std::string scene_error(const Blockers& b) {
  FogScene s;
  s.blockers = b;
  try {
    validate_scene(s);
  } catch (const Error& e) {
    return e.what();
  }
  return "no error";
}

Blockers sample_blockers() {
  Blockers b;
  b.completion.enabled = false;
  b.completion.max_height_m = 24.5;
  b.skyline = Blockers::Skyline{35, {{-40, 12}, {10, 18.25}, {95, 6}}};
  // A wall as mr-studio draws it: a vertical rectangle over a plan segment.
  b.polygons.push_back({{{12, 0, -30}, {12, 0, 15}, {12, 30, 15}, {12, 30, -30}}});
  b.canopy = Blockers::Canopy{9.5, 0.45, 25, 0.5, 7};
  return b;
}

TEST(BlockersAnnotations, RoundTripIsExactAndTheSchemaIsTheScenes) {
  Annotations a;
  a.camera_height_m = 1.6;
  a.blockers = sample_blockers();
  const std::string text = annotations_to_json(a);
  EXPECT_NE(text.find("\"blockers\""), std::string::npos);
  const Annotations b = annotations_from_json(text, "a.json");
  ASSERT_TRUE(b.blockers);
  EXPECT_EQ(annotations_to_json(b), text);
  FogScene s1, s2;
  s1.blockers = *a.blockers;
  s2.blockers = *b.blockers;
  EXPECT_EQ(scene_to_json(s2), scene_to_json(s1));

  // The scene document's "blockers" object, pasted into an annotations document, reads the same.
  const std::string scene_text = scene_to_json(s1);
  const auto start = scene_text.find("\"blockers\": ");
  ASSERT_NE(start, std::string::npos);
  // The object runs to its matching brace (other keys, e.g. "objects", may follow it).
  std::size_t end = start + 12;
  for (int depth = 0; end < scene_text.size(); ++end) {
    depth += scene_text[end] == '{' ? 1 : scene_text[end] == '}' ? -1 : 0;
    if (depth == 0 && scene_text[end] == '}') break;
  }
  ASSERT_LT(end, scene_text.size());
  const std::string object = scene_text.substr(start + 12, end + 1 - (start + 12));
  const Annotations c = annotations_from_json(kHead + ", \"blockers\": " + object + "}", "c.json");
  ASSERT_TRUE(c.blockers);
  FogScene s3;
  s3.blockers = *c.blockers;
  EXPECT_EQ(scene_to_json(s3), scene_to_json(s1));

  // Left out: none, and none written.
  EXPECT_FALSE(annotations_from_json(kHead + "}").blockers);
  Annotations none;
  none.camera_height_m = 1.6;
  EXPECT_EQ(annotations_to_json(none).find("blockers"), std::string::npos);
  // Keys left out take the scene's defaults (completion on, as in a version 3 scene).
  const Annotations d =
      annotations_from_json(kHead + R"(, "blockers": {"canopy": {"gap_fraction": 0.2}}})");
  ASSERT_TRUE(d.blockers && d.blockers->canopy);
  EXPECT_TRUE(d.blockers->completion.enabled);
  EXPECT_EQ(d.blockers->canopy->gap_fraction, 0.2);
  EXPECT_EQ(d.blockers->canopy->height_m, Blockers::Canopy{}.height_m);
}

TEST(BlockersAnnotations, ErrorsNameTheField) {
  const std::string h = kHead + R"(, "blockers": )";
  struct Case {
    std::string blockers;
    std::vector<std::string> fragments;
  };
  const Case cases[] = {
      {R"({"skyline": {"samples": [[0, -5], [10, 3]]}})",
       {"a.json: /blockers/skyline/samples/0/1: ", "blockers.skyline.samples[0].height_m = -5"}},
      {R"({"skyline": {"samples": [[0, 5]]}})", {"a.json: /blockers/skyline/samples: "}},
      {R"({"skyline": {"distance_m": 0, "samples": [[0, 5], [9, 5]]}})",
       {"/blockers/skyline/distance_m: ", "blockers.skyline.distance_m = 0"}},
      {R"({"skyline": {"samples": [[0, "high"], [9, 5]]}})",
       {"/blockers/skyline/samples/0/1: expected a number"}},
      {R"({"skylin": {}})", {"/blockers/skylin: unknown key", "did you mean \"skyline\""}},
      {R"({"canopy": {"gap_fraction": 1.5}})",
       {"/blockers/canopy/gap_fraction: ", "must be in [0, 1]"}},
      {R"({"completion": {"max_height_m": 20000}})", {"/blockers/completion/max_height_m: "}},
      {R"({"polygons": [{"corners_m": [[0, 0, 5], [1, 0, 5]]}]})",
       {"/blockers/polygons/0/corners_m: ", "need 3"}},
      // A wall whose top is its bottom: no area.
      {R"({"polygons": [{"corners_m": [[0, 2, 5], [4, 2, 5], [4, 2, 5], [0, 2, 5]]}]})",
       {"/blockers/polygons/0/corners_m: ", "no area"}},
      // Not convex: an L-shaped outline.
      {R"({"polygons": [{"corners_m": [[0,0,5],[4,0,5],[4,1,5],[1,1,5],[1,4,5],[0,4,5]]}]})",
       {"/blockers/polygons/0/corners_m/3: ", "convex"}},
      {R"({"polygons": [{"corners_m": [[0, 0, 5], [4, 0, 5], [4, 3, 9], [0, 3, 5]]}]})",
       {"/blockers/polygons/0/corners_m/", "one plane"}},
      {R"([1, 2])", {"/blockers: expected an object"}},
  };
  for (const Case& c : cases) {
    const std::string what = annotations_error(h + c.blockers + "}");
    for (const std::string& f : c.fragments)
      EXPECT_NE(what.find(f), std::string::npos) << c.blockers << "\n -> " << what;
    EXPECT_EQ(what.find('\n'), std::string::npos) << what;
  }
  // validate_annotations on structs (no JSON) names the field the same way.
  Annotations a;
  a.blockers = sample_blockers();
  a.blockers->skyline->samples[2].azimuth_deg = std::nan("");
  try {
    validate_annotations(a, "mem");
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("mem: /blockers/skyline/samples/2/0: "), std::string::npos)
        << e.what();
  }
  a.blockers = sample_blockers();
  a.blockers->polygons[0].corners_m[1].y = std::numeric_limits<double>::infinity();
  EXPECT_THROW(annotations_to_json(a), Error);
}

// The scene's rules for blocker polygons: render/blockers.cpp fans them from their first corner,
// exact only for planar convex ones.
TEST(BlockersAnnotations, PolygonsMustBePlanarConvexWithAnArea) {
  auto with = [](std::vector<Vec3> corners) {
    Blockers b;
    b.polygons.push_back({std::move(corners)});
    return scene_error(b);
  };
  // Valid: a triangle, a wall, a wall with a corner on an edge (collinear), either winding, a
  // regular hexagon tilted in space, a 1 km wall.
  EXPECT_EQ(with({{1, 0, 2}, {3, 0, 2}, {3, 5, 2}}), "no error");
  EXPECT_EQ(with({{12, 0, -30}, {12, 0, 15}, {12, 30, 15}, {12, 30, -30}}), "no error");
  EXPECT_EQ(with({{12, 0, -30}, {12, 0, 0}, {12, 0, 15}, {12, 30, 15}, {12, 30, -30}}), "no error");
  EXPECT_EQ(with({{12, 30, -30}, {12, 30, 15}, {12, 0, 15}, {12, 0, -30}}), "no error");
  std::vector<Vec3> hexagon;
  for (int k = 0; k < 6; ++k) {
    const double t = k * std::numbers::pi / 3;
    // In the plane through (0, 5, 20) spanned by (1, 1, 0)/sqrt2 and (0, 0, 1).
    hexagon.push_back({3 * std::cos(t) / std::sqrt(2.0), 5 + 3 * std::cos(t) / std::sqrt(2.0),
                       20 + 3 * std::sin(t)});
  }
  EXPECT_EQ(with(hexagon), "no error");
  EXPECT_EQ(with({{-500, 0, 100}, {500, 0, 100}, {500, 20, 100}, {-500, 20, 100}}), "no error");
  // Invalid.
  EXPECT_NE(with({{0, 0, 5}, {1, 0, 5}, {2, 0, 5}}).find("no area"), std::string::npos);
  EXPECT_NE(with({{0, 0, 5}, {0, 0, 5}, {0, 0, 5}}).find("no area"), std::string::npos);
  EXPECT_NE(with({{0, 0, 5}, {4, 0, 5}, {4, 3, 9}, {0, 3, 5}}).find("one plane"),
            std::string::npos);
  const std::string reflex =
      with({{0, 0, 5}, {4, 0, 5}, {4, 1, 5}, {1, 1, 5}, {1, 4, 5}, {0, 4, 5}});
  EXPECT_NE(reflex.find("blockers.polygons[0].corners_m[3] = a reflex corner"), std::string::npos)
      << reflex;
  std::vector<Vec3> star;  // a pentagram: every turn the same way, twice around
  for (int k = 0; k < 5; ++k) {
    const double t = k * 4 * std::numbers::pi / 5;
    star.push_back({std::sin(t), 5 + std::cos(t), 10});
  }
  EXPECT_NE(with(star).find("must be simple and convex"), std::string::npos) << with(star);
  // A bow tie (self-crossing quadrilateral).
  EXPECT_NE(with({{0, 0, 5}, {4, 4, 5}, {4, 0, 5}, {0, 4, 5}}), "no error");
}

TEST(BlockersAnnotations, EstimateCopiesThemIntoTheScene) {
  const Camera camera = Camera::from_horizontal_fov(160, 120, 50);
  const Image photo = test::make_test_photo(160, 120);
  Annotations a;
  a.horizon = std::array<PixelPoint, 2>{PixelPoint{0, 50}, PixelPoint{159, 50}};
  a.camera_height_m = 1.5;
  const SceneEstimate plain = estimate_scene(photo, camera, a);
  a.blockers = sample_blockers();
  const SceneEstimate est = estimate_scene(photo, camera, a);
  FogScene want = plain.scene;
  want.blockers = *a.blockers;
  EXPECT_EQ(scene_to_json(est.scene), scene_to_json(want));  // the blockers, nothing else
  bool noted = false;
  for (const std::string& n : est.notes)
    noted |= n ==
             "blockers: annotated (a skyline of 3 points, 1 polygon(s), a canopy, completion "
             "of structures cut by the frame off)";
  EXPECT_TRUE(noted);
  // Without blockers in the annotations the scene keeps its defaults.
  EXPECT_EQ(scene_to_json(plain.scene).find("\"polygons\""), std::string::npos);
  EXPECT_TRUE(plain.scene.blockers.completion.enabled);
}

}  // namespace
}  // namespace mr
