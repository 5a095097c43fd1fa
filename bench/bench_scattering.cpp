// The scattering core on a real photo with its depth map and a low sun casting shafts, at
// 1920x1080 and 3840x2160, per quality preset; with the speed-up and the error of the gradient
// acceleration (against the same march without it), shadow rays per second, and scaling with
// the thread count.
//
//   build/bench/mr_bench_scattering --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
//
// Scene: sample_photos/leuven.jpg + leuven_depth.exr (hfov 60 deg, camera 1.6 m above the
// street, horizon at row 362 of 563: pitch +7.05 deg), resized with OIIO (depth: nearest, so
// discontinuities stay sharp); a fog bank 15 m deep of 120 m visibility, albedo 0.9, g 0.5, sun
// at azimuth -70, elevation 18 degrees, sky radiance from the photo.
#include <benchmark/benchmark.h>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>

#include <cmath>
#include <filesystem>
#include <map>
#include <tuple>

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
  auto key = std::make_pair(width, height);
  if (auto it = cache.find(key); it != cache.end()) return it->second;
  const fs::path dir = fs::path(MR_SOURCE_DIR) / "sample_photos";
  const mr::Image photo = mr::read_image(dir / "leuven.jpg");  // scene-linear
  mr::ReadOptions raw;
  raw.to_scene_linear = false;
  raw.reject_non_finite = false;
  const mr::Image depth = mr::read_image(dir / "leuven_depth.exr", raw);
  OIIO::ImageBuf photo_buf(OIIO::ImageSpec(photo.width(), photo.height(), 3, OIIO::TypeDesc::FLOAT),
                           const_cast<float*>(photo.data()));
  OIIO::ImageBuf depth_buf(OIIO::ImageSpec(depth.width(), depth.height(), 1, OIIO::TypeDesc::FLOAT),
                           const_cast<float*>(depth.data()));
  const OIIO::ROI roi(0, width, 0, height, 0, 1, 0, 3);
  Inputs in;
  in.photo = to_image(OIIO::ImageBufAlgo::resize(photo_buf, "", 0, roi));
  in.depth = to_image(OIIO::ImageBufAlgo::resample(depth_buf, false, OIIO::ROI(0, width, 0, height, 0, 1, 0, 1)));
  in.depth.set_channel_names({"Z"});
  for (float& d : in.depth.pixels())
    if (!(d > 0) || !std::isfinite(d)) d = INFINITY;
  in.camera = mr::Camera::from_horizontal_fov(width, height, 60.0);
  return cache[key] = std::move(in);
}

mr::FogScene scene(mr::Quality quality, bool accelerate) {
  mr::FogScene s;
  const float sigma = float(mr::extinction_from_visibility(120.0));
  s.medium.sigma_t_per_m = {sigma, sigma, sigma};
  s.medium.albedo = {0.9f, 0.9f, 0.9f};
  s.medium.g = 0.5;
  s.medium.layer_bottom_m = 0;  // a fog bank 15 m deep: sunlight enters through its top
  s.medium.layer_top_m = 15;
  s.pose.pitch_deg = 7.05;
  s.lighting.sun = mr::Sun{mr::direction_from_azimuth_elevation(-70, 18), {4, 3.8, 3.4}, 0.27};
  s.render.quality = quality;
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
  if (accelerate && threads == 0) state.counters["accel_err_%"] = 100.0 * acceleration_error(in, quality);
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
