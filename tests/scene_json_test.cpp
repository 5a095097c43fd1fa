// The JSON scene document (docs/scene.md) and validate_scene: exact round trips, defaults,
// and one-line errors that name the source, the JSON path (or C++ field) and what was found.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <functional>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "mr/error.h"
#include "mr/scattering.h"
#include "mr/scene.h"
#include "mr/scene_json.h"
#include "test_support.h"

namespace mr {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kNan = std::numeric_limits<double>::quiet_NaN();

// ---- field-by-field equality (the structs have no operator==) ----

void expect_eq(const Vec3& a, const Vec3& b, const std::string& what) {
  EXPECT_EQ(a.x, b.x) << what;
  EXPECT_EQ(a.y, b.y) << what;
  EXPECT_EQ(a.z, b.z) << what;
}

void expect_eq(const Rgb& a, const Rgb& b, const std::string& what) {
  for (int i = 0; i < 3; ++i) EXPECT_EQ(a[i], b[i]) << what << "[" << i << "]";
}

void expect_scene_eq(const FogScene& a, const FogScene& b) {
  expect_eq(a.pose.position_m, b.pose.position_m, "pose.position_m");
  EXPECT_EQ(a.pose.yaw_deg, b.pose.yaw_deg);
  EXPECT_EQ(a.pose.pitch_deg, b.pose.pitch_deg);
  EXPECT_EQ(a.pose.roll_deg, b.pose.roll_deg);

  expect_eq(a.medium.sigma_t_per_m, b.medium.sigma_t_per_m, "medium.sigma_t_per_m");
  expect_eq(a.medium.albedo, b.medium.albedo, "medium.albedo");
  EXPECT_EQ(a.medium.g, b.medium.g);
  ASSERT_EQ(a.medium.height_fog.has_value(), b.medium.height_fog.has_value());
  if (a.medium.height_fog) {
    EXPECT_EQ(a.medium.height_fog->base_height_m, b.medium.height_fog->base_height_m);
    EXPECT_EQ(a.medium.height_fog->scale_height_m, b.medium.height_fog->scale_height_m);
  }
  EXPECT_EQ(a.medium.layer_bottom_m, b.medium.layer_bottom_m);
  EXPECT_EQ(a.medium.layer_top_m, b.medium.layer_top_m);
  EXPECT_EQ(a.medium.noise.amplitude, b.medium.noise.amplitude);
  EXPECT_EQ(a.medium.noise.scale_m, b.medium.noise.scale_m);
  EXPECT_EQ(a.medium.noise.octaves, b.medium.noise.octaves);
  EXPECT_EQ(a.medium.noise.seed, b.medium.noise.seed);

  ASSERT_EQ(a.lighting.sun.has_value(), b.lighting.sun.has_value());
  if (a.lighting.sun) {
    expect_eq(a.lighting.sun->direction_to_sun, b.lighting.sun->direction_to_sun, "sun.direction");
    expect_eq(a.lighting.sun->irradiance, b.lighting.sun->irradiance, "sun.irradiance");
    EXPECT_EQ(a.lighting.sun->irradiance_auto, b.lighting.sun->irradiance_auto);
    EXPECT_EQ(a.lighting.sun->angular_radius_deg, b.lighting.sun->angular_radius_deg);
  }
  ASSERT_EQ(a.lighting.sky_radiance.has_value(), b.lighting.sky_radiance.has_value());
  if (a.lighting.sky_radiance)
    expect_eq(*a.lighting.sky_radiance, *b.lighting.sky_radiance, "lighting.sky_radiance");
  ASSERT_EQ(a.lighting.lamps.size(), b.lighting.lamps.size());
  for (std::size_t i = 0; i < a.lighting.lamps.size(); ++i) {
    const Lamp& la = a.lighting.lamps[i];
    const Lamp& lb = b.lighting.lamps[i];
    const std::string p = "lamps[" + std::to_string(i) + "]";
    expect_eq(la.position_m, lb.position_m, p + ".position_m");
    expect_eq(la.intensity_per_sr, lb.intensity_per_sr, p + ".intensity_per_sr");
    expect_eq(la.spot_direction, lb.spot_direction, p + ".spot_direction");
    EXPECT_EQ(la.inner_angle_deg, lb.inner_angle_deg) << p;
    EXPECT_EQ(la.outer_angle_deg, lb.outer_angle_deg) << p;
  }

  EXPECT_EQ(a.render.quality, b.render.quality);
  EXPECT_EQ(a.render.backend, b.render.backend);
  EXPECT_EQ(a.render.march_steps, b.render.march_steps);
  EXPECT_EQ(a.render.grid_step, b.render.grid_step);
  EXPECT_EQ(a.render.gradient_acceleration, b.render.gradient_acceleration);
  EXPECT_EQ(a.render.volumetric_shadows, b.render.volumetric_shadows);
  EXPECT_EQ(a.render.light_path_attenuation, b.render.light_path_attenuation);
  EXPECT_EQ(a.render.max_distance_m, b.render.max_distance_m);
  EXPECT_EQ(a.render.seed, b.render.seed);
  EXPECT_EQ(a.render.threads, b.render.threads);
  EXPECT_EQ(a.render.shadow_traversal, b.render.shadow_traversal);

  ASSERT_EQ(a.camera.has_value(), b.camera.has_value());
  if (a.camera) {
    EXPECT_EQ(a.camera->width, b.camera->width);
    EXPECT_EQ(a.camera->height, b.camera->height);
    EXPECT_EQ(a.camera->focal_px, b.camera->focal_px);
    EXPECT_EQ(a.camera->principal_point_px, b.camera->principal_point_px);
  }
}

// A scene with every field away from its default, with values that have no short decimal
// form (1/3, 0.1f) so that the round trip must be bit-exact, not merely close.
FogScene every_field_set() {
  FogScene s;
  s.pose.position_m = {1.0 / 3.0, 12.75, -0.1};
  s.pose.yaw_deg = -37.123456789012345;
  s.pose.pitch_deg = 4.5e-7;
  s.pose.roll_deg = -179.99999999999997;
  s.medium.sigma_t_per_m = {0.1f, 1.0f / 3.0f, 9999.9f};
  s.medium.albedo = {0.9f, 0.95f, 1e-30f};
  s.medium.g = -0.7654321;
  s.medium.height_fog = Medium::HeightFog{-3.25, 0.001};
  s.medium.layer_bottom_m = -12.5;
  s.medium.layer_top_m = 1e6;
  s.medium.noise = {0.35, 7.7, 8, 4294967295u};
  Sun sun;
  sun.direction_to_sun = {0.3, 0.2, -0.9};
  sun.irradiance = {5.5f, 4.25f, 3.125e-3f};
  sun.angular_radius_deg = 5;
  s.lighting.sun = sun;
  s.lighting.sky_radiance = Rgb{0.3f, 0.35f, 0.41f};
  Lamp a;
  a.position_m = {-4, 5.5, 20.000000000000004};
  a.intensity_per_sr = {250, 200, 1e-7f};
  a.spot_direction = {0, -1, 0.25};
  a.inner_angle_deg = 20;
  a.outer_angle_deg = 35.5;
  Lamp b;
  b.position_m = {6, 4, 30};
  b.intensity_per_sr = {0, 0, 0};
  b.spot_direction = {1e-3, 0, 0};
  b.inner_angle_deg = 0;
  b.outer_angle_deg = 1e-9;
  s.lighting.lamps = {a, b};
  s.camera = SceneCamera{4032, 3024, 3123.4567890123457, std::array<double, 2>{2016.1 / 3, 1511.5}};
  s.render.quality = Quality::final;
  s.render.backend = Backend::cpu;
  s.render.march_steps = 4096;
  s.render.grid_step = 3;
  s.render.gradient_acceleration = false;
  s.render.volumetric_shadows = false;
  s.render.light_path_attenuation = false;
  s.render.max_distance_m = 123456.789;
  s.render.seed = 0;
  s.render.threads = 7;
  s.render.shadow_traversal = ShadowTraversal::multi_index;
  return s;
}

// The message of the mr::Error that `f` throws ("" and a test failure when it does not).
std::string error_of(const std::function<void()>& f,
                     ErrorCode expected_code = ErrorCode::invalid_argument) {
  try {
    f();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), expected_code) << e.what();
    const std::string what = e.what();
    EXPECT_EQ(what.find('\n'), std::string::npos) << "not one line: " << what;
    return what;
  } catch (const std::exception& e) {
    ADD_FAILURE() << "not an mr::Error: " << e.what();
    return "";
  }
  ADD_FAILURE() << "no error thrown";
  return "";
}

