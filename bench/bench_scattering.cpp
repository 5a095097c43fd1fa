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
//
// BM_Scattering renders through the public API. Its `reuse` argument: 0 = every render builds
// the occluder geometry afresh (the cache of render/occluder_cache.h cleared first), 1 = the
// geometry of the previous render of the same photo is reused (mr-studio slider changes) for the
// same scene again, 2 = the same with the fog's density changed by 1 % for every render (a fog
// slider: the surface's AO and sun-disk answers are reused too, render/surface_query_cache.h),
// 3 = with the sun turned by 0.5 degrees of azimuth for every render (a sun slider: the AO is),
// 4 = as 2 with a draft render of the photo at half the size before each (untimed), as
// mr-studio renders every edit: a small draft pass, then the view's size (both geometries
// stay cached, render/occluder_cache.h).
// BM_Stages runs the CPU core's stages one by one (private headers) and reports each one's wall
// time, the render's process CPU time (user + system, all threads: compare it when other work
// shares the machine) and the occluder triangle count:
//
//   build/bench/mr_bench_scattering --benchmark_filter=BM_Stages --benchmark_repetitions=5
//   --benchmark_report_aggregates_only=true
//
// MR_BENCH_DUMP=<prefix> writes BM_Stages' last R, T and sun visibility (raw floats),
// MR_BENCH_EXACT=1 renders without the gradient acceleration, MR_BENCH_STEPS=<n> with n march
// steps (the reference for the acceleration's error: MR_BENCH_EXACT=1 MR_BENCH_STEPS=128).
// MR_BENCH_GRIDS=1 (BM_Stages, BM_Geometry): the surface's regular pixels as Embree grids
// (OccluderSceneOptions::surface_grids; the Mgrid_px counter says how many pixels).
// MR_BENCH_COMPACT=1 (BM_Stages, BM_Geometry): Embree's compact BVH (OccluderSceneOptions::
// compact), to weigh its smaller build memory against its dearer leaves.
// MR_BENCH_QUALITY=low|medium|high (BM_Stages, BM_Geometry): Embree's build quality
// (OccluderSceneOptions::build_quality; medium is the core's).
//
// BM_Geometry runs the geometry stages alone (normals, mesh, blockers, BVH), with each one's
// CPU time and minor page faults: `perf record` it to profile them.
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <map>
#include <string>
#include <tuple>
#include <utility>

#include "leuven_scene.h"
#include "mr/mr.h"
#include "render/blockers.h"
#include "render/embree_scene.h"
#include "render/occluder_cache.h"
#include "render/occluder_mesh.h"
#include "render/scattering_cpu.h"

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
// with R above 1 % of the mean), and of T (pixels with T above 1 %), computed once per size and
// quality.
struct AccelerationError {
  double r = 0, t = 0;
};
AccelerationError acceleration_error(const Inputs& in, mr::Quality q) {
  static std::map<std::tuple<int, int, int>, AccelerationError> cache;
  const auto key = std::make_tuple(in.camera.width, in.camera.height, int(q));
  if (auto it = cache.find(key); it != cache.end()) return it->second;
  const auto fast = mr::render_scattering(in.photo, in.depth, in.camera, scene(q, true));
  const auto exact = mr::render_scattering(in.photo, in.depth, in.camera, scene(q, false));
  double mean = 0;
  for (float v : exact.inscatter.pixels()) mean += v;
  mean /= double(exact.inscatter.pixels().size());
  AccelerationError result;
  double err = 0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < exact.inscatter.pixels().size(); ++i) {
    const double e = exact.inscatter.pixels()[i];
    if (e < 0.01 * mean) continue;
    err += std::fabs(fast.inscatter.pixels()[i] - e) / e;
    ++n;
  }
  result.r = n ? err / double(n) : 0.0;
  err = 0;
  n = 0;
  for (std::size_t i = 0; i < exact.transmittance.pixels().size(); ++i) {
    const double e = exact.transmittance.pixels()[i];
    if (e < 0.01) continue;
    err += std::fabs(fast.transmittance.pixels()[i] - e) / e;
    ++n;
  }
  result.t = n ? err / double(n) : 0.0;
  return cache[key] = result;
}

