// Helpers for the Vulkan backend's tests: scenes, and the GPU-vs-CPU comparison of the issue's
// acceptance bar (mean relative error of T and R over all pixels; 99th percentile outside
// one-pixel bands at shadow edges).
#pragma once

#include <gtest/gtest.h>

#include <cstdlib>
#include <string>

#include "mr/scattering.h"
#include "render/vulkan/vulkan_backend.h"

namespace mr::vktest {

/// Tests run on lavapipe unless $MR_VULKAN_DEVICE says otherwise (an empty value: the best
/// device), with the Khronos validation layer on unless $MR_VULKAN_VALIDATION=0.
inline void configure_environment() {
  setenv("MR_VULKAN_DEVICE", "llvmpipe", 0);
  setenv("MR_VULKAN_VALIDATION", "1", 0);
}

/// The shared backend, or nullptr (and the test is skipped by the caller) when there is none.
render::vulkan::Backend* backend_or_null(std::string* why);

/// Fails the current test if the validation layer reported anything.
void expect_validation_clean();

struct Errors {
  double mean_t = 0, mean_r = 0;  ///< mean relative error over all pixels and channels
  double p99_t = 0, p99_r = 0;    ///< 99th percentile outside the shadow-edge bands
  double max_t = 0, max_r = 0;    ///< outside the bands, for the record
  std::size_t pixels = 0, edge_pixels = 0;
};

/// Relative error |g - c| / max(|c|, floor), floor = 1e-3 of the layer's mean. A pixel is in a
/// shadow-edge band when the sun visibility (either backend's) differs within its 3x3
/// neighbourhood, or between the two backends.
Errors compare(const ScatteringLayers& gpu, const ScatteringLayers& cpu);

/// Writes <name>_{cpu,gpu}_{T,R}.png to $MR_TEST_IMAGES (if set), for looking at results.
void maybe_write_images(const std::string& name, const ScatteringLayers& gpu, const ScatteringLayers& cpu);

}  // namespace mr::vktest
