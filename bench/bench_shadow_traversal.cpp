// Shadow-ray traversal benchmark (issue 17, seed 004): standard kd-tree traversal, SATO, SRDH,
// the multi-index tree and Embree on the seed's kind of scenes and on the product's own shadow
// rays. Prints a table (Markdown) per scene: nodes and triangle tests per ray by outcome
// (occluded / unoccluded; exact counts), Mrays/s on 1 and 2 threads (medians of --reps runs;
// wall clock and CPU time: on a loaded machine only the CPU-time rates and the counts mean much),
// build time and memory.
//
//   build/bench/mr_bench_shadow_traversal [--size 1024] [--reps 3] [--scenes
//   atrium,bedroom,forest,leuven] build/bench/mr_bench_shadow_traversal --record   # records the
//   leuven rays first (see below)
//
// Scenes (bench/shadow_scenes.h): a Sponza-like atrium, a bedroom-like interior, a forest of
// thin occluders; size x size primary hit points (Embree rtcIntersect1 from the scene's
// camera), each with a shadow ray to a point light and one to a random point of an area light
// (2 rays per hit; point-light rays first, in scanline order, then the area light's).
// "leuven": the shadow rays of the CPU core's sunlit 1080p fog render of
// sample_photos/leuven.jpg (bench/leuven_scene.h, normal quality, 2 threads), recorded by a
// ShadowQuery that answers with Embree and keeps 1 block of 1024 consecutive rays (per thread)
// in every --record-every blocks, written to --rays-file and replayed on the same occluder mesh
// (normals, full-resolution mesh, blockers: as BM_Stages in bench_scattering.cpp builds it).
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <fstream>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <sys/resource.h>
#include <unistd.h>

#include "leuven_scene.h"
#include "mr/mr.h"
#include "render/blockers.h"
#include "render/embree_scene.h"
#include "render/occluder_mesh.h"
#include "render/scattering_cpu.h"
#include "render/shadow_traversal/depth_image_surface.h"
#include "render/shadow_traversal/kd_tree.h"
#include "render/shadow_traversal/multi_index_query.h"
#include "shadow_scenes.h"

namespace {

using mr::render::shadow::KdTree;
using mr::render::shadow::KdTreeOptions;
using mr::render::shadow::KindCounters;
using mr::render::shadow::Order;
using mr::render::shadow::Ray;
using Clock = std::chrono::steady_clock;

// The kd-tree's build options (--cost-intersect, --max-leaf, --empty-bonus override them).
KdTreeOptions g_tree_options;
// --packets-only: no SRDH tree or training and only the rows that compare the 8-wide packet
// traversal with the single-ray ones and Embree (standard, multi-index, packets, Embree).
bool g_packets_only = false;

double now_s() {
  return std::chrono::duration<double>(Clock::now().time_since_epoch()).count();
}
double thread_cpu_s() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}
double process_cpu_s() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}
double rss_mb() {
  std::ifstream f("/proc/self/statm");
  long pages = 0, resident = 0;
  f >> pages >> resident;
  return double(resident) * double(sysconf(_SC_PAGESIZE)) / 1048576.0;
}
double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

// ----------------------------------------------------------------------------------------------
// Recording the product's rays

struct Recorder final : mr::render::ShadowQuery {
  const mr::render::OccluderScene* scene = nullptr;
  int keep_every = 8;
  mutable std::mutex mutex;
  mutable std::vector<std::unique_ptr<std::vector<Ray>>> streams;
  mutable std::atomic<std::uint64_t> total{0};

  struct Local {
    std::vector<Ray>* kept = nullptr;
    std::uint64_t seen = 0;
    const Recorder* owner = nullptr;
  };
  std::vector<Ray>& mine(std::uint64_t& seen) const {
    thread_local Local local;
    if (local.owner != this) {
      const std::lock_guard lock(mutex);
      streams.push_back(std::make_unique<std::vector<Ray>>());
      local = {streams.back().get(), 0, this};
    }
    seen = local.seen;
    local.seen += 1;
    return *local.kept;
  }
  void record(const Ray& r) const {
    std::uint64_t seen = 0;
    std::vector<Ray>& v = mine(seen);
    total.fetch_add(1, std::memory_order_relaxed);
    if ((seen / 1024) % std::uint64_t(keep_every) == 0) v.push_back(r);
  }
  bool occluded(const std::array<float, 3>& o, const std::array<float, 3>& d, float tn,
                float tf) const override {
    record({o, d, tn, tf});
    return scene->occluded(o, d, tn, tf);
  }
  void occluded8(const mr::render::RayPacket8& p, bool out[8]) const override {
    for (int k = 0; k < 8; ++k)
      if (p.valid[k])
        record({{p.origin_x[k], p.origin_y[k], p.origin_z[k]},
                {p.direction_x[k], p.direction_y[k], p.direction_z[k]},
                p.t_near[k],
                p.t_far[k]});
    scene->occluded8(p, out);
  }
  const char* name() const override { return "recorder"; }
};

struct LeuvenGeometry {
  mr::render::TriangleMesh mesh;
  mr::Image normals;
};