void BM_Scattering(benchmark::State& state) {
  const int width = int(state.range(0)), height = int(state.range(1));
  const auto quality = mr::Quality(state.range(2));
  const bool accelerate = state.range(3) != 0;
  const int threads = int(state.range(4));
  const int reuse = int(state.range(5));
  const Inputs& in = inputs(width, height);
  mr::FogScene s = scene(quality, accelerate);
  s.render.threads = threads;
  s.render.backend = mr::Backend::cpu;
  mr::ScatteringLayers::Timings t;
  const mr::FogScene first = s;
  // mr-studio's draft pass (reuse 4): half the size, draft quality.
  const Inputs* half = reuse == 4 ? &inputs(width / 2, height / 2) : nullptr;
  mr::FogScene draft = s;
  draft.render.quality = mr::Quality::draft;
  if (half) mr::render_scattering(half->photo, half->depth, half->camera, draft);
  if (reuse) mr::render_scattering(in.photo, in.depth, in.camera, s);  // builds the geometry
  int renders = 0;
  for (auto _ : state) {
    if (!reuse) {
      state.PauseTiming();
      mr::render::clear_occluder_geometry_cache();
      state.ResumeTiming();
    }
    ++renders;
    if (reuse == 4) {
      state.PauseTiming();
      mr::render_scattering(half->photo, half->depth, half->camera, draft);
      state.ResumeTiming();
    }
    if (reuse == 2 || reuse == 4)
      for (int c = 0; c < 3; ++c)
        s.medium.sigma_t_per_m[c] = first.medium.sigma_t_per_m[c] * float(1 + 0.01 * renders);
    if (reuse == 3)
      s.lighting.sun->direction_to_sun = mr::direction_from_azimuth_elevation(
          mr::bench::kLeuvenSunAzimuthDeg + 0.5 * renders, mr::bench::kLeuvenSunElevationDeg);
    const auto out = mr::render_scattering(in.photo, in.depth, in.camera, s);
    t = out.timings;
    benchmark::DoNotOptimize(out.inscatter.data());
  }
  state.counters["mesh_ms"] = t.mesh_s * 1e3;
  state.counters["bvh_ms"] = t.bvh_s * 1e3;
  state.counters["scatter_ms"] = t.scatter_s * 1e3;
  state.counters["Mrays/s"] = double(t.shadow_rays) / t.scatter_s / 1e6;
  state.counters["exact_%"] = 100.0 * double(t.exact_pixels) / (double(width) * height);
  if (accelerate && threads == 0) {
    const AccelerationError e = acceleration_error(in, quality);
    state.counters["accel_err_%"] = 100.0 * e.r;
    state.counters["accel_err_T_%"] = 100.0 * e.t;
  }
}

// width, height, quality (0 draft, 1 normal, 2 final), acceleration, threads (0 = all), reuse
BENCHMARK(BM_Scattering)
    ->ArgNames({"w", "h", "q", "accel", "threads", "reuse"})
    ->Args({1920, 1080, 0, 1, 0, 0})
    ->Args({1920, 1080, 1, 1, 0, 0})
    ->Args({1920, 1080, 1, 1, 0, 1})
    ->Args({1920, 1080, 1, 1, 0, 2})
    ->Args({1920, 1080, 1, 1, 0, 3})
    ->Args({1920, 1080, 1, 1, 0, 4})
    ->Args({1920, 1080, 1, 0, 0, 0})
    ->Args({1920, 1080, 2, 1, 0, 0})
    ->Args({1920, 1080, 1, 1, 1, 0})
    ->Args({3840, 2160, 0, 1, 0, 0})
    ->Args({3840, 2160, 1, 1, 0, 0})
    ->Args({3840, 2160, 1, 0, 0, 0})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(1);

double process_cpu_s() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

