// The `mr fog` path split into decode / compute / encode at 2, 12 and 24 MP, against the I/O
// floor: a plain OpenImageIO decode + encode of the same JPEG.
//
//   build/bench/mr_bench_fog --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
//
// The photo is a sample photo (sample_photos/leuven.jpg) resized with OIIO to each size,
// with a synthetic depth map (a ground plane receding to 500 m); files live in a temp folder.
#include <benchmark/benchmark.h>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>

#include <unistd.h>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>

#include "mr/mr.h"

namespace fs = std::filesystem;

namespace {

struct Inputs {
  fs::path photo, depth, folder;
  int width = 0, height = 0;
};

// Sizes in megapixels at 3:2.
const Inputs& inputs_for(int megapixels) {
  static std::map<int, Inputs> cache;
  auto it = cache.find(megapixels);
  if (it != cache.end()) return it->second;
  Inputs in;
  in.folder = fs::temp_directory_path() / ("mr-bench-" + std::to_string(::getpid()));
  fs::create_directories(in.folder);
  in.height = int(std::lround(std::sqrt(megapixels * 1e6 / 1.5)));
  in.width = int(std::lround(in.height * 1.5));
  const fs::path source = fs::path(MR_SOURCE_DIR) / "sample_photos" / "leuven.jpg";
  OIIO::ImageBuf src(source.string());
  OIIO::ImageBuf photo;
  if (src.read()) {
    photo = OIIO::ImageBufAlgo::resize(src, "", 0, OIIO::ROI(0, in.width, 0, in.height, 0, 1, 0, 3));
  } else {  // no sample photo: a gradient
    photo.reset(OIIO::ImageSpec(in.width, in.height, 3, OIIO::TypeDesc::UINT8));
    OIIO::ImageBufAlgo::fill(photo, {0.2f, 0.3f, 0.4f}, {0.2f, 0.3f, 0.4f}, {0.9f, 0.8f, 0.6f}, {0.9f, 0.8f, 0.6f});
  }
  in.photo = in.folder / ("photo" + std::to_string(megapixels) + ".jpg");
  photo.set_write_format(OIIO::TypeDesc::UINT8);
  photo.write(in.photo.string());
  mr::Image depth(in.width, in.height, 1, {"Z"});
  for (int y = 0; y < in.height; ++y) {
    const float d = y < in.height / 3 ? 0.0f : 500.0f / (1.0f + 30.0f * float(y - in.height / 3) / in.height);
    for (int x = 0; x < in.width; ++x) depth.at(x, y, 0) = d;
  }
  in.depth = in.folder / ("depth" + std::to_string(megapixels) + ".exr");
  mr::WriteOptions raw;
  raw.colorspace = mr::colorspace::raw;
  raw.pixel_type = mr::PixelType::float32;
  mr::write_image(in.depth, depth, raw);
  return cache[megapixels] = in;
}

void set_rate(benchmark::State& state, const Inputs& in) {
  state.counters["MP/s"] = benchmark::Counter(in.width * double(in.height) / 1e6,
                                              benchmark::Counter::kIsIterationInvariantRate);
}

mr::FogParams params() {
  mr::FogParams p;
  const float s = float(mr::extinction_from_visibility(150.0));
  p.sigma_t_per_m = {s, s, s};
  return p;  // airlight: auto, as `mr fog` does by default
}

void BM_Decode(benchmark::State& state) {
  const Inputs& in = inputs_for(int(state.range(0)));
  for (auto _ : state) benchmark::DoNotOptimize(mr::read_image(in.photo));
  set_rate(state, in);
}

void BM_DecodeDepth(benchmark::State& state) {
  const Inputs& in = inputs_for(int(state.range(0)));
  const auto cam = mr::Camera::from_horizontal_fov(in.width, in.height, 60.0);
  for (auto _ : state) benchmark::DoNotOptimize(mr::read_depth(in.depth, cam));
  set_rate(state, in);
}

void BM_Compute(benchmark::State& state) {
  const Inputs& in = inputs_for(int(state.range(0)));
  const mr::Image photo = mr::read_image(in.photo);
  const auto depth = mr::read_depth(in.depth, mr::Camera::from_horizontal_fov(in.width, in.height, 60.0));
  for (auto _ : state) benchmark::DoNotOptimize(mr::fog(photo, depth.distance_m, params()));
  set_rate(state, in);
}

void BM_Encode(benchmark::State& state) {
  const Inputs& in = inputs_for(int(state.range(0)));
  const mr::Image photo = mr::read_image(in.photo);
  const fs::path out = in.folder / "out.jpg";
  for (auto _ : state) mr::write_image(out, photo);
  set_rate(state, in);
}

void BM_FogPathTotal(benchmark::State& state) {
  const Inputs& in = inputs_for(int(state.range(0)));
  const fs::path out = in.folder / "fogged.jpg";
  for (auto _ : state) {
    const mr::Image photo = mr::read_image(in.photo);
    const auto depth = mr::read_depth(in.depth, mr::Camera::from_metadata(photo.width(), photo.height(), photo.metadata()));
    mr::write_image(out, mr::fog(photo, depth.distance_m, params()).composite);
  }
  set_rate(state, in);
}

// The floor: OIIO decodes the JPEG to uint8 and encodes it again, no colour or float work.
void BM_OiioDecodeEncodeFloor(benchmark::State& state) {
  const Inputs& in = inputs_for(int(state.range(0)));
  const fs::path out = in.folder / "floor.jpg";
  for (auto _ : state) {
    OIIO::ImageBuf buf(in.photo.string());
    buf.read(0, 0, true, OIIO::TypeDesc::UINT8);
    buf.write(out.string());
  }
  set_rate(state, in);
}

// The sky light by direction of the haze look (mr::sky_light_from_photo with the brightness
// scale and tint: issue 11), which `mr fog` computes once per photo before the streamed fog: a
// synthetic 4:3 photo, 60 % sky with cloud-like texture over a tilted ground line, width in px.
void BM_SkyLight(benchmark::State& state) {
  const int w = int(state.range(0)), h = w * 3 / 4;
  const mr::Camera camera = mr::Camera::from_horizontal_fov(w, h, 60);
  mr::Image photo(w, h, 3), distance(w, h, 1);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const bool sky = y < h * 0.6 - 0.1 * x * h / w;
      const double c = 0.3 + 0.4 * std::sin(x * 0.03 * 1280 / w) * std::cos(y * 0.02 * 1280 / w);
      for (int k = 0; k < 3; ++k) photo.at(x, y, k) = float(std::clamp(c + 0.1 * k, 0.0, 1.0));
      distance.at(x, y, 0) = sky ? std::numeric_limits<float>::infinity() : 100.0f;
    }
  mr::FogScene scene;  // the gallery's haze look: 2 km visibility in a 1.5 km layer, g = 0.6
  const float sigma = float(mr::extinction_from_visibility(2000));
  scene.medium.sigma_t_per_m = {sigma, sigma, sigma};
  scene.medium.g = 0.6;
  scene.medium.layer_top_m = 1500;
  for (auto _ : state) {
    const mr::SkyLight light =
        mr::sky_light_from_photo(photo, distance, camera, scene, {0.5, 0.6, 0.8});
    benchmark::DoNotOptimize(light.scale.pixels().data());
  }
  state.counters["MP"] = double(w) * h / 1e6;
}
BENCHMARK(BM_SkyLight)
    ->Arg(1280)
    ->Arg(4000)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(2);

#define MR_SIZES ->Arg(2)->Arg(12)->Arg(24)->Unit(benchmark::kMillisecond)->UseRealTime()
BENCHMARK(BM_Decode) MR_SIZES;
BENCHMARK(BM_DecodeDepth) MR_SIZES;
BENCHMARK(BM_Compute) MR_SIZES;
BENCHMARK(BM_Encode) MR_SIZES;
BENCHMARK(BM_FogPathTotal) MR_SIZES;
BENCHMARK(BM_OiioDecodeEncodeFloor) MR_SIZES;

struct Cleanup {
  ~Cleanup() {
    std::error_code ec;
    fs::remove_all(fs::temp_directory_path() / ("mr-bench-" + std::to_string(::getpid())), ec);
  }
} cleanup;

}  // namespace

BENCHMARK_MAIN();
