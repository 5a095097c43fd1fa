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

#include <cmath>
#include <filesystem>
#include <map>
#include <unistd.h>

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