std::string parse_error(const std::string& text) {
  return error_of([&] { scene_from_json(text, "scene.json"); });
}

// A minimal document with `body` added to it (body: members to append, e.g. "\"medium\": {}").
std::string doc(const std::string& body) {
  return std::string("{\"format\": \"libmr-scene\", \"version\": 1") +
         (body.empty() ? "" : ", " + body) + "}";
}

#define EXPECT_CONTAINS(haystack, needle)                               \
  do {                                                                  \
    const std::string h_ = (haystack);                                  \
    EXPECT_NE(h_.find(needle), std::string::npos) << "message: " << h_; \
  } while (0)

// ---- round trips and defaults ----

TEST(SceneJson, RoundTripOfEveryFieldIsExact) {
  const FogScene s = every_field_set();
  const std::string text = scene_to_json(s);
  const FogScene back = scene_from_json(text, "roundtrip.json");
  expect_scene_eq(s, back);
  // Writing again gives the same bytes: the document is a fixed point.
  EXPECT_EQ(scene_to_json(back), text);
}

// Many random valid scenes: every float and double, whatever its digits, reads back bit for
// bit (this exercises the short float spelling, whose double rounding can miss in rare cases).
TEST(SceneJson, RandomScenesRoundTripExactly) {
  std::mt19937_64 rng(42);
  auto uniform = [&rng](double lo, double hi) {
    return std::uniform_real_distribution<double>(lo, hi)(rng);
  };
  // Log-uniform over many decades, so that tiny and huge magnitudes both occur.
  auto magnitude = [&](double lo_exp, double hi_exp) {
    return std::pow(10.0, uniform(lo_exp, hi_exp));
  };
  auto colour = [&](double lo_exp, double hi_exp) {
    return Rgb{static_cast<float>(magnitude(lo_exp, hi_exp)),
               static_cast<float>(magnitude(lo_exp, hi_exp)),
               static_cast<float>(magnitude(lo_exp, hi_exp))};
  };
  auto vec = [&] { return Vec3{uniform(-1e4, 1e4), uniform(-1, 1), magnitude(-300, 150)}; };
  for (int i = 0; i < 2000; ++i) {
    FogScene s;
    s.pose.position_m = vec();
    s.pose.yaw_deg = uniform(-720, 720);
    s.pose.pitch_deg = uniform(-90, 90);
    s.pose.roll_deg = uniform(-180, 180);
    s.medium.sigma_t_per_m = colour(-30, 4);
    s.medium.albedo = colour(-40, 0);
    s.medium.g = uniform(-0.999, 0.999);
    s.medium.height_fog = Medium::HeightFog{uniform(-100, 100), magnitude(-3, 5)};
    s.medium.layer_bottom_m = uniform(-1e3, 0);
    s.medium.layer_top_m = magnitude(-5, 8);
    s.medium.noise = {uniform(0, 1), magnitude(-2, 3), 1 + static_cast<int>(rng() % 8),
                      static_cast<std::uint32_t>(rng())};
    s.lighting.sun = Sun{vec(), colour(-10, 10), uniform(0, 5)};
    s.lighting.sky_radiance = colour(-20, 20);
    s.lighting.lamps.resize(rng() % 4);
    for (Lamp& l : s.lighting.lamps) {
      l.position_m = vec();
      l.intensity_per_sr = colour(-38, 38);
      l.spot_direction = vec();
      l.outer_angle_deg = uniform(1e-6, 180);
      l.inner_angle_deg = uniform(0, l.outer_angle_deg);
    }
    s.render.max_distance_m = magnitude(-3, 5);
    s.render.seed = static_cast<std::uint32_t>(rng());
    const std::string text = scene_to_json(s);
    const FogScene back = scene_from_json(text, "random.json");
    expect_scene_eq(s, back);
    if (::testing::Test::HasFailure()) {
      ADD_FAILURE() << "scene " << i << ":\n" << text;
      break;
    }
  }
}

TEST(SceneJson, RoundTripOfDefaultsAndUnboundedLayer) {
  FogScene s;
  const std::string text = scene_to_json(s);
  expect_scene_eq(s, scene_from_json(text, "defaults.json"));
  EXPECT_CONTAINS(text, "\"layer_bottom_m\": null");
  EXPECT_CONTAINS(text, "\"sky_radiance\": \"auto\"");
  EXPECT_CONTAINS(text, "\"sun\": null");
  EXPECT_CONTAINS(text, "\"height_fog\": null");
}