LeuvenGeometry leuven_geometry(const mr::bench::Inputs& in, const mr::FogScene& s) {
  LeuvenGeometry g;
  g.normals = mr::render::estimate_normals(in.depth.view(), in.camera, s.pose);
  g.mesh = mr::render::reconstruct_occluder_mesh(in.depth.view(), in.camera, s.pose, {},
                                                 g.normals.view());
  mr::render::append_blockers(g.mesh, in.depth.view(), g.normals.view(), in.camera, s.pose,
                              s.blockers);
  return g;
}

mr::FogScene leuven_scene_for_rays(const mr::bench::Inputs& in) {
  mr::FogScene s = mr::bench::leuven_sun_scene(mr::Quality::normal);
  s.lighting.sky_radiance = mr::estimate_airlight(in.photo);
  return s;
}

void record_leuven(const std::string& path, int keep_every) {
  const mr::bench::Inputs& in = mr::bench::leuven_inputs(1920, 1080);
  mr::FogScene s = leuven_scene_for_rays(in);
  s.render.threads = 2;
  LeuvenGeometry g = leuven_geometry(in, s);
  mr::render::OccluderScene scene(mr::render::TriangleMesh(g.mesh));
  auto recorder = std::make_shared<Recorder>();
  recorder->scene = &scene;
  recorder->keep_every = keep_every;
  scene.set_shadow_query(recorder);
  const int w = in.camera.width, h = in.camera.height;
  mr::Image transmittance(w, h, 3), inscatter(w, h, 3), sun_visibility(w, h, 1),
      optical_depth(w, h, 3);
  mr::render::CoreInputs core_in;
  core_in.camera = &in.camera;
  core_in.scene = &s;
  core_in.distance_m = in.depth.view();
  core_in.normals = g.normals.view();
  core_in.photo = in.photo.view();
  core_in.occluders = &scene;
  core_in.sky_radiance = *s.lighting.sky_radiance;
  mr::render::CoreOutputs out{transmittance.view(), inscatter.view(), sun_visibility.view(),
                              optical_depth.view()};
  tbb::task_arena arena(2);
  arena.execute([&] { mr::render::render_scattering_cpu(core_in, out); });
  std::vector<Ray> all;
  for (const auto& v : recorder->streams) all.insert(all.end(), v->begin(), v->end());
  std::ofstream f(path, std::ios::binary);
  const std::uint64_t n = all.size(), total = recorder->total.load();
  f.write(reinterpret_cast<const char*>(&n), sizeof n);
  f.write(reinterpret_cast<const char*>(&total), sizeof total);
  f.write(reinterpret_cast<const char*>(all.data()), std::streamsize(n * sizeof(Ray)));
  std::printf("recorded %llu of the render's %llu shadow rays (1 block of 1024 in %d) to %s\n",
              (unsigned long long)n, (unsigned long long)total, keep_every, path.c_str());
}

std::vector<Ray> load_rays(const std::string& path, std::uint64_t& total) {
  std::ifstream f(path, std::ios::binary);
  std::uint64_t n = 0;
  f.read(reinterpret_cast<char*>(&n), sizeof n);
  f.read(reinterpret_cast<char*>(&total), sizeof total);
  std::vector<Ray> rays(n);
  f.read(reinterpret_cast<char*>(rays.data()), std::streamsize(n * sizeof(Ray)));
  if (!f) {
    std::fprintf(stderr, "cannot read %s (run with --record first)\n", path.c_str());
    std::exit(1);
  }
  return rays;
}

