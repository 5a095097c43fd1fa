// Cancelling a render (mr::CancelToken, mr/cancel.h) on the CPU core and on the Vulkan backend
// (lavapipe; skipped without a Vulkan device, as in tests/vulkan_*.cpp). What a cancel guarantees,
// tested without any wall-clock bar (those depend on the machine's load; the latency from the
// request to the return is measured by bench/bench_cancel.cpp):
//  * a render cancelled from another thread while it runs throws mr::Error(cancelled) and stops
//    before finishing its work: rows (CPU) or tiles (Vulkan) done < total, seen as output rows
//    it never wrote (the outputs are pre-filled with NaN);
//  * the public entry points then leave the caller's outputs (`layers_out`) untouched;
//  * a render with a token that is never requested is bit-identical to one without (max
//    difference 0 on every layer);
//  * a token requested before the call throws at once and leaves `layers_out` untouched.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>
#include <thread>

#include "mr/cancel.h"
#include "mr/error.h"
#include "mr/scattering.h"
#include "render/embree_scene.h"
#include "render/occluder_mesh.h"
#include "render/scattering_cpu.h"
#include "render/vulkan/vulkan_backend.h"
#include "scattering_scenes.h"
#include "test_support.h"
#include "vulkan_test_support.h"

namespace mr {
namespace {

// Sunlit street with a lamp, shafts and wisps: every part of the core runs.
FogScene street_scene(Backend backend) {
  FogScene s = test::base_scene();
  s.pose.pitch_deg = -5;
  s.lighting.sun = Sun{direction_from_azimuth_elevation(-60, 25), {3, 3, 3}, 0.27};
  s.lighting.sky_radiance = Rgb{0.3f, 0.3f, 0.35f};
  Lamp lamp;
  lamp.position_m = {-1.0, 3.0, 8.0};
  s.lighting.lamps = {lamp};
  s.medium.noise.amplitude = 0.3;
  s.render.quality = Quality::normal;
  s.render.backend = backend;
  return s;
}

void expect_identical(const ScatteringLayers& a, const ScatteringLayers& b) {
  EXPECT_EQ(test::max_abs_diff(a.transmittance, b.transmittance), 0.0);
  EXPECT_EQ(test::max_abs_diff(a.inscatter, b.inscatter), 0.0);
  EXPECT_EQ(test::max_abs_diff(a.sun_visibility, b.sun_visibility), 0.0);
  EXPECT_EQ(test::max_abs_diff(a.optical_depth, b.optical_depth), 0.0);
  EXPECT_EQ(a.timings.exact_pixels, b.timings.exact_pixels);
  EXPECT_EQ(a.timings.interpolated_pixels, b.timings.interpolated_pixels);
}

// Lighter than street_scene (the long renders to cancel): sun and shafts only.
FogScene sunlit_street(Backend backend) {
  FogScene s = street_scene(backend);
  s.lighting.lamps.clear();
  s.medium.noise.amplitude = 0;
  return s;
}

// Requests `token` from another thread `after` the call started (a point inside a render that
// takes far longer; only where the cancel lands depends on it, no result does) and joins it.
class RequestLater {
 public:
  RequestLater(CancelToken& token, std::chrono::milliseconds after)
      : thread_([&token, after] {
          std::this_thread::sleep_for(after);
          token.request();
        }) {}
  ~RequestLater() { thread_.join(); }

 private:
  std::thread thread_;
};

// Rows of a pre-filled (NaN) output that the render wrote completely.
int rows_written(const Image& image) {
  int rows = 0;
  for (int y = 0; y < image.height(); ++y) {
    bool all = true;
    for (int x = 0; x < image.width() && all; ++x)
      for (int c = 0; c < image.channels(); ++c) all = all && !std::isnan(image.at(x, y, c));
    rows += all;
  }
  return rows;
}

// The inputs of the core for a scene, as render_scattering builds them (normals, occluder mesh).
struct CoreSetup {
  Camera camera;
  FogScene scene;
  Image depth, normals;
  render::TriangleMesh mesh;
  std::optional<render::OccluderScene> occluders;
  Image transmittance, inscatter, sun_visibility, optical_depth;

