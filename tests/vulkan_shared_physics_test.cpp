// Issue 14's acceptance: the physics is written once (render/physics/*.h) and both backends
// render from it. The Monte Carlo reference scene (tests/mc_comparison_scene.h: ground, two
// boxes, a low sun through a fog layer, a point lamp, sky) rendered by the CPU core and by the
// Vulkan backend (lavapipe):
//  * CPU vs Vulkan within the existing GPU = CPU bar (tests/vulkan_scattering_test.cpp: mean
//    relative error of T and R < 1 %, 99th percentile < 5 % outside shadow-edge bands);
//  * each against the Monte Carlo reference with the CPU core's bars (mean relative error of R
//    < 3 % at normal quality, < 1 % at final; tests/mc_reference_test.cpp), and the GPU's
//    measured error within 1.5 times the CPU's plus 0.5 %: its shadow maps give the sun hard
//    penumbrae (README "GPU backend").
// The closed-form scenes run through both backends as tests/scattering_test.cpp, compiled once
// per backend (mr_scattering_tests, and mr_vulkan_tests as Vulkan.Scattering.*), and the
// shared header itself is tested from C++ in tests/shared_physics_test.cpp.
#include <gtest/gtest.h>

#include <cstdio>
#include <string>

#include "mc_comparison_scene.h"
#include "mr/scattering.h"
#include "test_support.h"
#include "vulkan_test_support.h"

namespace mr {
namespace {

TEST(SharedPhysicsBackends, MonteCarloSceneOnTheCpuAndVulkanBackends) {
  vktest::configure_environment();
  std::string why;
  if (!vktest::backend_or_null(&why)) GTEST_SKIP() << why;
  const test::ComparisonScene& cs = test::comparison_scene();
  const Image photo = test::make_test_photo(cs.camera.width, cs.camera.height);
  for (const Quality q : {Quality::normal, Quality::final}) {
    const char* name = q == Quality::normal ? "normal" : "final";
    const double bar = q == Quality::normal ? 0.03 : 0.01;
    FogScene s = cs.scene;
    s.render.quality = q;
    s.render.backend = Backend::cpu;
    const ScatteringLayers cpu = render_scattering(photo, cs.distance, cs.camera, s);
    s.render.backend = Backend::vulkan;
    const ScatteringLayers gpu = render_scattering(photo, cs.distance, cs.camera, s);
    ASSERT_EQ(cpu.backend, "cpu");
    ASSERT_EQ(gpu.backend.rfind("vulkan", 0), 0u) << gpu.backend;
    vktest::maybe_write_images(std::string("mc_scene_") + name, gpu, cpu);

    const vktest::Errors e = vktest::compare(gpu, cpu);
    const test::McComparison ref_cpu = test::compare_with_reference(cpu.inscatter, cs);
    const test::McComparison ref_gpu = test::compare_with_reference(gpu.inscatter, cs);
    std::printf(
        "[ Shared   ] %s: GPU vs CPU: T mean %.4f %% p99 %.4f %% | R mean %.4f %% p99 "
        "%.4f %%; against Monte Carlo: CPU %.4f %% (sky %.4f %%), GPU %.4f %% (sky "
        "%.4f %%)\n",
        name, 100 * e.mean_t, 100 * e.p99_t, 100 * e.mean_r, 100 * e.p99_r, 100 * ref_cpu.mean_rel,
        100 * ref_cpu.mean_rel_sky, 100 * ref_gpu.mean_rel, 100 * ref_gpu.mean_rel_sky);
    EXPECT_LT(e.mean_t, 0.01) << name;
    EXPECT_LT(e.mean_r, 0.01) << name;
    EXPECT_LT(e.p99_t, 0.05) << name;
    EXPECT_LT(e.p99_r, 0.05) << name;
    EXPECT_LT(ref_cpu.mean_rel, bar) << name;
    EXPECT_LT(ref_cpu.mean_rel_sky, bar) << name;
    EXPECT_LT(ref_gpu.mean_rel, 1.5 * ref_cpu.mean_rel + 0.005) << name;
    EXPECT_LT(ref_gpu.mean_rel_sky, 1.5 * ref_cpu.mean_rel_sky + 0.005) << name;
  }
  vktest::expect_validation_clean();
}

}  // namespace
}  // namespace mr