// Issue 12 item 4: leuven's recorded rays against Embree (the whole mesh, as the core traces
// it) and against the depth-image traversal of the surface (render/shadow_traversal/
// depth_image_surface.h) plus Embree for the triangles after the surface (blockers): build
// times, answers compared ray by ray, tracing CPU time in packets of 8 (one thread).
void depth_image_comparison(const std::vector<Ray>& rays, int reps) {
  const mr::bench::Inputs& in = mr::bench::leuven_inputs(1920, 1080);
  const mr::FogScene s = leuven_scene_for_rays(in);
  mr::Image normals = mr::render::estimate_normals(in.depth.view(), in.camera, s.pose);
  mr::render::MeshOptions options;
  options.pixel_layout = true;
  mr::render::TriangleMesh mesh = mr::render::reconstruct_occluder_mesh(
      in.depth.view(), in.camera, s.pose, options, normals.view());
  mr::render::append_blockers(mesh, in.depth.view(), normals.view(), in.camera, s.pose, s.blockers);
  mr::render::TriangleMesh extras;
  extras.positions = mesh.positions;
  extras.indices.assign(mesh.indices.begin() + 3 * std::ptrdiff_t(mesh.surface_triangle_count),
                        mesh.indices.end());
  double t = now_s();
  double c = process_cpu_s();
  const mr::render::OccluderScene embree{mr::render::TriangleMesh(mesh)};
  std::printf("Embree BVH (whole mesh, %zu triangles): %.0f ms wall, %.0f ms CPU\n",
              mesh.triangle_count(), 1e3 * (now_s() - t), 1e3 * (process_cpu_s() - c));
  t = now_s();
  c = process_cpu_s();
  mr::render::DepthImageSurface surface(mesh, in.camera, s.pose);
  std::printf("depth-image pyramid (%zu surface triangles): %.0f ms wall, %.0f ms CPU\n",
              mesh.surface_triangle_count, 1e3 * (now_s() - t), 1e3 * (process_cpu_s() - c));
  t = now_s();
  const mr::render::OccluderScene extra_scene{std::move(extras)};
  std::printf("Embree BVH of the %zu triangles after the surface: %.0f ms wall\n",
              extra_scene.triangle_count(), 1e3 * (now_s() - t));
  const std::size_t n = rays.size();
  std::vector<char> a(n), b(n);
  auto pack = [&](std::size_t first, mr::render::RayPacket8& p) {
    for (int k = 0; k < 8; ++k) {
      const std::size_t i = first + std::size_t(k);
      p.valid[k] = i < n ? -1 : 0;
      if (i >= n) continue;
      const Ray& r = rays[i];
      p.origin_x[k] = r.origin[0];
      p.origin_y[k] = r.origin[1];
      p.origin_z[k] = r.origin[2];
      p.direction_x[k] = r.direction[0];
      p.direction_y[k] = r.direction[1];
      p.direction_z[k] = r.direction[2];
      p.t_near[k] = r.t_near;
      p.t_far[k] = r.t_far;
    }
  };
  std::vector<double> embree_s, image_s;
  for (int rep = 0; rep < reps; ++rep) {
    c = thread_cpu_s();
    for (std::size_t first = 0; first < n; first += 8) {
      mr::render::RayPacket8 p;
      pack(first, p);
      bool hit[8];
      embree.occluded8(p, hit);
      for (int k = 0; k < 8 && first + k < n; ++k) a[first + k] = hit[k];
    }
    embree_s.push_back(thread_cpu_s() - c);
    surface.count_work(rep == 0);
    const auto counters0 = mr::render::DepthImageSurface::thread_counters();
    c = thread_cpu_s();
    for (std::size_t first = 0; first < n; first += 8) {
      mr::render::RayPacket8 p;
      pack(first, p);
      bool hit[8], extra_hit[8];
      surface.occluded8(p, hit);
      bool any_missed = false;
      for (int k = 0; k < 8; ++k) {
        if (hit[k]) p.valid[k] = 0;
        any_missed = any_missed || p.valid[k] != 0;
      }
      if (any_missed) {
        extra_scene.occluded8(p, extra_hit);
        for (int k = 0; k < 8; ++k) hit[k] = hit[k] || extra_hit[k];
      }
      for (int k = 0; k < 8 && first + k < n; ++k) b[first + k] = hit[k];
    }
    image_s.push_back(thread_cpu_s() - c);
    const auto counters1 = mr::render::DepthImageSurface::thread_counters();
    if (rep == 0)
      std::printf("depth image: %.1f nodes and %.2f triangle tests per ray\n",
                  double(counters1[0] - counters0[0]) / double(n),
                  double(counters1[1] - counters0[1]) / double(n));
  }
  std::size_t differ = 0, occluded = 0;
  for (std::size_t i = 0; i < n; ++i) {
    differ += a[i] != b[i];
    occluded += a[i] != 0;
  }
  std::sort(embree_s.begin(), embree_s.end());
  std::sort(image_s.begin(), image_s.end());
  std::printf("%zu rays (%zu occluded by Embree), %zu answers differ\n", n, occluded, differ);
  std::printf(
      "CPU time, one thread, median of %d: Embree %.0f ms (%.2f Mrays/s), depth image "
      "%.0f ms (%.2f Mrays/s)\n",
      reps, 1e3 * embree_s[embree_s.size() / 2], 1e-6 * double(n) / embree_s[embree_s.size() / 2],
      1e3 * image_s[image_s.size() / 2], 1e-6 * double(n) / image_s[image_s.size() / 2]);
}

// ----------------------------------------------------------------------------------------------
// The seed's scenes: primary hits and their shadow rays

