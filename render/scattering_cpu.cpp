#include "render/scattering_cpu.h"

#include <tbb/blocked_range2d.h>
#include <tbb/combinable.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <optional>
#include <vector>

#include "render/embree_scene.h"
#include "render/huge_pages.h"
#include "render/math.h"
#include "render/medium.h"
#include "render/photo_fallback.h"
#include "render/physics/resolve.h"
#include "render/physics/scattering.h"
#include "render/surface_query_cache.h"
#include "shaders/scattering_params.h"  // kEdgeBisections, kShaftRefinement (shared with the GPU)

namespace mr::render {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// The adaptive grid (render_scattering_cpu, pass 1; issue 12 item 4): exact samples first at
// every kCoarseFactor-th grid point, the grid's own spacing only in the coarse cells that need
// it; a coarse cell whose gradient interpolation's error estimate exceeds kRefineTolerance
// (relative) is refined. Measured at 1080p normal on bench/bench_scattering.cpp's scene (mean
// relative error of R against the final preset without acceleration: 0.1647 % with the plain
// grid, 16.4 M shadow rays), before the AO test below: factor 2 at tolerance 1e-2 8.6 M rays,
// 0.1685 %; 5e-3 10.0 M rays, 0.1681 %; factor 4 at 1e-2 7.3 M rays, 0.1754 %. Again on
// 2026-12-07, with everything since (against 128 unaccelerated steps; the exact 32-step march
// itself 0.1517 %): factor 2 6.73 M rays, 0.1652 %; 3 5.45 M, 0.1674 %; 4 5.39 M, 0.1711 %; 4 at
// 5e-3 8.03 M, 0.1728 % (more exact samples carry more of the march's jitter noise). Factor 3:
// the tests' Monte Carlo and closed-form errors equal or lower, the forest of
// bench/bench_forest_shafts.cpp (an edge in nearly every cell) 0.4966 -> 0.5013 % at the same
// rays; the 1080p slider render 11-18 % faster (README, issue 12).
constexpr std::size_t kCoarseFactor = 3;
constexpr double kRefineTolerance = 1e-2;
// ...and one whose corners' ambient occlusion differs by more than kRefineAo (two of normal's
// 8 rays): AO is noisy and steps at walls' feet, and T's surface term reads it (without this,
// T's mean error against the final preset rose 0.0564 % -> 0.0579 %; with it 0.0564 %, at
// 10.5 M rays).
constexpr double kRefineAo = 0.25;
// Pass 2's thin cells (thin_edge) whose corners' R differ by at most this (relative): marched
// with the preset's steps, not finer ones where the corners saw shadow (thin_zone). The thin
// shadows there are shallow (bridge's cables against the sky): a miss costs little.
constexpr double kThinShallow = 0.02;
constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;
constexpr double kGoldenAngle = 2.39996322972865332;
// Step multiplier for pixels next to a shaft's edge (see render_scattering_cpu's pass 2), and
// bisection steps for a shaft edge's crossing (Core::march): one definition for both backends.
using gpu::kEdgeBisections;
using gpu::kShaftRefinement;
using gpu::kShaftRefinementBisections;

using physics::fract;
using physics::pixel_jitter;

// The smooth cone falloff of a spot lamp (1 for point lamps).
double spot_factor(const Lamp& lamp, const Vec3d& from_lamp_unit) {
  if (lamp.outer_angle_deg >= 180.0) return 1.0;
  return physics::spot_cone(dot(normalized(vec(lamp.spot_direction)), from_lamp_unit),
                            std::cos(lamp.inner_angle_deg * kDeg),
                            std::cos(lamp.outer_angle_deg * kDeg));
}

Vec3d rgb(const std::array<float, 3>& c) {
  return {c[0], c[1], c[2]};
}

// Thin shadows (issue 11): a shadow that a view ray crosses in less than a march step or two
// is caught only where the pixel's jitter puts a sample in it. A march reports what it caught
// (ThinShadows) so that its neighbours can look for the same shadow where their own view ray
// passes it (render_scattering_cpu's hints): one ray each, instead of more steps everywhere.
constexpr int kMaxThinShadows = 4;
// A shadowed run of at most this many march samples, lit on both sides, is thin.
constexpr int kThinRunSamples = 2;
struct ThinShadows {
  // Midpoints (distance along the view ray, m) of the thin shadows the march caught and
  // bisected.
  float mid_m[kMaxThinShadows] = {};
  // Every shadowed run's extent, from the lit sample before it to the lit sample after it (the
  // march's ends where there is none): a hint there is known already.
  float run_lo_m[kMaxThinShadows] = {}, run_hi_m[kMaxThinShadows] = {};
  unsigned char mids = 0, runs = 0;  // (runs beyond kMaxThinShadows are not kept)
  // The hints that moved a sample (Core::march), for a march redone with more hints.
  float hinted_m[kMaxThinShadows] = {};
  unsigned char hinted = 0;
  // Where the march saw shadow at all: from the lit sample before the first shadowed run to the
  // lit sample after the last (the march's ends where there is none); lo > hi: nowhere. Pass 2
  // marches its thin cells' pixels with finer steps there (StepZone).
  float shadow_lo_m = 0, shadow_hi_m = -1;
  // The march samples' own sun visibility (bit i: sample i, before any hint), when there are
  // at most 64: a march redone with hints reads it instead of tracing its rays again.
  std::uint64_t visible_bits = 0;
  unsigned char visible_samples = 0;  // 0: not kept
  bool knows(double t_m) const {
    for (int r = 0; r < runs; ++r)
      if (t_m >= run_lo_m[r] && t_m <= run_hi_m[r]) return true;
    return false;
  }
};

struct PixelSample {
  double inscatter[3] = {0, 0, 0};
  double camera_od[3] = {0, 0, 0};  // optical depth camera -> surface (or end of the sky march)
  double shaft = 1;                 // fraction of march samples that saw the sun (1: no sun)
  double ao = 1;                    // ambient occlusion at the surface
  double sun_disk = -1;             // sun_disk_visibility at the surface, -1: not known
  // Where the march's samples changed sun visibility (the bisected crossings, m along the view
  // ray), when there were at most kMaxCrossings; kCrossingsUnknown otherwise, or where no march
  // made the sample. Pass 2 refines its shaft-edge pixels' marches around the corners' ones.
  static constexpr int kMaxCrossings = 8;
  static constexpr unsigned char kCrossingsUnknown = 255;
  float crossing_m[kMaxCrossings] = {};
  unsigned char crossings = kCrossingsUnknown;
};

// Distances along a pixel's view ray (m) where a neighbour's thin shadows may lie (hints).
struct Hints {
  static constexpr int kMax = 16;
  double t_m[kMax];
  int n = 0;
  void add(double t) {  // (a shadow hinted by two corners once)
    if (n == kMax || !std::isfinite(t) || std::find(t_m, t_m + n, t) != t_m + n) return;
    t_m[n++] = t;
  }
};

// Stretches of a view ray (m) over which Core::march splits each of its segments in `factor`
// (pass 2's thin cells: where their corners saw shadow; its shaft-edge cells: around the
// corners' crossings).
struct StepZone {
  static constexpr int kMax = 4 * PixelSample::kMaxCrossings + 1;  // (edge_zone: + beyond)
  double lo_m[kMax] = {}, hi_m[kMax] = {};  // stretches lo > hi are empty
  int n = 0;
  int factor = 1;
  // Whether one more segment on each side of those overlapping a stretch is split too (the
  // thin cells' stretch, from the corners' outermost shadow, carried; not the edge cells'
  // crossings: their own march bisects a crossing that falls beside its split segment anyway).
  bool widen = true;
  void add(double lo, double hi) {
    if (n < kMax) {
      lo_m[n] = lo;
      hi_m[n] = hi;
      ++n;
    }
  }
};

class Core {
 public:
  Core(const CoreInputs& in, const MarchPlan& plan) : in_(in), plan_(plan), scene_(*in.scene) {
    const Medium& m = scene_.medium;
    for (int c = 0; c < 3; ++c) sigma_[c] = m.sigma_t_per_m[c];
    sigma3_ = {sigma_[0], sigma_[1], sigma_[2]};
    albedo_ = rgb(m.albedo);
    shape_ = medium_shape(m);
    sky_ = rgb(in.sky_radiance);
    sigma_mean_ = (sigma_[0] + sigma_[1] + sigma_[2]) / 3.0;
    sigma_min_ = std::min({sigma_[0], sigma_[1], sigma_[2]});
    grey_ = sigma_[0] == sigma_[1] && sigma_[1] == sigma_[2];
    if (scene_.lighting.sun) {
      const Sun& sun = *scene_.lighting.sun;
      sun_dir_ = normalized(vec(sun.direction_to_sun));
      sun_irradiance_ = rgb(sun.irradiance);
      // An orthonormal frame around the sun direction for sampling its disk.
      const Vec3d helper = std::fabs(sun_dir_[1]) < 0.9 ? Vec3d{0, 1, 0} : Vec3d{1, 0, 0};
      sun_u_ = normalized(cross(helper, sun_dir_));
      sun_v_ = cross(sun_dir_, sun_u_);
      sun_tan_radius_ = std::tan(sun.angular_radius_deg * kDeg);
      // The surface's sun-disk rays: one set for every pixel (sun_disk_visibility), so their
      // directions once per render instead of a sincos and a normalization per ray.
      const int disk_rays = sun_tan_radius_ > 0 ? plan.sun_surface_rays : 1;
      for (int i = 0; i < disk_rays; ++i) {
        Vec3d dir = sun_dir_;
        if (sun_tan_radius_ > 0) {
          // A spiral turned by the seed, as for AO: a penumbra on a smooth surface steps
          // consistently instead of speckling.
          const double r = sun_tan_radius_ * std::sqrt((i + 0.5) / disk_rays);
          const double phi = kGoldenAngle * i + 2 * kPi * pixel_jitter(0, 0, scene_.render.seed);
          dir =
              normalized(add(add(sun_dir_, sun_u_, r * std::cos(phi)), sun_v_, r * std::sin(phi)));
        }
        disk_dirs_.push_back(dir);
      }
      // cos / sin of the golden-angle spiral's angles, looked up per march step (sincos per
      // step measured 9 % of a render).
      const std::size_t max_steps = std::size_t(
          plan.steps * kShaftRefinement + plan.lamp_steps * int(scene_.lighting.lamps.size()) + 2);
      spiral_.resize(kSpiralRotations + max_steps);
      for (std::size_t n = 0; n < spiral_.size(); ++n)
        spiral_[n] = {std::cos(kGoldenAngle * double(n)), std::sin(kGoldenAngle * double(n))};
      // Light-path optical depth toward the sun does not depend on x/z: only on height.
    }
    origin_ = vec(scene_.pose.position_m);
    const auto [forward, right, up] = scene_.pose.axes();
    forward_ = vec(forward);
    right_ = vec(right);
    up_ = vec(up);
    constant_source_ =
        !scene_.lighting.sun && scene_.lighting.lamps.empty() && scene_.medium.noise.amplitude <= 0;
    if (in.surface_queries) {
      // Everything the surface's answers depend on beyond the cached geometry.
      SurfaceQuerySettings settings;
      settings.mesh_step = plan.mesh_step;
      settings.ao_rays = plan.ao_rays;
      settings.ao_partial_rays = plan.ao_partial_rays;
      settings.seed = scene_.render.seed;
      settings.camera_forward = forward_;
      settings.sun_disk_directions = disk_dirs_;
      in.surface_queries->use(settings);
    }
  }

  std::size_t shadow_rays() const { return rays_.combine(std::plus<>()); }

  // CameraPose::ray_direction, with the pose's axes computed once (not 6 trig calls a ray).
  Vec3d ray(int x, int y) const {
    const Camera& cam = *in_.camera;
    return physics::camera_ray(forward_, right_, up_, cam.focal_px, cam.cx, cam.cy, x, y);
  }

  // Direction of march step i's sample of the sun's disk: stratified in radius over the ray's
  // steps, a golden-angle spiral in angle, rotated per pixel (rotation < kSpiralRotations).
  Vec3d sun_sample_direction(std::size_t i, double jitter, double steps,
                             std::uint32_t rotation) const {
    if (sun_tan_radius_ <= 0) return sun_dir_;
    const double r = sun_tan_radius_ * std::sqrt(fract((double(i) + jitter) / steps));
    const auto [c, s] = spiral_[i + rotation];
    return normalized(add(add(sun_dir_, sun_u_, r * c), sun_v_, r * s));
  }

  // The march's far end: the surface, or for the sky where the fog has (almost) ended.
  double march_length(const RayDensity& rd, double distance) const {
    return physics::march_length(rd.shared(), distance, scene_.render.max_distance_m, sigma_min_);
  }

