// Issue 16: inserting a ~100k-triangle model (a UV sphere of 224 x 224 quads, 99 904 triangles)
// into a 12 MP photo (4000 x 3000; ground, a side wall, a back wall at 30 m) under sun and sky:
// the full-quality render (16 camera rays, 16 sun and 64 sky rays per pixel, full-resolution
// occluder mesh) and the interactive preview at preview resolution (1000 x 750: 1 camera ray,
// 1 sun and 8 sky rays in a fixed pattern, occluder mesh at half that) through insert_objects.
// Each iteration is a first frame: normals, occluder mesh, both BVHs and the render. Run:
//   build/bench/mr_bench_insert --benchmark_repetitions=3
// and read the CPU column (the machine is shared; wall times mean little there).
//
// mr-studio's preview is an mr::InsertPreview: the photo's part (normals, occluder mesh, BVH,
// tile bounds) is made once per photo (BM_PreviewPrepare), then each frame builds the objects'
// scene when they changed and shades only the screen tiles the objects and their shadows can
// touch: BM_PreviewFirstFrame (the model dropped on a prepared photo), BM_PreviewDrag (a frame
// of a drag: the model 5 cm further each frame, the draft settings), BM_PreviewRefine (the idle
// refinement at the same placement: 2 x 2 camera rays, 8 sun and 32 sky rays). The frames run at
// the bench's preview size (1000 x 750) and at mr-studio's draft size (577 x 433 = 0.25 MP, what
// a drag shows there).
#include <benchmark/benchmark.h>

#include <cmath>
#include <limits>
#include <memory>
#include <vector>

#include "../tests/insert_test_meshes.h"
#include "mr/insert.h"

namespace {

struct Photo {
  mr::Camera camera;
  mr::Image photo, distance_m;
};

// Analytic depth: ground y = 0, a wall x = 6 (z in 4..40), a back wall z = 30; the photo a
// smooth pattern (its values do not change the work).
Photo make_photo(int width, int height) {
  Photo p;
  p.camera = mr::Camera::from_horizontal_fov(width, height, 60);
  mr::CameraPose pose;
  pose.position_m = {0, 1.6, 0};
  pose.pitch_deg = -8;
  p.photo = mr::Image::uninitialized(width, height, 3);
  p.distance_m = mr::Image::uninitialized(width, height, 1);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const mr::Vec3 d = pose.ray_direction(p.camera, x, y);
      double t = std::numeric_limits<double>::infinity();
      if (d.y < 0) t = std::min(t, -1.6 / d.y);
      if (d.z > 0) t = std::min(t, 30 / d.z);
      if (d.x > 0) {
        const double tw = 6 / d.x;
        const double z = tw * d.z;
        if (z > 4 && z < 40 && 1.6 + tw * d.y < 8) t = std::min(t, tw);
      }
      p.distance_m.view().at(x, y, 0) = float(t);
      for (int c = 0; c < 3; ++c)
        p.photo.view().at(x, y, c) =
            0.2f + 0.1f * float(c) + 0.05f * std::sin(0.01f * float(x + y));
    }
  return p;
}

mr::FogScene make_scene() {
  mr::FogScene s;
  s.pose.position_m = {0, 1.6, 0};
  s.pose.pitch_deg = -8;
  s.lighting.sun = mr::Sun{mr::direction_from_azimuth_elevation(125, 38), {3, 3, 3}, 0.27};
  s.lighting.sky_radiance = mr::Rgb{0.3f, 0.35f, 0.45f};
  return s;
}

std::vector<mr::InsertObject> model() {
  mr::InsertObject o;
  o.mesh = mr::test::uv_sphere(1.0, 224, 224, {0.7f, 0.4f, 0.3f}, 0.5f);
  o.placement.position_m = {0.5, 1.0, 9};
  return {o};
}

void BM_InsertFull12MP(benchmark::State& state) {
  static const Photo p = make_photo(4000, 3000);
  const mr::FogScene scene = make_scene();
  const auto objects = model();
  mr::InsertOptions options;
  for (auto _ : state) {
    mr::InsertResult r =
        mr::insert_objects(p.photo, p.distance_m, p.camera, scene, objects, options);
    benchmark::DoNotOptimize(r.composite.data());
    state.counters["mesh_s"] = r.timings.mesh_s;
    state.counters["render_s"] = r.timings.render_s;
    state.counters["triangles"] = double(r.timings.triangles);
  }
}
BENCHMARK(BM_InsertFull12MP)->Unit(benchmark::kMillisecond)->MeasureProcessCPUTime()->Iterations(1);

void BM_InsertPreview(benchmark::State& state) {
  static const Photo p = make_photo(1000, 750);
  const mr::FogScene scene = make_scene();
  const auto objects = model();
  const mr::InsertOptions options = mr::InsertOptions::preview();
  for (auto _ : state) {
    mr::InsertResult r =
        mr::insert_objects(p.photo, p.distance_m, p.camera, scene, objects, options);
    benchmark::DoNotOptimize(r.composite.data());
    state.counters["mesh_s"] = r.timings.mesh_s;
    state.counters["render_s"] = r.timings.render_s;
  }
}
BENCHMARK(BM_InsertPreview)->Unit(benchmark::kMillisecond)->MeasureProcessCPUTime();

