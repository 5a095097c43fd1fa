// The scattering core on a real photo with its depth map and a low sun casting shafts, at
// 1920x1080 and 3840x2160, per quality preset; with the speed-up and the error of the gradient
// acceleration (against the same march without it), shadow rays per second, and scaling with
// the thread count.
//
//   build/bench/mr_bench_scattering --benchmark_repetitions=3
//   --benchmark_report_aggregates_only=true
//
// Scene: sample_photos/leuven.jpg + leuven_depth.exr (hfov 60 deg, camera 1.6 m above the
// street, horizon at row 362 of 563: pitch +7.05 deg), resized with OIIO (depth: nearest, so
// discontinuities stay sharp); a fog bank 15 m deep of 120 m visibility, albedo 0.9, g 0.5, sun
// at azimuth -70, elevation 18 degrees, sky radiance from the photo.
#include <benchmark/benchmark.h>

#include <cmath>
#include <map>
#include <tuple>

#include "leuven_scene.h"
#include "mr/mr.h"

namespace {

using mr::bench::Inputs;

const Inputs& inputs(int width, int height) {
  return mr::bench::leuven_inputs(width, height);
}

mr::FogScene scene(mr::Quality quality, bool accelerate) {
  mr::FogScene s = mr::bench::leuven_sun_scene(quality);
  s.render.gradient_acceleration = accelerate;
  return s;
}

// Mean relative error of R with the acceleration against the same march without it (pixels
// with R above 1 % of the mean), computed once per size and quality.
double acceleration_error(const Inputs& in, mr::Quality q) {
  static std::map<std::tuple<int, int, int>, double> cache;
  const auto key = std::make_tuple(in.camera.width, in.camera.height, int(q));
  if (auto it = cache.find(key); it != cache.end()) return it->second;
  const auto fast = mr::render_scattering(in.photo, in.depth, in.camera, scene(q, true));
  const auto exact = mr::render_scattering(in.photo, in.depth, in.camera, scene(q, false));
  double mean = 0;
  for (float v : exact.inscatter.pixels()) mean += v;
  mean /= double(exact.inscatter.pixels().size());
  double err = 0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < exact.inscatter.pixels().size(); ++i) {
    const double e = exact.inscatter.pixels()[i];
    if (e < 0.01 * mean) continue;
    err += std::fabs(fast.inscatter.pixels()[i] - e) / e;
    ++n;
  }
  return cache[key] = n ? err / double(n) : 0.0;
}

void BM_Scattering(benchmark::State& state) {
  const int width = int(state.range(0)), height = int(state.range(1));
  const auto quality = mr::Quality(state.range(2));
  const bool accelerate = state.range(3) != 0;
  const int threads = int(state.range(4));
  const Inputs& in = inputs(width, height);
  mr::FogScene s = scene(quality, accelerate);
  s.render.threads = threads;
  mr::ScatteringLayers::Timings t;
  for (auto _ : state) {
    const auto out = mr::render_scattering(in.photo, in.depth, in.camera, s);
    t = out.timings;
    benchmark::DoNotOptimize(out.inscatter.data());
  }
  state.counters["mesh_ms"] = t.mesh_s * 1e3;
  state.counters["bvh_ms"] = t.bvh_s * 1e3;
  state.counters["scatter_ms"] = t.scatter_s * 1e3;
  state.counters["Mrays/s"] = double(t.shadow_rays) / t.scatter_s / 1e6;
  state.counters["exact_%"] = 100.0 * double(t.exact_pixels) / (double(width) * height);
  if (accelerate && threads == 0)
    state.counters["accel_err_%"] = 100.0 * acceleration_error(in, quality);
}

// width, height, quality (0 draft, 1 normal, 2 final), acceleration, threads (0 = all)
BENCHMARK(BM_Scattering)
    ->ArgNames({"w", "h", "q", "accel", "threads"})
    ->Args({1920, 1080, 0, 1, 0})
    ->Args({1920, 1080, 1, 1, 0})
    ->Args({1920, 1080, 1, 0, 0})
    ->Args({1920, 1080, 2, 1, 0})
    ->Args({1920, 1080, 1, 1, 1})
    ->Args({3840, 2160, 0, 1, 0})
    ->Args({3840, 2160, 1, 1, 0})
    ->Args({3840, 2160, 1, 0, 0})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(1);

}  // namespace

BENCHMARK_MAIN();