// MR_BENCH_GRIDS=1: BM_Stages and BM_Geometry give the surface's regular pixels to Embree as
// grids (MeshOptions::pixel_layout + OccluderSceneOptions::surface_grids, both off by default).
bool grids_wanted() {
  const char* grids = std::getenv("MR_BENCH_GRIDS");
  return grids && *grids == '1';
}

// The occluder scene's options as BM_Stages and BM_Geometry build it: the core's defaults, or
// what MR_BENCH_GRIDS, MR_BENCH_COMPACT and MR_BENCH_QUALITY ask for.
mr::render::OccluderSceneOptions scene_options_wanted() {
  mr::render::OccluderSceneOptions options;
  options.surface_grids = grids_wanted();
  if (const char* compact = std::getenv("MR_BENCH_COMPACT")) options.compact = *compact == '1';
  if (const char* q = std::getenv("MR_BENCH_QUALITY"))
    options.build_quality = std::string(q) == "low"    ? mr::render::BuildQuality::low
                            : std::string(q) == "high" ? mr::render::BuildQuality::high
                                                       : mr::render::BuildQuality::medium;
  return options;
}

// The CPU core's stages as libmr/src/scattering.cpp runs them on a fresh photo (CPU backend,
// full-resolution mesh, decimated when `merge` is 1 as the core does, the blockers' completion
// on), each timed.
void BM_Stages(benchmark::State& state) {
  using Clock = std::chrono::steady_clock;
  auto since = [](Clock::time_point t) {
    return std::chrono::duration<double>(Clock::now() - t).count();
  };
  const int width = int(state.range(0)), height = int(state.range(1));
  const auto quality = mr::Quality(state.range(2));
  const Inputs& in = inputs(width, height);
  // MR_BENCH_EXACT=1: without the gradient acceleration (with MR_BENCH_DUMP, the reference
  // for the acceleration's error pixel by pixel).
  const char* exact_env = std::getenv("MR_BENCH_EXACT");
  mr::FogScene s = scene(quality, !(exact_env && *exact_env == '1'));
  // MR_BENCH_STEPS=<n>: n march steps instead of the preset's (with MR_BENCH_EXACT=1 and
  // MR_BENCH_DUMP, a many-step reference: the 32-step unaccelerated march is itself noisy).
  if (const char* steps = std::getenv("MR_BENCH_STEPS")) s.render.march_steps = std::atoi(steps);
  s.lighting.sky_radiance = mr::estimate_airlight(in.photo);
  mr::Image transmittance = mr::Image::uninitialized(width, height, 3);
  mr::Image inscatter = mr::Image::uninitialized(width, height, 3);
  mr::Image sun_visibility = mr::Image::uninitialized(width, height, 1);
  mr::Image optical_depth = mr::Image::uninitialized(width, height, 3);
  double normals_s = 0, mesh_s = 0, blockers_s = 0, bvh_s = 0, cpu_s = 0;
  // Process CPU time (all threads) of the geometry (normals, mesh, blockers, BVH) and of the
  // render: comparable across runs on a machine other work shares, where wall times are not.
  double geometry_cpu_s = 0, render_cpu_s = 0;
  std::size_t triangles = 0, grid_pixels = 0;
  mr::render::CoreOutputs out;
  // Minor page faults and system CPU (the kernel zeroing fresh memory: render/huge_pages.h).
  auto usage = [] {
    rusage u;
    getrusage(RUSAGE_SELF, &u);
    return std::make_pair(double(u.ru_minflt),
                          double(u.ru_stime.tv_sec) + 1e-6 * double(u.ru_stime.tv_usec));
  };
  double faults = 0, sys_s = 0;
  for (auto _ : state) {
    const auto usage0 = usage();
    const double cpu0 = process_cpu_s();
    auto t = Clock::now();
    const mr::Image normals = mr::render::estimate_normals(in.depth.view(), in.camera, s.pose);
    normals_s = since(t);
    t = Clock::now();
    mr::render::MeshOptions mesh_options;
    mesh_options.pixel_layout = grids_wanted();
    if (state.range(3) != 0)
      mesh_options.planar_merge_tolerance = mr::render::kCpuPlanarMergeTolerance;
    mr::render::TriangleMesh mesh = mr::render::reconstruct_occluder_mesh(
        in.depth.view(), in.camera, s.pose, mesh_options, normals.view());
    mesh_s = since(t);
    t = Clock::now();
    mr::render::append_blockers(mesh, in.depth.view(), normals.view(), in.camera, s.pose,
                                s.blockers);
    blockers_s = since(t);
    triangles = mesh.triangle_count();
    t = Clock::now();
    const mr::render::OccluderScene occluders(std::move(mesh), scene_options_wanted());
    bvh_s = since(t);
    grid_pixels = occluders.grid_pixel_count();
    const double cpu1 = process_cpu_s();
    geometry_cpu_s = cpu1 - cpu0;
    mr::render::CoreInputs core_in;
    core_in.camera = &in.camera;
    core_in.scene = &s;
    core_in.distance_m = in.depth.view();
    core_in.normals = normals.view();
    core_in.photo = in.photo.view();
    core_in.occluders = &occluders;
    core_in.sky_radiance = *s.lighting.sky_radiance;
    out = mr::render::CoreOutputs{transmittance.view(), inscatter.view(), sun_visibility.view(),
                                  optical_depth.view()};
    mr::render::render_scattering_cpu(core_in, out);
    const double cpu2 = process_cpu_s();
    cpu_s = cpu2 - cpu0;
    render_cpu_s = cpu2 - cpu1;
    const auto usage1 = usage();
    faults = usage1.first - usage0.first;
    sys_s = usage1.second - usage0.second;
  }
  // MR_BENCH_DUMP=<prefix>: the last render's R, T and sun visibility as raw floats
  // (<prefix>.R.f32, ...), to compare two builds' outputs pixel by pixel.
  if (const char* prefix = std::getenv("MR_BENCH_DUMP")) {
    auto dump = [&](const mr::Image& image, const char* name) {
      const std::string path = std::string(prefix) + "." + name + ".f32";
      if (std::FILE* f = std::fopen(path.c_str(), "wb")) {
        std::fwrite(image.data(), sizeof(float), image.pixels().size(), f);
        std::fclose(f);
      }
    };
    dump(inscatter, "R");
    dump(transmittance, "T");
    dump(sun_visibility, "S");
  }
  state.counters["normals_ms"] = normals_s * 1e3;
  state.counters["mesh_ms"] = mesh_s * 1e3;
  state.counters["blockers_ms"] = blockers_s * 1e3;
  state.counters["bvh_ms"] = bvh_s * 1e3;
  state.counters["grid_ms"] = out.grid_s * 1e3;
  state.counters["interp_ms"] = out.interpolation_s * 1e3;
  state.counters["surface_ms"] = out.surface_s * 1e3;
  state.counters["cpu_ms"] = cpu_s * 1e3;
  state.counters["geometry_cpu_ms"] = geometry_cpu_s * 1e3;
  state.counters["render_cpu_ms"] = render_cpu_s * 1e3;
  state.counters["Mtriangles"] = double(triangles) / 1e6;
  state.counters["Mgrid_px"] = double(grid_pixels) / 1e6;
  state.counters["kfaults"] = faults * 1e-3;
  state.counters["sys_ms"] = sys_s * 1e3;
  state.counters["Mrays"] = double(out.shadow_rays) / 1e6;
  state.counters["exact_%"] = 100.0 * double(out.exact_pixels) / (double(width) * height);
}

