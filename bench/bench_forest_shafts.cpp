// Shafts in a forest (the slow case of the sun bank look on photos of trees): the CPU core on
// tests/scattering_scenes.h's forest_depth (300 thin trunks with branches) under issue 11's sun
// bank (sun 8 degrees up in front of the camera, height fog of 90 m visibility), where nearly
// every grid cell has a shadow edge. Prints the render's process CPU time (user + system, all
// threads: comparable on a machine other work shares), the passes' wall times, the exact pixels
// and the shadow rays; with --reference, the mean relative error of R against the same scene
// marched exactly at every pixel with that many steps (cached in a file, it is slow).
//
//   build/bench/mr_bench_forest_shafts [--width 1280] [--height 720] [--runs 1]
//       [--reference 512 --reference-file /tmp/forest_ref_1280.f32] [--dump R.f32]
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <string>
#include <vector>

#include "mr/mr.h"
#include "render/blockers.h"
#include "render/embree_scene.h"
#include "render/occluder_mesh.h"
#include "render/scattering_cpu.h"
#include "tests/scattering_scenes.h"

namespace {

double process_cpu_s() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

struct Result {
  mr::Image inscatter;
  mr::render::CoreOutputs out;
  double render_cpu_s = 0;
};

Result render(const mr::Image& depth, const mr::Camera& cam, const mr::FogScene& s) {
  const mr::Image normals = mr::render::estimate_normals(depth.view(), cam, s.pose);
  mr::render::TriangleMesh mesh =
      mr::render::reconstruct_occluder_mesh(depth.view(), cam, s.pose, {}, normals.view());
  mr::render::append_blockers(mesh, depth.view(), normals.view(), cam, s.pose, s.blockers);
  const mr::render::OccluderScene occluders(std::move(mesh));
  Result r;
  r.inscatter = mr::Image(cam.width, cam.height, 3);
  mr::Image transmittance(cam.width, cam.height, 3), sun_visibility(cam.width, cam.height, 1),
      optical_depth(cam.width, cam.height, 3);
  mr::render::CoreInputs in;
  in.camera = &cam;
  in.scene = &s;
  in.distance_m = depth.view();
  in.normals = normals.view();
  in.occluders = &occluders;
  in.sky_radiance = *s.lighting.sky_radiance;
  r.out = mr::render::CoreOutputs{transmittance.view(), r.inscatter.view(), sun_visibility.view(),
                                  optical_depth.view()};
  const double cpu0 = process_cpu_s();
  mr::render::render_scattering_cpu(in, r.out);
  r.render_cpu_s = process_cpu_s() - cpu0;
  return r;
}

bool read_floats(const std::string& path, std::vector<float>& v) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return false;
  const std::size_t n = std::fread(v.data(), sizeof(float), v.size(), f);
  std::fclose(f);
  return n == v.size();
}
void write_floats(const std::string& path, const float* data, std::size_t n) {
  if (std::FILE* f = std::fopen(path.c_str(), "wb")) {
    std::fwrite(data, sizeof(float), n, f);
    std::fclose(f);
  }
}

}  // namespace

int main(int argc, char** argv) {
  int width = 1280, height = 720, runs = 1, reference_steps = 0;
  std::string reference_file, dump;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string a = argv[i];
    if (a == "--width")
      width = std::atoi(argv[i + 1]);
    else if (a == "--height")
      height = std::atoi(argv[i + 1]);
    else if (a == "--runs")
      runs = std::atoi(argv[i + 1]);
    else if (a == "--reference")
      reference_steps = std::atoi(argv[i + 1]);
    else if (a == "--reference-file")
      reference_file = argv[i + 1];
    else if (a == "--dump")
      dump = argv[i + 1];
    else {
      std::fprintf(stderr, "ERROR: unknown option %s\n", a.c_str());
      return 2;
    }
  }
  const mr::Camera cam = mr::Camera::from_horizontal_fov(width, height, 60);
  mr::FogScene s = mr::test::low_sun_height_fog_scene();
  const mr::Image depth = mr::test::forest_depth(cam, s.pose);
  std::size_t sky = 0;
  for (float d : depth.pixels()) sky += !std::isfinite(d);
  std::printf("forest %dx%d, sky %.1f %%\n", width, height,
              100.0 * double(sky) / depth.pixels().size());
  Result last;
  for (int run = 0; run < runs; ++run) {
    last = render(depth, cam, s);
    const mr::render::CoreOutputs& o = last.out;
    std::printf(
        "run %d: render CPU %.2f s, wall grid %.2f / interpolation %.2f / surface %.2f s, exact "
        "%zu (%.1f %%), Mrays %.2f (%.0f a pixel)\n",
        run, last.render_cpu_s, o.grid_s, o.interpolation_s, o.surface_s, o.exact_pixels,
        100.0 * double(o.exact_pixels) / (double(width) * height), double(o.shadow_rays) / 1e6,
        double(o.shadow_rays) / (double(width) * height));
    std::fflush(stdout);
  }
  if (!dump.empty()) write_floats(dump, last.inscatter.data(), last.inscatter.pixels().size());
  if (reference_steps > 0) {
    std::vector<float> ref(last.inscatter.pixels().size());
    if (reference_file.empty() || !read_floats(reference_file, ref)) {
      mr::FogScene rs = s;
      rs.render.gradient_acceleration = false;
      rs.render.march_steps = reference_steps;
      const Result r = render(depth, cam, rs);
      std::printf("reference (%d steps, every pixel exact): render CPU %.2f s\n", reference_steps,
                  r.render_cpu_s);
      ref.assign(r.inscatter.pixels().begin(), r.inscatter.pixels().end());
      if (!reference_file.empty()) write_floats(reference_file, ref.data(), ref.size());
    }
    double mean = 0;
    for (float v : ref) mean += v;
    mean /= double(ref.size());
    double err = 0, signed_err = 0, worst = 0;
    std::size_t n = 0, over5 = 0;
    for (std::size_t i = 0; i < ref.size(); ++i) {
      if (ref[i] < 0.01 * mean) continue;
      const double e = (last.inscatter.pixels()[i] - ref[i]) / ref[i];
      err += std::fabs(e);
      signed_err += e;
      worst = std::max(worst, std::fabs(e));
      over5 += std::fabs(e) > 0.05;
      ++n;
    }
    std::printf(
        "R vs reference: mean |rel| %.4f %%, mean rel %+.4f %%, max %.2f %%, >5 %%: %zu px\n",
        100.0 * err / double(n), 100.0 * signed_err / double(n), 100.0 * worst, over5);
  }
  return 0;
}
