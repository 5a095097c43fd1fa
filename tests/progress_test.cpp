// Progress reports (mr::Progress through mr::CancelToken, mr/cancel.h): what reaches the callback
// (forward-only, a stage's start and end always), from the CPU core, the Vulkan backend, the
// streamed fog path, estimation and material transfer; a callback that cancels. No timing
// assertions: the throttle interval is 0 wherever a test counts reports.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include "mr/cancel.h"
#include "mr/error.h"
#include "mr/estimate.h"
#include "mr/fog_stream.h"
#include "mr/io.h"
#include "mr/scattering.h"
#include "scattering_scenes.h"
#include "test_support.h"
#include "vulkan_test_support.h"

namespace mr {
namespace {

struct Seen {
  std::string stage;
  std::size_t done, total;
};

// Collects every report (the callback is never called on two threads at once).
struct Recorder {
  std::vector<Seen> seen;
  void attach(CancelToken& token, std::chrono::milliseconds interval = {}) {
    token.set_progress(
        [this](const Progress& p) {
          seen.push_back({std::string(p.stage), p.done, p.total});
        },
        interval);
  }
  std::vector<Seen> of(const std::string& stage) const {
    std::vector<Seen> out;
    for (const Seen& s : seen)
      if (s.stage == stage) out.push_back(s);
    return out;
  }
};

// Within the stage: starts at 0, strictly increasing, ends at total, one total throughout.
void expect_forward_to_total(const std::vector<Seen>& s, const std::string& what) {
  ASSERT_GE(s.size(), 2u) << what;
  EXPECT_EQ(s.front().done, 0u) << what;
  EXPECT_EQ(s.back().done, s.back().total) << what;
  for (std::size_t i = 1; i < s.size(); ++i) {
    EXPECT_GT(s[i].done, s[i - 1].done) << what << " report " << i;
    EXPECT_EQ(s[i].total, s[0].total) << what << " report " << i;
  }
}

TEST(Progress, TokenPassesStartsEndsAndForwardReportsOnly) {
  CancelToken token;
  Recorder rec;
  rec.attach(token);
  token.report("a", 0, 10);
  token.report("a", 3, 10);
  token.report("a", 2, 10);   // late: dropped
  token.report("a", 3, 10);   // repeated: dropped
  token.report("a", 12, 10);  // clamped to the total
  token.report("a", 10, 10);  // the end again: dropped
  token.report("b", 1, 4);    // a new stage
  token.report("b", 0, 0);    // no total: ignored
  ASSERT_EQ(rec.seen.size(), 4u);
  EXPECT_EQ(rec.seen[0].done, 0u);
  EXPECT_EQ(rec.seen[1].done, 3u);
  EXPECT_EQ(rec.seen[2].done, 10u);
  EXPECT_EQ(rec.seen[3].stage, "b");
  EXPECT_EQ(rec.seen[3].done, 1u);
  EXPECT_FALSE(token.requested());
}

TEST(Progress, ThrottledTokenStillPassesStartAndEnd) {
  CancelToken token;
  Recorder rec;
  rec.attach(token, std::chrono::hours(1));
  token.report("a", 0, 1000);
  for (std::size_t i = 1; i < 1000; ++i) token.report("a", i, 1000);
  token.report("a", 1000, 1000);
  ASSERT_EQ(rec.seen.size(), 2u);  // an hour's interval: only the milestones
  EXPECT_EQ(rec.seen[0].done, 0u);
  EXPECT_EQ(rec.seen[1].done, 1000u);
}

TEST(Progress, ThrowingCallbackRequestsTheCancellation) {
  CancelToken token;
  token.set_progress([](const Progress&) { throw std::runtime_error("no"); });
  EXPECT_NO_THROW(token.report("a", 0, 1));
  EXPECT_TRUE(token.requested());
  token.reset();
  token.set_progress({});
  EXPECT_FALSE(token.has_progress());
  EXPECT_NO_THROW(report_progress(&token, "a", 0, 1));
  EXPECT_NO_THROW(report_progress(nullptr, "a", 0, 1));
}

FogScene street_scene() {
  FogScene s = test::base_scene();
  s.pose.pitch_deg = -5;
  s.lighting.sun = Sun{direction_from_azimuth_elevation(-60, 25), {3, 3, 3}, 0.27};
  s.lighting.sky_radiance = Rgb{0.3f, 0.3f, 0.35f};
  Lamp lamp;
  lamp.position_m = {-1.0, 3.0, 8.0};
  s.lighting.lamps = {lamp};
  s.render.quality = Quality::normal;
  s.render.backend = Backend::cpu;
  return s;
}

TEST(Progress, CpuRenderReportsItsWorkForwardToTheTotalAndTheSameResult) {
  const Camera cam = Camera::from_horizontal_fov(320, 180, 60);
  const FogScene s = street_scene();
  const Image depth = test::street_depth(cam, s.pose);
  CancelToken token;
  Recorder rec;
  rec.attach(token);
  const ScatteringLayers with = render_scattering(Image(), depth, cam, s, &token);
  const ScatteringLayers without = render_scattering(Image(), depth, cam, s);
  expect_forward_to_total(rec.of("render"), "render");
  EXPECT_GT(rec.of("render").size(), 20u);  // rows, not just start and end
  EXPECT_EQ(test::max_abs_diff(with.inscatter, without.inscatter), 0.0);
  EXPECT_EQ(test::max_abs_diff(with.transmittance, without.transmittance), 0.0);
}

TEST(Progress, CallbackCancelsTheRenderThroughTheToken) {
  const Camera cam = Camera::from_horizontal_fov(320, 180, 60);
  const FogScene s = street_scene();
  const Image depth = test::street_depth(cam, s.pose);
  CancelToken token;
  std::size_t last = 0, total = 0;
  token.set_progress(
      [&](const Progress& p) {
        // In the render itself (the occluder stage before it may pass in one step when the
        // CPU geometry cache already holds this photo's mesh).
        if (p.stage != "render") return;
        last = p.done;
        total = p.total;
        if (p.fraction() > 0.2) token.request();
      },
      {});
  ScatteringLayers layers;
  try {
    (void)fog(test::make_test_photo(320, 180), depth, cam, s, &layers, &token);
    FAIL() << "no throw";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::cancelled) << e.what();
  }
  EXPECT_LT(last, total);  // stopped before the end
  EXPECT_TRUE(layers.transmittance.empty());
}

// The streamed path (sky light only): rows written, in strips, up to the photo's height.
TEST(Progress, StreamedFogReportsRowsWrittenUpToTheHeight) {
  test::ScratchDir dir;
  const int w = 256, h = 200;
  write_image(dir / "p.png", test::make_test_photo(w, h));
  Image depth(w, h, 1, {"Z"});
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) depth.at(x, y, 0) = 5.0f + float(x + y);
  write_image(dir / "p_depth.exr", depth);
  FogScene scene;
  scene.medium.sigma_t_per_m = {0.02f, 0.02f, 0.02f};
  scene.lighting.sky_radiance = Rgb{0.7f, 0.7f, 0.75f};
  scene.render.backend = Backend::cpu;
  StreamFogRequest r;
  r.photo = dir / "p.png";
  r.depth = dir / "p_depth.exr";
  r.output = dir / "out.png";
  r.scene = &scene;
  r.strip_rows = 16;
  CancelToken token;
  Recorder rec;
  rec.attach(token);
  FogStreamer streamer;
  const StreamFogResult result = streamer.fog_file(r, &token);
  ASSERT_TRUE(result.streamed) << result.reason;
  const auto rows = rec.of("render");
  expect_forward_to_total(rows, "stream");
  EXPECT_EQ(rows.back().total, std::size_t(h));
  EXPECT_EQ(rows.size(), 1 + result.strips);  // the start, then each strip as it is written

