// The annotations document (docs/annotations.md): strict reading, errors naming the JSON
// pointer, exact round trips, atomic saving.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <string>

#include "mr/annotations.h"
#include "mr/error.h"
#include "test_support.h"

namespace mr {
namespace {

// Expects annotations_from_json(text) to fail with invalid_argument and a message containing
// every fragment.
void expect_error(const std::string& text, std::initializer_list<std::string> fragments) {
  try {
    annotations_from_json(text, "a.json");
    ADD_FAILURE() << "no error for: " << text;
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::invalid_argument);
    const std::string what = e.what();
    EXPECT_EQ(what.rfind("a.json: ", 0), 0u) << what;
    for (const auto& f : fragments)
      EXPECT_NE(what.find(f), std::string::npos) << what << " lacks " << f;
    EXPECT_EQ(what.find('\n'), std::string::npos) << what;
  }
}

const std::string kHead = R"({"format": "libmr-annotations", "version": 1)";

Annotations full() {
  Annotations a;
  a.horizon = std::array<PixelPoint, 2>{PixelPoint{0.25, 361.5}, PixelPoint{750, 362.125}};
  a.known_length = Annotations::KnownLength{{100, 500}, {300, 510.5}, 3.3};
  Annotations::Plane p;
  p.polygon = {{10, 20}, {30, 20}, {30, 400}, {10, 400.1}};
  a.planes.push_back(p);
  p.base = std::array<PixelPoint, 2>{PixelPoint{10, 400}, PixelPoint{30, 401}};
  a.planes.push_back(p);
  a.distance_hints.push_back({{{0, 0}, {5, 0}, {5, 5}}, 250.0});
  a.shadow_pairs.push_back({{100, 300}, {100, 450}, {180, 470}});
  a.sunlit_patch = {{1, 500}, {20, 500}, {20, 520}};
  a.shadowed_patch = {{101, 500}, {120, 500}, {120, 520}};
  return a;
}

void expect_equal(const Annotations& a, const Annotations& b) {
  EXPECT_EQ(a.horizon, b.horizon);
  EXPECT_EQ(a.camera_height_m, b.camera_height_m);
  ASSERT_EQ(a.known_length.has_value(), b.known_length.has_value());
  if (a.known_length) {
    EXPECT_EQ(a.known_length->a, b.known_length->a);
    EXPECT_EQ(a.known_length->b, b.known_length->b);
    EXPECT_EQ(a.known_length->length_m, b.known_length->length_m);
  }
  ASSERT_EQ(a.planes.size(), b.planes.size());
  for (std::size_t i = 0; i < a.planes.size(); ++i) {
    EXPECT_EQ(a.planes[i].polygon, b.planes[i].polygon);
    EXPECT_EQ(a.planes[i].base, b.planes[i].base);
  }
  ASSERT_EQ(a.distance_hints.size(), b.distance_hints.size());
  for (std::size_t i = 0; i < a.distance_hints.size(); ++i) {
    EXPECT_EQ(a.distance_hints[i].polygon, b.distance_hints[i].polygon);
    EXPECT_EQ(a.distance_hints[i].distance_m, b.distance_hints[i].distance_m);
  }
  ASSERT_EQ(a.shadow_pairs.size(), b.shadow_pairs.size());
  for (std::size_t i = 0; i < a.shadow_pairs.size(); ++i) {
    EXPECT_EQ(a.shadow_pairs[i].caster_top, b.shadow_pairs[i].caster_top);
    EXPECT_EQ(a.shadow_pairs[i].caster_foot, b.shadow_pairs[i].caster_foot);
    EXPECT_EQ(a.shadow_pairs[i].shadow_tip, b.shadow_pairs[i].shadow_tip);
  }
  EXPECT_EQ(a.sunlit_patch, b.sunlit_patch);
  EXPECT_EQ(a.shadowed_patch, b.shadowed_patch);
}

TEST(Annotations, MinimalDocumentIsEmpty) {
  const Annotations a = annotations_from_json(kHead + "}");
  EXPECT_FALSE(a.horizon);
  EXPECT_FALSE(a.camera_height_m);
  EXPECT_FALSE(a.known_length);
  EXPECT_TRUE(a.planes.empty());
  EXPECT_TRUE(a.shadow_pairs.empty());
}

TEST(Annotations, ParsesEveryKey) {
  const Annotations a = annotations_from_json(kHead + R"(,
    "horizon": [[0, 362], [750, 361]], "camera_height_m": 1.6,
    "planes": [{"polygon": [[1, 2], [3, 4], [5, 6]], "base": [[1, 6], [5, 6]]}],
    "distance_hints": [{"polygon": [[0, 0], [9, 0], [9, 9]], "distance_m": 80}],
    "shadow_pairs": [{"caster_top": [1, 2], "caster_foot": [1, 9], "shadow_tip": [4, 10]}],
    "sunlit_patch": [[0, 0], [1, 0], [1, 1]], "shadowed_patch": [[5, 0], [6, 0], [6, 1]]})");
  ASSERT_TRUE(a.horizon);
  EXPECT_EQ((*a.horizon)[1], (PixelPoint{750, 361}));
  EXPECT_EQ(*a.camera_height_m, 1.6);
  ASSERT_EQ(a.planes.size(), 1u);
  EXPECT_EQ(a.planes[0].polygon.size(), 3u);
  ASSERT_TRUE(a.planes[0].base);
  EXPECT_EQ(a.distance_hints.at(0).distance_m, 80);
  EXPECT_EQ(a.shadow_pairs.at(0).shadow_tip, (PixelPoint{4, 10}));
  EXPECT_EQ(a.sunlit_patch.size(), 3u);
}

