// The parameter structs shared by C++ and GLSL (shaders/scattering_params.h) have the same
// layout on both sides: a shader (shaders/layout_check.comp) copies every member as GLSL reads
// it, and each must come back exactly as C++ wrote it.
#include <gtest/gtest.h>

#include <cstring>
#include <type_traits>
#include <vector>

#include "render/vulkan/vulkan_backend.h"
#include "shaders/scattering_params.h"
#include "vulkan_test_support.h"

namespace mr {
namespace {

namespace gpu = render::gpu;

static_assert(std::is_standard_layout_v<gpu::ScatterParams> && std::is_trivially_copyable_v<gpu::ScatterParams>);
static_assert(sizeof(gpu::ScatterParams) % 16 == 0 && sizeof(gpu::GpuLamp) == 64 && sizeof(gpu::ShadowLayer) == 128);

TEST(VulkanLayout, ParameterStructsMatchGlsl) {
  std::string why;
  if (!vktest::backend_or_null(&why)) GTEST_SKIP() << why;
  // Every 4-byte word a distinct value (as float for float members, as int for integer ones).
  gpu::ScatterParams p;
  gpu::GpuLamp lamps[2];
  gpu::ShadowLayer layers[2];
  float next = 1.0f;
  auto fill = [&](void* data, std::size_t bytes, bool) {
    float* f = static_cast<float*>(data);
    for (std::size_t i = 0; i < bytes / 4; ++i) f[i] = next++;
  };
  fill(&p, sizeof(p), true);
  // Integer members hold integers.
  for (gpu::ivec4* v : {&p.image, &p.region, &p.tile, &p.grid, &p.grid_count, &p.plan}) {
    v->x = int(next++);
    v->y = int(next++);
    v->z = int(next++);
    v->w = int(next++);
  }
  p.flags = {std::uint32_t(next), std::uint32_t(next + 1), std::uint32_t(next + 2), std::uint32_t(next + 3)};
  next += 4;
  fill(lamps, sizeof(lamps), true);
  fill(layers, sizeof(layers), true);

  // What the shader writes, in its order (layout_check.comp).
  std::vector<float> want;
  auto add4 = [&](const gpu::vec4& v) { want.insert(want.end(), {v.x, v.y, v.z, v.w}); };
  auto addi = [&](const gpu::ivec4& v) { want.insert(want.end(), {float(v.x), float(v.y), float(v.z), float(v.w)}); };
  add4(p.origin); add4(p.right); add4(p.up); add4(p.forward); add4(p.camera);
  addi(p.image); addi(p.region); addi(p.tile); addi(p.grid); addi(p.grid_count); addi(p.plan);
  want.insert(want.end(), {float(p.flags.x), float(p.flags.y), float(p.flags.z), float(p.flags.w)});
  add4(p.sigma); add4(p.albedo); add4(p.sky); add4(p.layer); add4(p.noise);
  add4(p.sun_dir); add4(p.sun_u); add4(p.sun_v); add4(p.sun_irradiance); add4(p.misc); add4(p.cascade_end);
  for (const auto& l : lamps) {
    add4(l.position); add4(l.intensity); add4(l.spot); add4(l.cone);
  }
  for (const auto& l : layers) {
    for (const auto& c : l.view_proj.col) add4(c);
    add4(l.origin); add4(l.axis); add4(l.bounds); add4(l.pad);
  }
  ASSERT_EQ(want.size() * sizeof(float), sizeof(p) + sizeof(lamps) + sizeof(layers))
      << "layout_check.comp must echo every member";
  const std::vector<float> got = render::vulkan::echo_parameter_layout(
      &p, sizeof(p), lamps, sizeof(lamps), layers, sizeof(layers), want.size() / 4);
  ASSERT_EQ(got.size(), want.size());
  for (std::size_t i = 0; i < want.size(); ++i) EXPECT_EQ(got[i], want[i]) << "word " << i;
  vktest::expect_validation_clean();
}

}  // namespace
}  // namespace mr