void BM_PreviewPrepare(benchmark::State& state) {
  const Photo p = make_photo(int(state.range(0)), int(state.range(1)));
  const mr::FogScene scene = make_scene();
  for (auto _ : state) {
    mr::InsertPreview preview(p.photo, p.distance_m, p.camera, scene, mr::InsertOptions::preview());
    benchmark::DoNotOptimize(&preview);
  }
}
BENCHMARK(BM_PreviewPrepare)
    ->Args({1000, 750})
    ->Args({577, 433})
    ->Unit(benchmark::kMillisecond)
    ->MeasureProcessCPUTime();

void BM_PreviewFirstFrame(benchmark::State& state) {
  const Photo p = make_photo(int(state.range(0)), int(state.range(1)));
  const mr::FogScene scene = make_scene();
  const auto objects = model();
  for (auto _ : state) {
    state.PauseTiming();
    auto preview = std::make_unique<mr::InsertPreview>(p.photo, p.distance_m, p.camera, scene,
                                                       mr::InsertOptions::preview());
    state.ResumeTiming();
    const mr::InsertResult& r = preview->render(objects, mr::InsertOptions::preview());
    benchmark::DoNotOptimize(r.composite.data());
    const auto& f = preview->last_frame();
    state.counters["objects_s"] = f.objects_s;
    state.counters["render_s"] = f.render_s;
    state.counters["tiles"] = double(f.tiles_rendered);
    state.counters["tiles_total"] = double(f.tiles_total);
    state.PauseTiming();
    preview.reset();
    state.ResumeTiming();
  }
}
BENCHMARK(BM_PreviewFirstFrame)
    ->Args({1000, 750})
    ->Args({577, 433})
    ->Unit(benchmark::kMillisecond)
    ->MeasureProcessCPUTime();

void BM_PreviewDrag(benchmark::State& state) {
  const Photo p = make_photo(int(state.range(0)), int(state.range(1)));
  const mr::FogScene scene = make_scene();
  auto objects = model();
  mr::InsertPreview preview(p.photo, p.distance_m, p.camera, scene, mr::InsertOptions::preview());
  preview.render(objects, mr::InsertOptions::preview());
  int frame = 0;
  for (auto _ : state) {
    objects[0].placement.position_m.x = 0.5 + 0.05 * double(++frame % 40);
    const mr::InsertResult& r = preview.render(objects, mr::InsertOptions::preview());
    benchmark::DoNotOptimize(r.composite.data());
    const auto& f = preview.last_frame();
    state.counters["objects_s"] = f.objects_s;
    state.counters["render_s"] = f.render_s;
    state.counters["tiles"] = double(f.tiles_rendered);
    state.counters["reset"] = double(f.tiles_reset);
  }
}
BENCHMARK(BM_PreviewDrag)
    ->Args({1000, 750})
    ->Args({577, 433})
    ->Unit(benchmark::kMillisecond)
    ->MeasureProcessCPUTime();

// A frame at an unchanged placement with the draft settings (the objects' scene reused): the
// tiles' shading alone.
void BM_PreviewStill(benchmark::State& state) {
  const Photo p = make_photo(int(state.range(0)), int(state.range(1)));
  const mr::FogScene scene = make_scene();
  const auto objects = model();
  mr::InsertPreview preview(p.photo, p.distance_m, p.camera, scene, mr::InsertOptions::preview());
  preview.render(objects, mr::InsertOptions::preview());
  for (auto _ : state) {
    const mr::InsertResult& r = preview.render(objects, mr::InsertOptions::preview());
    benchmark::DoNotOptimize(r.composite.data());
    state.counters["shadow_rays"] = double(r.timings.shadow_rays);
    state.counters["camera_rays"] = double(r.timings.camera_rays);
  }
}
BENCHMARK(BM_PreviewStill)
    ->Args({1000, 750})
    ->Args({577, 433})
    ->Unit(benchmark::kMillisecond)
    ->MeasureProcessCPUTime();

void BM_PreviewRefine(benchmark::State& state) {
  static const Photo p = make_photo(1000, 750);
  const mr::FogScene scene = make_scene();
  const auto objects = model();
  mr::InsertPreview preview(p.photo, p.distance_m, p.camera, scene, mr::InsertOptions::preview());
  preview.render(objects, mr::InsertOptions::preview());
  for (auto _ : state) {
    const mr::InsertResult& r = preview.render(objects, mr::InsertOptions::preview_refined());
    benchmark::DoNotOptimize(r.composite.data());
    state.counters["render_s"] = preview.last_frame().render_s;
    state.counters["rebuilt"] = preview.last_frame().objects_rebuilt;
  }
}
BENCHMARK(BM_PreviewRefine)->Unit(benchmark::kMillisecond)->MeasureProcessCPUTime();

}  // namespace

BENCHMARK_MAIN();
