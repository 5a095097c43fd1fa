// The Vulkan scattering backend on whatever Vulkan device runs it ($MR_VULKAN_DEVICE picks one by
// name; lavapipe on a machine without a GPU): the same scene as bench_scattering (leuven.jpg with
// its depth map, a 15 m fog bank of 120 m visibility, a low sun casting shafts), at 1920x1080 and
// 3840x2160, normal and final quality, with the GPU time split into upload / shadow maps /
// scattering / download (timestamp queries; upload and download include the host's staging
// copies), the CPU's mesh reconstruction beside it, and the CPU backend in the same session.
//
//   build/bench/mr_bench_vulkan --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
//   build/bench/mr_bench_vulkan --benchmark_filter='w:1920/h:1080/q:1'   # 1080p normal only
#include <benchmark/benchmark.h>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>

#include "mr/mr.h"

namespace fs = std::filesystem;

namespace {

struct Inputs {
  mr::Image photo, depth;
  mr::Camera camera;
};

mr::Image to_image(const OIIO::ImageBuf& buf) {
  const auto& spec = buf.spec();
  mr::Image im(spec.width, spec.height, spec.nchannels);
  buf.get_pixels(buf.roi(), OIIO::TypeDesc::FLOAT, im.data());
  return im;
}

const Inputs& inputs(int width, int height) {
  static std::map<std::pair<int, int>, Inputs> cache;
  const auto key = std::make_pair(width, height);
  if (auto it = cache.find(key); it != cache.end()) return it->second;
  const fs::path dir = fs::path(MR_SOURCE_DIR) / "sample_photos";
  const mr::Image photo = mr::read_image(dir / "leuven.jpg");
  mr::ReadOptions raw;
  raw.to_scene_linear = false;
  raw.reject_non_finite = false;
  const mr::Image depth = mr::read_image(dir / "leuven_depth.exr", raw);
  OIIO::ImageBuf photo_buf(OIIO::ImageSpec(photo.width(), photo.height(), 3, OIIO::TypeDesc::FLOAT),
                           const_cast<float*>(photo.data()));
  OIIO::ImageBuf depth_buf(OIIO::ImageSpec(depth.width(), depth.height(), 1, OIIO::TypeDesc::FLOAT),
                           const_cast<float*>(depth.data()));
  Inputs in;
  in.photo = to_image(OIIO::ImageBufAlgo::resize(photo_buf, "", 0, OIIO::ROI(0, width, 0, height, 0, 1, 0, 3)));
  in.depth = to_image(OIIO::ImageBufAlgo::resample(depth_buf, false, OIIO::ROI(0, width, 0, height, 0, 1, 0, 1)));
  in.depth.set_channel_names({"Z"});
  for (float& d : in.depth.pixels())
    if (!(d > 0) || !std::isfinite(d)) d = INFINITY;
  in.camera = mr::Camera::from_horizontal_fov(width, height, 60.0);
  return cache[key] = std::move(in);
}

mr::FogScene scene(mr::Quality quality, mr::Backend backend) {
  mr::FogScene s;
  const float sigma = float(mr::extinction_from_visibility(120.0));
  s.medium.sigma_t_per_m = {sigma, sigma, sigma};
  s.medium.albedo = {0.9f, 0.9f, 0.9f};
  s.medium.g = 0.5;
  s.medium.layer_bottom_m = 0;
  s.medium.layer_top_m = 15;
  s.pose.pitch_deg = 7.05;
  s.lighting.sun = mr::Sun{mr::direction_from_azimuth_elevation(-70, 18), {4, 3.8f, 3.4f}, 0.27};
  s.render.quality = quality;
  s.render.backend = backend;
  return s;
}

void BM_Vulkan(benchmark::State& state) {
  const int width = int(state.range(0)), height = int(state.range(1));
  const auto quality = mr::Quality(state.range(2));
  const auto backend = state.range(3) ? mr::Backend::vulkan : mr::Backend::cpu;
  const Inputs& in = inputs(width, height);
  const mr::FogScene s = scene(quality, backend);
  mr::ScatteringLayers::Timings t;
  std::string device;
  try {
    for (auto _ : state) {
      const auto out = mr::render_scattering(in.photo, in.depth, in.camera, s);
      t = out.timings;
      device = out.backend;
      benchmark::DoNotOptimize(out.inscatter.data());
    }
  } catch (const mr::Error& e) {
    state.SkipWithError(e.what());
    return;
  }
  state.SetLabel(device);
  state.counters["mesh_ms"] = t.mesh_s * 1e3;  // CPU: depth -> normals + occluder mesh
  state.counters["scatter_ms"] = t.scatter_s * 1e3;  // the backend call, wall time
  if (backend == mr::Backend::vulkan) {
    state.counters["upload_ms"] = t.upload_s * 1e3;
    state.counters["shadow_ms"] = t.shadow_maps_s * 1e3;
    state.counters["gpu_scatter_ms"] = t.gpu_scatter_s * 1e3;
    state.counters["download_ms"] = t.download_s * 1e3;
    state.counters["tiles"] = t.tiles;
  }
}

// width, height, quality (1 normal, 2 final), backend (1 vulkan, 0 cpu: the peer in this session)
BENCHMARK(BM_Vulkan)
    ->ArgNames({"w", "h", "q", "vk"})
    ->Args({1920, 1080, 1, 1})
    ->Args({1920, 1080, 1, 0})
    ->Args({1920, 1080, 2, 1})
    ->Args({3840, 2160, 1, 1})
    ->Args({3840, 2160, 1, 0})
    ->Args({3840, 2160, 2, 1})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(1);

}  // namespace
BENCHMARK_MAIN();