std::vector<Ray> scene_rays(const mr::bench::ShadowScene& s,
                            const mr::render::OccluderScene& embree, int size) {
  using V3 = std::array<float, 3>;
  auto sub = [](V3 a, V3 b) { return V3{a[0] - b[0], a[1] - b[1], a[2] - b[2]}; };
  auto cross = [](V3 a, V3 b) {
    return V3{a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
  };
  auto norm = [](V3 a) {
    const float l = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
    return V3{a[0] / l, a[1] / l, a[2] / l};
  };
  const V3 fwd = norm(sub(s.look_at, s.eye));
  const V3 right = norm(cross(fwd, {0, 1, 0}));
  const V3 up = cross(right, fwd);
  const float half = std::tan(0.5f * s.fov_deg * 3.14159265f / 180.0f);
  std::vector<V3> hits;
  hits.reserve(std::size_t(size) * std::size_t(size));
  for (int y = 0; y < size; ++y)
    for (int x = 0; x < size; ++x) {
      const float u = (2.0f * (float(x) + 0.5f) / float(size) - 1.0f) * half;
      const float v = (1.0f - 2.0f * (float(y) + 0.5f) / float(size)) * half;
      const V3 d{fwd[0] + u * right[0] + v * up[0], fwd[1] + u * right[1] + v * up[1],
                 fwd[2] + u * right[2] + v * up[2]};
      const float t = embree.intersect_distance(s.eye, d, 0.0f, INFINITY);
      if (!std::isfinite(t)) continue;
      const float tb = t * (1.0f - 1e-4f);  // just in front of the surface
      hits.push_back({s.eye[0] + tb * d[0], s.eye[1] + tb * d[1], s.eye[2] + tb * d[2]});
    }
  std::vector<Ray> rays;
  rays.reserve(2 * hits.size());
  for (const V3& p : hits) rays.push_back({p, sub(s.point_light, p), 0.0f, 1.0f - 1e-4f});
  std::uint32_t state = 12345;
  auto rnd = [&] {
    state = state * 1664525u + 1013904223u;
    return float(state >> 8) / 16777216.0f;
  };
  for (const V3& p : hits) {
    const float a = rnd(), b = rnd();
    const V3 l{s.area_light_corner[0] + a * s.area_light_u[0] + b * s.area_light_v[0],
               s.area_light_corner[1] + a * s.area_light_u[1] + b * s.area_light_v[1],
               s.area_light_corner[2] + a * s.area_light_u[2] + b * s.area_light_v[2]};
    rays.push_back({p, sub(l, p), 0.0f, 1.0f - 1e-4f});
  }
  return rays;
}

// ----------------------------------------------------------------------------------------------
// Measuring

// A method traces rays [first, last) in order, with its own prediction state, counting if asked.
using Method = std::function<std::uint64_t(const std::vector<Ray>&, std::size_t, std::size_t,
                                           KindCounters*, std::vector<char>*)>;

struct Row {
  std::string name;
  KindCounters counters;
  bool has_counters = true;
  double wall1 = 0, cpu1 = 0, wall2 = 0, cpu2 = 0;  // medians, seconds
  std::size_t disagreements = 0;
  std::string build;
};

void measure(Row& row, const Method& m, const std::vector<Ray>& rays,
             const std::vector<char>& reference, int reps, bool timed) {
  if (row.has_counters) {
    std::vector<char> answers;
    m(rays, 0, rays.size(), &row.counters, &answers);
    for (std::size_t i = 0; i < rays.size(); ++i) row.disagreements += answers[i] != reference[i];
  } else {
    std::vector<char> answers;
    m(rays, 0, rays.size(), nullptr, &answers);
    for (std::size_t i = 0; i < rays.size(); ++i) row.disagreements += answers[i] != reference[i];
  }
  std::vector<double> w1, c1, w2, c2;
  for (int r = 0; r < (timed ? reps : 0); ++r) {
    double t0 = now_s(), c0 = thread_cpu_s();
    m(rays, 0, rays.size(), nullptr, nullptr);
    w1.push_back(now_s() - t0);
    c1.push_back(thread_cpu_s() - c0);
    // 2 threads: chunks of 8192 consecutive rays, alternating between the threads.
    t0 = now_s();
    c0 = process_cpu_s();
    std::vector<std::thread> threads;
    for (int k = 0; k < 2; ++k)
      threads.emplace_back([&, k] {
        for (std::size_t first = std::size_t(k) * 8192; first < rays.size(); first += 2 * 8192)
          m(rays, first, std::min(rays.size(), first + 8192), nullptr, nullptr);
      });
    for (auto& t : threads) t.join();
    w2.push_back(now_s() - t0);
    c2.push_back(process_cpu_s() - c0);
  }
  row.wall1 = median(w1);
  row.cpu1 = median(c1);
  row.wall2 = median(w2);
  row.cpu2 = median(c2);
}

void run_scene(const std::string& name, const mr::render::TriangleMesh& mesh,
               const std::vector<Ray>& rays, int reps, const std::string& note) {
  std::printf("\n### %s: %zu triangles, %zu shadow rays%s\n\n", name.c_str(), mesh.triangle_count(),
              rays.size(), note.c_str());
  std::fflush(stdout);
  // Builds. The kd-tree is built once (the plain tree: standard, SATO, SRDH's order), then the
  // multi-index parts are added to the same tree (its traversals use neither SATO's nor SRDH's
  // order bits), so "multi-index" costs the plain build plus its own parts.
  double rss0 = rss_mb(), t0 = now_s(), c0 = process_cpu_s();
  const mr::render::OccluderScene embree{mr::render::TriangleMesh(mesh)};
  const double embree_build = now_s() - t0, embree_cpu = process_cpu_s() - c0;
  const double embree_mb =
      rss_mb() - rss0 - double(mesh.positions.size() * 4 + mesh.indices.size() * 4) / 1048576.0;
  KdTreeOptions plain_options = g_tree_options;
  plain_options.multi_index = false;
  t0 = now_s();
  c0 = process_cpu_s();
  KdTree tree(mesh, plain_options);
  const double plain_build = now_s() - t0, plain_cpu = process_cpu_s() - c0;
  const double plain_mb = double(tree.memory_bytes(false)) / 1048576.0;
  t0 = now_s();
  c0 = process_cpu_s();
  tree.build_multi_index(g_tree_options);
  const double multi_build = plain_build + now_s() - t0,
               multi_cpu = plain_cpu + process_cpu_s() - c0;
  const KdTree& plain = tree;
  KdTree& trained = tree;
  const KdTree& multi = tree;
  // SRDH's representative ray set: every 16th ray of the frame.
  std::vector<Ray> sample;
  for (std::size_t i = 0; i < rays.size(); i += 16) sample.push_back(rays[i]);
  if (g_packets_only) sample.clear();  // no SRDH: its order and tree are those of the SAH
  t0 = now_s();
  c0 = process_cpu_s();
  trained.train_srdh(sample);
  const double srdh_train = now_s() - t0, srdh_cpu = process_cpu_s() - c0;
  // SRDH's own tree: split costs from the same sample rays (then its order, trained on them).
  t0 = now_s();
  c0 = process_cpu_s();
  // (--packets-only: a one-triangle stand-in, not reported.)
  mr::render::TriangleMesh stand_in;
  stand_in.positions = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  stand_in.indices = {0, 1, 2};
  stand_in.surface_triangle_count = 1;
  KdTree srdh_tree(g_packets_only ? stand_in : mesh, sample, plain_options);
  srdh_tree.train_srdh(sample);
  const double srdh_build = now_s() - t0, srdh_build_cpu = process_cpu_s() - c0;

  std::vector<char> reference(rays.size());
  std::size_t occluded = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    reference[i] =
        embree.occluded(rays[i].origin, rays[i].direction, rays[i].t_near, rays[i].t_far);
    occluded += std::size_t(reference[i]);
  }
  std::printf(
      "occluded (Embree): %.1f %%. Builds (wall / process CPU s, memory): Embree %.2f / %.2f s, "
      "~%.0f MB (RSS growth less the mesh); kd-tree %.2f / %.2f s, %.0f MB (%zu nodes, %zu leaves, "
      "%.2f references per triangle, depth %d); "
      "SRDH training on %zu rays %.2f / %.2f s; SRDH tree from them (build + order) %.2f / %.2f s, "
      "%zu nodes, %.2f references per triangle; multi-index (plain tree + its parts) %.2f / %.2f "
      "s, %.0f MB (%zu lifted "
      "triangles, ropes for %zu leaves)\n\n",
      100.0 * double(occluded) / double(std::max<std::size_t>(rays.size(), 1)), embree_build,
      embree_cpu, embree_mb, plain_build, plain_cpu, plain_mb, plain.node_count(),
      plain.leaf_count(),
      double(plain.reference_count()) / double(std::max<std::size_t>(1, plain.triangle_count())),
      plain.max_depth(), sample.size(), srdh_train, srdh_cpu, srdh_build, srdh_build_cpu,
      srdh_tree.node_count(),
      double(srdh_tree.reference_count()) /
          double(std::max<std::size_t>(1, srdh_tree.triangle_count())),
      multi_build, multi_cpu, double(multi.memory_bytes(true)) / 1048576.0, multi.lifted_count(),
      multi.leaf_count());

  auto ordered = [](const KdTree& tree, Order order) -> Method {
    return [&tree, order](const std::vector<Ray>& r, std::size_t a, std::size_t b, KindCounters* c,
                          std::vector<char>* out) {
      std::uint64_t hits = 0;
      for (std::size_t i = a; i < b; ++i) {
        const bool h = tree.occluded(r[i], order, c);
        hits += h;
        if (out) out->push_back(h);
      }
      return hits;
    };
  };
  // prediction: 0 = previous ray's outcome, 1 = always occluded, 2 = always unoccluded, 3 = oracle
  auto multi_method = [&reference](const KdTree& tree, int prediction) -> Method {
    return [&tree, prediction, &reference](const std::vector<Ray>& r, std::size_t a, std::size_t b,
                                           KindCounters* c, std::vector<char>* out) {
      std::uint64_t hits = 0;
      bool previous = false;
      for (std::size_t i = a; i < b; ++i) {
        const bool predict = prediction == 0   ? previous
                             : prediction == 1 ? true
                             : prediction == 2 ? false
                                               : bool(reference[i]);
        const bool h = tree.occluded_multi_index(r[i], predict, c);
        previous = h;
        hits += h;
        if (out) out->push_back(h);
      }
      return hits;
    };
  };
  const Method embree1 = [&embree](const std::vector<Ray>& r, std::size_t a, std::size_t b,
                                   KindCounters*, std::vector<char>* out) {
    std::uint64_t hits = 0;
    for (std::size_t i = a; i < b; ++i) {
      const bool h = embree.occluded(r[i].origin, r[i].direction, r[i].t_near, r[i].t_far);
      hits += h;
      if (out) out->push_back(h);
    }
    return hits;
  };
  const Method embree8 = [&embree](const std::vector<Ray>& r, std::size_t a, std::size_t b,
                                   KindCounters*, std::vector<char>* out) {
    std::uint64_t hits = 0;
    mr::render::occluded_rays(
        embree, b - a,
        [&](std::size_t i) {
          const Ray& x = r[a + i];
          return mr::render::ShadowRay{x.origin, x.direction, x.t_near, x.t_far};
        },
        [&](std::size_t, bool h) {
          hits += h;
          if (out) out->push_back(h);
        });
    return hits;
  };
  // The CPU core's packet path: 8 consecutive rays per packet (render::occluded_rays), the
  // kd-tree's 8-wide traversal (what MultiIndexShadowQuery::occluded8 now does).
  auto packet_method = [](const KdTree& tree) -> Method {
    return [&tree](const std::vector<Ray>& r, std::size_t a, std::size_t b, KindCounters* c,
                   std::vector<char>* out) {
      std::uint64_t hits = 0;
      for (std::size_t first = a; first < b; first += 8) {
        const std::size_t n = std::min<std::size_t>(8, b - first);
        const unsigned h = tree.occluded8(&r[first], (1u << n) - 1u, c);
        hits += unsigned(__builtin_popcount(h));
        if (out)
          for (std::size_t k = 0; k < n; ++k) out->push_back(char((h >> k) & 1u));
      }
      return hits;
    };
  };
  char buf[256];
  std::vector<Row> rows;
  auto add = [&](const std::string& label, const Method& m, bool counters, const std::string& build,
                 bool timed = true) {
    Row row;
    row.name = label;
    row.has_counters = counters;
    row.build = build;
    measure(row, m, rays, reference, reps, timed);
    rows.push_back(row);
  };
  std::snprintf(buf, sizeof buf, "%.2f s, %.0f MB", plain_cpu,
                double(plain.memory_bytes(false)) / 1048576.0);
  add("standard", ordered(plain, Order::standard), true, buf);
  if (!g_packets_only) {
    add("SATO", ordered(plain, Order::sato), true, buf);
    std::snprintf(buf, sizeof buf, "%.2f + %.2f s, %.0f MB", plain_cpu, srdh_cpu,
                  double(plain.memory_bytes(false)) / 1048576.0);
    add("SRDH (order only)", ordered(plain, Order::srdh), true, buf);
    std::snprintf(buf, sizeof buf, "%.2f s, %.0f MB", srdh_build_cpu,
                  double(srdh_tree.memory_bytes(false)) / 1048576.0);
    add("SRDH (ray-set build + order)", ordered(srdh_tree, Order::srdh), true, buf);
  }
  std::snprintf(buf, sizeof buf, "%.2f s, %.0f MB", multi_cpu,
                double(multi.memory_bytes(true)) / 1048576.0);
  add("multi-index", multi_method(multi, 0), true, buf);
  if (!g_packets_only) {
    // Ablations: counts only (not timed, to save the machine's time).
    add("multi-index, oracle prediction", multi_method(multi, 3), true, buf, false);
    add("lifted indices only", multi_method(multi, 1), true, buf, false);
    add("ropes only", multi_method(multi, 2), true, buf, false);
  }
  // The same tree (the plain tree's nodes; the multi-index parts unused), 8-wide packets.
  add("kd 8-wide packets (product path)", packet_method(multi), true, buf);
  std::snprintf(buf, sizeof buf, "%.2f s, ~%.0f MB", embree_cpu, embree_mb);
  add("Embree rtcOccluded1", embree1, false, buf);
  add("Embree 8-wide (product)", embree8, false, buf);

  const double base_on = double(rows[0].counters.occluded.nodes) /
                         double(std::max<std::uint64_t>(1, rows[0].counters.occluded.rays));
  (void)base_on;
  std::printf(
      "| method | occl. nodes/ray | occl. tris/ray | unocc. nodes/ray | unocc. tris/ray | "
      "1T Mrays/s (wall) | 1T Mrays/CPU-s | 2T Mrays/s (wall) | 2T Mrays/CPU-s | "
      "build (CPU), memory | answers != Embree |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|\n");
  const double n = double(rays.size()) / 1e6;
  for (const Row& r : rows) {
    auto per = [](std::uint64_t a, std::uint64_t b) { return b ? double(a) / double(b) : 0.0; };
    if (r.has_counters) {
      const auto& base = rows[0].counters;
      auto pct = [&](double v, double b) {
        char s[64];
        std::snprintf(s, sizeof s, "%.1f (%+.0f%%)", v, b > 0 ? 100.0 * (v / b - 1.0) : 0.0);
        return std::string(s);
      };
      std::printf("| %s | %s | %s | %s | %s |", r.name.c_str(),
                  pct(per(r.counters.occluded.nodes, r.counters.occluded.rays),
                      per(base.occluded.nodes, base.occluded.rays))
                      .c_str(),
                  pct(per(r.counters.occluded.primitives, r.counters.occluded.rays),
                      per(base.occluded.primitives, base.occluded.rays))
                      .c_str(),
                  pct(per(r.counters.unoccluded.nodes, r.counters.unoccluded.rays),
                      per(base.unoccluded.nodes, base.unoccluded.rays))
                      .c_str(),
                  pct(per(r.counters.unoccluded.primitives, r.counters.unoccluded.rays),
                      per(base.unoccluded.primitives, base.unoccluded.rays))
                      .c_str());
    } else {
      std::printf("| %s | - | - | - | - |", r.name.c_str());
    }
    if (r.wall1 > 0)
      std::printf(" %.2f | %.2f | %.2f | %.2f | %s | %zu |\n", n / r.wall1, n / r.cpu1, n / r.wall2,
                  n / (r.cpu2 / 2.0), r.build.c_str(), r.disagreements);
    else
      std::printf(" - | - | - | - | %s | %zu |\n", r.build.c_str(), r.disagreements);
  }
  for (const Row& r : rows)
    if (r.counters.packets)
      std::printf(
          "\n%s: %.1f node fetches per packet of 8 (%.2f per ray; the per-ray columns count "
          "a node for every ray active there)\n",
          r.name.c_str(), double(r.counters.packet_nodes) / double(r.counters.packets),
          double(r.counters.packet_nodes) /
              double(std::max<std::uint64_t>(
                  1, r.counters.occluded.rays + r.counters.unoccluded.rays)));
  for (const Row& r : rows)
    if (r.has_counters && r.counters.rope_fallbacks)
      std::printf("\n%s: %llu rope walks fell back to a root descent\n", r.name.c_str(),
                  (unsigned long long)r.counters.rope_fallbacks);
  std::fflush(stdout);
}

