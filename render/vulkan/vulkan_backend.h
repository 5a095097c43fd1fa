// Private to libmr: the scattering core on Vulkan compute (DESIGN.md sections 2, 3, 7), one of
// the backends behind render/backend.h. It reproduces the CPU backend (render/cpu_backend.h,
// render_scattering_cpu) on a GPU: the same march, closed
// forms and gradient acceleration (shaders/scattering_common.glsl), with volumetric shadows from
// shadow maps of the occluder mesh instead of Embree rays (see README "Vulkan backend").
//
// No Vulkan type appears here: the loader is opened at run time, so libmr runs (on the CPU)
// where Vulkan is missing.
#pragma once

#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include "render/backend.h"
#include "render/occluder_mesh.h"

namespace mr::render::vulkan {

/// No usable Vulkan here: no loader, no driver or device, a device without what the backend
/// needs, or out of (device) memory. The dispatcher falls back to the CPU on it (backend auto).
class Unavailable : public BackendUnavailable {
 public:
  explicit Unavailable(const std::string& message) : BackendUnavailable("vulkan: " + message) {}
};

struct BackendOptions {
  /// Largest tile (output pixels per dispatch); 0 = from the device's limits. Images larger
  /// than a tile are rendered tile by tile, with the same result. With a cancel token
  /// (CoreInputs::cancel) 0 means at most 2^16 pixels, so a cancel waits for one small tile.
  std::size_t max_tile_pixels = 0;
  /// Shadow-map size in texels (each sun cascade, each lamp cube face); 0 = from the image
  /// size and quality.
  int shadow_map_size = 0;
};

/// Where the time went (seconds). gpu_*: timestamp queries on the device; host_*: the host's
/// copies into and out of staging memory.
struct BackendTimings {
  double gpu_upload_s = 0, gpu_shadow_maps_s = 0, gpu_scatter_s = 0, gpu_download_s = 0;
  double host_upload_s = 0, host_download_s = 0;
  int tiles = 0;
  int shadow_layers = 0;
  int shadow_map_size = 0;
};

struct DeviceInfo {
  std::string name;          ///< e.g. "llvmpipe (LLVM 15.0.6, 256 bits)"
  std::string type;          ///< "discrete GPU", "integrated GPU", "virtual GPU", "CPU", "other"
  bool cpu_implementation = false;  ///< a software rasterizer (lavapipe / SwiftShader)
};

class Backend final : public ScatteringBackend {
 public:
  /// The process-wide backend, created on first use (instance, device, pipelines). Throws
  /// Unavailable (the same message again on later calls) when there is no usable device.
  /// Device choice: discrete > integrated > virtual > CPU implementation, unless
  /// $MR_VULKAN_DEVICE names (a substring of) a device. $MR_VULKAN_VALIDATION=1 enables the
  /// Khronos validation layer and counts its warnings and errors (validation_messages()).
  static Backend& shared();
  /// shared(), for Backend::automatic: throws Unavailable when the best device is a CPU
  /// implementation, found out before any device is created (a probe of ~0.1 s instead of a
  /// device and its pipelines); a later shared() may still create that device.
  static Backend& shared_hardware();

  ~Backend() override;
  Backend(const Backend&) = delete;
  Backend& operator=(const Backend&) = delete;

  const DeviceInfo& device() const;

  // ScatteringBackend: "vulkan: <device name>"; the normals and the full-resolution occluder
  // mesh (rasterized into shadow maps, cheap at any resolution: from the coarse draft mesh, whose
  // surface lies up to a fine pixel's depth step in front of the ground, 23 % of a flat sunlit
  // ground shadowed itself, issue 13); render() below with the default options.
  std::string name() const override;
  void prepare_occluders(const CoreInputs& in, Occluders& occluders,
                         FrameTimings& timings) override;
  void render(const CoreInputs& in, Occluders& occluders, CoreOutputs& out,
              FrameTimings& timings) override;

  /// Renders every pixel of `out` like render_scattering_cpu(in, out). `mesh`: the occluder mesh
  /// (nullptr or empty: nothing casts shadows; in.occluders is ignored). Thread-safe (renders
  /// are serialised). Throws Unavailable (e.g. out of device memory) or mr::Error; cancelled
  /// (in.cancel requested; checked before the shadow maps and each tile) leaves `out` partial.
  void render(const CoreInputs& in, const TriangleMesh* mesh, CoreOutputs& out,
              const BackendOptions& options = {}, BackendTimings* timings = nullptr);

  /// Validation-layer warnings and errors so far (0 without $MR_VULKAN_VALIDATION), and the
  /// first few of their messages.
  std::size_t validation_messages() const;
  std::string validation_log() const;
  bool validation_enabled() const;

  struct Impl;

 private:
  friend std::vector<float> echo_parameter_layout(const void*, std::size_t, const void*, std::size_t,
                                                  const void*, std::size_t, std::size_t);
  explicit Backend(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// For tests/vulkan_layout_test.cpp: runs shaders/layout_check.comp on the shared backend with
/// these bytes as its ScatterParams, GpuLamp[2] and ShadowLayer[2] buffers, and returns the
/// `out_vec4s` vec4s it wrote (every member, as GLSL read it).
std::vector<float> echo_parameter_layout(const void* params, std::size_t params_bytes, const void* lamps,
                                         std::size_t lamps_bytes, const void* layers, std::size_t layers_bytes,
                                         std::size_t out_vec4s);

}  // namespace mr::render::vulkan