TEST(SceneJson, WritesEveryKeyPrettyAndReadably) {
  const std::string text = scene_to_json(every_field_set());
  EXPECT_EQ(text.rfind("{\n  \"format\": \"libmr-scene\",\n  \"version\": 5,\n", 0), 0u) << text;
  for (const char* key : {"camera_pose",
                          "position_m",
                          "yaw_deg",
                          "pitch_deg",
                          "roll_deg",
                          "medium",
                          "sigma_t_per_m",
                          "albedo",
                          "\"g\"",
                          "height_fog",
                          "base_height_m",
                          "scale_height_m",
                          "layer_bottom_m",
                          "layer_top_m",
                          "noise",
                          "amplitude",
                          "scale_m",
                          "octaves",
                          "seed",
                          "lighting",
                          "sun",
                          "direction_to_sun",
                          "irradiance",
                          "angular_radius_deg",
                          "sky_radiance",
                          "lamps",
                          "intensity_per_sr",
                          "spot_direction",
                          "inner_angle_deg",
                          "outer_angle_deg",
                          "render",
                          "quality",
                          "backend",
                          "march_steps",
                          "grid_step",
                          "gradient_acceleration",
                          "volumetric_shadows",
                          "light_path_attenuation",
                          "max_distance_m",
                          "threads",
                          "shadow_traversal",
                          "camera",
                          "width",
                          "height",
                          "focal_px",
                          "principal_point_px"})
    EXPECT_CONTAINS(text, key);
  // Vectors and colours on one line; floats in their short form.
  EXPECT_CONTAINS(text, "\"sigma_t_per_m\": [0.1, 0.33333334, 9999.9]");
  EXPECT_CONTAINS(text, "\"quality\": \"final\"");
  EXPECT_CONTAINS(text, "\"backend\": \"cpu\"");
}

TEST(SceneJson, MinimalDocumentGivesDefaults) {
  expect_scene_eq(scene_from_json("{\"format\": \"libmr-scene\", \"version\": 1}", "min.json"),
                  FogScene{});
  // Empty sections, a sun object with no keys and a lamp with no keys take defaults too.
  const FogScene s =
      scene_from_json(doc("\"camera_pose\": {}, \"medium\": {\"height_fog\": {}, \"noise\": {}}, "
                          "\"lighting\": {\"sun\": {}, \"lamps\": [{}]}, \"render\": {}"),
                      "sections.json");
  ASSERT_TRUE(s.medium.height_fog);
  EXPECT_EQ(s.medium.height_fog->scale_height_m, Medium::HeightFog{}.scale_height_m);
  ASSERT_TRUE(s.lighting.sun);
  expect_eq(s.lighting.sun->direction_to_sun, Sun{}.direction_to_sun, "sun");
  ASSERT_EQ(s.lighting.lamps.size(), 1u);
  expect_eq(s.lighting.lamps[0].intensity_per_sr, Lamp{}.intensity_per_sr, "lamp");
  EXPECT_EQ(s.lighting.lamps[0].outer_angle_deg, 180);
}

// The versioning policy (docs/scene.md) makes the defaults part of format version 1: a
// minimal document must keep rendering the same. If this fails because a default in
// mr/scene.h changed, bump kSceneFormatVersion and read version-1 documents with these values.
TEST(SceneJson, Version1DefaultsArePinned) {
  const FogScene s = scene_from_json("{\"format\": \"libmr-scene\", \"version\": 1}", "min.json");
  expect_eq(s.pose.position_m, {0, 1.6, 0}, "pose.position_m");
  EXPECT_EQ(s.pose.yaw_deg, 0);
  EXPECT_EQ(s.pose.pitch_deg, 0);
  EXPECT_EQ(s.pose.roll_deg, 0);
  expect_eq(s.medium.sigma_t_per_m, {0.0261f, 0.0261f, 0.0261f}, "sigma_t_per_m");
  expect_eq(s.medium.albedo, {1, 1, 1}, "albedo");
  EXPECT_EQ(s.medium.g, 0);
  EXPECT_FALSE(s.medium.height_fog);
  EXPECT_EQ(s.medium.layer_bottom_m, -kInf);
  EXPECT_EQ(s.medium.layer_top_m, kInf);
  EXPECT_EQ(s.medium.noise.amplitude, 0);
  EXPECT_EQ(s.medium.noise.scale_m, 10);
  EXPECT_EQ(s.medium.noise.octaves, 4);
  EXPECT_EQ(s.medium.noise.seed, 1u);
  EXPECT_FALSE(s.lighting.sun);
  EXPECT_FALSE(s.lighting.sky_radiance);
  EXPECT_TRUE(s.lighting.lamps.empty());
  EXPECT_EQ(s.render.quality, Quality::normal);
  EXPECT_EQ(s.render.backend, Backend::automatic);
  EXPECT_EQ(s.render.march_steps, 0);
  EXPECT_EQ(s.render.grid_step, 0);
  EXPECT_TRUE(s.render.gradient_acceleration);
  EXPECT_TRUE(s.render.volumetric_shadows);
  EXPECT_TRUE(s.render.light_path_attenuation);
  EXPECT_EQ(s.render.max_distance_m, 0);
  EXPECT_EQ(s.render.seed, 1u);
  EXPECT_EQ(s.render.threads, 0);
  EXPECT_EQ(s.render.shadow_traversal, ShadowTraversal::embree);
  // Defaults of the optional parts, taken when their object is given empty.
  const FogScene t = scene_from_json(
      doc("\"medium\": {\"height_fog\": {}}, \"lighting\": {\"sun\": {}, \"lamps\": [{}]}"), "t");
  EXPECT_EQ(t.medium.height_fog->base_height_m, 0);
  EXPECT_EQ(t.medium.height_fog->scale_height_m, 20);
  expect_eq(t.lighting.sun->direction_to_sun, {0, 1, 0}, "direction_to_sun");
  expect_eq(t.lighting.sun->irradiance, {3, 3, 3}, "irradiance");
  // No irradiance: relative to the photo's exposure (issue 11 item 5); "auto" says the same and
  // is what a scene with an automatic sun is written with.
  EXPECT_TRUE(t.lighting.sun->irradiance_auto);
  const FogScene u = scene_from_json(doc("\"lighting\": {\"sun\": {\"irradiance\": \"auto\"}}"), "u");
  EXPECT_TRUE(u.lighting.sun->irradiance_auto);
  EXPECT_TRUE(scene_from_json(scene_to_json(u), "u2").lighting.sun->irradiance_auto);
  const FogScene v = scene_from_json(doc("\"lighting\": {\"sun\": {\"irradiance\": 2}}"), "v");
  EXPECT_FALSE(v.lighting.sun->irradiance_auto);
  EXPECT_EQ(t.lighting.sun->angular_radius_deg, 0.27);
  const Lamp& lamp = t.lighting.lamps.at(0);
  expect_eq(lamp.position_m, {0, 0, 0}, "lamp.position_m");
  expect_eq(lamp.intensity_per_sr, {100, 90, 70}, "lamp.intensity_per_sr");
  expect_eq(lamp.spot_direction, {0, -1, 0}, "lamp.spot_direction");
  EXPECT_EQ(lamp.inner_angle_deg, 180);
  EXPECT_EQ(lamp.outer_angle_deg, 180);
}