double peak_rss_mb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_maxrss) / 1024.0;
}

/// --build-only: the kd-tree build alone (no rays, no Embree): its CPU time and memory.
void build_only(const std::string& name, const mr::render::TriangleMesh& mesh) {
  const double rss0 = rss_mb(), peak0 = peak_rss_mb();
  double t0 = now_s(), c0 = process_cpu_s();
  KdTreeOptions plain_options = g_tree_options;
  plain_options.multi_index = false;
  KdTree tree(mesh, plain_options);
  const double wall = now_s() - t0, cpu = process_cpu_s() - c0, peak1 = peak_rss_mb();
  t0 = now_s();
  c0 = process_cpu_s();
  tree.build_multi_index(g_tree_options);
  const double multi_wall = now_s() - t0, multi_cpu = process_cpu_s() - c0;
  std::printf(
      "%s: %zu triangles; kd-tree %.2f s wall / %.2f s process CPU, %zu nodes, %zu leaves (%zu "
      "empty), "
      "%.2f references per triangle, depth %d, %.0f MB; multi-index parts +%.2f s wall / "
      "+%.2f s CPU, %.0f MB in all (%zu lifted); RSS before %.0f MB, peak before %.0f MB, "
      "peak after the plain build %.0f MB, peak after all %.0f MB\n",
      name.c_str(), mesh.triangle_count(), wall, cpu, tree.node_count(), tree.leaf_count(),
      tree.empty_leaf_count(),
      double(tree.reference_count()) / double(std::max<std::size_t>(1, tree.triangle_count())),
      tree.max_depth(), double(tree.memory_bytes(false)) / 1048576.0, multi_wall, multi_cpu,
      double(tree.memory_bytes(true)) / 1048576.0, tree.lifted_count(), rss0, peak0, peak1,
      peak_rss_mb());
  std::fflush(stdout);
}