  CoreSetup(int w, int h, const FogScene& s, bool embree)
      : camera(Camera::from_horizontal_fov(w, h, 60)), scene(s) {
    depth = test::street_depth(camera, scene.pose);
    normals = render::estimate_normals(depth.view(), camera, scene.pose);
    mesh = render::reconstruct_occluder_mesh(depth.view(), camera, scene.pose);
    if (embree) occluders.emplace(render::TriangleMesh(mesh));
    const float nan = std::numeric_limits<float>::quiet_NaN();
    for (Image* im : {&transmittance, &inscatter, &optical_depth}) *im = Image(w, h, 3);
    sun_visibility = Image(w, h, 1);
    for (Image* im : {&transmittance, &inscatter, &sun_visibility, &optical_depth})
      for (float& v : im->pixels()) v = nan;
  }
  render::CoreInputs inputs(const CancelToken* token) const {
    render::CoreInputs in;
    in.camera = &camera;
    in.scene = &scene;
    in.distance_m = depth.view();
    in.normals = normals.view();
    in.occluders = occluders ? &*occluders : nullptr;
    in.sky_radiance = {0.3f, 0.3f, 0.35f};
    in.cancel = token;
    return in;
  }
  render::CoreOutputs outputs() {
    return {transmittance.view(), inscatter.view(), sun_visibility.view(), optical_depth.view()};
  }
};

TEST(Cancel, ErrorCodeHasAName) {
  EXPECT_STREQ(to_string(ErrorCode::cancelled), "cancelled");
  EXPECT_NO_THROW(throw_if_cancelled(nullptr, "x"));
  CancelToken token;
  EXPECT_NO_THROW(throw_if_cancelled(&token, "x"));
  token.request();
  try {
    throw_if_cancelled(&token, "render");
    FAIL() << "no throw";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::cancelled);
    EXPECT_STREQ(e.what(), "render: cancelled");
  }
  token.reset();
  EXPECT_FALSE(token.requested());
}

TEST(Cancel, CpuRenderWithAnUnusedTokenIsBitIdentical) {
  const Camera cam = Camera::from_horizontal_fov(320, 180, 60);
  const FogScene s = street_scene(Backend::cpu);
  const Image depth = test::street_depth(cam, s.pose);
  CancelToken token;
  expect_identical(render_scattering(Image(), depth, cam, s),
                   render_scattering(Image(), depth, cam, s, &token));
}

TEST(Cancel, RequestedBeforeTheCallThrowsAndLeavesTheOutputsAlone) {
  const Camera cam = Camera::from_horizontal_fov(64, 48, 60);
  const FogScene s = street_scene(Backend::cpu);
  const Image depth = test::street_depth(cam, s.pose);
  const Image photo = test::make_test_photo(64, 48);
  CancelToken token;
  token.request();
  ScatteringLayers layers;
  layers.backend = "untouched";
  try {
    (void)fog(photo, depth, cam, s, &layers, &token);
    FAIL() << "no throw";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::cancelled) << e.what();
  }
  EXPECT_EQ(layers.backend, "untouched");
  EXPECT_TRUE(layers.transmittance.empty());
}

// A render that takes seconds, cancelled 30 ms in: it throws cancelled and has not done all its
// rows (the core checks the token before each row of each pass and skips the rest).
// Final quality (every pixel marched): seconds of work even on many cores.
FogScene long_cpu_render() {
  FogScene s = sunlit_street(Backend::cpu);
  s.render.quality = Quality::final;
  return s;
}

TEST(Cancel, CpuRenderCancelledWhileRunningStopsBeforeFinishingItsRows) {
  CoreSetup setup(1280, 720, long_cpu_render(), /*embree=*/true);
  CancelToken token;
  render::CoreOutputs out = setup.outputs();
  bool cancelled = false;
  {
    RequestLater later(token, std::chrono::milliseconds(30));
    try {
      render::render_scattering_cpu(setup.inputs(&token), out);
    } catch (const Error& e) {
      cancelled = e.code() == ErrorCode::cancelled;
      EXPECT_TRUE(cancelled) << e.what();
    }
  }
  ASSERT_TRUE(cancelled) << "the render finished before the request (it should take seconds)";
  const int done = rows_written(setup.transmittance);
  std::printf("cpu core 1280x720 cancelled after 30 ms: %d of %d output rows written\n", done,
              setup.camera.height);
  EXPECT_LT(done, setup.camera.height);
}