TEST(Annotations, RoundTripIsExact) {
  const Annotations a = full();
  const std::string text = annotations_to_json(a);
  expect_equal(a, annotations_from_json(text));
  Annotations b;
  b.camera_height_m = 0.1 + 0.2;  // not a short decimal
  expect_equal(b, annotations_from_json(annotations_to_json(b)));
}

TEST(Annotations, SaveAndLoad) {
  test::ScratchDir dir;
  const auto path = dir / "a.json";
  save_annotations(path, full());
  expect_equal(full(), load_annotations(path));
  EXPECT_EQ(dir.list(), std::vector<std::string>{"a.json"});  // no temporary left
  try {
    load_annotations(dir / "missing.json");
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::io);
    EXPECT_NE(std::string(e.what()).find("missing.json"), std::string::npos);
  }
}

TEST(Annotations, HeaderErrors) {
  expect_error("{}", {"/format", "missing"});
  expect_error(R"({"format": "libmr-scene", "version": 1})", {"/format", "libmr-annotations"});
  expect_error(R"({"format": "libmr-annotations"})", {"/version", "missing"});
  expect_error(R"({"format": "libmr-annotations", "version": 2})", {"/version", "not supported"});
  expect_error("[1, 2]", {"expected an object"});
  expect_error(kHead + R"(, "horizon": [[0, 1], [2, 3]],})", {"line 1, column"});
  expect_error(kHead + R"(, "camera_height_m": 1, "camera_height_m": 2})", {"duplicate key"});
}

TEST(Annotations, UnknownKeysAreErrors) {
  expect_error(kHead + R"(, "horizn": [[0, 1], [2, 3]]})", {"/horizn", "did you mean \"horizon\""});
  expect_error(kHead + R"(, "planes": [{"polygon": [[0,0],[1,0],[1,1]], "colour": 1}]})",
               {"/planes/0/colour", "unknown key"});
}

TEST(Annotations, ValueErrorsNameThePointer) {
  expect_error(kHead + R"(, "horizon": [[0, 1], [2, null]]})",
               {"/horizon/1/1", "expected a number", "null"});
  expect_error(kHead + R"(, "horizon": [[0, 1]]})", {"/horizon", "two points"});
  expect_error(kHead + R"(, "horizon": [[5, 5], [5.5, 5.5]]})", {"/horizon", "less than 1 pixel"});
  expect_error(kHead + R"(, "camera_height_m": -1.6})", {"/camera_height_m", "> 0"});
  expect_error(kHead + R"(, "camera_height_m": 0})", {"/camera_height_m", "> 0"});
  expect_error(kHead + R"(, "camera_height_m": "1.6"})", {"/camera_height_m", "a string"});
  expect_error(kHead + R"(, "planes": [{"polygon": [[0, 0], [1, 1]]}]})",
               {"/planes/0/polygon", "at least 3 points", "found 2"});
  expect_error(kHead + R"(, "planes": [{"base": [[0, 0], [1, 1]]}]})",
               {"/planes/0/polygon", "missing"});
  expect_error(
      kHead + R"(, "distance_hints": [{"polygon": [[0,0],[1,0],[1,1]], "distance_m": -5}]})",
      {"/distance_hints/0/distance_m", "> 0"});
  expect_error(kHead + R"(, "camera_height_m": 1.6,
                "known_length": {"a": [0, 0], "b": [9, 9], "length_m": 2}})",
               {"/known_length", "not both"});
  expect_error(kHead + R"(, "known_length": {"a": [0, 0], "b": [9, 9]}})",
               {"/known_length/length_m", "missing"});
  expect_error(kHead + R"(, "shadow_pairs": [{"caster_top": [0, 0], "caster_foot": [0, 5]}]})",
               {"/shadow_pairs/0/shadow_tip", "missing"});
  expect_error(kHead + R"(, "sunlit_patch": [[0,0],[1,0],[1,1]]})", {"/shadowed_patch", "missing"});
}