// Every ```json block of the format's documentation is a valid scene.
TEST(SceneJson, DocumentationExamplesParse) {
  const std::string md =
      test::read_bytes(std::filesystem::path(MR_SOURCE_DIR) / "docs" / "scene.md");
  ASSERT_FALSE(md.empty());
  int examples = 0;
  for (std::size_t at = md.find("```json\n"); at != std::string::npos;
       at = md.find("```json\n", at + 1)) {
    const std::size_t begin = at + 8;
    const std::size_t end = md.find("\n```", begin);
    ASSERT_NE(end, std::string::npos);
    const FogScene s = scene_from_json(md.substr(begin, end - begin + 1), "docs/scene.md");
    ++examples;
    // The valley example: two lamps, a low sun ahead, height fog from visibility.
    ASSERT_EQ(s.lighting.lamps.size(), 2u);
    ASSERT_TRUE(s.lighting.sun);
    EXPECT_NEAR(s.lighting.sun->direction_to_sun.y, std::sin(3 * M_PI / 180), 1e-12);
    ASSERT_TRUE(s.medium.height_fog);
    EXPECT_FLOAT_EQ(s.medium.sigma_t_per_m[0], 3.912f / 80);
  }
  EXPECT_EQ(examples, 1);
}

TEST(SceneJson, ColoursAcceptOneNumber) {
  const FogScene s = scene_from_json(
      doc("\"medium\": {\"sigma_t_per_m\": 0.02, \"albedo\": 0.9}, "
          "\"lighting\": {\"sky_radiance\": 0.5, \"lamps\": [{\"intensity_per_sr\": 40}]}"),
      "grey.json");
  expect_eq(s.medium.sigma_t_per_m, {0.02f, 0.02f, 0.02f}, "sigma_t");
  expect_eq(s.medium.albedo, {0.9f, 0.9f, 0.9f}, "albedo");
  ASSERT_TRUE(s.lighting.sky_radiance);
  expect_eq(*s.lighting.sky_radiance, {0.5f, 0.5f, 0.5f}, "sky");
  expect_eq(s.lighting.lamps[0].intensity_per_sr, {40, 40, 40}, "lamp");
}

TEST(SceneJson, SkyRadianceAutoOrNullIsEstimated) {
  EXPECT_FALSE(scene_from_json(doc("\"lighting\": {\"sky_radiance\": \"auto\"}"), "a")
                   .lighting.sky_radiance);
  EXPECT_FALSE(
      scene_from_json(doc("\"lighting\": {\"sky_radiance\": null}"), "a").lighting.sky_radiance);
  EXPECT_CONTAINS(parse_error(doc("\"lighting\": {\"sky_radiance\": \"bright\"}")),
                  "scene.json: /lighting/sky_radiance: expected \"auto\"");
}

TEST(SceneJson, LayerBoundsNullMeansUnbounded) {
  const FogScene s = scene_from_json(
      doc("\"medium\": {\"layer_bottom_m\": null, \"layer_top_m\": 80}"), "layer.json");
  EXPECT_EQ(s.medium.layer_bottom_m, -kInf);
  EXPECT_EQ(s.medium.layer_top_m, 80);
  const FogScene t = scene_from_json(doc("\"medium\": {\"layer_top_m\": null}"), "layer.json");
  EXPECT_EQ(t.medium.layer_top_m, kInf);
}

TEST(SceneJson, VisibilityMapsToKoschmiederExtinction) {
  const FogScene s = scene_from_json(doc("\"medium\": {\"visibility_m\": 120}"), "vis.json");
  for (float c : s.medium.sigma_t_per_m) EXPECT_FLOAT_EQ(c, static_cast<float>(3.912 / 120));
  const FogScene rgb =
      scene_from_json(doc("\"medium\": {\"visibility_m\": [100, 200, 400]}"), "vis.json");
  EXPECT_FLOAT_EQ(rgb.medium.sigma_t_per_m[0], 3.912f / 100);
  EXPECT_FLOAT_EQ(rgb.medium.sigma_t_per_m[1], 3.912f / 200);
  EXPECT_FLOAT_EQ(rgb.medium.sigma_t_per_m[2], 3.912f / 400);
  // Both at once is ambiguous; zero visibility is meaningless.
  EXPECT_CONTAINS(parse_error(doc("\"medium\": {\"visibility_m\": 100, \"sigma_t_per_m\": 0.1}")),
                  "scene.json: /medium: give either sigma_t_per_m or visibility_m");
  EXPECT_CONTAINS(parse_error(doc("\"medium\": {\"visibility_m\": 0}")),
                  "scene.json: /medium/visibility_m: visibility must be > 0");
  EXPECT_CONTAINS(parse_error(doc("\"medium\": {\"visibility_m\": [100, -1, 5]}")),
                  "scene.json: /medium/visibility_m/1:");
  // So short that sigma_t is beyond the validated range: the error points at visibility_m.
  EXPECT_CONTAINS(parse_error(doc("\"medium\": {\"visibility_m\": 1e-4}")),
                  "scene.json: /medium/visibility_m: medium.sigma_t_per_m[0] = ");
}

TEST(SceneJson, SunFromAzimuthAndElevation) {
  const FogScene s = scene_from_json(
      doc("\"lighting\": {\"sun\": {\"azimuth_deg\": 90, \"elevation_deg\": 30}}"), "sun.json");
  ASSERT_TRUE(s.lighting.sun);
  const Vec3 expected = direction_from_azimuth_elevation(90, 30);
  expect_eq(s.lighting.sun->direction_to_sun, expected, "direction_to_sun");
  EXPECT_NEAR(s.lighting.sun->direction_to_sun.x, std::cos(30 * M_PI / 180), 1e-12);
  EXPECT_NEAR(s.lighting.sun->direction_to_sun.y, 0.5, 1e-12);
  EXPECT_NEAR(s.lighting.sun->direction_to_sun.z, 0, 1e-12);
  EXPECT_CONTAINS(
      parse_error(doc("\"lighting\": {\"sun\": {\"azimuth_deg\": 90, \"elevation_deg\": 30, "
                      "\"direction_to_sun\": [0, 1, 0]}}")),
      "scene.json: /lighting/sun: give either direction_to_sun or azimuth_deg + elevation_deg");
  EXPECT_CONTAINS(parse_error(doc("\"lighting\": {\"sun\": {\"azimuth_deg\": 90}}")),
                  "scene.json: /lighting/sun: azimuth_deg needs elevation_deg");
  EXPECT_CONTAINS(
      parse_error(doc("\"lighting\": {\"sun\": {\"azimuth_deg\": 0, \"elevation_deg\": 95}}")),
      "scene.json: /lighting/sun/elevation_deg: 95: must be in [-90, 90]");
}

// ---- bad input: every error names the source and the JSON path ----

