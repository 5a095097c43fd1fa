#include "vulkan_test_support.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <vector>

#include "mr/io.h"

namespace mr::vktest {

render::vulkan::Backend* backend_or_null(std::string* why) {
#if defined(__SANITIZE_ADDRESS__)
  // Mesa 22.3's lavapipe + LLVM 15 leak ~27 MB in ~24k allocations per process under
  // LeakSanitizer, from a driver the loader unloads (frames "<unknown module>": no narrow
  // suppression can match them). The Vulkan tests run in the normal build.
  if (why) *why = "skipped under AddressSanitizer: Mesa's lavapipe leaks (see vulkan_test_support.cpp)";
  std::printf("NOTE: Vulkan tests skipped under AddressSanitizer (Mesa's lavapipe leaks)\n");
  return nullptr;
#endif
  configure_environment();
  try {
    return &render::vulkan::Backend::shared();
  } catch (const Error& e) {
    if (why) *why = e.what();
    return nullptr;
  }
}

void expect_validation_clean() {
  render::vulkan::Backend* b = backend_or_null(nullptr);
  if (!b) return;
  EXPECT_EQ(b->validation_messages(), 0u) << b->validation_log();
}

namespace {

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  const std::size_t k = std::min(v.size() - 1, std::size_t(q * double(v.size())));
  std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(k), v.end());
  return v[k];
}

}  // namespace

Errors compare(const ScatteringLayers& gpu, const ScatteringLayers& cpu) {
  Errors e;
  const int w = cpu.inscatter.width(), h = cpu.inscatter.height();
  std::vector<unsigned char> edge(std::size_t(w) * h, 0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float vc = cpu.sun_visibility.at(x, y, 0), vg = gpu.sun_visibility.at(x, y, 0);
      bool band = std::fabs(vc - vg) > 0.01f;
      for (int dy = -1; dy <= 1 && !band; ++dy)
        for (int dx = -1; dx <= 1 && !band; ++dx) {
          const int nx = x + dx, ny = y + dy;
          if (nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
          band = std::fabs(cpu.sun_visibility.at(nx, ny, 0) - vc) > 0.01f ||
                 std::fabs(gpu.sun_visibility.at(nx, ny, 0) - vg) > 0.01f;
        }
      edge[std::size_t(y) * w + x] = band;
      e.edge_pixels += band;
    }
  auto layer = [&](const Image& g, const Image& c, double& mean, double& p99, double& worst) {
    double avg = 0;
    for (float v : c.pixels()) avg += std::fabs(v);
    avg /= double(c.pixels().size());
    const double floor = std::max(1e-3 * avg, 1e-12);
    double sum = 0;
    std::vector<double> outside;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        for (int ch = 0; ch < 3; ++ch) {
          const double cv = c.at(x, y, ch), gv = g.at(x, y, ch);
          const double err = std::fabs(gv - cv) / std::max(std::fabs(cv), floor);
          sum += err;
          if (!edge[std::size_t(y) * w + x]) outside.push_back(err);
        }
    mean = sum / (3.0 * w * h);
    p99 = percentile(outside, 0.99);
    worst = outside.empty() ? 0 : *std::max_element(outside.begin(), outside.end());
  };
  layer(gpu.transmittance, cpu.transmittance, e.mean_t, e.p99_t, e.max_t);
  layer(gpu.inscatter, cpu.inscatter, e.mean_r, e.p99_r, e.max_r);
  e.pixels = std::size_t(w) * h;
  return e;
}

void maybe_write_images(const std::string& name, const ScatteringLayers& gpu, const ScatteringLayers& cpu) {
  const char* dir = std::getenv("MR_TEST_IMAGES");
  if (!dir || !*dir) return;
  std::filesystem::create_directories(dir);
  const std::filesystem::path d(dir);
  // R scaled so its 99th percentile is white.
  std::vector<float> r(cpu.inscatter.pixels().begin(), cpu.inscatter.pixels().end());
  std::sort(r.begin(), r.end());
  const float scale = r.empty() || r[r.size() * 99 / 100] <= 0 ? 1.0f : 1.0f / r[r.size() * 99 / 100];
  auto scaled = [&](const Image& im) {
    Image out = im;
    for (float& v : out.pixels()) v *= scale;
    return out;
  };
  write_image(d / (name + "_cpu_R.png"), scaled(cpu.inscatter));
  write_image(d / (name + "_gpu_R.png"), scaled(gpu.inscatter));
  write_image(d / (name + "_cpu_T.png"), cpu.transmittance);
  write_image(d / (name + "_gpu_T.png"), gpu.transmittance);
  // Relative error of T, 10 % = white; and the sun visibility of each.
  Image err(cpu.transmittance.width(), cpu.transmittance.height(), 3);
  for (std::size_t i = 0; i < err.pixels().size(); ++i) {
    const float c = cpu.transmittance.pixels()[i], g = gpu.transmittance.pixels()[i];
    err.pixels()[i] = std::fabs(g - c) / std::max(std::fabs(c), 1e-6f) * 10.0f;
  }
  write_image(d / (name + "_err_T.png"), err);
  write_image(d / (name + "_cpu_V.png"), cpu.sun_visibility);
  write_image(d / (name + "_gpu_V.png"), gpu.sun_visibility);
}

}  // namespace mr::vktest