  // Where pixel (x, y)'s view ray passes a thin shadow that pixel (xn, yn)'s march caught at
  // distance tn_m along its own ray: the point of (x, y)'s ray nearest to the line through
  // that shadow along the sun's direction (a shadow volume is swept along it). NaN where the
  // view ray runs (nearly) along the sun or the point lies behind the camera.
  double hint_on_ray(int x, int y, int xn, int yn, double tn_m) const {
    if (!scene_.lighting.sun) return kNaN;
    const Vec3d w = ray(x, y);
    // Lines o + t w and p + s u with p = o + tn wn: r = o - p = -tn wn.
    const Vec3d r = ray(xn, yn) * -tn_m;
    const double b = dot(w, sun_dir_), d = dot(w, r), e = dot(sun_dir_, r);
    const double denom = 1 - b * b;
    if (denom < 1e-6) return kNaN;
    const double t = (b * e - d) / denom;
    return t > 0 ? t : kNaN;
  }

  // Whether the sun (its centre) is hidden at distance t_m along pixel (x, y)'s view ray, where
  // the march would sample it: one shadow ray testing a hint before a march is redone for it.
  bool hint_shadowed(int x, int y, double t_m) const {
    if (!scene_.lighting.sun || !in_.occluders) return false;
    const Vec3d w = ray(x, y);
    const RayDensity rd(scene_.medium, origin_, w);
    if (!(t_m < march_length(rd, in_.distance_m.at(x, y, 0)))) return false;
    rays_.local() += 1;
    return sun_centre_hidden(w, t_m);
  }

  // One shadow ray toward the sun's centre from distance t_m along view direction w (a hint's
  // test, in hint_shadowed and in march).
  bool sun_centre_hidden(const Vec3d& w, double t_m) const {
    return in_.occluders->occluded(f3(add(origin_, w, t_m)), f3(sun_dir_), float(1e-3 + 1e-4 * t_m),
                                   float(kInf));
  }

  // `steps`: view-ray segments (the preset's, or more where a pixel straddles a shaft edge).
  // `hints`: distances along the view ray where a neighbour's thin shadow may lie: each one
  // whose segment's sample and both neighbours' saw the sun is tested (one shadow ray toward
  // the sun's centre, see `centred`), and where the sun is hidden there the segment's sample
  // moves there, so that the shadow is bisected as if the jitter had put the sample in it.
  // `known`: this pixel's earlier march with the same steps, whose samples' sun visibility
  // (ThinShadows::visible_bits) is reused. `thin`: where to say what the march caught. `zone`:
  // where the segments are split (the segments that overlap it, and one more on each side).
  PixelSample march(int x, int y, int steps, const Hints* hints = nullptr,
                    const ThinShadows* known = nullptr, ThinShadows* thin = nullptr,
                    const StepZone* zone = nullptr) const {
    PixelSample s;
    const double distance = in_.distance_m.at(x, y, 0);
    const Vec3d w = ray(x, y);
    const RayDensity rd(scene_.medium, origin_, w);
    const double length = march_length(rd, distance);
    const double od_unit_total = rd.optical_depth(0, length);
    const Medium& m = scene_.medium;
    const bool has_noise = m.noise.amplitude > 0;

    if (constant_source_ || length <= 0) {
      // Sky light only: sum over segments telescopes to albedo L (1 - tau(D)) exactly (to the
      // very end of the fog for the sky).
      s.crossings = 0;
      const double od_exact = rd.optical_depth(0, distance);
      for (int c = 0; c < 3; ++c) s.camera_od[c] = scaled_optical_depth(sigma_[c], od_exact);
      sky_only_inscatter(s.camera_od, m.albedo, in_.sky_radiance, s.inscatter);
      return s;
    }

    // Segment boundaries: uniform in transmittance, plus equiangular ones around each lamp.
    thread_local std::vector<double> bounds;  // no allocation per march
    bounds.clear();
    const int factor = zone ? std::max(1, zone->factor) : 1;
    bounds.reserve(
        std::size_t(steps * factor + plan_.lamp_steps * scene_.lighting.lamps.size() + 2));
    bounds.push_back(0);
    const double od_mean_total = sigma_mean_ * od_unit_total;
    const double one_minus_tau_end = -std::expm1(-od_mean_total);
    auto boundary = [&](int i, int n) {
      return i < n ? physics::uniform_boundary(rd.shared(), i, n, sigma_mean_, od_mean_total,
                                               one_minus_tau_end, length)
                   : length;
    };
    // With a zone: the segments that overlap one of its stretches (and one more on each side
    // where it widens) split in `factor`, with the boundaries a march of steps * factor segments
    // has there (the same fractions of the transmittance). The rest are the preset's. split_runs:
    // the split segments' runs as distances (lo, hi), for the bisections below.
    thread_local std::vector<unsigned char> split;
    thread_local std::vector<std::pair<double, double>> split_runs;
    split_runs.clear();
    if (factor > 1) {
      thread_local std::vector<double> preset_bound;
      thread_local std::vector<unsigned char> overlaps;
      preset_bound.resize(std::size_t(steps) + 1);
      for (int i = 0; i <= steps; ++i) preset_bound[i] = boundary(i, steps);
      overlaps.assign(std::size_t(steps), 0);
      for (int i = 0; i < steps; ++i)
        for (int z = 0; z < zone->n && !overlaps[i]; ++z)
          overlaps[i] = preset_bound[i + 1] >= zone->lo_m[z] && preset_bound[i] <= zone->hi_m[z];
      split.assign(std::size_t(steps), 0);
      for (int i = 0; i < steps; ++i)
        split[i] =
            overlaps[i] ||
            (zone->widen && ((i > 0 && overlaps[i - 1]) || (i + 1 < steps && overlaps[i + 1])));
      for (int i = 0; i < steps;) {
        if (!split[i]) {
          ++i;
          continue;
        }
        const int first = i;
        while (i < steps && split[i]) ++i;
        split_runs.emplace_back(preset_bound[first], preset_bound[i]);
      }
    }
    for (int i = 0; i < steps; ++i) {
      if (factor > 1 && split[i])
        for (int k = 1; k < factor; ++k) {
          const double t = boundary(i * factor + k, steps * factor);
          if (t > 0 && t < length) bounds.push_back(t);
        }
      if (i + 1 == steps) break;
      const double t = boundary(i + 1, steps);
      if (t > 0 && t < length) bounds.push_back(t);
    }
    bounds.push_back(length);
    thread_local std::vector<physics::LampOnRay> lamp_rays;
    lamp_rays.clear();
    lamp_rays.reserve(scene_.lighting.lamps.size());
    for (const Lamp& lamp : scene_.lighting.lamps) {
      const physics::LampOnRay lr = physics::lamp_on_ray(vec(lamp.position_m), origin_, w, length);
      lamp_rays.push_back(lr);
      for (int i = 1; i < plan_.lamp_steps; ++i) {
        const double t = physics::lamp_boundary(lr, i, plan_.lamp_steps);
        if (t > 0 && t < length) bounds.push_back(t);
      }
    }
    // Without lamps the boundaries (0, the uniform ones, length) come in order: the sort (~33
    // values per march) only where lamps add theirs; the same sorted array either way.
    if (!std::is_sorted(bounds.begin(), bounds.end())) std::sort(bounds.begin(), bounds.end());
    bounds.erase(std::unique(bounds.begin(), bounds.end()), bounds.end());

    const double jitter = pixel_jitter(x, y, scene_.render.seed);
    const std::uint32_t pixel_rotation =
        std::uint32_t(x * 73856093u ^ y * 19349663u) % kSpiralRotations;
    const std::size_t segments = bounds.size() - 1;

    // First the segments' sample points, then their sun visibility in 8-wide packets (the rays
    // of one view ray toward the sun are nearly parallel and close: coherent), then the sums.
    thread_local std::vector<double> sample_t;
    thread_local std::vector<unsigned char> sun_visible;
    thread_local std::vector<double> crossing;  // visibility changes between samples i, i + 1
    // Samples moved to a hint (below): they, and the bisection of their edges, look at the
    // sun's centre, as hint_shadowed does, instead of the segment's point of its disk: where
    // a small occluder's shadow is a penumbra (a kite's, ~100 m behind it), a disk sample
    // would catch it or not at random, and the flood along the shaft would stop there. The
    // centre's shadow is as deep in sum (the penumbra is it blurred by the disk).
    thread_local std::vector<unsigned char> centred;
    sample_t.resize(segments);
    crossing.resize(segments);
    sun_visible.assign(segments, 1);
    for (std::size_t i = 0; i < segments; ++i)
      sample_t[i] = physics::segment_sample_t(bounds[i], bounds[i + 1], jitter, int(i));
    std::size_t rays = 0;
    if (scene_.lighting.sun && in_.occluders && known && known->visible_samples == segments) {
      for (std::size_t i = 0; i < segments; ++i) sun_visible[i] = (known->visible_bits >> i) & 1u;
    } else if (scene_.lighting.sun && in_.occluders) {
      occluded_rays(
          *in_.occluders, segments,
          [&](std::size_t i) {
            const double ts = sample_t[i];
            const Vec3d xs = add(origin_, w, ts);
            const Vec3d dir = sun_sample_direction(i, jitter, double(segments + 1), pixel_rotation);
            return ShadowRay{{float(xs[0]), float(xs[1]), float(xs[2])},
                             {float(dir[0]), float(dir[1]), float(dir[2])},
                             float(1e-3 + 1e-4 * ts)};
          },
          [&](std::size_t i, bool blocked) { sun_visible[i] = !blocked; });
      rays += segments;
    }
    if (scene_.lighting.sun && in_.occluders) {
      if (thin) {
        *thin = ThinShadows{};
        if (segments <= 64) {
          for (std::size_t i = 0; i < segments; ++i)
            thin->visible_bits |= std::uint64_t(sun_visible[i]) << i;
          thin->visible_samples = (unsigned char)segments;
        }
      }
      if (hints) centred.assign(segments, 0);  // (read only with hints)
      for (int h = 0; hints && h < hints->n; ++h) {
        const double th = hints->t_m[h];
        if (!(th > bounds[0] && th < bounds[segments])) continue;
        const std::size_t k =
            std::size_t(std::upper_bound(bounds.begin(), bounds.end(), th) - bounds.begin()) - 1;
        if (k >= segments || !sun_visible[k] || (k > 0 && !sun_visible[k - 1]) ||
            (k + 1 < segments && !sun_visible[k + 1]))
          continue;
        ++rays;
        if (sun_centre_hidden(w, th)) {
          sample_t[k] = th;
          sun_visible[k] = 0;
          centred[k] = 1;
          if (thin && thin->hinted < kMaxThinShadows) thin->hinted_m[thin->hinted++] = float(th);
        }
      }
      // Shaft edges: where the visibility changes between two samples, bisect for the crossing
      // (to 1/64 of the gap), so each segment gets its exact lit part instead of all or nothing:
      // one sample per segment alone leaves a jitter-dithered edge of 1/steps steps. The
      // crossings of one view ray are bisected together, one step of each in a packet (the
      // same rays as one crossing after another; single rays were a tenth of the render).
      thread_local std::vector<std::size_t> edges;
      thread_local std::vector<double> edge_lo, edge_hi;
      thread_local std::vector<Vec3d> edge_dir;
      edges.clear();
      for (std::size_t i = 0; i + 1 < segments; ++i)
        if (sun_visible[i] != sun_visible[i + 1]) edges.push_back(i);
      edge_lo.resize(edges.size());
      edge_hi.resize(edges.size());
      edge_dir.resize(edges.size());
      for (std::size_t e = 0; e < edges.size(); ++e) {
        const std::size_t i = edges[e];
        edge_lo[e] = sample_t[i];
        edge_hi[e] = sample_t[i + 1];
        edge_dir[e] = hints && (centred[i] || centred[i + 1])
                          ? sun_dir_
                          : sun_sample_direction(i, jitter, double(segments + 1), pixel_rotation);
      }
      // A refined march (pass 2's shaft-edge cells) has closer samples: fewer bisections; a
      // zoned one (pass 2's thin cells) where the edge's samples are a split segment's.
      const int bisections = steps > plan_.steps ? kShaftRefinementBisections : kEdgeBisections;
      thread_local std::vector<int> edge_bisections;
      edge_bisections.resize(edges.size());
      for (std::size_t e = 0; e < edges.size(); ++e) {
        bool in_split = false;
        for (const auto& [lo, hi] : split_runs) in_split |= edge_lo[e] >= lo && edge_hi[e] <= hi;
        edge_bisections[e] =
            in_split ? std::min(bisections, kShaftRefinementBisections) : bisections;
      }
      thread_local std::vector<std::size_t> active;  // the edges still bisected
      for (int k = 0; k < bisections && !edges.empty(); ++k) {
        active.clear();
        for (std::size_t e = 0; e < edges.size(); ++e)
          if (k < edge_bisections[e]) active.push_back(e);
        if (active.empty()) break;
        rays += active.size();
        if (active.size() == 1) {  // one ray: Embree's single-ray path is cheaper than a packet
          const std::size_t e = active[0];
          const double mid = 0.5 * (edge_lo[e] + edge_hi[e]);
          const bool visible = !in_.occluders->occluded(f3(add(origin_, w, mid)), f3(edge_dir[e]),
                                                        float(1e-3 + 1e-4 * mid), float(kInf));
          (visible == bool(sun_visible[edges[e]]) ? edge_lo[e] : edge_hi[e]) = mid;
          continue;
        }
        occluded_rays(
            *in_.occluders, active.size(),
            [&](std::size_t a) {
              const std::size_t e = active[a];
              const double mid = 0.5 * (edge_lo[e] + edge_hi[e]);
              const Vec3d xs = add(origin_, w, mid);
              const Vec3d& dir = edge_dir[e];
              return ShadowRay{{float(xs[0]), float(xs[1]), float(xs[2])},
                               {float(dir[0]), float(dir[1]), float(dir[2])},
                               float(1e-3 + 1e-4 * mid)};
            },
            [&](std::size_t a, bool blocked) {
              const std::size_t e = active[a];
              const double mid = 0.5 * (edge_lo[e] + edge_hi[e]);
              (!blocked == bool(sun_visible[edges[e]]) ? edge_lo[e] : edge_hi[e]) = mid;
            });
      }
      for (std::size_t e = 0; e < edges.size(); ++e)
        crossing[edges[e]] = 0.5 * (edge_lo[e] + edge_hi[e]);
      if (edges.size() <= std::size_t(PixelSample::kMaxCrossings)) {
        s.crossings = (unsigned char)edges.size();
        for (std::size_t e = 0; e < edges.size(); ++e) s.crossing_m[e] = float(crossing[edges[e]]);
      }
      // The shadowed runs and the thin shadows among them, for the neighbours' hints.
      for (std::size_t i = 0; thin && i < segments;) {
        if (sun_visible[i]) {
          ++i;
          continue;
        }
        const std::size_t a = i;
        while (i < segments && !sun_visible[i]) ++i;
        const float run_lo = float(a > 0 ? sample_t[a - 1] : 0.0),
                    run_hi = float(i < segments ? sample_t[i] : length);
        if (thin->shadow_lo_m > thin->shadow_hi_m) thin->shadow_lo_m = run_lo;
        thin->shadow_hi_m = run_hi;
        if (thin->runs < kMaxThinShadows) {
          thin->run_lo_m[thin->runs] = run_lo;
          thin->run_hi_m[thin->runs] = run_hi;
          ++thin->runs;
        }
        if (a > 0 && i < segments && i - a <= std::size_t(kThinRunSamples) &&
            thin->mids < kMaxThinShadows)
          thin->mid_m[thin->mids++] = float(0.5 * (crossing[a - 1] + crossing[i - 1]));
      }
    }

    Vec3d od{0, 0, 0}, tau{1, 1, 1}, inscatter{0, 0, 0};
    int sun_samples = 0;
    double sun_seen_fraction = 0;
    const bool light_path = scene_.render.light_path_attenuation;
    // Per view ray, not per segment: the sun's phase function, and the sun's optical depth at
    // each boundary (two segments meet there), computed where a lit segment first asks for it
    // (NaN: not yet). The same expressions as physics::sun_path_transmittance and
    // sun_inscatter evaluate per segment, so the same values.
    const double sun_phase =
        scene_.lighting.sun ? physics::henyey_greenstein(m.g, dot(w, sun_dir_)) : 0.0;
    thread_local std::vector<double> sun_od_at_bound;
    if (scene_.lighting.sun && light_path) sun_od_at_bound.assign(segments + 1, kNaN);
    auto sun_od_at = [&](std::size_t j) {
      double& od_j = sun_od_at_bound[j];
      if (std::isnan(od_j))
        od_j = physics::sun_path_optical_depth(shape_, origin_ + w * bounds[j], sun_dir_);
      return od_j;
    };
    for (std::size_t i = 0; i < segments; ++i) {
      const double ta = bounds[i], tb = bounds[i + 1];
      const double ts = sample_t[i];
      const Vec3d xs = add(origin_, w, ts);
      const double modulation = has_noise ? noise_modulation(m.noise, xs) : 1.0;
      const double seg_od_unit = rd.optical_depth(ta, tb) * modulation;
      const Vec3d tau_before = tau;
      const Vec3d weight = physics::advance_segment(od, tau, sigma3_, albedo_, seg_od_unit);
      if (physics::segment_dark(weight, tau_before)) continue;

      if (scene_.lighting.sun) {
        const bool vis = sun_visible[i];
        const bool vis_prev = i > 0 ? bool(sun_visible[i - 1]) : vis;
        const bool vis_next = i + 1 < segments ? bool(sun_visible[i + 1]) : vis;
        const double tl = vis_prev != vis ? std::max(ta, crossing[i - 1]) : ta;
        const double tr = vis_next != vis ? std::min(tb, crossing[i]) : tb;
        const Vec3d lit_weight =
            physics::sun_lit_weight(rd.shared(), ta, tb, tl, tr, vis_prev, vis, vis_next,
                                    modulation, weight, albedo_, tau_before, sigma3_);
        sun_seen_fraction += physics::sun_seen_fraction(ta, tb, tl, tr, vis_prev, vis, vis_next);
        ++sun_samples;
        if (lit_weight.x + lit_weight.y + lit_weight.z > 0) {
          const Vec3d tau_sun = light_path
                                    ? physics::sun_path_transmittance_ends(
                                          shape_, rd.shared(), origin_, w, sun_dir_, ta, tb, xs,
                                          modulation, sigma3_, sun_od_at(i), sun_od_at(i + 1))
                                    : Vec3d{1, 1, 1};
          inscatter +=
              physics::sun_inscatter_phase(lit_weight, sun_phase, sun_irradiance_, tau_sun);
        }
      }
      for (std::size_t li = 0; li < scene_.lighting.lamps.size(); ++li) {
        const Lamp& lamp = scene_.lighting.lamps[li];
        const physics::LampOnRay& lr = lamp_rays[li];
        const double tm = physics::lamp_segment_t(lr, ta, tb);
        const Vec3d xm = add(origin_, w, tm);
        const physics::TowardLamp to_lamp = physics::toward_lamp(xm, vec(lamp.position_m));
        const double r = to_lamp.r;
        if (r < 1e-9) continue;
        const Vec3d l = to_lamp.l;
        const double spot = spot_factor(lamp, -l);
        if (spot <= 0) continue;
        if (in_.occluders) {
          ++rays;
          if (in_.occluders->occluded(f3(xm), f3(l), float(1e-3 + 1e-4 * tm),
                                      float(r * (1 - 1e-4))))
            continue;
        }
        const double lamp_modulation = has_noise ? noise_modulation(m.noise, xm) : 1.0;
        const double phase = physics::henyey_greenstein(m.g, dot(w, l));
        const double od_lamp = light_path ? RayDensity(m, xm, l).optical_depth(0, r) : 0.0;
        inscatter += physics::lamp_inscatter(lr, rd.shared(), ta, tb, tm, lamp_modulation, phase,
                                             spot, od_lamp, albedo_, sigma3_, tau_before,
                                             rgb(lamp.intensity_per_sr));
      }
      inscatter += weight * sky_;
    }
    for (int c = 0; c < 3; ++c) s.inscatter[c] = inscatter[c];
    for (int c = 0; c < 3; ++c) s.camera_od[c] = od[c];
    s.shaft = sun_samples ? sun_seen_fraction / sun_samples : 1.0;
    rays_.local() += rays;
    return s;
  }