TEST(SceneJson, UnknownKeyIsAnErrorNamingItsPath) {
  EXPECT_CONTAINS(parse_error(doc("\"medium\": {\"albdo\": 0.5}")),
                  "scene.json: /medium/albdo: unknown key; did you mean \"albedo\"?");
  EXPECT_CONTAINS(parse_error(doc("\"lighting\": {\"lamps\": [{}, {\"brightness\": 1}]}")),
                  "scene.json: /lighting/lamps/1/brightness: unknown key; expected one of:");
  // A lamp has a "color" (with intensity "auto"): the British spelling is a near miss.
  EXPECT_CONTAINS(parse_error(doc("\"lighting\": {\"lamps\": [{}, {\"colour\": 1}]}")),
                  "scene.json: /lighting/lamps/1/colour: unknown key; did you mean \"color\"?");
  EXPECT_CONTAINS(parse_error(doc("\"mediums\": {}")), "scene.json: /mediums: unknown key");
  // A key holding an escaped newline or a '/' is shown escaped: the message stays one line
  // and the pointer stays a valid RFC 6901 pointer.
  EXPECT_CONTAINS(parse_error(doc("\"medium\": {\"al\\nbedo\": 1}")),
                  "scene.json: /medium/al\\u000abedo: unknown key");
  EXPECT_CONTAINS(parse_error(doc("\"medium\": {\"a/b~c\": 1}")),
                  "scene.json: /medium/a~1b~0c: unknown key");
  EXPECT_CONTAINS(parse_error(doc("\"render\": {\"Quality\": \"final\"}")),
                  "/render/Quality: unknown key; did you mean \"quality\"?");
}

TEST(SceneJson, WrongTypeNamesPathAndWhatWasFound) {
  EXPECT_CONTAINS(
      parse_error(doc("\"lighting\": {\"lamps\": [{}, {\"position_m\": \"up there\"}]}")),
      "scene.json: /lighting/lamps/1/position_m: expected an array of 3 numbers, found a string");
  EXPECT_CONTAINS(parse_error(doc("\"medium\": {\"g\": \"0.5\"}")),
                  "scene.json: /medium/g: expected a number, found a string (\"0.5\")");
  EXPECT_CONTAINS(
      parse_error(doc("\"render\": {\"volumetric_shadows\": 1}")),
      "scene.json: /render/volumetric_shadows: expected true or false, found a number (1)");
  EXPECT_CONTAINS(parse_error(doc("\"render\": {\"march_steps\": 12.5}")),
                  "scene.json: /render/march_steps: expected an integer");
  EXPECT_CONTAINS(
      parse_error(doc("\"lighting\": {\"lamps\": {}}")),
      "scene.json: /lighting/lamps: expected an array of lamp objects, found an object");
  EXPECT_CONTAINS(parse_error(doc("\"camera_pose\": [1, 2, 3]")),
                  "scene.json: /camera_pose: expected an object, found an array of 3 elements");
  EXPECT_CONTAINS(parse_error("[1, 2]"), "scene.json: expected a JSON object at the top level");
  EXPECT_CONTAINS(parse_error(doc("\"medium\": {\"noise\": {\"seed\": -1}}")),
                  "scene.json: /medium/noise/seed: expected an integer from 0 to 4294967295");
}

TEST(SceneJson, ArrayOfWrongLength) {
  EXPECT_CONTAINS(parse_error(doc("\"camera_pose\": {\"position_m\": [1, 2]}")),
                  "scene.json: /camera_pose/position_m: expected an array of 3 numbers, found an "
                  "array of 2 elements");
  EXPECT_CONTAINS(parse_error(doc("\"medium\": {\"albedo\": [1, 1, 1, 1]}")),
                  "scene.json: /medium/albedo: expected a number or an array of 3 numbers");
  EXPECT_CONTAINS(parse_error(doc("\"lighting\": {\"sun\": {\"irradiance\": [1, \"2\", 3]}}")),
                  "scene.json: /lighting/sun/irradiance/1: expected a number, found a string");
}

TEST(SceneJson, NullWhereANumberIsRequired) {
  // JSON has no NaN; null is the nearest thing a writer produces for one.
  EXPECT_CONTAINS(parse_error(doc("\"medium\": {\"g\": null}")),
                  "scene.json: /medium/g: expected a number, found null");
  EXPECT_CONTAINS(
      parse_error(doc("\"lighting\": {\"lamps\": [{}, {}, {\"position_m\": [0, null, 0]}]}")),
      "scene.json: /lighting/lamps/2/position_m/1: expected a number, found null");
  EXPECT_CONTAINS(parse_error(doc("\"camera_pose\": {\"yaw_deg\": 1e999}")),
                  "scene.json: /camera_pose/yaw_deg: number overflow");
}

TEST(SceneJson, OutOfRangeValuesNameJsonPathAndField) {
  EXPECT_CONTAINS(parse_error(doc("\"medium\": {\"sigma_t_per_m\": [0.01, -0.5, 0.01]}")),
                  "scene.json: /medium/sigma_t_per_m/1: medium.sigma_t_per_m[1] = -0.5: must be in "
                  "[0, 10000]");
  EXPECT_CONTAINS(parse_error(doc("\"medium\": {\"sigma_t_per_m\": -0.5}")),
                  "scene.json: /medium/sigma_t_per_m: medium.sigma_t_per_m[0] = -0.5");
  EXPECT_CONTAINS(parse_error(doc("\"medium\": {\"g\": 1}")),
                  "scene.json: /medium/g: medium.g = 1: must be in (-1, 1)");
  EXPECT_CONTAINS(parse_error(doc("\"medium\": {\"g\": -1.5}")),
                  "scene.json: /medium/g: medium.g = -1.5: must be in (-1, 1)");
  EXPECT_CONTAINS(
      parse_error(doc("\"lighting\": {\"lamps\": [{\"inner_angle_deg\": 40, \"outer_angle_deg\": "
                      "30}]}")),
      "scene.json: /lighting/lamps/0/inner_angle_deg: lighting.lamps[0].inner_angle_deg = 40: must "
      "be in [0, outer_angle_deg = 30]");
  EXPECT_CONTAINS(
      parse_error(doc("\"camera_pose\": {\"position_m\": [0, 0, 0], \"pitch_deg\": 91}")),
      "scene.json: /camera_pose/pitch_deg: pose.pitch_deg = 91");
  EXPECT_CONTAINS(parse_error(doc("\"medium\": {\"layer_bottom_m\": 50, \"layer_top_m\": 10}")),
                  "scene.json: /medium/layer_bottom_m: medium.layer_bottom_m = 50: must be < "
                  "medium.layer_top_m = 10");
  EXPECT_CONTAINS(parse_error(doc("\"render\": {\"march_steps\": 5000}")),
                  "scene.json: /render/march_steps: render.march_steps = 5000");
  EXPECT_CONTAINS(parse_error(doc("\"lighting\": {\"sun\": {\"direction_to_sun\": [0, 0, 0]}}")),
                  "scene.json: /lighting/sun/direction_to_sun: lighting.sun.direction_to_sun = (0, "
                  "0, 0): must have a non-zero length");
}