TEST(Annotations, ValidateRejectsNonFiniteValues) {
  Annotations a = full();
  a.planes[1].polygon[2][1] = std::numeric_limits<double>::quiet_NaN();
  try {
    validate_annotations(a, "gui");
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::invalid_argument);
    EXPECT_NE(std::string(e.what()).find("gui: /planes/1/polygon/2/1"), std::string::npos)
        << e.what();
  }
  EXPECT_THROW(annotations_to_json(a), Error);  // never writes what it could not read back
  Annotations b;
  b.camera_height_m = std::numeric_limits<double>::infinity();
  EXPECT_THROW(validate_annotations(b), Error);
}

// The interior box (optional, added to version 1): parsed, round-tripped, errors by pointer.
TEST(Annotations, InteriorBox) {
  const Annotations a = annotations_from_json(kHead + R"(, "camera_height_m": 1.5,
    "interior_box": {"floor": [[10, 400], [200, 300.5], [500, 310], [630, 420]],
                     "ceiling_point": [300, 40]}})");
  ASSERT_TRUE(a.interior_box);
  EXPECT_EQ(a.interior_box->floor.size(), 4u);
  EXPECT_EQ(a.interior_box->floor[1], (PixelPoint{200, 300.5}));
  EXPECT_FALSE(a.interior_box->ceiling_height_m);
  EXPECT_EQ(a.interior_box->ceiling_point, (PixelPoint{300, 40}));
  Annotations b = full();
  b.interior_box = Annotations::InteriorBox{{{1, 2}, {3.25, 4}, {5, 6.5}}, 2.7, std::nullopt};
  const Annotations c = annotations_from_json(annotations_to_json(b));
  ASSERT_TRUE(c.interior_box);
  EXPECT_EQ(c.interior_box->floor, b.interior_box->floor);
  EXPECT_EQ(c.interior_box->ceiling_height_m, 2.7);
  EXPECT_FALSE(c.interior_box->ceiling_point);
  expect_error(kHead + R"(, "interior_box": {"floor": [[0, 0], [9, 9]]}})",
               {"/interior_box/floor", "at least 3 points", "found 2"});
  expect_error(kHead + R"(, "interior_box": {"ceiling_height_m": 2.5}})",
               {"/interior_box/floor", "missing"});
  expect_error(
      kHead + R"(, "interior_box": {"floor": [[0, 0], [9, 9], [20, 0]], "ceiling_height_m": 0}})",
      {"/interior_box/ceiling_height_m", "> 0"});
  expect_error(
      kHead + R"(, "interior_box": {"floor": [[0, 0], [9, 9], [20, 0]], "ceiling_point": [1]}})",
      {"/interior_box/ceiling_point", "a point"});
  expect_error(kHead + R"(, "interior_box": {"floor": [[0, 0], [9, 9], [20, 0]], "walls": 3}})",
               {"/interior_box/walls", "unknown key"});
  expect_error(kHead + R"(, "interior_box": {"floor": [[0, 0], [0.5, 0.5], [20, 0]]}})",
               {"/interior_box/floor/1", "less than 1 pixel"});
  expect_error(kHead + R"(, "interior_box": {"floor": [[0, 0], [9, null], [20, 0]]}})",
               {"/interior_box/floor/1/1", "expected a number"});
  expect_error(
      kHead + R"(, "camera_height_m": 1.5, "interior_box": {"floor": [[0, 0], [9, 9], [20, 0]],
                "ceiling_height_m": 2.5, "ceiling_point": [5, 1]}})",
      {"/interior_box/ceiling_height_m", "fixes the camera height"});
}

}  // namespace
}  // namespace mr