  // Where a surface pixel's shadow and AO rays start: its point moved onto the occluder mesh
  // along the view ray (when the mesh is coarse), then 1 mm + 1e-3 of its distance off along
  // its normal. A coarse mesh (draft: the nearest surface of each mesh_step x mesh_step block,
  // render/depth_downsample.h) lies up to a fine pixel's depth step in front of the pixel's own
  // surface: on flat ground that is about (mesh_step - 1) / (2 f) of the distance (f in pixels)
  // above it, as much as the normal offset, so 41 % of a sunlit ground shadowed
  // itself at draft before. Moving onto the mesh first makes the offset count from the surface
  // the rays are traced against. The search along the view ray reaches back only by the largest
  // depth change to a neighbour within mesh_step pixels that continues the surface (within
  // 30 %, or on the pixel's plane), so a foreground object widened by the coarse mesh never
  // captures the point.
  Vec3d shadow_origin(int x, int y, double distance, const Vec3d& n) const {
    const Vec3d w = ray(x, y);
    double t_surface = distance;
    if (in_.occluders && plan_.mesh_step > 1) {
      const int r = plan_.mesh_step;
      const int w_px = in_.distance_m.width, h_px = in_.distance_m.height;
      // How far the surface's depth changes within mesh_step pixels (either way: the last row
      // has no nearer neighbour, yet its block's coarse surface lies as far in front of it).
      // A neighbour continues the surface when within 30 % or where the pixel's plane predicts
      // it within 5 % (near the horizon, ground rows differ by more than 30 %).
      const double plane_offset = dot(w, n) * distance;  // dot(x0 - camera, n)
      double change = 0;
      for (int j = std::max(0, y - r); j <= std::min(h_px - 1, y + r); ++j)
        for (int i = std::max(0, x - r); i <= std::min(w_px - 1, x + r); ++i) {
          const double d = in_.distance_m.at(i, j, 0);
          if (!std::isfinite(d)) continue;
          bool same = std::fabs(d - distance) <= 0.3 * distance;
          if (!same) {
            const double den = dot(ray(i, j), n);
            same = den < 0 && std::fabs(plane_offset / den - d) <= 0.05 * d;
          }
          if (same) change = std::max(change, std::fabs(d - distance));
        }
      const double t_lo = std::max(0.0, (distance - change) * (1 - 2e-3) - 1e-3);
      const double t_hi = distance * (1 + 1e-4) + 1e-4;
      rays_.local() += 1;
      const double hit =
          in_.occluders->intersect_distance(f3(origin_), f3(w), float(t_lo), float(t_hi));
      if (std::isfinite(hit)) t_surface = std::min(hit, distance);
    }
    return add(add(origin_, w, t_surface), n, 1e-3 + 1e-3 * distance);
  }

  // Ambient occlusion at a surface pixel (1 when there is nothing to occlude or no need).
  double ambient_occlusion_at(int x, int y) const {
    if (!in_.occluders || plan_.ao_rays <= 0 || in_.normals.data == nullptr) return 1.0;
    const double distance = in_.distance_m.at(x, y, 0);
    if (!std::isfinite(distance)) return 1.0;
    const Vec3d n = {in_.normals.at(x, y, 0), in_.normals.at(x, y, 1), in_.normals.at(x, y, 2)};
    if (dot(n, n) < 0.5) return 1.0;
    SurfaceQueryCache* const kept = in_.surface_queries;
    if (kept)
      if (const std::optional<float> ao = kept->ambient_occlusion(x, y)) return *ao;
    const Vec3d x0 = shadow_origin(x, y, distance, n);
    // One ray set for the whole render, in a frame that turns with the normal (occlusion.h):
    // neighbouring samples agree where the geometry does, so interpolating them stays smooth;
    // the plan's ao_partial_rays where the first ones disagree.
    int traced = 0;
    const float ao = ambient_occlusion(*in_.occluders, f3(x0), f3(n), plan_.ao_rays,
                                       float(std::max(1.0, 0.25 * distance)), scene_.render.seed,
                                       f3(-forward_), plan_.ao_partial_rays, &traced);
    rays_.local() += std::size_t(traced);
    if (kept) kept->set_ambient_occlusion(x, y, ao);
    return ao;
  }

