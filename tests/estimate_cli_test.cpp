// `mr estimate` driven the way a user drives it: outputs (scene JSON, distance EXR, overlay),
// and errors with exit codes.
#include <gtest/gtest.h>

#include <cmath>
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

std::string q(const fs::path& p) {
  return "'" + p.string() + "'";
}

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
  const auto r = test::run(kMr + " estimate " + q(dir / "photo.png") + " --annotations " +
                           q(dir / "a.json") + " --fov 50 -o " + q(dir / "scene.json") +
                           " --depth-out " + q(dir / "d.exr") + " --overlay " + q(dir / "o.png"));
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
  const auto r = test::run(kMr + " estimate " + q(dir / "photo.png") + " -o " + q(dir / "s.json"));
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
  auto r = test::run(kMr + " estimate " + q(dir / "photo.png") + " --annotations " +
                     q(dir / "bad.json") + " -o " + q(dir / "s.json"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("ERROR: " + (dir / "bad.json").string() + ": /planes/0/polygon"),
            std::string::npos)
      << r.output;
  // Valid JSON that does not fit the photo: a plane above the horizon.
  Annotations a = annotations;
  a.planes[0].polygon = {{60, 5}, {100, 5}, {100, 20}};
  save_annotations(dir / "above.json", a);
  r = test::run(kMr + " estimate " + q(dir / "photo.png") + " --annotations " +
                q(dir / "above.json") + " -o " + q(dir / "s.json"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("above.json: /planes/0/polygon: lies entirely on or above the horizon"),
            std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(dir / "s.json"));  // nothing written on failure
}

TEST_F(EstimateCli, UnreadablePhotoFails) {
  test::write_bytes(dir / "broken.jpg", "not a jpeg");
  const auto r = test::run(kMr + " estimate " + q(dir / "broken.jpg") + " -o " + q(dir / "s.json"));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("ERROR: "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("broken.jpg"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir / "s.json"));
}

TEST_F(EstimateCli, MissingOutputIsUsageError) {
  const auto r = test::run(kMr + " estimate " + q(dir / "photo.png"));
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
  const auto r = test::run(
      kMr + " fog " + q(in) + " --depth auto --annotations '{dir}/{stem}.json' --fov 50 " +
      "--quality draft -q -o " + q(dir / "out") + " --save-scene '" + pattern + "'");
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
      test::run(kMr + " fog " + q(in) + " --depth auto --quality draft -o " + q(dir / "out2") +
                " --save-scene '" + (dir / "scenes" / "same.json").string() + "{ext}'");
  EXPECT_EQ(clash.exit_code, 2) << clash.output;
  EXPECT_NE(clash.output.find("for both"), std::string::npos) << clash.output;
  EXPECT_FALSE(fs::exists(dir / "out2"));
  EXPECT_FALSE(fs::exists(dir / "scenes" / "same.json.png"));
}

}  // namespace
}  // namespace mr
