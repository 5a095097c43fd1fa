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

#include <cmath>
#include <cstdio>
#include <map>

#include "leuven_scene.h"
#include "mr/mr.h"

namespace {

using mr::bench::Inputs;

const Inputs& inputs(int width, int height) {
  return mr::bench::leuven_inputs(width, height);
}

mr::FogScene scene(mr::Quality quality, mr::Backend backend) {
  mr::FogScene s = mr::bench::leuven_sun_scene(quality);
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
  state.counters["mesh_ms"] = t.mesh_s * 1e3;        // CPU: depth -> normals + occluder mesh
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