  // The fraction of the sun's disk a surface pixel sees past the occluders (-1 where that does
  // not apply: no sun, no surface or normal, or the surface faces away from the sun).
  double sun_disk_visibility(int x, int y) const {
    if (!scene_.lighting.sun || in_.normals.data == nullptr) return -1;
    const double distance = in_.distance_m.at(x, y, 0);
    if (!std::isfinite(distance)) return -1;
    const Vec3d n = {in_.normals.at(x, y, 0), in_.normals.at(x, y, 1), in_.normals.at(x, y, 2)};
    if (dot(n, n) < 0.5 || dot(n, sun_dir_) <= 0) return -1;
    if (!in_.occluders) return 1;
    const int count = int(disk_dirs_.size());
    SurfaceQueryCache* const kept = in_.surface_queries;
    if (kept)
      if (const std::optional<int> seen = kept->sun_disk_seen(x, y)) return double(*seen) / count;
    const Vec3d xo = shadow_origin(x, y, distance, n);
    rays_.local() += std::size_t(count);
    int seen = 0;
    occluded_rays(
        *in_.occluders, std::size_t(count),
        [&](std::size_t index) {
          const Vec3d& dir = disk_dirs_[index];
          return ShadowRay{{float(xo[0]), float(xo[1]), float(xo[2])},
                           {float(dir[0]), float(dir[1]), float(dir[2])},
                           0.0f};
        },
        [&](std::size_t, bool blocked) { seen += !blocked; });
    if (kept) kept->set_sun_disk_seen(x, y, seen);
    return double(seen) / count;
  }

  // T's surface factor S (DESIGN.md section 3) at a surface pixel; writes the sun visibility.
  // known_sun_disk: the pixel's sun_disk_visibility when already known (interpolation), else -1.
  // camera_ray: ray(x, y) when the caller has it (pass 3 computes it once for both terms).
  void surface_term(int x, int y, double ao, double known_sun_disk, double S[3],
                    float* sun_visibility, const Vec3d* camera_ray = nullptr) const {
    S[0] = S[1] = S[2] = 1.0;
    *sun_visibility = 1.0f;
    const double distance = in_.distance_m.at(x, y, 0);
    const bool lights = scene_.lighting.sun || !scene_.lighting.lamps.empty();
    if (!std::isfinite(distance) || !lights || in_.normals.data == nullptr) return;
    const Vec3d n = {in_.normals.at(x, y, 0), in_.normals.at(x, y, 1), in_.normals.at(x, y, 2)};
    if (dot(n, n) < 0.5) return;
    const Medium& m = scene_.medium;
    const Vec3d x0 = add(origin_, camera_ray ? *camera_ray : ray(x, y), distance);
    // Lamp shadow rays leave from here (traced only where the pixel has a lamp in front of it).
    std::optional<Vec3d> xo_cache;
    auto xo = [&] {
      if (!xo_cache) xo_cache = shadow_origin(x, y, distance, n);
      return *xo_cache;
    };
    Vec3d direct{0, 0, 0}, direct_fogged{0, 0, 0};
    std::size_t rays = 0;
    const bool light_path = scene_.render.light_path_attenuation;
    if (scene_.lighting.sun) {
      const double cos_i = dot(n, sun_dir_);
      double visible = 0;
      if (cos_i > 0) {
        visible = known_sun_disk >= 0 ? known_sun_disk : sun_disk_visibility(x, y);
      }
      *sun_visibility = float(visible);
      const double od_sun =
          light_path ? physics::sun_path_optical_depth(shape_, x0, sun_dir_) : 0.0;
      physics::add_surface_light(direct, direct_fogged,
                                 sun_irradiance_ * std::max(0.0, cos_i) * visible,
                                 physics::transmittance(sigma3_, od_sun));
    }
    for (const Lamp& lamp : scene_.lighting.lamps) {
      const physics::TowardLamp to_lamp = physics::toward_lamp(x0, vec(lamp.position_m));
      const double r2 = to_lamp.r2, r = to_lamp.r;
      if (r < 1e-6) continue;
      const Vec3d l = to_lamp.l;
      const double cos_i = dot(n, l);
      if (cos_i <= 0) continue;
      const double spot = spot_factor(lamp, -l);
      if (spot <= 0) continue;
      if (in_.occluders) {
        ++rays;
        if (in_.occluders->occluded(f3(xo()), f3(l), 0.0f, float(r * (1 - 1e-4)))) continue;
      }
      const double od_lamp = light_path ? RayDensity(m, x0, l).optical_depth(0, r) : 0.0;
      physics::add_surface_light(direct, direct_fogged,
                                 rgb(lamp.intensity_per_sr) * spot * cos_i / r2,
                                 physics::transmittance(sigma3_, od_lamp));
    }
    rays_.local() += rays;
    const Vec3d s = physics::surface_factor(direct, direct_fogged, sky_, ao);
    for (int c = 0; c < 3; ++c) S[c] = s[c];
  }

  // Camera transmittance in closed form (exact unless noise modulates the view ray).
  void camera_optical_depth(int x, int y, double od[3]) const {
    camera_optical_depth(ray(x, y), x, y, od);
  }
  // The same along w = ray(x, y).
  void camera_optical_depth(const Vec3d& w, int x, int y, double od[3]) const {
    const RayDensity rd(scene_.medium, origin_, w);
    const double length = march_length(rd, in_.distance_m.at(x, y, 0));
    const double unit =
        rd.optical_depth(0, std::isfinite(in_.distance_m.at(x, y, 0)) ? length : kInf);
    for (int c = 0; c < 3; ++c) od[c] = physics::scaled_optical_depth(sigma_[c], unit);
  }

  bool has_noise() const { return scene_.medium.noise.amplitude > 0; }
  // Sky light only: every pixel is a closed form, cheaper than interpolating.
  bool constant_source() const { return constant_source_; }
  bool needs_ao() const {
    return in_.occluders && (scene_.lighting.sun || !scene_.lighting.lamps.empty());
  }
  // Whether T at pixel (x, y) can depend on its AO. S = (fogged direct + ambient) / (direct +
  // ambient) (physics::surface_factor) is exactly 1 whatever the AO where there is no direct
  // light: a surface facing away from the sun, without lamps (the photo fallback only ever
  // looks at sun-facing pixels); the sky and pixels without a normal take no surface term.
  bool ao_matters_at(int x, int y) const {
    if (!needs_ao() || in_.normals.data == nullptr) return false;
    if (!std::isfinite(in_.distance_m.at(x, y, 0))) return false;
    const Vec3d n = {in_.normals.at(x, y, 0), in_.normals.at(x, y, 1), in_.normals.at(x, y, 2)};
    if (dot(n, n) < 0.5) return false;
    return !scene_.lighting.lamps.empty() || dot(n, sun_dir_) > 0;
  }

 private:
  const CoreInputs& in_;
  MarchPlan plan_;
  const FogScene& scene_;
  double sigma_[3];
  Vec3d sigma3_, albedo_, sky_, sun_irradiance_;
  physics::MediumShape shape_{};  // the medium's smooth density, for the shared physics
  double sigma_mean_ = 0, sigma_min_ = 0;
  bool grey_ = false;
  Vec3d sun_dir_{0, 1, 0}, sun_u_{1, 0, 0}, sun_v_{0, 0, 1};
  double sun_tan_radius_ = 0;
  std::vector<Vec3d> disk_dirs_;  // the surface's sun-disk ray directions (sun_disk_visibility)
  static constexpr std::uint32_t kSpiralRotations = 1024;
  std::vector<std::pair<double, double>> spiral_;  // cos, sin of kGoldenAngle * n
  Vec3d origin_{};
  Vec3d forward_{0, 0, 1}, right_{1, 0, 0}, up_{0, 1, 0};  // the camera's axes (world)
  bool constant_source_ = false;
  mutable tbb::combinable<std::size_t> rays_{[] { return std::size_t(0); }};
};

// Per-pixel state of the gradient-accelerated pass. The exact grid samples keep their whole
// PixelSample (pass 2 interpolates from them); every pixel keeps only what pass 3 reads: R goes
// straight into the output image (as float, what pass 3 wrote before), AO and the surface's sun
// visibility in doubles, the camera's optical depth only when noise keeps pass 3 from its closed
// form. A full-frame PixelSample array (88 bytes a pixel, 182 MB at 1080p, zeroed by the kernel
// on every render) was a tenth of the render's CPU time in page faults. The per-pixel and
// per-sample arrays are HugePageArrays (render/huge_pages.h), left uninitialized: every pixel
// is set by pass 1 or 2 before pass 3 reads it, and a grid sample is read only where present.
// As zero-filled std::vectors (ao, sun_disk, grid, the gradients: ~85 MB at 1080p) their 4 KiB
// page faults and serial zeroing cost ~0.3 s of CPU a render on the 2-core VM.
struct Sparse {
  int width = 0, height = 0;
  ImageView inscatter;                                // the output R (3 channels)
  std::optional<HugePageArray<double>> ao, sun_disk;  // per pixel
  std::optional<HugePageArray<double>> camera_od;     // 3 per pixel, only when keep_camera_od
  bool keep_camera_od = false;
  std::optional<HugePageArray<PixelSample>> grid;  // the grid samples, row-major over gx x gy
  std::vector<int> grid_column, grid_row;  // a pixel column's (row's) index in gx (gy), or -1
  std::size_t columns = 0;                 // gx.size()
  std::vector<unsigned char> present;      // whether a grid sample was traced (adaptive grid)

  void init(int w, int h, ImageView r, bool keep_od, const std::vector<int>& gx,
            const std::vector<int>& gy, bool keep_grid) {
    width = w;
    height = h;
    inscatter = r;
    keep_camera_od = keep_od;
    columns = gx.size();
    ao.emplace(std::size_t(w) * h);
    sun_disk.emplace(std::size_t(w) * h);
    if (keep_od) camera_od.emplace(3 * std::size_t(w) * h);
    grid_column.assign(std::size_t(w), -1);
    grid_row.assign(std::size_t(h), -1);
    for (std::size_t i = 0; i < gx.size(); ++i) grid_column[std::size_t(gx[i])] = int(i);
    for (std::size_t j = 0; j < gy.size(); ++j) grid_row[std::size_t(gy[j])] = int(j);
    if (keep_grid) {
      grid.emplace(gx.size() * gy.size());
      present.assign(gx.size() * gy.size(), 0);
    }
  }
  // Whether pixel (x, y) is a traced grid sample.
  bool has(int x, int y) const {
    const int i = grid_column[std::size_t(x)], j = grid_row[std::size_t(y)];
    return i >= 0 && j >= 0 && present[std::size_t(j) * columns + std::size_t(i)];
  }
  bool present_at(std::size_t i, std::size_t j) const { return present[j * columns + i] != 0; }
  // Keeps grid sample (i, j).
  void put(std::size_t i, std::size_t j, const PixelSample& s) {
    (*grid)[j * columns + i] = s;
    present[j * columns + i] = 1;
  }
  const PixelSample& grid_at(std::size_t i, std::size_t j) const {
    return (*grid)[j * columns + i];
  }
  PixelSample& grid_at(std::size_t i, std::size_t j) { return (*grid)[j * columns + i]; }
  void set(int x, int y, const PixelSample& s) {
    const std::size_t idx = std::size_t(y) * width + x;
    for (int c = 0; c < 3; ++c) inscatter.at(x, y, c) = float(s.inscatter[c]);
    if (keep_camera_od)
      for (int c = 0; c < 3; ++c) (*camera_od)[3 * idx + c] = s.camera_od[c];
    (*ao)[idx] = s.ao;
    (*sun_disk)[idx] = s.sun_disk;
  }
  // What pass 3 reads of pixel (x, y) (R as stored; the camera's optical depth 0 unless kept).
  PixelSample at(int x, int y) const {
    const std::size_t idx = std::size_t(y) * width + x;
    PixelSample s;
    for (int c = 0; c < 3; ++c) s.inscatter[c] = inscatter.at(x, y, c);
    if (keep_camera_od)
      for (int c = 0; c < 3; ++c) s.camera_od[c] = (*camera_od)[3 * idx + c];
    s.ao = (*ao)[idx];
    s.sun_disk = (*sun_disk)[idx];
    return s;
  }
};

using physics::depth_continuous;

}  // namespace

MarchPlan march_plan(const RenderSettings& settings) {
  MarchPlan plan;
  switch (settings.quality) {
    case Quality::draft:
      plan = {12, 8, 4, 2, 8, 2, 32};
      break;
    case Quality::normal:
      plan = {32, 16, 3, 4, 8, 1, 32};
      break;
    case Quality::final:
      plan = {128, 48, 1, 16, 32, 1, 64};
      break;
  }
  if (settings.march_steps > 0) plan.steps = settings.march_steps;
  if (settings.grid_step > 0) plan.grid_step = settings.grid_step;
  if (!settings.gradient_acceleration) plan.grid_step = 1;
  return plan;
}

