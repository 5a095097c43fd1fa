#include "render/scattering_cpu.h"

#include <tbb/blocked_range2d.h>
#include <tbb/combinable.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>
#include <vector>

#include "render/embree_scene.h"
#include "render/math.h"
#include "render/medium.h"
#include "render/photo_fallback.h"
#include "render/physics/resolve.h"
#include "render/physics/scattering.h"
#include "shaders/scattering_params.h"  // kEdgeBisections, kShaftRefinement (shared with the GPU)

namespace mr::render {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;
constexpr double kGoldenAngle = 2.39996322972865332;
// Step multiplier for pixels next to a shaft's edge (see render_scattering_cpu's pass 2), and
// bisection steps for a shaft edge's crossing (Core::march): one definition for both backends.
using gpu::kEdgeBisections;
using gpu::kShaftRefinement;

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

struct PixelSample {
  double inscatter[3] = {0, 0, 0};
  double camera_od[3] = {0, 0, 0};  // optical depth camera -> surface (or end of the sky march)
  double shaft = 1;                 // fraction of march samples that saw the sun (1: no sun)
  double ao = 1;                    // ambient occlusion at the surface
  double sun_disk = -1;             // sun_disk_visibility at the surface, -1: not known
};

class Core {
 public:
  Core(const CoreInputs& in, const MarchPlan& plan) : in_(in), plan_(plan), scene_(*in.scene) {
    const Medium& m = scene_.medium;
    for (int c = 0; c < 3; ++c) sigma_[c] = m.sigma_t_per_m[c];
    sigma3_ = {sigma_[0], sigma_[1], sigma_[2]};
    albedo_ = rgb(m.albedo);
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

  // `steps`: view-ray segments (the preset's, or more where a pixel straddles a shaft edge).
  PixelSample march(int x, int y, int steps) const {
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
      const double od_exact = rd.optical_depth(0, distance);
      for (int c = 0; c < 3; ++c) s.camera_od[c] = scaled_optical_depth(sigma_[c], od_exact);
      sky_only_inscatter(s.camera_od, m.albedo, in_.sky_radiance, s.inscatter);
      return s;
    }

    // Segment boundaries: uniform in transmittance, plus equiangular ones around each lamp.
    thread_local std::vector<double> bounds;  // no allocation per march
    bounds.clear();
    bounds.reserve(std::size_t(steps + plan_.lamp_steps * scene_.lighting.lamps.size() + 2));
    bounds.push_back(0);
    bounds.push_back(length);
    const double od_mean_total = sigma_mean_ * od_unit_total;
    const double one_minus_tau_end = -std::expm1(-od_mean_total);
    for (int i = 1; i < steps; ++i) {
      const double t = physics::uniform_boundary(rd.shared(), i, steps, sigma_mean_, od_mean_total,
                                                 one_minus_tau_end, length);
      if (t > 0 && t < length) bounds.push_back(t);
    }
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
    std::sort(bounds.begin(), bounds.end());
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
    sample_t.resize(segments);
    crossing.resize(segments);
    sun_visible.assign(segments, 1);
    for (std::size_t i = 0; i < segments; ++i)
      sample_t[i] = physics::segment_sample_t(bounds[i], bounds[i + 1], jitter, int(i));
    std::size_t rays = 0;
    if (scene_.lighting.sun && in_.occluders) {
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
      // Shaft edges: where the visibility changes between two samples, bisect for the crossing
      // (to 1/64 of the gap), so each segment gets its exact lit part instead of all or nothing:
      // one sample per segment alone leaves a jitter-dithered edge of 1/steps steps.
      for (std::size_t i = 0; i + 1 < segments; ++i) {
        if (sun_visible[i] == sun_visible[i + 1]) continue;
        double lo = sample_t[i], hi = sample_t[i + 1];
        const Vec3d dir = sun_sample_direction(i, jitter, double(segments + 1), pixel_rotation);
        for (int k = 0; k < kEdgeBisections; ++k) {
          const double mid = 0.5 * (lo + hi);
          const bool visible = !in_.occluders->occluded(f3(add(origin_, w, mid)), f3(dir),
                                                        float(1e-3 + 1e-4 * mid), float(kInf));
          (visible == bool(sun_visible[i]) ? lo : hi) = mid;
        }
        rays += kEdgeBisections;
        crossing[i] = 0.5 * (lo + hi);
      }
    }

    Vec3d od{0, 0, 0}, tau{1, 1, 1}, inscatter{0, 0, 0};
    int sun_samples = 0;
    double sun_seen_fraction = 0;
    const bool light_path = scene_.render.light_path_attenuation;
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
          const Vec3d tau_sun =
              light_path ? sun_path_transmittance(rd, w, ta, tb, xs, modulation) : Vec3d{1, 1, 1};
          inscatter +=
              physics::sun_inscatter(lit_weight, m.g, w, sun_dir_, sun_irradiance_, tau_sun);
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

  // The sun's light-path transmittance over segment [ta, tb] of view ray w, averaged with the
  // segment's in-scatter weight rho(t) tau_camera(t) by 4-point Gauss-Legendre quadrature
  // (closed-form optical depths, no rays). One value at the jittered sample xs instead (as
  // before, and as the GPU still does) is exact in expectation but, in height fog under a low
  // sun, varies by orders of magnitude across a long sky segment (od_sun = sigma H e^(-y/H) /
  // sin(elevation)), which the per-pixel jitter turned into a grainy sky (issue 11, sun bank).
  Vec3d sun_path_transmittance(const RayDensity& rd, const Vec3d& w, double ta, double tb,
                               const Vec3d& xs, double modulation) const {
    constexpr double kNode[4] = {-0.8611363115940526, -0.3399810435848563, 0.3399810435848563,
                                 0.8611363115940526};
    constexpr double kWeight[4] = {0.3478548451374538, 0.6521451548625461, 0.6521451548625461,
                                   0.3478548451374538};
    const Medium& m = scene_.medium;
    const double od_xs = RayDensity(m, xs, sun_dir_).optical_depth(0, kInf);
    // Where the sun's optical depth changes by less than 0.01 (times the largest sigma_t) over
    // the segment, its transmittance varies by under 1 % there: the point value is as good and
    // four times cheaper (homogeneous fog under a layer top, short segments).
    const double sigma_max = std::max({sigma3_.x, sigma3_.y, sigma3_.z});
    const double od_a = RayDensity(m, add(origin_, w, ta), sun_dir_).optical_depth(0, kInf);
    const double od_b = RayDensity(m, add(origin_, w, tb), sun_dir_).optical_depth(0, kInf);
    if (!(sigma_max * std::fabs(od_a - od_b) > 0.01)) return physics::transmittance(sigma3_, od_xs);
    const double mid = 0.5 * (ta + tb), half = 0.5 * (tb - ta);
    Vec3d num{0, 0, 0}, den{0, 0, 0};
    for (int k = 0; k < 4; ++k) {
      const double t = mid + half * kNode[k];
      const double rho = rd.density(t);
      if (!(rho > 0)) continue;
      const Vec3d camera_tau =
          physics::transmittance(sigma3_, rd.optical_depth(ta, t) * modulation);
      const Vec3d sun_tau = physics::transmittance(
          sigma3_, RayDensity(m, add(origin_, w, t), sun_dir_).optical_depth(0, kInf));
      const Vec3d weight = camera_tau * (kWeight[k] * rho);
      num += weight * sun_tau;
      den += weight;
    }
    if (!(den.x > 0 && den.y > 0 && den.z > 0)) return physics::transmittance(sigma3_, od_xs);
    return {num.x / den.x, num.y / den.y, num.z / den.z};
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
    const Vec3d x0 = shadow_origin(x, y, distance, n);
    rays_.local() += std::size_t(plan_.ao_rays);
    return ambient_occlusion(*in_.occluders, f3(x0), f3(n), plan_.ao_rays,
                             float(std::max(1.0, 0.25 * distance)),
                             scene_.render.seed ^ std::uint32_t(x * 7919 + y * 104729));
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
    const Vec3d xo = shadow_origin(x, y, distance, n);
    const int count = sun_tan_radius_ > 0 ? plan_.sun_surface_rays : 1;
    rays_.local() += std::size_t(count);
    int seen = 0;
    occluded_rays(
        *in_.occluders, std::size_t(count),
        [&](std::size_t index) {
          const int i = int(index);
          Vec3d dir = sun_dir_;
          if (sun_tan_radius_ > 0) {
            const double r = sun_tan_radius_ * std::sqrt((i + 0.5) / count);
            const double phi = kGoldenAngle * (i + pixel_jitter(x, y, scene_.render.seed) * count);
            dir = normalized(
                add(add(sun_dir_, sun_u_, r * std::cos(phi)), sun_v_, r * std::sin(phi)));
          }
          return ShadowRay{{float(xo[0]), float(xo[1]), float(xo[2])},
                           {float(dir[0]), float(dir[1]), float(dir[2])},
                           0.0f};
        },
        [&](std::size_t, bool blocked) { seen += !blocked; });
    return double(seen) / count;
  }

  // T's surface factor S (DESIGN.md section 3) at a surface pixel; writes the sun visibility.
  // known_sun_disk: the pixel's sun_disk_visibility when already known (interpolation), else -1.
  void surface_term(int x, int y, double ao, double known_sun_disk, double S[3],
                    float* sun_visibility) const {
    S[0] = S[1] = S[2] = 1.0;
    *sun_visibility = 1.0f;
    const double distance = in_.distance_m.at(x, y, 0);
    const bool lights = scene_.lighting.sun || !scene_.lighting.lamps.empty();
    if (!std::isfinite(distance) || !lights || in_.normals.data == nullptr) return;
    const Vec3d n = {in_.normals.at(x, y, 0), in_.normals.at(x, y, 1), in_.normals.at(x, y, 2)};
    if (dot(n, n) < 0.5) return;
    const Medium& m = scene_.medium;
    const Vec3d x0 = add(origin_, ray(x, y), distance);
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
      const double od_sun = light_path ? RayDensity(m, x0, sun_dir_).optical_depth(0, kInf) : 0.0;
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
    const Vec3d w = ray(x, y);
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

 private:
  const CoreInputs& in_;
  MarchPlan plan_;
  const FogScene& scene_;
  double sigma_[3];
  Vec3d sigma3_, albedo_, sky_, sun_irradiance_;
  double sigma_mean_ = 0, sigma_min_ = 0;
  bool grey_ = false;
  Vec3d sun_dir_{0, 1, 0}, sun_u_{1, 0, 0}, sun_v_{0, 0, 1};
  double sun_tan_radius_ = 0;
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
// on every render) was a tenth of the render's CPU time in page faults.
struct Sparse {
  int width = 0, height = 0;
  ImageView inscatter;               // the output R (3 channels)
  std::vector<double> ao, sun_disk;  // per pixel
  std::vector<double> camera_od;     // 3 per pixel, only when keep_camera_od
  bool keep_camera_od = false;
  std::vector<PixelSample> grid;           // the grid samples, row-major over gx x gy (when kept)
  std::vector<int> grid_column, grid_row;  // a pixel column's (row's) index in gx (gy), or -1
  std::size_t columns = 0;                 // gx.size()

  void init(int w, int h, ImageView r, bool keep_od, const std::vector<int>& gx,
            const std::vector<int>& gy, bool keep_grid) {
    width = w;
    height = h;
    inscatter = r;
    keep_camera_od = keep_od;
    columns = gx.size();
    ao.resize(std::size_t(w) * h);
    sun_disk.resize(std::size_t(w) * h);
    if (keep_od) camera_od.resize(3 * std::size_t(w) * h);
    grid_column.assign(std::size_t(w), -1);
    grid_row.assign(std::size_t(h), -1);
    for (std::size_t i = 0; i < gx.size(); ++i) grid_column[std::size_t(gx[i])] = int(i);
    for (std::size_t j = 0; j < gy.size(); ++j) grid_row[std::size_t(gy[j])] = int(j);
    if (keep_grid) grid.resize(gx.size() * gy.size());
  }
  // Whether pixel (x, y) is a grid sample.
  bool has(int x, int y) const {
    return grid_column[std::size_t(x)] >= 0 && grid_row[std::size_t(y)] >= 0;
  }
  const PixelSample& grid_at(std::size_t i, std::size_t j) const { return grid[j * columns + i]; }
  PixelSample& grid_at(std::size_t i, std::size_t j) { return grid[j * columns + i]; }
  void set(int x, int y, const PixelSample& s) {
    const std::size_t idx = std::size_t(y) * width + x;
    for (int c = 0; c < 3; ++c) inscatter.at(x, y, c) = float(s.inscatter[c]);
    if (keep_camera_od)
      for (int c = 0; c < 3; ++c) camera_od[3 * idx + c] = s.camera_od[c];
    ao[idx] = s.ao;
    sun_disk[idx] = s.sun_disk;
  }
  // What pass 3 reads of pixel (x, y) (R as stored; the camera's optical depth 0 unless kept).
  PixelSample at(int x, int y) const {
    const std::size_t idx = std::size_t(y) * width + x;
    PixelSample s;
    for (int c = 0; c < 3; ++c) s.inscatter[c] = inscatter.at(x, y, c);
    if (keep_camera_od)
      for (int c = 0; c < 3; ++c) s.camera_od[c] = camera_od[3 * idx + c];
    s.ao = ao[idx];
    s.sun_disk = sun_disk[idx];
    return s;
  }
};

using physics::depth_continuous;

}  // namespace

MarchPlan march_plan(const RenderSettings& settings) {
  MarchPlan plan;
  switch (settings.quality) {
    case Quality::draft:
      plan = {12, 8, 4, 2, 4, 2};
      break;
    case Quality::normal:
      plan = {32, 16, 3, 4, 8, 1};
      break;
    case Quality::final:
      plan = {128, 48, 1, 16, 32, 1};
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

  // Pass 1: exact samples on the sparse grid (and the last row / column, so every pixel lies in
  // a cell with four samples).
  std::vector<int> gx, gy;
  for (int x = 0; x < w; x += g) gx.push_back(x);
  if (gx.back() != w - 1) gx.push_back(w - 1);
  for (int y = 0; y < h; y += g) gy.push_back(y);
  if (gy.back() != h - 1) gy.push_back(h - 1);

  const bool closed_form_camera = !core.has_noise();
  Sparse sparse;
  sparse.init(w, h, out.inscatter, !closed_form_camera, gx, gy, g > 1);

  auto exact = [&](int x, int y, int steps) {
    PixelSample s = core.march(x, y, steps);
    if (core.needs_ao()) s.ao = core.ambient_occlusion_at(x, y);
    s.sun_disk = core.sun_disk_visibility(x, y);
    sparse.set(x, y, s);
    return s;
  };
  // Progress (mr/cancel.h): one "render" stage in units of work weighted by their measured cost
  // (1280x720 street with sun, grid step 3: pass 1 0.75 s for 103k samples, pass 2 0.12 s for
  // 102k cells, pass 3 0.12 s for 0.9 MP): a sample 8, a cell 1, a row of pass 3 w / 8.
  constexpr std::size_t kSampleWork = 8, kCellWork = 1;
  const std::size_t kRowWork = std::max<std::size_t>(1, std::size_t(w) / 8);
  const std::size_t cells = g > 1 ? (gx.size() - 1) * (gy.size() - 1) : 0;
  ProgressCounter progress(
      in.cancel, "render",
      gx.size() * gy.size() * kSampleWork + cells * kCellWork + std::size_t(h) * kRowWork);
  tbb::parallel_for(tbb::blocked_range2d<std::size_t>(0, gy.size(), 0, gx.size()),
                    [&](const tbb::blocked_range2d<std::size_t>& r) {
                      for (std::size_t j = r.rows().begin(); j < r.rows().end(); ++j) {
                        if (stop()) return;
                        for (std::size_t i = r.cols().begin(); i < r.cols().end(); ++i) {
                          const PixelSample s = exact(gx[i], gy[j], plan.steps);
                          if (g > 1) sparse.grid_at(i, j) = s;
                        }
                        progress.add(r.cols().size() * kSampleWork);
                      }
                    });
  throw_if_stopped();
  std::size_t exact_count = gx.size() * gy.size();
  out.grid_s = seconds_since(pass_start);
  pass_start = Clock::now();

  // Pass 2: every other pixel from its cell's four samples with their gradients, where all
  // four are depth-continuous with it and agree on the sun's shadowing; else exactly.
  tbb::combinable<std::size_t> interpolated{[] { return std::size_t(0); }};
  tbb::combinable<std::size_t> exact_more{[] { return std::size_t(0); }};
  if (g > 1) {
    auto d = [&](int x, int y) { return double(in.distance_m.at(x, y, 0)); };
    // Gradient of a sample along one grid axis from its grid neighbours (central where both
    // are continuous with it, one-sided where one is, else flat).
    auto gradient = [&](std::size_t i, std::size_t j, bool along_x, int c) {
      const int x = gx[i], y = gy[j];
      const PixelSample& s = sparse.grid_at(i, j);
      auto value = [&](const PixelSample& p) {
        return c < 3 ? p.inscatter[c] : (c < 6 ? p.camera_od[c - 3] : p.ao);
      };
      const std::size_t n = along_x ? gx.size() : gy.size();
      const std::size_t k = along_x ? i : j;
      double slope_sum = 0;
      int slopes = 0;
      for (int side : {-1, 1}) {
        if ((side < 0 && k == 0) || (side > 0 && k + 1 >= n)) continue;
        const int nx = along_x ? gx[k + side] : x, ny = along_x ? y : gy[k + side];
        if (!depth_continuous(d(nx, ny), d(x, y))) continue;
        const double dist = along_x ? nx - x : ny - y;
        const PixelSample& neighbour =
            along_x ? sparse.grid_at(k + side, j) : sparse.grid_at(i, k + side);
        physics::add_slope(slope_sum, slopes, value(s), value(neighbour), dist);
      }
      return physics::mean_slope(slope_sum, slopes);
    };
    constexpr int kValues = physics::kResolveValues;  // R (3), camera optical depth (3), AO
    // Every sample's gradients once (cells share corners: four cells would redo them).
    using Gradients = std::array<double, 2 * kValues>;  // d/dx of each value, then d/dy
    std::vector<Gradients> sample_gradients(gx.size() * gy.size());
    tbb::parallel_for(std::size_t(0), gy.size(), [&](std::size_t j) {
      if (stop()) return;
      for (std::size_t i = 0; i < gx.size(); ++i)
        for (int c = 0; c < kValues; ++c) {
          sample_gradients[j * gx.size() + i][c] = gradient(i, j, true, c);
          sample_gradients[j * gx.size() + i][kValues + c] = gradient(i, j, false, c);
        }
    });
    throw_if_stopped();
    tbb::parallel_for(
        tbb::blocked_range2d<std::size_t>(0, gy.size() - 1, 0, gx.size() - 1),
        [&](const tbb::blocked_range2d<std::size_t>& r) {
          for (std::size_t j = r.rows().begin(); j < r.rows().end(); ++j) {
            if (stop()) return;
            for (std::size_t i = r.cols().begin(); i < r.cols().end(); ++i) {
              const int x0 = gx[i], x1 = gx[i + 1], y0 = gy[j], y1 = gy[j + 1];
              const std::array<std::pair<std::size_t, std::size_t>, 4> corners{
                  {{i, j}, {i + 1, j}, {i, j + 1}, {i + 1, j + 1}}};
              // The corners' gradients, once per cell.
              double value[4][kValues], grad_x[4][kValues], grad_y[4][kValues];
              double shaft_min = 1, shaft_max = 0;
              for (int k = 0; k < 4; ++k) {
                const auto [ci, cj] = corners[k];
                const PixelSample& s = sparse.grid_at(ci, cj);
                for (int c = 0; c < kValues; ++c) {
                  value[k][c] = c < 3 ? s.inscatter[c] : (c < 6 ? s.camera_od[c - 3] : s.ao);
                  grad_x[k][c] = sample_gradients[cj * gx.size() + ci][c];
                  grad_y[k][c] = sample_gradients[cj * gx.size() + ci][kValues + c];
                }
                shaft_min = std::min(shaft_min, s.shaft);
                shaft_max = std::max(shaft_max, s.shaft);
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
              const bool shadow_edge =
                  physics::cell_has_edge(shaft_min, shaft_max, lum_min, lum_max);
              const double disk0 = sparse.grid_at(i, j).sun_disk;
              const bool sun_disk_agrees = disk0 >= 0 &&
                                           sparse.grid_at(i + 1, j).sun_disk == disk0 &&
                                           sparse.grid_at(i, j + 1).sun_disk == disk0 &&
                                           sparse.grid_at(i + 1, j + 1).sun_disk == disk0;
              for (int y = y0; y <= y1; ++y)
                for (int x = x0; x <= x1; ++x) {
                  if (sparse.has(x, y)) continue;
                  // Cells share edges: the first cell to reach a pixel decides it.
                  if ((x == x1 && i + 2 < gx.size()) || (y == y1 && j + 2 < gy.size())) continue;
                  bool ok = !shadow_edge;
                  for (int k = 0; k < 4 && ok; ++k)
                    ok = depth_continuous(d(x, y), d(gx[corners[k].first], gy[corners[k].second]));
                  if (!ok) {
                    // A shaft's edge crosses the cell: its pixels get finer steps, or thin slivers
                    // of shadow that one step misses or catches would show as grain.
                    exact(x, y, shadow_edge ? plan.steps * kShaftRefinement : plan.steps);
                    ++exact_more.local();
                    continue;
                  }
                  const double fx = double(x - x0) / (x1 - x0), fy = double(y - y0) / (y1 - y0);
                  PixelSample p;
                  double acc[kValues] = {};
                  for (int k = 0; k < 4; ++k) {
                    const double weight = physics::corner_weight(k, fx, fy);
                    const double dx = x - gx[corners[k].first], dy = y - gy[corners[k].second];
                    for (int c = 0; c < kValues; ++c)
                      acc[c] += weight * physics::extrapolate(value[k][c], grad_x[k][c],
                                                              grad_y[k][c], dx, dy);
                  }
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
                  ++interpolated.local();
                }
            }
            progress.add(r.cols().size() * kCellWork);
          }
        });
  }
  throw_if_stopped();
  exact_count += exact_more.combine(std::plus<>());
  out.interpolation_s = seconds_since(pass_start);
  pass_start = Clock::now();

  // Pass 3: per pixel, the transmittance map T = tau(camera, surface) * S(surface) and the AOVs.
  // With the photo, every surface pixel's sun visibility first (the photo fallback compares a
  // pixel with its neighbours', see render/photo_fallback.h; the Vulkan backend asks the same).
  const bool photo_fallback = PhotoFallback::wanted(*in.scene, in.distance_m, in.normals,
                                                    in.photo, in.occluders != nullptr);
  std::optional<PhotoFallback> fallback;
  std::vector<float> disk;
  if (photo_fallback) {
    fallback.emplace(*in.camera, *in.scene, in.distance_m, in.normals, in.photo, in.sky_radiance);
    disk.assign(std::size_t(w) * h, -1.0f);
    tbb::parallel_for(0, h, [&](int y) {
      if (stop()) return;
      for (int x = 0; x < w; ++x) {
        const PixelSample& s = sparse.at(x, y);
        disk[std::size_t(y) * w + x] =
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
        if (closed_form_camera) core.camera_optical_depth(x, y, od);
        double S[3];
        float sun_visible = 1.0f;
        double sun_disk = s.sun_disk;
        if (photo_fallback) {
          sun_disk = disk[std::size_t(y) * w + x];
          if (sun_disk >= 0 && sun_disk < 1 && fallback->shows_sunlit(x, y, s.ao, disk.data()))
            sun_disk = 1;
        }
        core.surface_term(x, y, s.ao, sun_disk, S, &sun_visible);
        for (int c = 0; c < 3; ++c) {
          out.transmittance.at(x, y, c) = float(std::exp(-od[c]) * S[c]);  // R: pass 1 or 2
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