TEST(SceneJson, BadEnumStrings) {
  EXPECT_CONTAINS(parse_error(doc("\"render\": {\"quality\": \"ultra\"}")),
                  "scene.json: /render/quality: expected one of \"draft\", \"normal\", \"final\", "
                  "found a string (\"ultra\")");
  EXPECT_CONTAINS(parse_error(doc("\"render\": {\"backend\": \"opengl\"}")),
                  "scene.json: /render/backend: expected one of \"auto\", \"cpu\", \"vulkan\"");
  const FogScene s =
      scene_from_json(doc("\"render\": {\"quality\": \"draft\", \"backend\": \"auto\"}"), "q");
  EXPECT_EQ(s.render.quality, Quality::draft);
  EXPECT_EQ(s.render.backend, Backend::automatic);
}

TEST(SceneJson, FormatAndVersion) {
  EXPECT_CONTAINS(parse_error("{\"format\": \"libmr-scene\", \"version\": 6}"),
                  "scene.json: /version: version 6 is newer than this libmr supports (it reads "
                  "versions 1 to 5); upgrade libmr");
  EXPECT_CONTAINS(parse_error("{\"format\": \"libmr-scene\", \"version\": 0}"),
                  "scene.json: /version: version 0 does not exist");
  EXPECT_CONTAINS(parse_error("{\"format\": \"libmr-scene\"}"), "scene.json: /version: missing");
  EXPECT_CONTAINS(parse_error("{\"version\": 1}"), "scene.json: /format: missing");
  EXPECT_CONTAINS(parse_error("{\"format\": \"gltf\", \"version\": 1}"),
                  "scene.json: /format: expected \"libmr-scene\", found a string (\"gltf\")");
  // A newer document is refused for its version, not for the keys this libmr does not know.
  EXPECT_CONTAINS(parse_error("{\"format\": \"libmr-scene\", \"version\": 6, \"depth\": {}}"),
                  "/version: version 6 is newer");
}

// ---- the camera (format version 2) ----

std::string doc2(const std::string& body) {
  return std::string("{\"format\": \"libmr-scene\", \"version\": 2") +
         (body.empty() ? "" : ", " + body) + "}";
}

TEST(SceneJson, CameraRoundTripsAndIsOptional) {
  FogScene s;
  s.camera = SceneCamera{1600, 1200, 1234.5678901234567, std::nullopt};
  const std::string text = scene_to_json(s);
  EXPECT_CONTAINS(text, "\"version\": 5");
  EXPECT_CONTAINS(text, "\"camera\": {");
  EXPECT_EQ(text.find("principal_point_px"), std::string::npos);  // the centre: left out
  const FogScene back = scene_from_json(text, "cam.json");
  expect_scene_eq(back, s);
  // Old documents (version 1, no camera) still read, without a camera; none is written then.
  EXPECT_FALSE(scene_from_json(doc(""), "v1.json").camera);
  EXPECT_EQ(scene_to_json(FogScene{}).find("\"camera\""), std::string::npos);
  EXPECT_FALSE(scene_from_json(doc2("\"camera\": null"), "null.json").camera);
  // The field of view instead of the focal length: f = (w / 2) / tan(fov / 2).
  const FogScene f = scene_from_json(
      doc2("\"camera\": {\"width\": 800, \"height\": 600, \"horizontal_fov_deg\": 90}"), "fov");
  ASSERT_TRUE(f.camera);
  EXPECT_NEAR(f.camera->focal_px, 400, 1e-9);
}

TEST(SceneJson, CameraForImageScalesResizedPhotos) {
  const SceneCamera c{4000, 3000, 3200, std::array<double, 2>{2010, 1490}};
  const Camera same = camera_for_image(c, 4000, 3000);
  EXPECT_EQ(same.focal_px, 3200);
  EXPECT_EQ(same.cx, 2010);
  EXPECT_EQ(same.cy, 1490);
  // A copy at a quarter of the size: the same field of view and principal point (in fractions).
  const Camera small = camera_for_image(c, 1000, 750);
  EXPECT_DOUBLE_EQ(small.focal_px, 800);
  EXPECT_DOUBLE_EQ(small.cx, 502.5);
  EXPECT_DOUBLE_EQ(small.cy, 372.5);
  const Camera ref = Camera::from_focal_px(4000, 3000, 3200);
  EXPECT_NEAR(small.horizontal_fov_deg(), ref.horizontal_fov_deg(), 1e-12);
  // Rounding to whole pixels (1001 x 750) is still the same photo; a rotated one is not.
  EXPECT_NO_THROW(camera_for_image(c, 1001, 750));
  const std::string rotated = error_of([&] { camera_for_image(c, 3000, 4000); });
  EXPECT_CONTAINS(rotated, "recorded for a 4000x3000 image, this one is 3000x4000");
  EXPECT_CONTAINS(rotated, "aspect ratio");
  // scene_camera records a Camera exactly (the centre as no principal point).
  const Camera cam = Camera::from_focal_px(640, 480, 500.123456789);
  const SceneCamera rec = scene_camera(cam);
  EXPECT_FALSE(rec.principal_point_px);
  const Camera again = camera_for_image(rec, 640, 480);
  EXPECT_EQ(again.focal_px, cam.focal_px);
  EXPECT_EQ(again.cx, cam.cx);
  EXPECT_EQ(again.cy, cam.cy);
}