// Through the public API (the dispatcher: normals, mesh, BVH, then the core): cancelled while
// running, it throws cancelled and leaves the caller's layers exactly as they were.
TEST(Cancel, CpuFogCancelledWhileRunningLeavesTheOutputsAlone) {
  const Camera cam = Camera::from_horizontal_fov(1280, 720, 60);
  const FogScene s = long_cpu_render();
  const Image depth = test::street_depth(cam, s.pose);
  const Image photo = test::make_test_photo(1280, 720);
  for (int after_ms : {0, 30, 300}) {  // before / around the mesh, and in the march
    CancelToken token;
    ScatteringLayers layers;
    layers.backend = "untouched";
    bool cancelled = false;
    {
      RequestLater later(token, std::chrono::milliseconds(after_ms));
      try {
        (void)fog(photo, depth, cam, s, &layers, &token);
      } catch (const Error& e) {
        cancelled = e.code() == ErrorCode::cancelled;
        EXPECT_TRUE(cancelled) << e.what();
      }
    }
    EXPECT_TRUE(cancelled) << "request after " << after_ms << " ms";
    EXPECT_EQ(layers.backend, "untouched");
    EXPECT_TRUE(layers.sun_visibility.empty());
    EXPECT_TRUE(layers.optical_depth.empty());
  }
}

class VulkanCancel : public ::testing::Test {
 protected:
  void SetUp() override {
    std::string why;
    if (!vktest::backend_or_null(&why)) GTEST_SKIP() << why;
  }
  void TearDown() override { vktest::expect_validation_clean(); }
};

TEST_F(VulkanCancel, RenderWithAnUnusedTokenIsBitIdentical) {
  // 320x240: a token caps tiles at 2^16 pixels, so this renders in one tile without a token and
  // in several with one.
  const Camera cam = Camera::from_horizontal_fov(320, 240, 60);
  const FogScene s = street_scene(Backend::vulkan);
  const Image depth = test::street_depth(cam, s.pose);
  CancelToken token;
  const ScatteringLayers plain = render_scattering(Image(), depth, cam, s);
  const ScatteringLayers tokened = render_scattering(Image(), depth, cam, s, &token);
  EXPECT_EQ(plain.timings.tiles, 1);
  EXPECT_GT(tokened.timings.tiles, 1);
  expect_identical(plain, tokened);
}

// Cancelled while its tiles render (a token caps tiles at 2^16 pixels: 1280x720 is 15 tiles):
// it throws cancelled with tiles left undone, seen as output rows it never wrote.
TEST_F(VulkanCancel, RenderCancelledWhileRunningStopsBeforeItsLastTile) {
  std::string why;
  render::vulkan::Backend* backend = vktest::backend_or_null(&why);
  ASSERT_NE(backend, nullptr);
  CoreSetup setup(1280, 720, sunlit_street(Backend::vulkan), /*embree=*/false);
  CancelToken token;
  render::CoreOutputs out = setup.outputs();
  bool cancelled = false;
  {
    RequestLater later(token, std::chrono::milliseconds(50));
    try {
      backend->render(setup.inputs(&token), &setup.mesh, out);
    } catch (const Error& e) {
      cancelled = e.code() == ErrorCode::cancelled;
      EXPECT_TRUE(cancelled) << e.what();
    }
  }
  if (!cancelled && !backend->device().cpu_implementation)
    GTEST_SKIP() << "a hardware GPU finished the render before the request: nothing to cancel";
  ASSERT_TRUE(cancelled) << "the render finished before the request (it takes seconds here)";
  const int done = rows_written(setup.transmittance);
  std::printf("vulkan 1280x720 cancelled after 50 ms: %d of %d output rows written\n", done,
              setup.camera.height);
  EXPECT_LT(done, setup.camera.height);
}

TEST_F(VulkanCancel, FogCancelledWhileRunningLeavesTheOutputsAlone) {
  const Camera cam = Camera::from_horizontal_fov(1280, 720, 60);
  const FogScene s = sunlit_street(Backend::vulkan);
  const Image depth = test::street_depth(cam, s.pose);
  const Image photo = test::make_test_photo(1280, 720);
  CancelToken token;
  ScatteringLayers layers;
  layers.backend = "untouched";
  bool cancelled = false;
  {
    RequestLater later(token, std::chrono::milliseconds(50));
    try {
      (void)fog(photo, depth, cam, s, &layers, &token);
    } catch (const Error& e) {
      cancelled = e.code() == ErrorCode::cancelled;
      EXPECT_TRUE(cancelled) << e.what();
    }
  }
  std::string why;
  if (!cancelled && !vktest::backend_or_null(&why)->device().cpu_implementation)
    GTEST_SKIP() << "a hardware GPU finished the render before the request: nothing to cancel";
  EXPECT_TRUE(cancelled);
  EXPECT_EQ(layers.backend, "untouched");
  EXPECT_TRUE(layers.sun_visibility.empty());
}

}  // namespace
}  // namespace mr