/// --explain: every ray on which the standard kd traversal and Embree disagree, answered again by
/// brute force (the same watertight test on every triangle: a one-leaf tree) and by Embree's
/// robust mode, to tell a tree bug (brute force agrees with Embree) from the triangle tests'
/// edge cases (brute force agrees with the tree).
void explain(const std::string& name, const mr::render::TriangleMesh& mesh,
             const std::vector<Ray>& rays) {
  const mr::render::OccluderScene embree{mr::render::TriangleMesh(mesh)};
  mr::render::OccluderSceneOptions robust_options;
  robust_options.robust = true;
  const mr::render::OccluderScene robust{mr::render::TriangleMesh(mesh), robust_options};
  KdTreeOptions plain_options = g_tree_options;
  plain_options.multi_index = false;
  const KdTree tree(mesh, plain_options);
  KdTreeOptions one_leaf = plain_options;
  one_leaf.max_leaf_size = std::numeric_limits<int>::max();
  const KdTree brute(mesh, one_leaf);
  std::size_t disagreements = 0, tree_bugs = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const Ray& r = rays[i];
    const bool e = embree.occluded(r.origin, r.direction, r.t_near, r.t_far);
    const bool k = tree.occluded(r, Order::standard);
    if (e == k) continue;
    ++disagreements;
    const bool b = brute.occluded(r, Order::standard);
    const bool rb = robust.occluded(r.origin, r.direction, r.t_near, r.t_far);
    tree_bugs += b != k;
    std::printf(
        "%s ray %zu: origin %.9g %.9g %.9g direction %.9g %.9g %.9g t %.9g..%.9g: Embree %d, "
        "Embree robust %d, kd-tree %d, brute-force watertight %d\n",
        name.c_str(), i, double(r.origin[0]), double(r.origin[1]), double(r.origin[2]),
        double(r.direction[0]), double(r.direction[1]), double(r.direction[2]), double(r.t_near),
        double(r.t_far), int(e), int(rb), int(k), int(b));
  }
  std::printf(
      "%s: %zu rays, %zu disagree with Embree, %zu where the tree differs from brute force\n",
      name.c_str(), rays.size(), disagreements, tree_bugs);
  std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
  int size = 1024, reps = 3, record_every = 8;
  bool record = false, only_build = false, only_explain = false;
  bool depth_image = false;
  std::size_t max_rays = 0;  // 0: all
  std::string scenes = "atrium,bedroom,forest,leuven";
  std::string rays_file = "shadow_rays_leuven_1080p.bin";
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&] { return i + 1 < argc ? std::string(argv[++i]) : std::string(); };
    if (a == "--size")
      size = std::atoi(next().c_str());
    else if (a == "--reps")
      reps = std::atoi(next().c_str());
    else if (a == "--scenes")
      scenes = next();
    else if (a == "--rays-file")
      rays_file = next();
    else if (a == "--depth-image")
      depth_image = true;
    else if (a == "--record")
      record = true;
    else if (a == "--record-every")
      record_every = std::atoi(next().c_str());
    else if (a == "--build-only")
      only_build = true;
    else if (a == "--explain")
      only_explain = true;
    else if (a == "--cost-intersect")
      g_tree_options.cost_intersect = float(std::atof(next().c_str()));
    else if (a == "--max-leaf")
      g_tree_options.max_leaf_size = std::atoi(next().c_str());
    else if (a == "--empty-bonus")
      g_tree_options.empty_bonus = float(std::atof(next().c_str()));
    else if (a == "--packets-only")
      g_packets_only = true;
    else if (a == "--max-rays")
      max_rays = std::size_t(std::atoll(next().c_str()));
    else if (a == "--help" || a == "-h") {
      std::printf(
          "usage: mr_bench_shadow_traversal [options]\n"
          "  --scenes LIST       comma-separated of atrium,bedroom,forest,leuven (default: all)\n"
          "  --size N            primary hits N x N for the seed's scenes (default 1024; the "
          "seed's)\n"
          "  --reps N            timed runs per method, median reported (default 3)\n"
          "  --record            first record leuven's shadow rays (a 1080p sunlit CPU render)\n"
          "  --record-every N    keep 1 block of 1024 rays in N per thread (default 8)\n"
          "  --rays-file PATH    leuven's rays (default shadow_rays_leuven_1080p.bin)\n"
          "  --build-only        only build the kd-tree per scene: CPU time, nodes, memory\n"
          "  --explain           only list the rays where the kd-tree and Embree disagree, with\n"
          "                      brute-force and robust-Embree answers\n"
          "  --max-rays N        replay about N of leuven's rays: every k-th block of 1024 (0: "
          "all)\n"
          "  --packets-only      no SATO/SRDH rows or builds, no ablations: standard, "
          "multi-index,\n"
          "                      kd 8-wide packets and Embree only\n"
          "  --cost-intersect C  kd-tree SAH: triangle test cost, node step = 1 (default 1.5)\n"
          "  --max-leaf N        kd-tree: always a leaf at N triangles or fewer (default 2)\n"
          "  --empty-bonus F     kd-tree SAH: cost factor of a split with an empty side (0.8)\n");
      return 0;
    } else {
      std::fprintf(stderr, "unknown argument %s\n", a.c_str());
      return 2;
    }
  }
  auto wants = [&](const std::string& s) {
    return ("," + scenes + ",").find("," + s + ",") != std::string::npos;
  };
  if (only_explain) {
    for (const auto& make : {&mr::bench::atrium, &mr::bench::bedroom, &mr::bench::forest}) {
      const mr::bench::ShadowScene s = make();
      if (!wants(s.name)) continue;
      const mr::render::OccluderScene embree{mr::render::TriangleMesh(s.mesh)};
      explain(s.name, s.mesh, scene_rays(s, embree, size));
    }
    if (wants("leuven")) {  // the recorded rays (--rays-file)
      std::uint64_t total = 0;
      const std::vector<Ray> rays = load_rays(rays_file, total);
      const mr::bench::Inputs& in = mr::bench::leuven_inputs(1920, 1080);
      const LeuvenGeometry g = leuven_geometry(in, leuven_scene_for_rays(in));
      explain("leuven 1080p sun", g.mesh, rays);
    }
    return 0;
  }
  if (only_build) {
    for (const auto& make : {&mr::bench::atrium, &mr::bench::bedroom, &mr::bench::forest}) {
      const mr::bench::ShadowScene s = make();
      if (wants(s.name)) build_only(s.name, s.mesh);
    }
    if (wants("leuven")) {
      const mr::bench::Inputs& in = mr::bench::leuven_inputs(1920, 1080);
      const LeuvenGeometry g = leuven_geometry(in, leuven_scene_for_rays(in));
      build_only("leuven 1080p", g.mesh);
    }
    return 0;
  }
  if (record) record_leuven(rays_file, record_every);
  if (depth_image) {
    std::uint64_t total = 0;
    depth_image_comparison(load_rays(rays_file, total), reps);
    return 0;
  }
  std::printf(
      "Counts are exact; times are medians of %d runs on a shared machine (CPU time is the "
      "steadier measure). Per-ray prediction of the multi-index tree: the previous ray's "
      "outcome.\n",
      reps);
  for (const auto& make : {&mr::bench::atrium, &mr::bench::bedroom, &mr::bench::forest}) {
    mr::bench::ShadowScene s = make();
    if (!wants(s.name)) continue;
    const mr::render::OccluderScene embree{mr::render::TriangleMesh(s.mesh)};
    const std::vector<Ray> rays = scene_rays(s, embree, size);
    char note[128];
    std::snprintf(note, sizeof note, " (%dx%d primary hits, a point and an area light)", size,
                  size);
    run_scene(s.name, s.mesh, rays, reps, note);
  }
  if (wants("leuven")) {
    std::uint64_t total = 0;
    std::vector<Ray> rays = load_rays(rays_file, total);
    if (max_rays > 0 && rays.size() > max_rays) {  // every k-th block of 1024 consecutive rays
      const std::size_t k = (rays.size() + max_rays - 1) / max_rays;
      std::vector<Ray> kept;
      for (std::size_t i = 0; i < rays.size(); ++i)
        if ((i / 1024) % k == 0) kept.push_back(rays[i]);
      rays = std::move(kept);
    }
    const mr::bench::Inputs& in = mr::bench::leuven_inputs(1920, 1080);
    const LeuvenGeometry g = leuven_geometry(in, leuven_scene_for_rays(in));
    char note[160];
    std::snprintf(note, sizeof note, " (recorded from a sunlit 1080p fog render, %llu rays in all)",
                  (unsigned long long)total);
    run_scene("leuven 1080p sun", g.mesh, rays, reps, note);
  }
  return 0;
}
