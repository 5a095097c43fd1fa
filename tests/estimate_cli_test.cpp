// `mr estimate` driven the way a user drives it: outputs (scene JSON, distance EXR, overlay),
// and errors with exit codes.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "mr/annotations.h"
#include "mr/estimate.h"
#include "mr/io.h"
#include "mr/scene_json.h"
#include "test_support.h"

namespace fs = std::filesystem;

namespace mr {
namespace {

const std::string kMr = MR_CLI_PATH;

using test::shell_quoted;

class EstimateCli : public ::testing::Test {
 protected:
  void SetUp() override {
    write_image(dir / "photo.png", test::make_test_photo(160, 120));
    annotations.horizon = std::array<PixelPoint, 2>{PixelPoint{0, 50}, PixelPoint{159, 47}};
    annotations.camera_height_m = 1.5;
    annotations.planes.push_back({{{60, 20}, {100, 20}, {100, 80}, {60, 80}}, std::nullopt});
    save_annotations(dir / "a.json", annotations);
  }
  test::ScratchDir dir;
  Annotations annotations;
};

TEST_F(EstimateCli, WritesSceneDepthAndOverlay) {
  const auto r = test::run(
      kMr + " estimate " + shell_quoted(dir / "photo.png") + " --annotations " +
      shell_quoted(dir / "a.json") + " --fov 50 -o " + shell_quoted(dir / "scene.json") +
      " --depth-out " + shell_quoted(dir / "d.exr") + " --overlay " + shell_quoted(dir / "o.png"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("horizon: annotated"), std::string::npos) << r.output;

  // The same estimate in-process: the files hold exactly it.
  const Camera camera = Camera::from_horizontal_fov(160, 120, 50);
  const GeometryEstimate g = estimate_geometry(read_image(dir / "photo.png"), camera, annotations);
  const FogScene scene = load_scene(dir / "scene.json");
  EXPECT_EQ(scene.pose.pitch_deg, g.pose.pitch_deg);
  EXPECT_EQ(scene.pose.roll_deg, g.pose.roll_deg);
  EXPECT_EQ(scene.pose.position_m.y, 1.5);
  EXPECT_FALSE(scene.lighting.sun);  // no shadow pairs

  ReadOptions raw;
  raw.to_scene_linear = false;
  raw.reject_non_finite = false;  // +inf = sky
  const Image d = read_image(dir / "d.exr", raw);
  ASSERT_EQ(d.width(), 160);
  ASSERT_EQ(d.height(), 120);
  ASSERT_EQ(d.channels(), 1);
  EXPECT_EQ(d.channel_names().at(0), "Z");
  std::size_t sky = 0;
  for (int y = 0; y < 120; ++y)
    for (int x = 0; x < 160; ++x) {
      const float want = g.distance_m.at(x, y, 0);
      if (std::isinf(want)) ++sky;
      EXPECT_EQ(d.at(x, y, 0), want) << x << "," << y;
    }
  EXPECT_GT(sky, 0u);
  EXPECT_GT(g.plane_pixels, 0u);

  const ImageFileInfo overlay = probe_image(dir / "o.png");
  EXPECT_EQ(overlay.width, 160);
  EXPECT_EQ(overlay.height, 120);
}

TEST_F(EstimateCli, WithoutAnnotationsFallsBackToLevelCamera) {
  const auto r = test::run(kMr + " estimate " + shell_quoted(dir / "photo.png") + " -o " +
                           shell_quoted(dir / "s.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("not annotated"), std::string::npos) << r.output;
  const FogScene scene = load_scene(dir / "s.json");
  EXPECT_EQ(scene.pose.pitch_deg, 0);
  EXPECT_EQ(scene.pose.position_m.y, 1.6);
}

TEST_F(EstimateCli, BadAnnotationsAreUsageErrorsNamingFileAndPointer) {
  test::write_bytes(
      dir / "bad.json",
      R"({"format": "libmr-annotations", "version": 1, "planes": [{"polygon": [[1, 2], [3, 4]]}]})");
  auto r = test::run(kMr + " estimate " + shell_quoted(dir / "photo.png") + " --annotations " +
                     shell_quoted(dir / "bad.json") + " -o " + shell_quoted(dir / "s.json"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("ERROR: " + (dir / "bad.json").string() + ": /planes/0/polygon"),
            std::string::npos)
      << r.output;
  // Valid JSON that does not fit the photo: a plane above the horizon.
  Annotations a = annotations;
  a.planes[0].polygon = {{60, 5}, {100, 5}, {100, 20}};
  save_annotations(dir / "above.json", a);
  r = test::run(kMr + " estimate " + shell_quoted(dir / "photo.png") + " --annotations " +
                shell_quoted(dir / "above.json") + " -o " + shell_quoted(dir / "s.json"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("above.json: /planes/0/polygon: lies entirely on or above the horizon"),
            std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(dir / "s.json"));  // nothing written on failure
}

TEST_F(EstimateCli, UnreadablePhotoFails) {
  test::write_bytes(dir / "broken.jpg", "not a jpeg");
  const auto r = test::run(kMr + " estimate " + shell_quoted(dir / "broken.jpg") + " -o " +
                           shell_quoted(dir / "s.json"));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("ERROR: "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("broken.jpg"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir / "s.json"));
}

TEST_F(EstimateCli, MissingOutputIsUsageError) {
  const auto r = test::run(kMr + " estimate " + shell_quoted(dir / "photo.png"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
}

// `mr fog --depth auto --save-scene PATTERN`: one scene per photo, the one it was rendered with:
// the annotated photo's pose from its annotations, the other's from the automatic estimate.
TEST_F(EstimateCli, FogSavesOneEstimatedScenePerPhoto) {
  const fs::path in = dir / "in";
  fs::create_directories(in);
  write_image(in / "a.png", test::make_test_photo(160, 120));
  write_image(in / "b.png", test::make_test_photo(120, 90));
  save_annotations(in / "a.json", annotations);
  const std::string pattern = (dir / "scenes" / "{stem}.scene.json").string();
  const auto r = test::run(kMr + " fog " + shell_quoted(in) +
                           " --depth auto --annotations '{dir}/{stem}.json' --fov 50 " +
                           "--quality draft -q -o " + shell_quoted(dir / "out") +
                           " --save-scene '" + pattern + "'");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  ASSERT_TRUE(fs::exists(dir / "scenes" / "a.scene.json")) << r.output;
  ASSERT_TRUE(fs::exists(dir / "scenes" / "b.scene.json")) << r.output;
  EXPECT_FALSE(fs::exists(dir / "scenes" / "a.json.scene.json"));  // annotations are not photos

  const FogScene a = load_scene(dir / "scenes" / "a.scene.json");
  const CameraPose pa = estimate_geometry(read_image(in / "a.png"),
                                          Camera::from_horizontal_fov(160, 120, 50), annotations)
                            .pose;
  EXPECT_EQ(a.pose.pitch_deg, pa.pitch_deg);
  EXPECT_EQ(a.pose.roll_deg, pa.roll_deg);
  EXPECT_EQ(a.pose.position_m.y, 1.5);
  const FogScene b = load_scene(dir / "scenes" / "b.scene.json");
  const GeometryEstimate gb = estimate_geometry(
      read_image(in / "b.png"), Camera::from_horizontal_fov(120, 90, 50), Annotations{});
  EXPECT_EQ(b.pose.pitch_deg, gb.pose.pitch_deg);
  EXPECT_EQ(b.pose.position_m.y, 1.6);
  EXPECT_NE(a.pose.pitch_deg, b.pose.pitch_deg);
  EXPECT_FLOAT_EQ(a.medium.sigma_t_per_m[0], float(3.912 / 150));  // the command line's medium

  // A pattern that gives one file for two photos is a usage error; nothing is written.
  const auto clash =
      test::run(kMr + " fog " + shell_quoted(in) + " --depth auto --quality draft -o " +
                shell_quoted(dir / "out2") + " --save-scene '" +
                (dir / "scenes" / "same.json").string() + "{ext}'");
  EXPECT_EQ(clash.exit_code, 2) << clash.output;
  EXPECT_NE(clash.output.find("for both"), std::string::npos) << clash.output;
  EXPECT_FALSE(fs::exists(dir / "out2"));
  EXPECT_FALSE(fs::exists(dir / "scenes" / "same.json.png"));
}

// Issue 11 item 3: `--seams soften` (the default with --depth auto and no sun or lamps) softens
// the fog where the guessed depth makes edges the photo lacks; `--seams keep` renders as before;
// any other value is a usage error that writes nothing. gallery/tune airport_snow's haze has such
// edges (its far city's rooftops).
TEST_F(EstimateCli, SeamsAreSoftenedUnlessKept) {
  const fs::path photo = fs::path(MR_SOURCE_DIR) / "gallery" / "tune" / "airport_snow.jpg";
  const fs::path look = fs::path(MR_SOURCE_DIR) / "gallery" / "looks" / "haze.json";
  auto fog = [&](const std::string& seams, const fs::path& out) {
    return test::run(kMr + " fog " + shell_quoted(photo) + " --depth auto --scene " +
                     shell_quoted(look) + " -v -o " + shell_quoted(out) + seams);
  };
  const auto soft = fog("", dir / "soft");
  ASSERT_EQ(soft.exit_code, 0) << soft.output;
  EXPECT_NE(soft.output.find("softened the fog's seams"), std::string::npos) << soft.output;
  const auto kept = fog(" --seams keep", dir / "kept");
  ASSERT_EQ(kept.exit_code, 0) << kept.output;
  EXPECT_EQ(kept.output.find("softened"), std::string::npos) << kept.output;
  const Image a = read_image(dir / "soft" / "airport_snow_fog.jpg");
  const Image b = read_image(dir / "kept" / "airport_snow_fog.jpg");
  double diff = 0;
  for (std::size_t i = 0; i < a.pixels().size(); ++i)
    diff = std::max(diff, double(std::abs(a.pixels()[i] - b.pixels()[i])));
  EXPECT_GT(diff, 0.02);
  const auto bad = fog(" --seams blur", dir / "bad");
  EXPECT_EQ(bad.exit_code, 2) << bad.output;
  EXPECT_NE(bad.output.find("--seams"), std::string::npos) << bad.output;
  EXPECT_FALSE(fs::exists(dir / "bad"));
}

// Issue 11 item 4: an estimated photo's fog gets a top (half the visibility, 30 m..2 km) unless
// the command line gives one (--layer, --layer-top) or asks for none.
TEST_F(EstimateCli, EstimatedPhotosFogLiesInALayerWithATop) {
  write_image(dir / "c.png", test::make_test_photo(96, 72));
  auto top = [&](const std::string& options, int* exit_code = nullptr) {
    const fs::path scene = dir / "c.top.json";  // per photo: the scene it was rendered with
    fs::remove(scene);
    const auto r =
        test::run(kMr + " fog " + shell_quoted(dir / "c.png") +
                  " --depth auto --quality draft -q --overwrite -o " + shell_quoted(dir / "o") +
                  " --save-scene '{dir}/{stem}.top.json' " + options);
    if (exit_code) *exit_code = r.exit_code;
    if (r.exit_code != 0) return std::nan("");
    return load_scene(scene).medium.layer_top_m;
  };
  EXPECT_NEAR(top("--visibility 150m"), 75, 1e-3);
  EXPECT_NEAR(top("--visibility 3km"), 1500, 0.05);
  EXPECT_NEAR(top("--visibility 150m --layer-top 60m"), 60, 1e-9);
  EXPECT_TRUE(std::isinf(top("--visibility 150m --layer-top none")));
  EXPECT_NEAR(top("--visibility 150m --layer 0,40"), 40, 1e-9);
  EXPECT_TRUE(std::isinf(top("--visibility 150m --height-fog 0,20")));
  int code = 0;
  top("--layer 0,40 --layer-top 60m", &code);
  EXPECT_EQ(code, 2);
}

// A ground grid (0.15 m stripes every 2 m) under a gradient sky, seen from 1.6 m by a camera
// 60 degrees across, pitched -8, rolled 4, turned 30 degrees (so both stripe families have
// finite vanishing points), 4x4 supersampled. Scene-linear (written as an 8-bit PNG: no EXIF).
Image grid_photo(const Camera& camera, const CameraPose& pose) {
  Image out(camera.width, camera.height, 3);
  for (int y = 0; y < camera.height; ++y)
    for (int x = 0; x < camera.width; ++x) {
      double rgb[3] = {0, 0, 0};
      for (int sy = 0; sy < 4; ++sy)
        for (int sx = 0; sx < 4; ++sx) {
          const Vec3 d =
              pose.ray_direction(camera, x + (sx + 0.5) / 4 - 0.5, y + (sy + 0.5) / 4 - 0.5);
          double c[3];
          if (d.y >= 0) {
            c[0] = 0.35 + 0.4 * y / camera.height, c[1] = 0.6, c[2] = 0.9;
          } else {
            const double t = -pose.position_m.y / d.y;
            const double gx = pose.position_m.x + t * d.x, gz = pose.position_m.z + t * d.z;
            const bool stripe = std::abs(gx - 2 * std::round(gx / 2)) < 0.075 ||
                                std::abs(gz - 2 * std::round(gz / 2)) < 0.075;
            const double v = stripe ? 0.1 : 0.45;
            c[0] = v, c[1] = 0.85 * v, c[2] = 0.7 * v;
          }
          for (int k = 0; k < 3; ++k) rgb[k] += c[k] / 16;
        }
      for (int k = 0; k < 3; ++k) out.at(x, y, k) = float(std::pow(rgb[k], 2.2));
    }
  return out;
}

// The focal length `mr estimate` finds from the vanishing points (no EXIF) is recorded in the
// scene, and `mr fog --scene` renders with it: the same image as an explicit --focal-px run,
// and not the one the 60-degree default would give.
TEST_F(EstimateCli, SceneCarriesTheVanishingPointFocalLengthToFog) {
  const Camera truth = Camera::from_horizontal_fov(480, 360, 50);
  CameraPose pose;
  pose.position_m = {0, 1.6, 0};
  pose.pitch_deg = -8;
  pose.roll_deg = 4;
  pose.yaw_deg = 30;
  write_image(dir / "grid.png", grid_photo(truth, pose));
  auto r = test::run(kMr + " estimate " + shell_quoted(dir / "grid.png") + " -o " +
                     shell_quoted(dir / "grid.json") + " --depth-out " +
                     shell_quoted(dir / "grid_depth.exr"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  ASSERT_NE(r.output.find("vanishing points"), std::string::npos) << r.output;
  const FogScene scene = load_scene(dir / "grid.json");
  ASSERT_TRUE(scene.camera);
  EXPECT_EQ(scene.camera->width, 480);
  EXPECT_EQ(scene.camera->height, 360);
  EXPECT_FALSE(scene.camera->principal_point_px);
  const double f = scene.camera->focal_px;
  std::printf("vanishing-point focal %.2f px (truth %.2f, 60-degree default %.2f)\n", f,
              truth.focal_px, Camera::from_horizontal_fov(480, 360, 60).focal_px);
  EXPECT_NEAR(f, truth.focal_px, 0.03 * truth.focal_px);

  char focal[64];
  std::snprintf(focal, sizeof focal, "%.17g", f);
  const std::string common = kMr + " fog " + shell_quoted(dir / "grid.png") + " --depth " +
                             shell_quoted(dir / "grid_depth.exr") + " --scene " +
                             shell_quoted(dir / "grid.json") +
                             " --quality draft --seed 3 -q --visibility 60m --height-fog 0,3 ";
  // (Height fog makes the image depend on each pixel's ray direction, hence on the focal length;
  // homogeneous fog under a uniform sky would depend on the distance map only.)
  r = test::run(common + "-o " + shell_quoted(dir / "from_scene") + " --save-scene '" +
                (dir / "saved" / "{stem}.json").string() + "'");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = test::run(common + "-o " + shell_quoted(dir / "explicit") + " --focal-px " + focal +
                " --save-scene " + shell_quoted(dir / "explicit.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = test::run(common + "-o " + shell_quoted(dir / "default") + " --fov 60");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  if (const char* out = std::getenv("MR_TEST_OUT")) {  // to look at
    fs::copy_file(dir / "grid.png", fs::path(out) / "grid.png",
                  fs::copy_options::overwrite_existing);
    fs::copy_file(dir / "from_scene" / "grid_fog.png", fs::path(out) / "grid_fog_scene_camera.png",
                  fs::copy_options::overwrite_existing);
  }
  const Image a = read_image(dir / "from_scene" / "grid_fog.png");
  const Image b = read_image(dir / "explicit" / "grid_fog.png");
  const Image c = read_image(dir / "default" / "grid_fog.png");
  ASSERT_EQ(a.pixel_count(), b.pixel_count());
  std::size_t differ_explicit = 0, differ_default = 0;
  for (int y = 0; y < a.height(); ++y)
    for (int x = 0; x < a.width(); ++x)
      for (int k = 0; k < 3; ++k) {
        differ_explicit += a.at(x, y, k) != b.at(x, y, k);
        differ_default += a.at(x, y, k) != c.at(x, y, k);
      }
  std::printf("values differing from the --focal-px run: %zu, from the 60-degree run: %zu\n",
              differ_explicit, differ_default);
  EXPECT_EQ(differ_explicit, 0u);
  EXPECT_GT(differ_default, std::size_t(a.pixel_count()));  // the test can tell them apart
  // The per-photo saved scene records the camera the photo was rendered with.
  const FogScene saved = load_scene(dir / "saved" / "grid.json");
  ASSERT_TRUE(saved.camera);
  EXPECT_EQ(saved.camera->focal_px, f);

  // A rotated photo (another aspect ratio) cannot take the recorded focal length: a clear error
  // naming both sizes, unless the command line gives one.
  Image rotated(360, 480, 3);
  const Image photo = read_image(dir / "grid.png");
  for (int y = 0; y < 480; ++y)
    for (int x = 0; x < 360; ++x)
      for (int k = 0; k < 3; ++k) rotated.at(x, y, k) = photo.at(y, 359 - x, k);
  fs::create_directories(dir / "rot");
  write_image(dir / "rot" / "tall.png", rotated);
  r = test::run(kMr + " fog " + shell_quoted(dir / "rot" / "tall.png") + " --depth auto --scene " +
                shell_quoted(dir / "grid.json") + " --quality draft -o " +
                shell_quoted(dir / "rot_out") + " --save-scene " + shell_quoted(dir / "kept.json"));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("recorded for a 480x360 image, this one is 360x480"), std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("give --fov or --focal-px"), std::string::npos) << r.output;
  // A single --save-scene file keeps the --scene file's camera (it is written before any photo
  // is read), and records none when the command line replaced it with its own focal length.
  const FogScene kept = load_scene(dir / "kept.json");
  ASSERT_TRUE(kept.camera);
  EXPECT_EQ(kept.camera->focal_px, f);
  EXPECT_FALSE(load_scene(dir / "explicit.json").camera);
  r = test::run(kMr + " fog " + shell_quoted(dir / "rot" / "tall.png") + " --depth auto --scene " +
                shell_quoted(dir / "grid.json") + " --fov 50 --quality draft -q -o " +
                shell_quoted(dir / "rot_out"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
}

// Blockers stated in the annotations (issue 13): `mr estimate -o` writes them into the scene,
// and `mr fog --depth auto --annotations` renders with them (the per-photo --save-scene shows
// them).
TEST_F(EstimateCli, AnnotatedBlockersReachTheScene) {
  Blockers b;
  b.skyline = Blockers::Skyline{30, {{-60, 14}, {80, 9.5}}};
  b.polygons.push_back({{{10, 0, -20}, {10, 0, 12}, {10, 25, 12}, {10, 25, -20}}});
  annotations.blockers = b;
  save_annotations(dir / "b.json", annotations);
  auto r =
      test::run(kMr + " estimate " + shell_quoted(dir / "photo.png") + " --annotations " +
                shell_quoted(dir / "b.json") + " --fov 50 -o " + shell_quoted(dir / "scene.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("blockers: annotated (a skyline of 2 points, 1 polygon(s)"),
            std::string::npos)
      << r.output;
  FogScene want;
  want.blockers = b;
  FogScene got;
  got.blockers = load_scene(dir / "scene.json").blockers;
  EXPECT_EQ(scene_to_json(got), scene_to_json(want));

  r = test::run(kMr + " fog " + shell_quoted(dir / "photo.png") + " --depth auto --annotations " +
                shell_quoted(dir / "b.json") + " --fov 50 --quality draft --out-dir " +
                shell_quoted(dir / "out") + " --save-scene " +
                shell_quoted(dir / "{stem}.scene.json"));  // per photo: as rendered
  ASSERT_EQ(r.exit_code, 0) << r.output;
  got.blockers = load_scene(dir / "photo.scene.json").blockers;
  EXPECT_EQ(scene_to_json(got), scene_to_json(want));
}

}  // namespace
}  // namespace mr