TEST(SceneJson, BadCameraValuesNameTheirPointer) {
  const std::string size = "\"width\": 640, \"height\": 480";
  EXPECT_CONTAINS(parse_error(doc2("\"camera\": {" + size + ", \"focal_px\": -5}")),
                  "scene.json: /camera/focal_px: must be > 0 pixels, found -5");
  EXPECT_CONTAINS(parse_error(doc2("\"camera\": {" + size + ", \"focal_px\": \"wide\"}")),
                  "scene.json: /camera/focal_px: expected a number, found a string");
  EXPECT_CONTAINS(parse_error(doc2("\"camera\": {\"height\": 480, \"focal_px\": 500}")),
                  "scene.json: /camera/width: missing");
  EXPECT_CONTAINS(parse_error(doc2("\"camera\": {\"width\": 0, \"height\": 480, \"focal_px\": 5}")),
                  "scene.json: /camera/width: must be >= 1, found 0");
  EXPECT_CONTAINS(
      parse_error(doc2("\"camera\": {\"width\": 64.5, \"height\": 48, \"focal_px\": 5}")),
      "scene.json: /camera/width: expected an integer");
  EXPECT_CONTAINS(parse_error(doc2("\"camera\": {" + size + "}")),
                  "scene.json: /camera/focal_px: missing; give focal_px or horizontal_fov_deg");
  EXPECT_CONTAINS(
      parse_error(doc2("\"camera\": {" + size + ", \"focal_px\": 5, \"horizontal_fov_deg\": 60}")),
      "scene.json: /camera: give either focal_px or horizontal_fov_deg, not both");
  EXPECT_CONTAINS(parse_error(doc2("\"camera\": {" + size + ", \"horizontal_fov_deg\": 180}")),
                  "scene.json: /camera/horizontal_fov_deg: must be in (0, 180) degrees, found 180");
  EXPECT_CONTAINS(
      parse_error(
          doc2("\"camera\": {" + size + ", \"focal_px\": 500, \"principal_point_px\": [320]}")),
      "scene.json: /camera/principal_point_px: expected an array of 2 numbers [cx, cy]");
  EXPECT_CONTAINS(parse_error(doc2("\"camera\": {" + size +
                                   ", \"focal_px\": 500, \"principal_point_px\": [320, 900]}")),
                  "scene.json: /camera/principal_point_px/1: must be inside the 640x480 image "
                  "(0..480), found 900");
  EXPECT_CONTAINS(parse_error(doc2("\"camera\": {" + size + ", \"focal_pz\": 500}")),
                  "scene.json: /camera/focal_pz: unknown key; did you mean \"focal_px\"?");
  EXPECT_CONTAINS(parse_error(doc2("\"camera\": [500]")),
                  "scene.json: /camera: expected an object, found an array");
  // The camera is a version-2 key.
  EXPECT_CONTAINS(parse_error(doc("\"camera\": {" + size + ", \"focal_px\": 500}")),
                  "scene.json: /camera: the camera is part of the format from version 2 on; this "
                  "document is version 1");
  // Writing refuses a camera it could not read back.
  FogScene s;
  s.camera = SceneCamera{640, 480, std::numeric_limits<double>::quiet_NaN(), std::nullopt};
  EXPECT_CONTAINS(error_of([&] { scene_to_json(s); }), "/camera/focal_px: must be > 0 pixels");
}

TEST(SceneJson, MalformedJsonReportsLineAndColumn) {
  // Line 3 misses the colon after "g": the error points at the number that came instead.
  const std::string text =
      "{\"format\": \"libmr-scene\", \"version\": 1,\n"
      "  \"medium\": {\n"
      "    \"g\" 0.5\n"
      "  }\n"
      "}\n";
  EXPECT_CONTAINS(parse_error(text), "scene.json: line 3, column 9: syntax error");
  EXPECT_CONTAINS(parse_error("{\"format\": \"libmr-scene\",\n \"version\": 1,\n"),
                  "scene.json: line 3, column 1: syntax error");
  EXPECT_CONTAINS(parse_error(""), "scene.json: line 1, column 1: syntax error");
  // Columns count characters, not bytes (the é is two bytes).
  EXPECT_CONTAINS(parse_error("{\"é\": tru}"), "scene.json: line 1, column 7:");
  const std::string msg = parse_error(text);
  EXPECT_EQ(msg.find("json.exception"), std::string::npos) << msg;
}

TEST(SceneJson, DuplicateKeyIsAnError) {
  EXPECT_CONTAINS(parse_error(doc("\"medium\": {\"g\": 0.1, \"g\": 0.2}")),
                  "scene.json: /medium/g: duplicate key");
  EXPECT_CONTAINS(
      parse_error(
          doc("\"lighting\": {\"lamps\": [{\"position_m\": [1, 2, 3]}, {\"inner_angle_deg\": "
              "1, \"inner_angle_deg\": 2}]}")),
      "scene.json: /lighting/lamps/1/inner_angle_deg: duplicate key");
}

TEST(SceneJson, ToJsonRefusesASceneItCouldNotReadBack) {
  FogScene s;
  s.medium.g = kNan;
  EXPECT_CONTAINS(error_of([&] { scene_to_json(s); }), "medium.g = nan");
}

// ---- files ----

TEST(SceneJson, SaveAndLoadRoundTrip) {
  test::ScratchDir dir;
  const FogScene s = every_field_set();
  save_scene(dir / "scene.json", s);
  expect_scene_eq(load_scene(dir / "scene.json"), s);
  EXPECT_EQ(dir.list(), std::vector<std::string>{"scene.json"});
}

TEST(SceneJson, SaveIsAtomic) {
  test::ScratchDir dir;
  // Into a missing folder: an io error naming the file, and nothing created.
  const std::string msg =
      error_of([&] { save_scene(dir / "missing" / "scene.json", FogScene{}); }, ErrorCode::io);
  EXPECT_CONTAINS(msg, (dir / "missing" / "scene.json").string());
  EXPECT_TRUE(dir.list().empty());

  // Overwriting replaces the content and leaves no temporary files.
  const auto path = dir / "scene.json";
  test::write_bytes(path, "old content");
  save_scene(path, every_field_set());
  expect_scene_eq(load_scene(path), every_field_set());
  save_scene(path, FogScene{});
  expect_scene_eq(load_scene(path), FogScene{});
  EXPECT_EQ(dir.list(), std::vector<std::string>{"scene.json"});

  // An invalid scene is refused before anything is written: the old file stays as it was.
  const std::string before = test::read_bytes(path);
  FogScene bad;
  bad.render.threads = -2;
  EXPECT_CONTAINS(error_of([&] { save_scene(path, bad); }), "render.threads = -2");
  EXPECT_EQ(test::read_bytes(path), before);
  EXPECT_EQ(dir.list(), std::vector<std::string>{"scene.json"});

  // A folder in the way: the rename fails, the folder survives, no temporary file is left.
  std::filesystem::create_directory(dir / "taken.json");
  error_of([&] { save_scene(dir / "taken.json", FogScene{}); }, ErrorCode::io);
  EXPECT_EQ(dir.list(), (std::vector<std::string>{"scene.json", "taken.json"}));
}

TEST(SceneJson, LoadErrorsNameTheFile) {
  test::ScratchDir dir;
  const auto missing = dir / "nope.json";
  EXPECT_CONTAINS(error_of([&] { load_scene(missing); }, ErrorCode::io), missing.string() + ": ");
  EXPECT_CONTAINS(error_of([&] { load_scene(dir.path()); }, ErrorCode::io), "is a folder");
  const auto bad = dir / "bad.json";
  test::write_bytes(bad, doc("\"medium\": {\"g\": 2}"));
  EXPECT_CONTAINS(error_of([&] { load_scene(bad); }), bad.string() + ": /medium/g: medium.g = 2");
}

// ---- validate_scene ----