void render_scattering_cpu(const CoreInputs& in, CoreOutputs& out) {
  using Clock = std::chrono::steady_clock;
  auto seconds_since = [](Clock::time_point t) {
    return std::chrono::duration<double>(Clock::now() - t).count();
  };
  auto pass_start = Clock::now();
  const MarchPlan plan = march_plan(in.scene->render);
  const Core core(in, plan);
  const int w = in.distance_m.width, h = in.distance_m.height;
  const int g = core.constant_source() ? 1 : std::max(1, plan.grid_step);
  // Cancellation: every row of every pass checks the token (one relaxed load) and skips its work
  // once it is requested; each pass's end throws. TBB's own cancellation is not needed.
  auto stop = [&] { return in.cancel && in.cancel->requested(); };
  auto throw_if_stopped = [&] { throw_if_cancelled(in.cancel, "render_scattering (cpu)"); };
  throw_if_stopped();
  // The outputs (83 MB at 1080p) are commonly fresh, never-written allocations
  // (Image::uninitialized): advised for huge pages before the passes below first write them,
  // they fault in 2 MiB at a time instead of 4 KiB (~20 k faults, ~0.2 s of CPU a 1080p render
  // on the 2-core VM). Memory already written keeps its pages; nothing else changes.
  for (const ImageView& v :
       {out.transmittance, out.inscatter, out.sun_visibility, out.optical_depth})
    if (v.data != nullptr && v.height > 0)
      advise_huge_pages(v.data, std::size_t(v.height) * std::size_t(v.row_stride) * sizeof(float));

  // Pass 1: exact samples on the sparse grid (and the last row / column, so every pixel lies in
  // a cell with four samples), adaptively (issue 12 item 4): first a coarse grid of every
  // kCoarseFactor-th sample, then the grid's own spacing only in the coarse cells where their
  // interpolation could not stand in for it (refine_coarse_cell below).
  std::vector<int> gx, gy;
  for (int x = 0; x < w; x += g) gx.push_back(x);
  if (gx.back() != w - 1) gx.push_back(w - 1);
  for (int y = 0; y < h; y += g) gy.push_back(y);
  if (gy.back() != h - 1) gy.push_back(h - 1);
  const std::size_t nx = gx.size(), ny = gy.size();

  const bool closed_form_camera = !core.has_noise();
  Sparse sparse;
  sparse.init(w, h, out.inscatter, !closed_form_camera, gx, gy, g > 1);

  // Where AO is traced: at the samples and exact pixels within ao_reach pixels (in x and y)
  // of a pixel whose T can depend on its AO (Core::ao_matters_at). Everywhere else its value
  // reaches no T: an interpolated pixel reads its cell's corners (at most one coarse cell,
  // g * kCoarseFactor pixels, away) and their gradients (their nearest traced neighbours, one
  // more cell), and which fine points exist there depends on the AO of the corners of the cells
  // around them (a third cell). The rest keep AO 1; T is bit-identical, and only
  // the coarse cells refined for the AO test alone (kRefineAo) change: on surfaces facing away
  // from the sun no longer, whose R then comes from the coarse cell's interpolation instead of
  // the fine grid's interpolation of the same (render_scattering_cpu's surface samples).
  // The test is a box sum over a summed-area table of ao_matters_at.
  const int ao_reach = 3 * g * int(kCoarseFactor) + 1;
  // (w + 1) x (h + 1) summed-area table (unused where AO is wanted everywhere). Every entry
  // is written below: row 0 and column 0 zero, the rest prefix sums (a zero-filled vector was a
  // serial pass over 8 MB of fresh 4 KiB pages at 1080p).
  const bool ao_everywhere = !core.needs_ao() || !in.scene->lighting.lamps.empty();
  HugePageArray<std::uint32_t> ao_table(ao_everywhere ? 0 : (std::size_t(w) + 1) * (h + 1));
  if (!ao_everywhere) {
    const std::size_t tw = std::size_t(w) + 1;
    std::fill(ao_table.data(), ao_table.data() + tw, 0u);
    tbb::parallel_for(0, h, [&](int y) {  // row prefix sums
      std::uint32_t sum = 0;
      std::uint32_t* row = &ao_table[(std::size_t(y) + 1) * tw];
      row[0] = 0;
      for (int x = 0; x < w; ++x) row[x + 1] = sum += core.ao_matters_at(x, y) ? 1u : 0u;
    });
    tbb::parallel_for(std::size_t(1), tw, [&](std::size_t x) {  // then down the columns
      for (int y = 1; y < h; ++y)
        ao_table[(std::size_t(y) + 1) * tw + x] += ao_table[std::size_t(y) * tw + x];
    });
  }
  auto ao_wanted = [&](int x, int y) {
    if (ao_everywhere) return core.needs_ao();
    const std::size_t tw = std::size_t(w) + 1;
    const std::size_t x0 = std::size_t(std::max(0, x - ao_reach)),
                      x1 = std::size_t(std::min(w, x + ao_reach + 1));
    const std::size_t y0 = std::size_t(std::max(0, y - ao_reach)),
                      y1 = std::size_t(std::min(h, y + ao_reach + 1));
    return ao_table[y1 * tw + x1] + ao_table[y0 * tw + x0] !=
           ao_table[y0 * tw + x1] + ao_table[y1 * tw + x0];
  };
  // known_sun_disk: the pixel's sun_disk_visibility when already traced (a probe below).
  // hints: where neighbours' thin shadows may cross the pixel's view ray (Core::march).
  // thin: where to keep what the march caught (coarse samples).
  auto exact = [&](int x, int y, int steps, double known_sun_disk = kNaN,
                   const Hints* hints = nullptr, ThinShadows* thin = nullptr,
                   const StepZone* zone = nullptr) {
    PixelSample s = core.march(x, y, steps, hints, nullptr, thin, zone);
    if (ao_wanted(x, y)) s.ao = core.ambient_occlusion_at(x, y);
    s.sun_disk = std::isnan(known_sun_disk) ? core.sun_disk_visibility(x, y) : known_sun_disk;
    sparse.set(x, y, s);
    return s;
  };
  // Progress (mr/cancel.h): one "render" stage in units of work weighted by their measured cost
  // (1280x720 street with sun, grid step 3: pass 1 0.75 s for 103k samples, pass 2 0.12 s for
  // 102k cells, pass 3 0.12 s for 0.9 MP): a sample 8, a cell 1, a row of pass 3 w / 8. A
  // sample the adaptive grid skips counts as done.
  constexpr std::size_t kSampleWork = 8, kCellWork = 1;
  const std::size_t kRowWork = std::max<std::size_t>(1, std::size_t(w) / 8);
  const std::size_t cells = g > 1 ? (nx - 1) * (ny - 1) : 0;
  ProgressCounter progress(in.cancel, "render",
                           nx * ny * kSampleWork + cells * kCellWork + std::size_t(h) * kRowWork);
  std::size_t exact_count = 0;

  // The coarse grid: fine indices 0, k, 2k, ... and the last (k = kCoarseFactor); its cells.
  auto coarse_indices = [](std::size_t n, std::size_t k) {
    std::vector<std::size_t> c;
    for (std::size_t i = 0; i < n; i += k) c.push_back(i);
    if (c.back() != n - 1) c.push_back(n - 1);
    return c;
  };
  // Not with noise: its wisps modulate the view ray's density on the noise's scale, so R and
  // the camera's optical depth (interpolated too, then) are not smooth over a coarse cell (the
  // GPU = CPU test's noisy scene: T's 99th percentile difference 1.9 % -> 5.0 % with it).
  const std::size_t k_coarse = g > 1 && !core.has_noise() ? kCoarseFactor : 1;
  const std::vector<std::size_t> cx = coarse_indices(nx, k_coarse),
                                 cy = coarse_indices(ny, k_coarse);
  auto d = [&](int x, int y) { return double(in.distance_m.at(x, y, 0)); };
  // What the grid samples' marches caught (thin shadows, below), row-major over gx x gy.
  const bool thin_hints = g > 1 && in.scene->lighting.sun && in.occluders;
  const std::size_t ncx_s = cx.size(), ncy_s = cy.size();
  // (Written for every grid sample, as it is traced or interpolated, before it is read.)
  HugePageArray<ThinShadows> grid_thin(thin_hints ? nx * ny : 0);
  // Those of coarse sample c (row-major over cx x cy).
  auto coarse_thin = [&](std::size_t c) -> ThinShadows& {
    return grid_thin[cy[c / ncx_s] * nx + cx[c % ncx_s]];
  };
  // Those of grid sample (i, j).
  auto thin_at = [&](std::size_t i, std::size_t j) -> ThinShadows& {
    return grid_thin[j * nx + i];
  };
  // Where a grid sample's march says what it caught (with thin_hints): reset, and handed to
  // the march only for a sky sample (the flood and thin_edge look at the sky only).
  auto sky_thin = [&](ThinShadows& slot, int x, int y) -> ThinShadows* {
    slot = ThinShadows{};  // (a march without the sun's rays, or a surface sample)
    return std::isfinite(d(x, y)) ? nullptr : &slot;
  };
  tbb::parallel_for(tbb::blocked_range2d<std::size_t>(0, cy.size(), 0, cx.size()),
                    [&](const tbb::blocked_range2d<std::size_t>& r) {
                      for (std::size_t b = r.rows().begin(); b < r.rows().end(); ++b) {
                        if (stop()) return;
                        for (std::size_t a = r.cols().begin(); a < r.cols().end(); ++a) {
                          ThinShadows* thin = thin_hints ? sky_thin(coarse_thin(b * ncx_s + a),
                                                                    gx[cx[a]], gy[cy[b]])
                                                         : nullptr;
                          const PixelSample s =
                              exact(gx[cx[a]], gy[cy[b]], plan.steps, kNaN, nullptr, thin);
                          if (g > 1) sparse.put(cx[a], cy[b], s);
                        }
                        progress.add(r.cols().size() * kSampleWork);
                      }
                    });
  throw_if_stopped();
  exact_count += cx.size() * cy.size();

  // Thin shadows (issue 11): a coarse sample whose march caught one hints it to its eight
  // neighbours, which test the point of their own view ray where it should be (one shadow ray
  // each, Core::hint_on_ray); where the sun is hidden there, the neighbour's march is redone
  // with the hint and catches the shadow too, and hints its own neighbours in the next wave:
  // a flood along the shaft, so that one sample's catch per shaft suffices. Every wave reads
  // the samples as the previous wave left them (deterministic). Without it the samples along
  // a thin shaft caught it where their jitter put a sample in it, and the grid interpolated
  // the dither into blobs (the kite's shaft a fan of dots). Sky samples only, as thin_edge
  // below: on the bench's street (1080p normal) 38 % of the coarse samples catch a thin
  // shadow, and the flood there redid 10 k surface marches, +2.5 % shadow rays but most of
  // the ~10 % of render CPU that the thin-shadow work added.
  auto sample_hints = [&](int x, int y, const ThinShadows& own, int xn, int yn,
                          const ThinShadows& neighbour, Hints& hints) {
    for (int m = 0; m < neighbour.mids; ++m) {
      const double t = core.hint_on_ray(x, y, xn, yn, neighbour.mid_m[m]);
      if (std::isfinite(t) && !own.knows(t)) hints.add(t);
    }
  };
  if (thin_hints) {
    std::vector<unsigned char> frontier(ncx_s * ncy_s, 0);
    std::vector<std::size_t> wave;
    for (std::size_t b = 0; b < ncy_s; ++b)
      for (std::size_t a = 0; a < ncx_s; ++a)
        if (coarse_thin(b * ncx_s + a).mids > 0 && !std::isfinite(d(gx[cx[a]], gy[cy[b]]))) {
          frontier[b * ncx_s + a] = 1;
          wave.push_back(b * ncx_s + a);
        }
    std::vector<std::size_t> candidates;
    // The samples a wave changed (candidate index, sample, what it caught): only those kept.
    struct Redone {
      std::size_t n;
      PixelSample sample;
      ThinShadows thin;
    };
    tbb::combinable<std::vector<Redone>> redone_local;
    std::vector<Redone> redone;
    while (!wave.empty() && !stop()) {
      candidates.clear();
      for (const std::size_t c : wave) {
        const std::size_t a = c % ncx_s, b = c / ncx_s;
        for (std::size_t bb = b > 0 ? b - 1 : 0; bb <= std::min(ncy_s - 1, b + 1); ++bb)
          for (std::size_t aa = a > 0 ? a - 1 : 0; aa <= std::min(ncx_s - 1, a + 1); ++aa)
            if (bb != b || aa != a) candidates.push_back(bb * ncx_s + aa);
      }
      std::sort(candidates.begin(), candidates.end());
      candidates.erase(std::unique(candidates.begin(), candidates.end()), candidates.end());
      tbb::parallel_for(std::size_t(0), candidates.size(), [&](std::size_t n) {
        const std::size_t c = candidates[n];
        const std::size_t a = c % ncx_s, b = c / ncx_s;
        const int x = gx[cx[a]], y = gy[cy[b]];
        if (std::isfinite(d(x, y))) return;  // sky only (thin_edge)
        const PixelSample& own = sparse.grid_at(cx[a], cy[b]);
        const ThinShadows& own_thin = coarse_thin(c);
        Hints hints;
        for (std::size_t bb = b > 0 ? b - 1 : 0; bb <= std::min(ncy_s - 1, b + 1); ++bb)
          for (std::size_t aa = a > 0 ? a - 1 : 0; aa <= std::min(ncx_s - 1, a + 1); ++aa)
            if (frontier[bb * ncx_s + aa])
              sample_hints(x, y, own_thin, gx[cx[aa]], gy[cy[bb]], coarse_thin(bb * ncx_s + aa),
                           hints);
        Hints shadowed;
        for (int m = 0; m < own_thin.hinted; ++m) shadowed.add(own_thin.hinted_m[m]);
        const int earlier = shadowed.n;
        for (int h = 0; h < hints.n; ++h)
          if (core.hint_shadowed(x, y, hints.t_m[h])) shadowed.add(hints.t_m[h]);
        if (shadowed.n == earlier) return;
        // The march again with the hints (and those of an earlier wave), its samples' own sun
        // visibility read back: R, the lit fraction and what it caught change; the camera's
        // optical depth, AO and the surface's sun visibility do not.
        ThinShadows fresh_thin;
        const PixelSample fresh = core.march(x, y, plan.steps, &shadowed, &own_thin, &fresh_thin);
        if (fresh_thin.mids <= own_thin.mids) return;
        PixelSample s = own;
        for (int k = 0; k < 3; ++k) s.inscatter[k] = fresh.inscatter[k];
        s.shaft = fresh.shaft;
        s.crossings = fresh.crossings;
        std::copy(std::begin(fresh.crossing_m), std::end(fresh.crossing_m), s.crossing_m);
        redone_local.local().push_back({n, s, fresh_thin});
      });
      for (const std::size_t c : wave) frontier[c] = 0;
      wave.clear();
      redone.clear();
      redone_local.combine_each([&](std::vector<Redone>& v) {
        redone.insert(redone.end(), v.begin(), v.end());
        v.clear();
      });
      std::sort(redone.begin(), redone.end(),
                [](const Redone& l, const Redone& r) { return l.n < r.n; });
      for (const Redone& r : redone) {
        const std::size_t c = candidates[r.n];
        const std::size_t a = c % ncx_s, b = c / ncx_s;
        sparse.put(cx[a], cy[b], r.sample);
        sparse.set(gx[cx[a]], gy[cy[b]], r.sample);
        coarse_thin(c) = r.thin;
        frontier[c] = 1;
        wave.push_back(c);
      }
    }
    throw_if_stopped();
  }
  // Whether a coarse cell of sky pixels has corners that disagree on having caught a thin
  // shadow: the shaft's edge in the image, which the fine grid (its samples marched with the
  // corners' hints) puts within a grid step instead of a coarse cell's interpolation, and
  // whose pixels pass 2 marches (the test ThinShaftInSunlitFogIsSmooth: error 21.1 % with the
  // flood alone, 14.8 % with the fine grid, 14.0 % with pass 2's pixels). Where the corners'
  // R differ by at most kRefineTolerance, the interpolation's own tolerance, the cell stays
  // interpolated (most of the bench's sky cells at a thin shadow). Sky only, for the cost:
  // on the bench's street 38 % of the coarse samples catch a thin shadow, the cells whose
  // corners disagree on one were a third of them, and refining those traced 8.3 -> 14.4 M
  // shadow rays. The sky's view rays are the longest (the march ends where the fog does), so
  // there shadows are thinnest against a step and in-scatter is all there is to see.
  auto thin_edge = [&](const std::array<std::pair<std::size_t, std::size_t>, 4>& corners) {
    if (!thin_hints) return false;
    bool any = false, all = true;
    double lum_min = kInf, lum_max = 0;
    for (const auto& [ci, cj] : corners) {
      if (std::isfinite(d(gx[ci], gy[cj]))) return false;
      const bool caught = thin_at(ci, cj).mids > 0;
      any |= caught;
      all &= caught;
      const double* r = sparse.grid_at(ci, cj).inscatter;
      lum_min = std::min(lum_min, r[0] + r[1] + r[2]);
      lum_max = std::max(lum_max, r[0] + r[1] + r[2]);
    }
    return any && !all && lum_max - lum_min > kRefineTolerance * lum_max;
  };
  // The hints of a cell's corners for fine sample (x, y) inside it.
  auto corner_hints = [&](const std::array<std::pair<std::size_t, std::size_t>, 4>& corners, int x,
                          int y, Hints& hints) {
    if (!thin_hints) return;
    const ThinShadows none;
    for (const auto& [ci, cj] : corners)
      sample_hints(x, y, none, gx[ci], gy[cj], thin_at(ci, cj), hints);
  };
  // Where pixel (x, y) of a thin cell gets finer steps: the stretch of its view ray where the
  // cell's corners saw shadow (ThinShadows::shadow_lo_m..shadow_hi_m, carried along the sun
  // onto its ray as hints are), split in kShaftRefinement. Elsewhere along the ray the corners
  // saw none, so thin shadows there are few. On the kite's sun bank (1280 px, with
  // kThinShallow) its thin cells' marches traced 2.61 -> about 1.2 M shadow rays at the error of
  // 128 steps along the whole ray (against 256 steps without acceleration, crop x 640-800,
  // y 60-200: 1.480 % against 1.474 %; x 500-1000, y 0-300: 0.567 % against 0.566 %). The
  // whole ray where a corner's end cannot be carried onto this one.
  auto thin_zone = [&](const std::array<std::pair<std::size_t, std::size_t>, 4>& corners, int x,
                       int y) {
    StepZone zone;
    zone.factor = kShaftRefinement;
    double lo = kInf, hi = -kInf;
    for (const auto& [ci, cj] : corners) {
      const ThinShadows& c = thin_at(ci, cj);
      if (!(c.shadow_lo_m <= c.shadow_hi_m)) continue;
      for (const float tc : {c.shadow_lo_m, c.shadow_hi_m}) {
        const double t = tc > 0 ? core.hint_on_ray(x, y, gx[ci], gy[cj], tc) : 0.0;
        if (std::isnan(t)) {
          zone.add(0, kInf);
          return zone;
        }
        lo = std::min(lo, t);
        hi = std::max(hi, t);
      }
    }
    zone.add(lo, hi);
    return zone;
  };

  constexpr int kValues = physics::kResolveValues;    // R (3), camera optical depth (3), AO
  using Gradients = std::array<double, 2 * kValues>;  // d/dx of each value, then d/dy
  auto values = [](const PixelSample& p, double v[kValues]) {
    for (int c = 0; c < 3; ++c) v[c] = p.inscatter[c];
    for (int c = 0; c < 3; ++c) v[3 + c] = p.camera_od[c];
    v[6] = p.ao;
  };
  // A sample's gradients along both grid axes from its nearest present grid neighbours on
  // each side (central where both are depth-continuous with it, one-sided where one is, else
  // flat). The nearest: the next fine sample where it was traced, else the next coarse one.
  HugePageArray<Gradients> sample_gradients(g > 1 ? nx * ny : 0);  // read only where present
  auto gradients_at = [&](std::size_t i, std::size_t j) {
    const PixelSample& s = sparse.grid_at(i, j);
    double v[kValues];
    values(s, v);
    const double ds = d(gx[i], gy[j]);
    Gradients out_g{};
    for (const bool along_x : {true, false}) {
      const std::size_t n = along_x ? nx : ny;
      const std::size_t k = along_x ? i : j;
      double slope_sum[kValues] = {};
      int slopes[kValues] = {};
      for (const int side : {-1, 1}) {
        for (std::size_t step = 1; step <= k_coarse; ++step) {
          if (side < 0 ? k < step : k + step >= n) break;
          const std::size_t k2 = side < 0 ? k - step : k + step;
          const std::size_t i2 = along_x ? k2 : i, j2 = along_x ? j : k2;
          if (!sparse.present_at(i2, j2)) continue;
          const int x2 = gx[i2], y2 = gy[j2];
          if (depth_continuous(d(x2, y2), ds)) {
            const double dist = along_x ? x2 - gx[i] : y2 - gy[j];
            double v2[kValues];
            values(sparse.grid_at(i2, j2), v2);
            for (int c = 0; c < kValues; ++c)
              physics::add_slope(slope_sum[c], slopes[c], v[c], v2[c], dist);
          }
          break;
        }
      }
      for (int c = 0; c < kValues; ++c)
        out_g[(along_x ? 0 : kValues) + c] = physics::mean_slope(slope_sum[c], slopes[c]);
    }
    return out_g;
  };

  // Which coarse cells get the fine grid. A coarse cell (a, b) spans fine indices
  // cx[a]..cx[a + 1] x cy[b]..cy[b + 1]; it is refined where the fine grid would find what its
  // four corners cannot: a depth discontinuity in it, a shadow edge or glow core (the fine
  // cells' own test), corners that disagree on the surface's sun visibility, a gradient
  // interpolation whose error estimate exceeds kRefineTolerance, or (probes below) a fine grid
  // point whose surface sun visibility differs from the corners'.
  //
  // A cell refined for its surface alone (corners that differ in AO or sun visibility, or a
  // probe's find) while R passes every test of an unrefined cell (no shadow edge or glow core,
  // no depth discontinuity, the gradient interpolation's error estimate within tolerance) gets
  // its fine grid points as surface samples: AO and sun visibility traced as at an exact
  // sample, R (with the camera's optical depth and the lit fraction) interpolated from the
  // coarse cell exactly as pass 2 interpolates an unrefined cell's pixels. Such cells were 83 %
  // of the refined ones on the bench scene (1080p normal), and a march is ~70 % of an exact
  // sample's rays. A fine point next to a fully refined cell is traced exactly.
  constexpr unsigned char kRefineNone = 0, kRefineFull = 1, kRefineSurface = 2;
  const std::size_t ncx = cx.size() - 1, ncy = cy.size() - 1;
  std::vector<unsigned char> refine(g > 1 ? ncx * ncy : 0, kRefineNone);
  if (g > 1 && k_coarse > 1 && ncx > 0 && ncy > 0) {
    tbb::parallel_for(std::size_t(0), cy.size(), [&](std::size_t b) {
      if (stop()) return;
      for (std::size_t a = 0; a < cx.size(); ++a)
        sample_gradients[cy[b] * nx + cx[a]] = gradients_at(cx[a], cy[b]);
    });
    throw_if_stopped();
    // Whether a coarse cell needs the fine grid (see above), from its corners' samples and
    // coarse gradients.
    auto refine_coarse_cell =
        [&](const std::array<std::pair<std::size_t, std::size_t>, 4>& corners) -> unsigned char {
      double value[4][kValues];
      const Gradients* grad[4];
      double shaft_min = 1, shaft_max = 0, lum_min = kInf, lum_max = 0;
      for (int k = 0; k < 4; ++k) {
        const auto [ci, cj] = corners[k];
        const PixelSample& s = sparse.grid_at(ci, cj);
        values(s, value[k]);
        grad[k] = &sample_gradients[cj * nx + ci];
        shaft_min = std::min(shaft_min, s.shaft);
        shaft_max = std::max(shaft_max, s.shaft);
        const double lum = value[k][0] + value[k][1] + value[k][2];
        lum_min = std::min(lum_min, lum);
        lum_max = std::max(lum_max, lum);
      }
      if (physics::cell_has_edge(shaft_min, shaft_max, lum_min, lum_max)) return kRefineFull;
      double ao_min = 1, ao_max = 0;
      for (int k = 0; k < 4; ++k) {
        ao_min = std::min(ao_min, value[k][6]);
        ao_max = std::max(ao_max, value[k][6]);
      }
      bool surface = ao_max - ao_min > kRefineAo;
      const double disk0 = sparse.grid_at(corners[0].first, corners[0].second).sun_disk;
      for (int k = 1; k < 4; ++k)
        surface |= sparse.grid_at(corners[k].first, corners[k].second).sun_disk != disk0;
      // Every pixel depth-continuous with every corner (else the fine grid's cells would
      // march some of them exactly, and their gradients see the discontinuity).
      const int x0 = gx[corners[0].first], x1 = gx[corners[3].first];
      const int y0 = gy[corners[0].second], y1 = gy[corners[3].second];
      double dc[4];
      for (int k = 0; k < 4; ++k) dc[k] = d(gx[corners[k].first], gy[corners[k].second]);
      for (int y = y0; y <= y1; ++y)
        for (int x = x0; x <= x1; ++x) {
          const double dp = d(x, y);
          for (int k = 0; k < 4; ++k)
            if (!depth_continuous(dp, dc[k])) return kRefineFull;
        }
      // The gradient interpolation's error estimate along each edge (corners A, B a
      // distance h apart along one axis, values v, slopes s along it): the Hermite curve
      // through both departs from the straight line by |sA - sB| h / 4 at the middle, and
      // the slopes' mean misses the secant by |vB - vA - (sA + sB) h / 2|; either, relative
      // to the values, above kRefineTolerance refines. Checked on R (the camera's optical
      // depth is a closed form in pass 3: without noise, the only case with coarse cells).
      constexpr int kEdges[4][3] = {{0, 1, 0}, {2, 3, 0}, {0, 2, 1}, {1, 3, 1}};
      constexpr int checked = 3;
      for (const auto& e : kEdges) {
        const int ka = e[0], kb = e[1];
        const bool along_x = e[2] == 0;
        const double h_px = along_x ? x1 - x0 : y1 - y0;
        const int off = along_x ? 0 : kValues;
        for (int c = 0; c < checked; ++c) {
          const double va = value[ka][c], vb = value[kb][c];
          const double sa = (*grad[ka])[off + c], sb = (*grad[kb])[off + c];
          const double bend = std::fabs(sa - sb) * h_px / 4;
          const double miss = std::fabs(vb - va - 0.5 * (sa + sb) * h_px);
          const double scale = std::max(std::fabs(va), std::fabs(vb));
          if (std::max(bend, miss) > kRefineTolerance * scale + 1e-12) return kRefineFull;
        }
      }
      if (thin_edge(corners)) return kRefineFull;
      return surface ? kRefineSurface : kRefineNone;
    };
    tbb::parallel_for(std::size_t(0), ncy, [&](std::size_t b) {
      if (stop()) return;
      for (std::size_t a = 0; a < ncx; ++a) {
        const std::size_t i0 = cx[a], i1 = cx[a + 1], j0 = cy[b], j1 = cy[b + 1];
        if (i1 - i0 < 2 && j1 - j0 < 2) continue;  // no fine sample inside
        const std::array<std::pair<std::size_t, std::size_t>, 4> corners{
            {{i0, j0}, {i1, j0}, {i0, j1}, {i1, j1}}};
        refine[b * ncx + a] = refine_coarse_cell(corners);
      }
    });
    throw_if_stopped();

    // The coarse cells around fine point (i, j): one, two on a coarse edge (none of the
    // coarse points themselves come here).
    std::vector<std::size_t> cell_x(nx), cell_y(ny);  // the cell whose left (top) edge is <= i
    for (std::size_t a = 0; a < ncx; ++a)
      for (std::size_t i = cx[a]; i < cx[a + 1]; ++i) cell_x[i] = a;
    cell_x[nx - 1] = ncx - 1;
    for (std::size_t b = 0; b < ncy; ++b)
      for (std::size_t j = cy[b]; j < cy[b + 1]; ++j) cell_y[j] = b;
    cell_y[ny - 1] = ncy - 1;
    auto for_cells = [&](std::size_t i, std::size_t j, auto&& f) {
      const std::size_t a = cell_x[i], b = cell_y[j];
      const bool on_x_edge = cx[a] == i && a > 0, on_y_edge = cy[b] == j && b > 0;
      f(a, b);
      if (on_x_edge) f(a - 1, b);
      if (on_y_edge) f(a, b - 1);
      if (on_x_edge && on_y_edge) f(a - 1, b - 1);
    };
    // A coarse cell's corners' common surface sun visibility, or -1.
    auto cell_disk = [&](std::size_t a, std::size_t b) {
      const double d0 = sparse.grid_at(cx[a], cy[b]).sun_disk;
      const bool agree = d0 >= 0 && sparse.grid_at(cx[a + 1], cy[b]).sun_disk == d0 &&
                         sparse.grid_at(cx[a], cy[b + 1]).sun_disk == d0 &&
                         sparse.grid_at(cx[a + 1], cy[b + 1]).sun_disk == d0;
      return agree ? d0 : -1.0;
    };
    // Probes: the surface's sun visibility (a few rays) at the fine points of unrefined cells
    // whose corners agree on it, so that a shadow on a surface between the coarse samples is
    // found as the fine grid finds it.
    std::vector<double> probe(nx * ny, kNaN);
    tbb::parallel_for(std::size_t(0), ny, [&](std::size_t j) {
      if (stop()) return;
      for (std::size_t i = 0; i < nx; ++i) {
        if (sparse.present_at(i, j)) continue;
        bool any_refined = false, any_agrees = false;
        for_cells(i, j, [&](std::size_t a, std::size_t b) {
          any_refined |= refine[b * ncx + a] != 0;
          any_agrees |= cell_disk(a, b) >= 0;
        });
        if (!any_refined && any_agrees) probe[j * nx + i] = core.sun_disk_visibility(gx[i], gy[j]);
      }
    });
    throw_if_stopped();
    std::vector<unsigned char> probe_refine(ncx * ncy, 0);
    tbb::parallel_for(std::size_t(0), ncy, [&](std::size_t b) {
      for (std::size_t a = 0; a < ncx; ++a) {
        if (refine[b * ncx + a]) continue;
        const double disk = cell_disk(a, b);
        if (disk < 0) continue;
        for (std::size_t j = cy[b]; j <= cy[b + 1] && !probe_refine[b * ncx + a]; ++j)
          for (std::size_t i = cx[a]; i <= cx[a + 1]; ++i) {
            const double p = probe[j * nx + i];
            if (!std::isnan(p) && p != disk) {
              probe_refine[b * ncx + a] = 1;
              break;
            }
          }
      }
    });
    for (std::size_t c = 0; c < refine.size(); ++c)
      if (refine[c] == kRefineNone && probe_refine[c]) refine[c] = kRefineSurface;

    // A surface sample at pixel (x, y) of coarse cell (a, b): R, the camera's optical depth and
    // the lit fraction as pass 2 would interpolate them there (resolve_cell), AO and the
    // surface's sun visibility as exact() traces them.
    auto surface_sample = [&](std::size_t a, std::size_t b, int x, int y, double known_sun_disk) {
      const std::size_t i0 = cx[a], i1 = cx[a + 1], j0 = cy[b], j1 = cy[b + 1];
      const int x0 = gx[i0], x1 = gx[i1], y0 = gy[j0], y1 = gy[j1];
      const std::array<std::pair<std::size_t, std::size_t>, 4> corners{
          {{i0, j0}, {i1, j0}, {i0, j1}, {i1, j1}}};
      const double fx = double(x - x0) / (x1 - x0), fy = double(y - y0) / (y1 - y0);
      double acc[kValues] = {};
      double shaft = 0;
      for (int k = 0; k < 4; ++k) {
        const auto [ci, cj] = corners[k];
        const PixelSample& c = sparse.grid_at(ci, cj);
        double v[kValues];
        values(c, v);
        const Gradients& gr = sample_gradients[cj * nx + ci];
        const double weight = physics::corner_weight(k, fx, fy);
        const double dx = x - gx[ci], dy = y - gy[cj];
        for (int m = 0; m < kValues; ++m)
          acc[m] += weight * physics::extrapolate(v[m], gr[m], gr[kValues + m], dx, dy);
        shaft += weight * c.shaft;
      }
      PixelSample p;
      for (int c = 0; c < 3; ++c) {
        p.inscatter[c] = std::max(0.0, acc[c]);
        p.camera_od[c] = std::max(0.0, acc[3 + c]);
      }
      p.shaft = shaft;
      if (ao_wanted(x, y)) p.ao = core.ambient_occlusion_at(x, y);
      p.sun_disk = std::isnan(known_sun_disk) ? core.sun_disk_visibility(x, y) : known_sun_disk;
      sparse.set(x, y, p);
      return p;
    };

    // The fine samples of the refined cells.
    tbb::combinable<std::size_t> fine{[] { return std::size_t(0); }};
    tbb::parallel_for(std::size_t(0), ny, [&](std::size_t j) {
      if (stop()) return;
      std::size_t work = 0;
      for (std::size_t i = 0; i < nx; ++i) {
        if (sparse.present_at(i, j)) continue;
        bool full = false, surface = false;
        std::size_t surface_a = 0, surface_b = 0;
        for_cells(i, j, [&](std::size_t a, std::size_t b) {
          const unsigned char r = refine[b * ncx + a];
          full |= r == kRefineFull;
          if (r == kRefineSurface && !surface) {
            surface = true;
            surface_a = a;
            surface_b = b;
          }
        });
        work += kSampleWork;
        if (full) {
          // The thin shadows of the refined cells' corners as hints.
          Hints hints;
          for_cells(i, j, [&](std::size_t a, std::size_t b) {
            if (refine[b * ncx + a] == kRefineFull)
              corner_hints({{{cx[a], cy[b]},
                             {cx[a + 1], cy[b]},
                             {cx[a], cy[b + 1]},
                             {cx[a + 1], cy[b + 1]}}},
                           gx[i], gy[j], hints);
          });
          ThinShadows* thin = thin_hints ? sky_thin(thin_at(i, j), gx[i], gy[j]) : nullptr;
          sparse.put(i, j, exact(gx[i], gy[j], plan.steps, probe[j * nx + i], &hints, thin));
          ++fine.local();
        } else if (surface) {
          sparse.put(i, j, surface_sample(surface_a, surface_b, gx[i], gy[j], probe[j * nx + i]));
          if (thin_hints) thin_at(i, j) = ThinShadows{};  // (interpolated: caught nothing)
        }
      }
      progress.add(work);
    });
    throw_if_stopped();
    const std::size_t fine_count = fine.combine(std::plus<>());
    exact_count += fine_count;
  }
  out.grid_s = seconds_since(pass_start);
  pass_start = Clock::now();

  // Where a shaft-edge cell's pixel (x, y) gets finer steps (kShaftRefinement): around each
  // crossing of its corners' marches, carried along the sun onto its own view ray as thin
  // shadows' hints are (Core::hint_on_ray); Core::march splits the segments there (not their
  // neighbours: on the bench's street 6.97 -> 6.73 M shadow rays, R's error against 128 steps
  // 0.1652 % both ways; the pillars test 0.1484 -> 0.1486 %). The shadow volumes' boundaries that
  // the corners' rays cross cross the pixel's ray nearby; elsewhere along it the corners saw none,
  // and the pixel's march keeps the preset's steps there. Where the pixel lies beyond the corners
  // depth-continuous with it (a silhouette's far side: their rays end before its own), its ray
  // beyond beyond_m too, which no corner that shares its surface marched. False (the whole ray
  // refined) where a crossing cannot be carried or the corners crossed none (an edge cell by
  // luminance alone).
  auto edge_zone = [&](const std::array<std::pair<std::size_t, std::size_t>, 4>& corners, int x,
                       int y, double beyond_m, StepZone& zone) {
    zone = StepZone{};
    zone.factor = kShaftRefinement;
    zone.widen = false;
    if (beyond_m < kInf) zone.add(beyond_m, kInf);
    int crossings = 0;
    for (const auto& [ci, cj] : corners) {
      const PixelSample& c = sparse.grid_at(ci, cj);
      for (int k = 0; k < c.crossings; ++k, ++crossings) {
        const double t = core.hint_on_ray(x, y, gx[ci], gy[cj], c.crossing_m[k]);
        if (std::isnan(t)) return false;
        zone.add(t, t);
      }
    }
    return crossings > 0;
  };

  // Pass 2: every other pixel from its cell's four samples with their gradients, where all
  // four are depth-continuous with it and agree on the sun's shadowing; else exactly. A cell:
  // an unrefined coarse cell, or a fine cell of a refined one.
  tbb::combinable<std::size_t> interpolated{[] { return std::size_t(0); }};
  tbb::combinable<std::size_t> exact_more{[] { return std::size_t(0); }};
  if (g > 1) {
    // Every sample's gradients once (cells share corners: four cells would redo them).
    tbb::parallel_for(std::size_t(0), ny, [&](std::size_t j) {
      if (stop()) return;
      for (std::size_t i = 0; i < nx; ++i)
        if (sparse.present_at(i, j)) sample_gradients[j * nx + i] = gradients_at(i, j);
    });
    throw_if_stopped();
    // Pixels on a cell's right (bottom) edge belong to the next cell, except on the last.
    // Everything that depends on the cell alone (corner values, gradients, depths, the edge
    // and sun-disk tests) is read once; per pixel only the weights and the sums remain, in
    // the same order of operations (the output is bit-identical to the per-pixel form).
    // The counts go to the caller's locals: a tbb::combinable's local() per pixel was a
    // thread-local lookup for each of ~2 M pixels.
    auto resolve_cell = [&](std::size_t i0, std::size_t i1, std::size_t j0, std::size_t j1,
                            std::size_t& interpolated_n, std::size_t& exact_n) {
      const int x0 = gx[i0], x1 = gx[i1], y0 = gy[j0], y1 = gy[j1];
      const std::array<std::pair<std::size_t, std::size_t>, 4> corners{
          {{i0, j0}, {i1, j0}, {i0, j1}, {i1, j1}}};
      const int corner_x[4] = {x0, x1, x0, x1}, corner_y[4] = {y0, y0, y1, y1};
      // The corners' gradients, once per cell.
      double value[4][kValues], grad_x[4][kValues], grad_y[4][kValues], corner_d[4];
      double shaft_min = 1, shaft_max = 0;
      for (int k = 0; k < 4; ++k) {
        const auto [ci, cj] = corners[k];
        const PixelSample& s = sparse.grid_at(ci, cj);
        values(s, value[k]);
        for (int c = 0; c < kValues; ++c) {
          grad_x[k][c] = sample_gradients[cj * nx + ci][c];
          grad_y[k][c] = sample_gradients[cj * nx + ci][kValues + c];
        }
        shaft_min = std::min(shaft_min, s.shaft);
        shaft_max = std::max(shaft_max, s.shaft);
        corner_d[k] = d(corner_x[k], corner_y[k]);
      }
      // A shadow boundary crosses the cell, or the in-scatter changes too fast across it
      // (the core of a lamp's glow) for gradients to follow: its pixels get their own
      // march.
      double lum_min = kInf, lum_max = 0;
      for (int k = 0; k < 4; ++k) {
        const double lum = value[k][0] + value[k][1] + value[k][2];
        lum_min = std::min(lum_min, lum);
        lum_max = std::max(lum_max, lum);
      }
      const bool shadow_edge = physics::cell_has_edge(shaft_min, shaft_max, lum_min, lum_max);
      // A thin shadow's edge in the sky (thin_edge): its pixels marched with the corners' thin
      // shadows as hints, and with the shaft edges' finer steps, for the thin shadows no corner
      // caught (the kite's shaft is many streaks a few pixels wide: against 256 steps without
      // acceleration, crop x 640-800, y 60-200, mean |R error| 2.18 % before, 2.00 % with the
      // preset's steps here, 1.50 % with kShaftRefinement's). The finer steps only where the
      // corners saw shadow (thin_zone), and not where the corners' R differ by at most
      // kThinShallow: there the thin shadows are shallow, and a miss costs little.
      const bool thin_cell = !shadow_edge && thin_edge(corners);
      const bool thin_deep = thin_cell && lum_max - lum_min > kThinShallow * lum_max;
      const double disk0 = sparse.grid_at(i0, j0).sun_disk;
      const bool sun_disk_agrees = disk0 >= 0 && sparse.grid_at(i1, j0).sun_disk == disk0 &&
                                   sparse.grid_at(i0, j1).sun_disk == disk0 &&
                                   sparse.grid_at(i1, j1).sun_disk == disk0;
      // The camera's optical depth is pass 3's closed form unless noise modulates it.
      const bool interpolate_od = !closed_form_camera;
      // A shaft-edge cell's pixels: finer steps around the corners' crossings only, when
      // every corner's march said where its crossings are (edge_zoned). Not with noise: its
      // camera optical depth is the march's sum there (T), sampled by every step of the ray (the
      // GPU = CPU noisy scene's T p99 difference 4.24 % -> 8.18 % zoned; the GPU refines the whole
      // ray).
      bool edge_zoned = shadow_edge && !core.has_noise();
      for (int k = 0; k < 4 && edge_zoned; ++k)
        edge_zoned = sparse.grid_at(corners[k].first, corners[k].second).crossings !=
                     PixelSample::kCrossingsUnknown;
      const int x_last = i1 + 1 < nx ? x1 - 1 : x1, y_last = j1 + 1 < ny ? y1 - 1 : y1;
      for (int y = y0; y <= y_last; ++y) {
        const double fy = double(y - y0) / (y1 - y0);
        double dy[4];
        for (int k = 0; k < 4; ++k) dy[k] = y - corner_y[k];
        for (int x = x0; x <= x_last; ++x) {
          if (sparse.has(x, y)) continue;
          // Whether the pixel is depth-continuous with every corner, and the farthest corner it
          // is depth-continuous with (-1: none).
          bool continuous = true;
          double continuous_far_m = -1;
          const double dp = d(x, y);
          for (int k = 0; k < 4; ++k) {
            if (depth_continuous(dp, corner_d[k]))
              continuous_far_m = std::max(continuous_far_m, corner_d[k]);
            else
              continuous = false;
            if (!continuous && !shadow_edge) break;
          }
          const bool ok = !shadow_edge && !thin_cell && continuous;
          if (!ok) {
            // A shaft's edge crosses the cell: its pixels get finer steps, or thin slivers
            // of shadow that one step misses or catches would show as grain.
            if (thin_cell) {
              Hints hints;
              corner_hints(corners, x, y, hints);
              const StepZone zone = thin_deep ? thin_zone(corners, x, y) : StepZone{};
              exact(x, y, plan.steps, kNaN, &hints, nullptr, &zone);
            } else if (shadow_edge && edge_zoned && continuous_far_m >= 0) {
              StepZone zone;
              if (edge_zone(corners, x, y, dp > continuous_far_m ? continuous_far_m : kInf, zone))
                exact(x, y, plan.steps, kNaN, nullptr, nullptr, &zone);
              else
                exact(x, y, plan.steps * kShaftRefinement);
            } else {
              exact(x, y, shadow_edge ? plan.steps * kShaftRefinement : plan.steps);
            }
            ++exact_n;
            continue;
          }
          const double fx = double(x - x0) / (x1 - x0);
          // The sums in scalars (registers), each over the corners in order 0..3 from 0.
          double r0 = 0, r1 = 0, r2 = 0, ao = 0, acc_od[3] = {0, 0, 0};
          for (int k = 0; k < 4; ++k) {
            const double weight = physics::corner_weight(k, fx, fy);
            const double dx = x - corner_x[k], dyk = dy[k];
            const double* v = value[k];
            const double* gxk = grad_x[k];
            const double* gyk = grad_y[k];
            r0 += weight * physics::extrapolate(v[0], gxk[0], gyk[0], dx, dyk);
            r1 += weight * physics::extrapolate(v[1], gxk[1], gyk[1], dx, dyk);
            r2 += weight * physics::extrapolate(v[2], gxk[2], gyk[2], dx, dyk);
            ao += weight * physics::extrapolate(v[6], gxk[6], gyk[6], dx, dyk);
            if (interpolate_od)
              for (int c = 0; c < 3; ++c)
                acc_od[c] +=
                    weight * physics::extrapolate(v[3 + c], gxk[3 + c], gyk[3 + c], dx, dyk);
          }
          const double acc[kValues] = {r0, r1, r2, acc_od[0], acc_od[1], acc_od[2], ao};
          PixelSample p;
          for (int c = 0; c < 3; ++c) {
            p.inscatter[c] = std::max(0.0, acc[c]);
            p.camera_od[c] = std::max(0.0, acc[3 + c]);
          }
          p.ao = std::clamp(acc[6], 0.0, 1.0);
          // The surface's sun visibility is a step function: taken from the cell's samples
          // only where all four agree (a shadow narrower than the grid spacing that falls
          // between samples is lost: the price of the acceleration), else traced.
          p.sun_disk = -1;
          if (sun_disk_agrees) p.sun_disk = disk0;
          sparse.set(x, y, p);
          ++interpolated_n;
        }
      }
    };
    tbb::parallel_for(tbb::blocked_range2d<std::size_t>(0, ncy, 0, ncx),
                      [&](const tbb::blocked_range2d<std::size_t>& r) {
                        for (std::size_t b = r.rows().begin(); b < r.rows().end(); ++b) {
                          if (stop()) return;
                          std::size_t work = 0, interpolated_n = 0, exact_n = 0;
                          for (std::size_t a = r.cols().begin(); a < r.cols().end(); ++a) {
                            work += (cx[a + 1] - cx[a]) * (cy[b + 1] - cy[b]) * kCellWork;
                            if (!refine[b * ncx + a] && k_coarse > 1) {
                              resolve_cell(cx[a], cx[a + 1], cy[b], cy[b + 1], interpolated_n,
                                           exact_n);
                              continue;
                            }
                            for (std::size_t j = cy[b]; j < cy[b + 1]; ++j)
                              for (std::size_t i = cx[a]; i < cx[a + 1]; ++i)
                                resolve_cell(i, i + 1, j, j + 1, interpolated_n, exact_n);
                          }
                          interpolated.local() += interpolated_n;
                          exact_more.local() += exact_n;
                          progress.add(work);
                        }
                      });
  }
  throw_if_stopped();
  exact_count += exact_more.combine(std::plus<>());
  out.interpolation_s = seconds_since(pass_start);
  // Pass 3 reads only the per-pixel arrays: the grid's samples (and the thin shadows they
  // caught), their gradients and the AO table go back to the pool now (render/huge_pages.h),
  // where the photo fallback's arrays below find them (already mapped) instead of fresh memory.
  sparse.grid.reset();
  grid_thin = HugePageArray<ThinShadows>(0);
  sample_gradients = HugePageArray<Gradients>(0);
  ao_table = HugePageArray<std::uint32_t>(0);
  pass_start = Clock::now();

  // Pass 3: per pixel, the transmittance map T = tau(camera, surface) * S(surface) and the AOVs.
  // With the photo, every surface pixel's sun visibility first (the photo fallback compares a
  // pixel with its neighbours', see render/photo_fallback.h; the Vulkan backend asks the same).
  const bool photo_fallback = PhotoFallback::wanted(*in.scene, in.distance_m, in.normals, in.photo,
                                                    in.occluders != nullptr);
  std::optional<PhotoFallback> fallback;
  std::optional<HugePageArray<float>> disk;  // every pixel written below
  if (photo_fallback) {
    fallback.emplace(*in.camera, *in.scene, in.distance_m, in.normals, in.photo, in.sky_radiance);
    fallback->cache_points();
    disk.emplace(std::size_t(w) * h);
    tbb::parallel_for(0, h, [&](int y) {
      if (stop()) return;
      for (int x = 0; x < w; ++x) {
        const PixelSample& s = sparse.at(x, y);
        (*disk)[std::size_t(y) * w + x] =
            float(s.sun_disk >= 0 ? s.sun_disk : core.sun_disk_visibility(x, y));
      }
    });
    throw_if_stopped();
  }
  tbb::parallel_for(tbb::blocked_range<int>(0, h), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y < rows.end(); ++y) {
      if (stop()) return;
      for (int x = 0; x < w; ++x) {
        const PixelSample& s = sparse.at(x, y);
        double od[3] = {s.camera_od[0], s.camera_od[1], s.camera_od[2]};
        const Vec3d view = core.ray(x, y);  // once for both terms below
        if (closed_form_camera) core.camera_optical_depth(view, x, y, od);
        double S[3];
        float sun_visible = 1.0f;
        double sun_disk = s.sun_disk;
        if (photo_fallback) {
          sun_disk = (*disk)[std::size_t(y) * w + x];
          if (sun_disk >= 0 && sun_disk < 1 && fallback->shows_sunlit(x, y, s.ao, disk->data()))
            sun_disk = 1;
        }
        core.surface_term(x, y, s.ao, sun_disk, S, &sun_visible, &view);
        // One exp for grey fog (physics::exp3: equal channels share it, bit for bit).
        const Vec3d camera_tau = physics::exp3(Vec3d{-od[0], -od[1], -od[2]});
        const double camera_tau_c[3] = {camera_tau.x, camera_tau.y, camera_tau.z};
        for (int c = 0; c < 3; ++c) {
          out.transmittance.at(x, y, c) = float(camera_tau_c[c] * S[c]);  // R: pass 1 or 2
          out.optical_depth.at(x, y, c) = float(od[c]);
        }
        out.sun_visibility.at(x, y, 0) = sun_visible;
      }
      progress.add(kRowWork);
    }
  });
  throw_if_stopped();
  const std::size_t interpolated_count = interpolated.combine(std::plus<>());
  out.surface_s = seconds_since(pass_start);
  out.exact_pixels = exact_count;
  out.interpolated_pixels = interpolated_count;
  out.shadow_rays = core.shadow_rays();
}

}  // namespace mr::render