  // A callback that cancels: fog_file throws cancelled and leaves no output.
  CancelToken stopper;
  stopper.set_progress(
      [&](const Progress& p) {
        if (p.done >= 32) stopper.request();
      },
      {});
  r.output = dir / "cancelled.png";
  try {
    (void)streamer.fog_file(r, &stopper);
    FAIL() << "no throw";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::cancelled) << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "cancelled.png"));
}

// A blue sky over textured ground: every step of the estimate runs.
Image sky_over_ground(int w, int h) {
  Image photo(w, h, 3);
  std::uint32_t state = 12345;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      state = state * 1664525u + 1013904223u;
      const float noise = float(state >> 8) / float(1u << 24);
      for (int c = 0; c < 3; ++c)
        photo.at(x, y, c) =
            y < h / 2 ? (c == 2 ? 0.6f : 0.25f + 0.05f * c) - 0.1f * y / h : 0.08f + 0.1f * noise;
    }
  return photo;
}

TEST(Progress, EstimationReportsItsStepsInOrder) {
  const Image photo = sky_over_ground(320, 240);
  const Camera camera = Camera::from_horizontal_fov(320, 240, 60);
  CancelToken token;
  Recorder rec;
  rec.attach(token);
  EstimateOptions options;
  options.cancel = &token;
  const SceneEstimate est = estimate_scene(photo, camera, Annotations{}, options);
  const std::vector<std::string> steps = {"horizon", "sky mask", "depth", "refine", "light"};
  ASSERT_EQ(rec.seen.size(), steps.size() + 1);
  for (std::size_t i = 0; i < steps.size(); ++i) {
    EXPECT_EQ(rec.seen[i].stage, steps[i]);
    EXPECT_EQ(rec.seen[i].done, i);
    EXPECT_EQ(rec.seen[i].total, steps.size());
  }
  EXPECT_EQ(rec.seen.back().stage, "light");
  EXPECT_EQ(rec.seen.back().done, steps.size());

  // The geometry alone: four steps; and the same estimate as without a token.
  rec.seen.clear();
  const GeometryEstimate g = estimate_geometry(photo, camera, Annotations{}, options);
  ASSERT_EQ(rec.seen.size(), 5u);
  EXPECT_EQ(rec.seen[3].stage, "refine");
  EXPECT_EQ(rec.seen[4].done, 4u);
  EXPECT_EQ(rec.seen[4].total, 4u);
  EXPECT_EQ(test::max_abs_diff(g.distance_m, estimate_geometry(photo, camera, {}).distance_m), 0.0);

  // Cancelled from the callback at the sky mask: throws cancelled before the depth step.
  CancelToken stopper;
  std::vector<std::string> seen;
  stopper.set_progress(
      [&](const Progress& p) {
        seen.emplace_back(p.stage);
        if (p.stage == "sky mask") stopper.request();
      },
      {});
  options.cancel = &stopper;
  try {
    (void)estimate_scene(photo, camera, Annotations{}, options);
    FAIL() << "no throw";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::cancelled) << e.what();
  }
  EXPECT_EQ(seen, (std::vector<std::string>{"horizon", "sky mask"}));
}

class VulkanProgress : public ::testing::Test {
 protected:
  void SetUp() override {
    std::string why;
    if (!vktest::backend_or_null(&why)) GTEST_SKIP() << why;
  }
};

// With a token the backend renders tiles of at most 2^16 pixels: 320x240 is two or more.
TEST_F(VulkanProgress, RenderReportsTilesUpToTheirCount) {
  const Camera cam = Camera::from_horizontal_fov(320, 240, 60);
  FogScene s = street_scene();
  s.render.backend = Backend::vulkan;
  const Image depth = test::street_depth(cam, s.pose);
  CancelToken token;
  Recorder rec;
  rec.attach(token);
  const ScatteringLayers layers = render_scattering(Image(), depth, cam, s, &token);
  const auto tiles = rec.of("render");
  expect_forward_to_total(tiles, "tiles");
  EXPECT_EQ(tiles.back().total, std::size_t(layers.timings.tiles));
  EXPECT_GE(layers.timings.tiles, 2);
  EXPECT_EQ(tiles.size(), std::size_t(layers.timings.tiles) + 1);
}

}  // namespace
}  // namespace mr