TEST(ValidateScene, DefaultsAndTheFullSceneAreValid) {
  EXPECT_NO_THROW(validate_scene(FogScene{}));
  EXPECT_NO_THROW(validate_scene(every_field_set()));
  FogScene s;
  s.medium.layer_bottom_m = -kInf;
  s.medium.layer_top_m = 5;
  EXPECT_NO_THROW(validate_scene(s));
  s.medium.layer_bottom_m = 4;
  s.medium.layer_top_m = kInf;
  EXPECT_NO_THROW(validate_scene(s));
}

TEST(ValidateScene, MessagesNameTheFieldAndTheValue) {
  struct Case {
    std::function<void(FogScene&)> mutate;
    std::string expected;
  };
  const std::vector<Case> cases = {
      {[](FogScene& s) { s.pose.position_m.z = kInf; }, "pose.position_m.z = inf: must be finite"},
      {[](FogScene& s) { s.pose.yaw_deg = kNan; }, "pose.yaw_deg = nan: must be finite"},
      {[](FogScene& s) { s.pose.roll_deg = 181; }, "pose.roll_deg = 181: must be in [-180, 180]"},
      {[](FogScene& s) { s.medium.sigma_t_per_m[2] = 2e4f; },
       "medium.sigma_t_per_m[2] = 20000: must be in [0, 10000]"},
      {[](FogScene& s) { s.medium.albedo[0] = 1.5f; }, "medium.albedo[0] = 1.5: must be in [0, 1]"},
      {[](FogScene& s) { s.medium.g = 1.2; }, "medium.g = 1.2: must be in (-1, 1)"},
      {[](FogScene& s) { s.medium.g = -1; }, "medium.g = -1: must be in (-1, 1)"},
      {[](FogScene& s) {
         s.medium.height_fog = Medium::HeightFog{0, 0};
       },
       "medium.height_fog.scale_height_m = 0: must be finite and > 0"},
      {[](FogScene& s) { s.medium.layer_top_m = kNan; }, "medium.layer_top_m = nan"},
      {[](FogScene& s) { s.medium.layer_bottom_m = kInf; },
       "medium.layer_bottom_m = inf: must be <"},
      {[](FogScene& s) { s.medium.noise.amplitude = 1.01; }, "medium.noise.amplitude = 1.01"},
      {[](FogScene& s) { s.medium.noise.scale_m = -1; }, "medium.noise.scale_m = -1"},
      {[](FogScene& s) { s.medium.noise.octaves = 9; },
       "medium.noise.octaves = 9: must be in 1..8"},
      {[](FogScene& s) {
         s.lighting.sun = Sun{};
         s.lighting.sun->direction_to_sun = {};
       },
       "lighting.sun.direction_to_sun = (0, 0, 0): must have a non-zero length"},
      {[](FogScene& s) {
         s.lighting.sun = Sun{};
         s.lighting.sun->irradiance[1] = -1;
       },
       "lighting.sun.irradiance[1] = -1: must be finite and >= 0"},
      {[](FogScene& s) {
         s.lighting.sun = Sun{};
         s.lighting.sun->angular_radius_deg = 6;
       },
       "lighting.sun.angular_radius_deg = 6: must be in [0, 5]"},
      {[](FogScene& s) {
         s.lighting.sky_radiance = Rgb{1, std::nanf(""), 1};
       },
       "lighting.sky_radiance[1] = nan"},
      {[](FogScene& s) {
         s.lighting.lamps.resize(3);
         s.lighting.lamps[2].position_m.y = kNan;
       },
       "lighting.lamps[2].position_m.y = nan: must be finite"},
      {[](FogScene& s) {
         s.lighting.lamps.resize(1);
         s.lighting.lamps[0].intensity_per_sr[0] = -3;
       },
       "lighting.lamps[0].intensity_per_sr[0] = -3"},
      {[](FogScene& s) {
         s.lighting.lamps.resize(2);
         s.lighting.lamps[1].spot_direction = {};
       },
       "lighting.lamps[1].spot_direction = (0, 0, 0): must have a non-zero length"},
      {[](FogScene& s) {
         s.lighting.lamps.resize(1);
         s.lighting.lamps[0].outer_angle_deg = 0;
       },
       "lighting.lamps[0].outer_angle_deg = 0: must be in (0, 180]"},
      {[](FogScene& s) {
         s.lighting.lamps.resize(1);
         s.lighting.lamps[0].outer_angle_deg = 190;
       },
       "lighting.lamps[0].outer_angle_deg = 190"},
      {[](FogScene& s) {
         s.lighting.lamps.resize(1);
         s.lighting.lamps[0].inner_angle_deg = 30;
         s.lighting.lamps[0].outer_angle_deg = 20;
       },
       "lighting.lamps[0].inner_angle_deg = 30: must be in [0, outer_angle_deg = 20]"},
      {[](FogScene& s) { s.lighting.lamps.resize(65); },
       "lighting.lamps = 65 lamps: at most 64 are supported"},
      {[](FogScene& s) { s.render.quality = static_cast<Quality>(7); }, "render.quality = 7"},
      {[](FogScene& s) { s.render.backend = static_cast<Backend>(-1); }, "render.backend = -1"},
      {[](FogScene& s) { s.render.march_steps = -1; },
       "render.march_steps = -1: must be in 0..4096"},
      {[](FogScene& s) { s.render.grid_step = 4; }, "render.grid_step = 4: must be in 0..3"},
      {[](FogScene& s) { s.render.max_distance_m = -1; }, "render.max_distance_m = -1"},
      {[](FogScene& s) { s.render.threads = -1; }, "render.threads = -1"},
  };
  for (const Case& c : cases) {
    FogScene s;
    c.mutate(s);
    const std::string msg = error_of([&] { validate_scene(s); });
    EXPECT_EQ(msg.rfind(c.expected, 0), 0u)
        << "expected \"" << c.expected << "\", got \"" << msg << "\"";
  }
}

TEST(ValidateScene, BoundariesThatAreAllowed) {
  FogScene s;
  s.lighting.lamps.resize(64);
  s.lighting.lamps[0].inner_angle_deg = 0;
  s.lighting.lamps[0].outer_angle_deg = 180;
  s.lighting.lamps[1].inner_angle_deg = 10;
  s.lighting.lamps[1].outer_angle_deg = 10;
  s.pose.pitch_deg = -90;
  s.pose.roll_deg = 180;
  s.medium.g = 0.999;
  s.medium.albedo = {0, 1, 0};
  s.medium.sigma_t_per_m = {0, 1e4f, 0};
  s.medium.noise.octaves = 1;
  s.lighting.sun = Sun{};
  s.lighting.sun->angular_radius_deg = 0;
  s.render.march_steps = 1;
  s.render.grid_step = 1;
  EXPECT_NO_THROW(validate_scene(s));
}

}  // namespace
}  // namespace mr