BENCHMARK(BM_Stages)
    ->ArgNames({"w", "h", "q", "merge"})
    ->Args({1920, 1080, 1, 0})
    ->Args({1920, 1080, 1, 1})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(1);

// The geometry stages of BM_Stages alone (normals, full-resolution mesh, blockers, BVH), each
// with its wall and process CPU time, repeated without the render: for profiling them (perf
// record on this benchmark alone) and for comparing builds of them.
void BM_Geometry(benchmark::State& state) {
  using Clock = std::chrono::steady_clock;
  const int width = int(state.range(0)), height = int(state.range(1));
  const Inputs& in = inputs(width, height);
  mr::FogScene s = scene(mr::Quality::normal, true);
  double wall_s[4] = {0, 0, 0, 0}, cpu_s[4] = {0, 0, 0, 0}, faults[4] = {0, 0, 0, 0};
  // Minor page faults (first touches of fresh memory): most of these stages' CPU time on the
  // development VM before the huge pages of render/huge_pages.h.
  auto minor_faults = [] {
    rusage u;
    getrusage(RUSAGE_SELF, &u);
    return double(u.ru_minflt);
  };
  double sys[4] = {0, 0, 0, 0};
  auto sys_s = [] {
    rusage u;
    getrusage(RUSAGE_SELF, &u);
    return double(u.ru_stime.tv_sec) + 1e-6 * double(u.ru_stime.tv_usec);
  };
  std::size_t triangles = 0;
  for (auto _ : state) {
    int stage = 0;
    auto t = Clock::now();
    double cpu = process_cpu_s(), fault = minor_faults(), kernel = sys_s();
    auto lap = [&] {
      const double c = process_cpu_s(), f = minor_faults(), k = sys_s();
      sys[stage] += k - kernel;
      kernel = k;
      faults[stage] += f - fault;
      fault = f;
      const auto now = Clock::now();
      wall_s[stage] += std::chrono::duration<double>(now - t).count();
      cpu_s[stage] += c - cpu;
      ++stage;
      t = now;
      cpu = c;
    };
    const mr::Image normals = mr::render::estimate_normals(in.depth.view(), in.camera, s.pose);
    lap();
    mr::render::MeshOptions mesh_options;
    mesh_options.pixel_layout = grids_wanted();
    mr::render::TriangleMesh mesh = mr::render::reconstruct_occluder_mesh(
        in.depth.view(), in.camera, s.pose, mesh_options, normals.view());
    lap();
    mr::render::append_blockers(mesh, in.depth.view(), normals.view(), in.camera, s.pose,
                                s.blockers);
    lap();
    triangles = mesh.triangle_count();
    const mr::render::OccluderScene occluders(std::move(mesh), scene_options_wanted());
    lap();
    benchmark::DoNotOptimize(occluders.triangle_count());
    // MR_BENCH_DUMP=<prefix>: the normals and the mesh (<prefix>.normals.f32, .positions.f32,
    // .indices.u32), to check that two builds make the same geometry bit for bit.
    if (const char* prefix = std::getenv("MR_BENCH_DUMP")) {
      auto dump = [&](const void* data, std::size_t bytes, const char* name) {
        const std::string path = std::string(prefix) + "." + name;
        if (std::FILE* f = std::fopen(path.c_str(), "wb")) {
          std::fwrite(data, 1, bytes, f);
          std::fclose(f);
        }
      };
      const mr::render::TriangleMesh& m = occluders.mesh();
      dump(normals.data(), sizeof(float) * normals.pixels().size(), "normals.f32");
      dump(m.positions.data(), sizeof(float) * m.positions.size(), "positions.f32");
      dump(m.indices.data(), sizeof(std::uint32_t) * m.indices.size(), "indices.u32");
    }
  }
  const double n = double(state.iterations());
  const char* names[4] = {"normals", "mesh", "blockers", "bvh"};
  for (int k = 0; k < 4; ++k) {
    state.counters[std::string(names[k]) + "_ms"] = wall_s[k] / n * 1e3;
    state.counters[std::string(names[k]) + "_cpu_ms"] = cpu_s[k] / n * 1e3;
    state.counters[std::string(names[k]) + "_kfaults"] = faults[k] / n * 1e-3;
    state.counters[std::string(names[k]) + "_sys_ms"] = sys[k] / n * 1e3;
  }
  state.counters["cpu_ms"] = (cpu_s[0] + cpu_s[1] + cpu_s[2] + cpu_s[3]) / n * 1e3;
  state.counters["Mtriangles"] = double(triangles) / 1e6;
}

BENCHMARK(BM_Geometry)
    ->ArgNames({"w", "h"})
    ->Args({1920, 1080})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(3);

}  // namespace

BENCHMARK_MAIN();
