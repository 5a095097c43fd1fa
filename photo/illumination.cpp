#include "photo/illumination.h"

#include <ceres/ceres.h>
#include <ceres/sphere_manifold.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <sstream>
#include <string>

#include "mr/error.h"
#include "core/vec3.h"
#include "photo/ceres_options.h"

namespace mr::photo {
namespace {

using vec3::add;  // core/vec3.h
using vec3::dot;
using vec3::norm;
using vec3::normalized;
using vec3::scale;
using vec3::sub;

constexpr double kDeg = std::numbers::pi / 180.0;

bool finite(const Vec3& a) {
  return std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(a.z);
}

/// Angle between two unit vectors in degrees, accurate near 0 and 180 (atan2, not acos).
double angle_deg(const Vec3& a, const Vec3& b) {
  const Vec3 c{a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
  return std::atan2(norm(c), dot(a, b)) / kDeg;
}

[[noreturn]] void fail(const std::string& message) {
  throw Error(ErrorCode::invalid_argument, message);
}

std::string pair_name(std::size_t i) { return "shadow pair " + std::to_string(i); }

/// Where the ray through pixel `px` meets the ground plane y = 0.
Vec3 lift_to_ground(const Camera& camera, const CameraPose& pose, const std::array<double, 2>& px,
                    std::size_t index, const char* what) {
  const Vec3 d = pose.ray_direction(camera, px[0], px[1]);
  // Rays within ~0.006 degrees of the horizon would meet the ground absurdly far away
  // (> 10,000 camera heights): treat them as on the horizon.
  if (!(d.y < -1e-4)) {
    std::ostringstream s;
    s << pair_name(index) << ": the " << what << " (" << px[0] << ", " << px[1]
      << ") is on or above the horizon: its ray does not meet the ground";
    fail(s.str());
  }
  const double t = -pose.position_m.y / d.y;
  return add(pose.position_m, scale(d, t));
}

/// The chord between the candidate sun direction and a pair's observed direction:
/// |l - d| = 2 sin(angle / 2).
struct ChordResidual {
  explicit ChordResidual(const Vec3& d) : d_(d) {}
  template <typename T>
  bool operator()(const T* l, T* r) const {
    r[0] = l[0] - T(d_.x);
    r[1] = l[1] - T(d_.y);
    r[2] = l[2] - T(d_.z);
    return true;
  }
  Vec3 d_;
};

/// Reprojection of one pair for the maximum-likelihood stage: parameters g = (X, Z, h), the
/// caster's foot (X, 0, Z) on the ground and its height, and the sun direction l. Residuals: the
/// pixel offsets of the projected top (X, h, Z), foot and shadow tip
/// (X - h l_x / l_y, 0, Z - h l_z / l_y) from the marks.
struct ReprojectionResidual {
  ReprojectionResidual(const Camera& camera, const CameraPose& pose, const ShadowPair& pair)
      : pair_(pair), c_(pose.position_m), f_(camera.focal_px), cx_(camera.cx), cy_(camera.cy) {
    const auto axes = pose.axes();
    fwd_ = axes[0];
    right_ = axes[1];
    up_ = axes[2];
  }
  template <typename T>
  bool project(const T& x, const T& y, const T& z, const std::array<double, 2>& mark,
               T* r) const {
    const T dx = x - T(c_.x), dy = y - T(c_.y), dz = z - T(c_.z);
    const T zf = dx * T(fwd_.x) + dy * T(fwd_.y) + dz * T(fwd_.z);
    if (!(zf > T(1e-6))) return false;  // behind the camera: not a valid step
    const T u = dx * T(right_.x) + dy * T(right_.y) + dz * T(right_.z);
    const T v = dx * T(up_.x) + dy * T(up_.y) + dz * T(up_.z);
    r[0] = u / zf * T(f_) + T(cx_ - 0.5 - mark[0]);
    r[1] = -v / zf * T(f_) + T(cy_ - 0.5 - mark[1]);
    return true;
  }
  template <typename T>
  bool operator()(const T* g, const T* l, T* r) const {
    if (!(l[1] > T(1e-6))) return false;  // the sun must stay above the horizon
    const T zero(0);
    const T k = g[2] / l[1];
    return project(g[0], g[2], g[1], pair_.caster_top_px, r) &&
           project(g[0], zero, g[1], pair_.caster_foot_px, r + 2) &&
           project(g[0] - k * l[0], zero, g[1] - k * l[2], pair_.shadow_tip_px, r + 4);
  }
  ShadowPair pair_;
  Vec3 c_, fwd_, right_, up_;
  double f_, cx_, cy_;
};

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

}  // namespace

SunFit fit_sun_direction(const std::vector<ShadowPair>& pairs, const Camera& camera,
                         const CameraPose& pose, const SunFitOptions& options) {
  if (pairs.empty()) fail("sun fit: no shadow pairs were given");
  if (!(camera.focal_px > 0) || !std::isfinite(camera.focal_px) || !std::isfinite(camera.cx) ||
      !std::isfinite(camera.cy))
    fail("sun fit: the camera has no valid focal length / principal point");
  if (!finite(pose.position_m) || !(pose.position_m.y > 0))
    fail("sun fit: the camera must be above the ground (pose.position_m.y > 0), got " +
         std::to_string(pose.position_m.y));
  if (!(options.robust_scale_deg > 0 && options.robust_scale_deg < 90))
    fail("sun fit: robust_scale_deg must be in (0, 90)");
  if (!(options.robust_scale_px > 0) || !std::isfinite(options.robust_scale_px))
    fail("sun fit: robust_scale_px must be positive");
  if (!(options.max_median_residual_px > 0))
    fail("sun fit: max_median_residual_px must be positive");
  if (options.use_initial_guess && (!std::isfinite(options.initial_azimuth_deg) ||
                                    !std::isfinite(options.initial_elevation_deg)))
    fail("sun fit: the initial guess is NaN or infinite");

  // 1. Lift every pair to 3D and turn it into an observed direction toward the sun.
  std::vector<Vec3> directions, tips;
  std::vector<std::array<double, 3>> casters;  // (X, Z, h): foot (X, 0, Z), height h
  directions.reserve(pairs.size());
  const Vec3 up{0, 1, 0};
  for (std::size_t i = 0; i < pairs.size(); ++i) {
    const ShadowPair& p = pairs[i];
    for (double v : {p.caster_top_px[0], p.caster_top_px[1], p.caster_foot_px[0],
                     p.caster_foot_px[1], p.shadow_tip_px[0], p.shadow_tip_px[1]})
      if (!std::isfinite(v)) fail(pair_name(i) + ": a pixel coordinate is NaN or infinite");
    const Vec3 foot = lift_to_ground(camera, pose, p.caster_foot_px, i, "caster foot");
    const Vec3 tip = lift_to_ground(camera, pose, p.shadow_tip_px, i, "shadow tip");
    // Closest point of the top's ray C + t r to the vertical line F + h up (both directions
    // unit, so a = c = 1): t = (b e - d) / (1 - b^2), h = (e - b d) / (1 - b^2),
    // with b = r . up, d = r . (C - F), e = up . (C - F).
    const Vec3 r = pose.ray_direction(camera, p.caster_top_px[0], p.caster_top_px[1]);
    const Vec3 w = sub(pose.position_m, foot);
    const double b = dot(r, up), d = dot(r, w), e = dot(up, w);
    const double denom = 1 - b * b;
    if (denom < 1e-10)
      fail(pair_name(i) + ": the caster top's ray is parallel to the vertical caster");
    const double t = (b * e - d) / denom;
    const double h = (e - b * d) / denom;
    if (!(t > 0))
      fail(pair_name(i) + ": the caster top's ray passes the caster behind the camera");
    // A top less than 1 mm above its foot (per metre of distance) is not above it.
    if (!(h > 1e-3 * std::max(1.0, norm(w)))) {
      std::ostringstream s;
      s << pair_name(i) << ": the caster top (" << p.caster_top_px[0] << ", "
        << p.caster_top_px[1] << ") is not above its foot (" << p.caster_foot_px[0] << ", "
        << p.caster_foot_px[1] << "): height " << h << " m";
      fail(s.str());
    }
    const Vec3 top = add(foot, scale(up, h));
    directions.push_back(normalized(sub(top, tip)));  // y > 0 as h > 0
    tips.push_back(tip);
    casters.push_back({foot.x, foot.z, h});
  }

  // 2. Start point: given, else the normalised mean of the observed directions (all have
  //    y > 0, so the mean is never zero).
  Vec3 start;
  if (options.use_initial_guess) {
    start = direction_from_azimuth_elevation(options.initial_azimuth_deg,
                                             options.initial_elevation_deg);
  } else {
    Vec3 sum{};
    for (const Vec3& d : directions) sum = add(sum, d);
    start = normalized(sum);
  }
  double l[3] = {start.x, start.y, start.z};

  // 3. Two stages: a plain squared loss from the start point (its basin is the whole sphere
  //    but the antipode of the mean), then the Cauchy loss from there, which pulls the fit back
  //    from mis-clicked pairs.
  const double chord_scale = 2 * std::sin(0.5 * options.robust_scale_deg * kDeg);
  int iterations = 0;
  bool converged = false;
  for (int stage = 0; stage < 2; ++stage) {
    ceres::Problem problem;
    for (const Vec3& d : directions) {
      problem.AddResidualBlock(
          new ceres::AutoDiffCostFunction<ChordResidual, 3, 3>(new ChordResidual(d)),
          stage == 0 ? nullptr : new ceres::CauchyLoss(chord_scale), l);
    }
    problem.SetManifold(l, new ceres::SphereManifold<3>());
    ceres::Solver::Summary summary;
    ceres::Solve(solver_options({.max_iterations = 100,
                                 .function_tolerance = 1e-12,
                                 .gradient_tolerance = 1e-14,
                                 .parameter_tolerance = 1e-12}),
                 &problem, &summary);
    iterations += int(summary.iterations.size());
    if (!summary.IsSolutionUsable())
      throw Error(ErrorCode::internal, "sun fit: Ceres failed: " + summary.message);
    converged = summary.termination_type == ceres::CONVERGENCE;
  }

  // 4. Maximum likelihood under pixel noise: the casters (foot and height) and the sun together,
  //    minimising the reprojection error of top, foot and tip of every pair (Cauchy loss,
  //    scale options.robust_scale_px), from the lifted casters and the angular fit. This
  //    weighs each pair by how well its pixels pin it down (a distant caster's ground position
  //    is uncertain along the view; the angular fit above weighs all pairs alike).
  //    Where it cannot run (the angular fit's sun would put a shadow tip behind the camera,
  //    which only grossly wrong marks do), the angular fit stands and the contradiction test
  //    below judges it.
  const double l_angular[3] = {l[0], l[1], l[2]};
  const std::vector<std::array<double, 3>> casters_lifted = casters;
  {
    ceres::Problem problem;
    for (std::size_t i = 0; i < pairs.size(); ++i) {
      problem.AddResidualBlock(
          new ceres::AutoDiffCostFunction<ReprojectionResidual, 6, 3, 3>(
              new ReprojectionResidual(camera, pose, pairs[i])),
          new ceres::CauchyLoss(options.robust_scale_px), casters[i].data(), l);
    }
    problem.SetManifold(l, new ceres::SphereManifold<3>());
    ceres::Solver::Summary summary;
    ceres::Solve(solver_options({.max_iterations = 200,
                                 .function_tolerance = 1e-12,
                                 .gradient_tolerance = 1e-14,
                                 .parameter_tolerance = 1e-12,
                                 .linear_solver = ceres::DENSE_SCHUR}),
                 &problem, &summary);
    iterations += int(summary.iterations.size());
    if (summary.IsSolutionUsable()) {
      converged = converged && summary.termination_type == ceres::CONVERGENCE;
    } else {
      std::copy(l_angular, l_angular + 3, l);
      casters = casters_lifted;
      converged = false;
    }
  }

  SunFit fit;
  fit.direction_to_sun = normalized(Vec3{l[0], l[1], l[2]});
  fit.converged = converged;
  fit.iterations = iterations;
  const Vec3& s = fit.direction_to_sun;
  fit.elevation_deg = std::asin(std::clamp(s.y, -1.0, 1.0)) / kDeg;
  fit.azimuth_deg = std::atan2(s.x, s.z) / kDeg;
  if (fit.azimuth_deg < 0) fit.azimuth_deg += 360;
  if (fit.azimuth_deg >= 360) fit.azimuth_deg -= 360;
  double sum_sq = 0;
  for (std::size_t i = 0; i < pairs.size(); ++i) {
    // Angle at the fitted top between the sun's ray and the ray to the marked tip.
    const Vec3 top{casters[i][0], casters[i][2], casters[i][1]};
    const Vec3 to_tip = sub(top, tips[i]);
    fit.residuals_deg.push_back(norm(to_tip) > 0 ? angle_deg(s, normalized(to_tip)) : 0.0);
    sum_sq += fit.residuals_deg.back() * fit.residuals_deg.back();
    double r[6];
    double e = 0;
    if (ReprojectionResidual(camera, pose, pairs[i])(casters[i].data(), l, r)) {
      for (double v : r) e += v * v;
    } else {
      e = std::numeric_limits<double>::infinity();  // a point behind the camera
    }
    fit.residuals_px.push_back(std::sqrt(e / 3));
  }
  fit.rms_residual_deg = std::sqrt(sum_sq / double(pairs.size()));
  fit.median_residual_px = median(fit.residuals_px);

  if (fit.median_residual_px > options.max_median_residual_px || !(s.y > 0)) {
    std::ostringstream m;
    m.precision(3);
    m << "sun fit: the shadow pairs are contradictory (median reprojection error "
      << fit.median_residual_px << " px > " << options.max_median_residual_px
      << " px; per pair:";
    for (std::size_t i = 0; i < pairs.size(); ++i)
      m << (i ? ", " : " ") << i << ": " << fit.residuals_px[i] << " px "
        << fit.residuals_deg[i] << " deg";
    m << "); check that each top belongs to its shadow's tip";
    fail(m.str());
  }
  return fit;
}

PatchStats PatchStats::from_pixels(const std::vector<std::array<float, 3>>& pixels) {
  if (pixels.empty()) fail("patch: no pixels");
  PatchStats st;
  st.pixel_count = pixels.size();
  for (const auto& p : pixels)
    for (int c = 0; c < 3; ++c) {
      if (!std::isfinite(p[c])) fail("patch: a pixel is NaN or infinite");
      st.mean[c] += p[c];
    }
  for (int c = 0; c < 3; ++c) st.mean[c] /= double(pixels.size());
  if (pixels.size() > 1) {
    for (const auto& p : pixels)
      for (int c = 0; c < 3; ++c) st.stddev[c] += (p[c] - st.mean[c]) * (p[c] - st.mean[c]);
    for (int c = 0; c < 3; ++c) st.stddev[c] = std::sqrt(st.stddev[c] / double(pixels.size() - 1));
  }
  return st;
}

SunSkyRatio fit_sun_sky_ratio(const SunSkyPatches& in) {
  static const char* const kChannel[3] = {"red", "green", "blue"};
  for (const PatchStats* p : {&in.lit, &in.shadowed}) {
    const char* which = p == &in.lit ? "sunlit patch" : "shadowed patch";
    for (int c = 0; c < 3; ++c)
      if (!std::isfinite(p->mean[c]) || !std::isfinite(p->stddev[c]) || p->stddev[c] < 0)
        fail(std::string("sun/sky ratio: the ") + which + "'s " + kChannel[c] +
             " mean or stddev is NaN, infinite or negative");
    if (p->pixel_count == 0) fail(std::string("sun/sky ratio: the ") + which + " has no pixels");
  }
  for (double a : {in.sky_visibility_lit, in.sky_visibility_shadowed})
    if (!(a > 0 && a <= 1)) fail("sun/sky ratio: sky visibility must be in (0, 1]");
  if (!finite(in.normal) || !finite(in.direction_to_sun) || !(norm(in.normal) > 0) ||
      !(norm(in.direction_to_sun) > 0))
    fail("sun/sky ratio: the normal and the sun direction must be finite and non-zero");
  SunSkyRatio out;
  out.cos_theta = dot(normalized(in.normal), normalized(in.direction_to_sun));
  if (!(out.cos_theta > 0.02))
    fail("sun/sky ratio: the sun is behind or grazing the surface (cos(theta) = " +
         std::to_string(out.cos_theta) + "), so the lit patch cannot be sunlit");

  constexpr double kLuma[3] = {0.2126, 0.7152, 0.0722};
  const double a_lit = in.sky_visibility_lit, a_sh = in.sky_visibility_shadowed;
  for (int c = 0; c < 3; ++c) {
    const double lit = in.lit.mean[c], sh = in.shadowed.mean[c];
    if (!(sh > 0))
      fail(std::string("sun/sky ratio: the shadowed patch's ") + kChannel[c] +
           " mean is not positive");
    const double q = lit / sh;
    const double k = a_sh * q - a_lit;
    if (!(k > 0))
      fail(std::string("sun/sky ratio: the sunlit patch is not brighter than the shadowed one "
                       "in ") + kChannel[c] + " (lit " + std::to_string(lit) + ", shadowed " +
           std::to_string(sh) + "): swapped marks, or not one material?");
    out.patch_ratio_rgb[c] = k;
    out.ratio_rgb[c] = k / out.cos_theta;
    // Standard errors of the means, propagated: d k = a_sh q sqrt((se_l / l)^2 + (se_s / s)^2).
    const double se_l = in.lit.stddev[c] / std::sqrt(double(in.lit.pixel_count));
    const double se_s = in.shadowed.stddev[c] / std::sqrt(double(in.shadowed.pixel_count));
    const double rel_l = lit > 0 ? se_l / lit : 0;
    out.ratio_sigma_rgb[c] =
        a_sh * q * std::sqrt(rel_l * rel_l + (se_s / sh) * (se_s / sh)) / out.cos_theta;
    out.ratio += kLuma[c] * out.ratio_rgb[c];
    out.ratio_sigma += kLuma[c] * kLuma[c] * out.ratio_sigma_rgb[c] * out.ratio_sigma_rgb[c];
  }
  out.ratio_sigma = std::sqrt(out.ratio_sigma);
  const auto [lo, hi] = std::minmax_element(out.ratio_rgb.begin(), out.ratio_rgb.end());
  out.channel_spread = (*hi - *lo) / out.ratio;
  return out;
}

ExposureRelativeSun exposure_relative_sun(ConstImageView photo, ConstImageView distance_m,
                                          const std::array<float, 3>& sky_radiance) {
  if (photo.channels < 3 || photo.width <= 0 || photo.height <= 0)
    fail("exposure_relative_sun: the photo must be RGB, has " + std::to_string(photo.channels) +
         " channels");
  const bool have_depth = distance_m.data != nullptr;
  if (have_depth && (distance_m.width != photo.width || distance_m.height != photo.height ||
                     distance_m.channels < 1))
    fail("exposure_relative_sun: the distance map is " + std::to_string(distance_m.width) + "x" +
         std::to_string(distance_m.height) + ", the photo " + std::to_string(photo.width) + "x" +
         std::to_string(photo.height));
  // An even stride keeps at most about a million pixels: a percentile needs no more.
  const std::size_t n = std::size_t(photo.width) * std::size_t(photo.height);
  const std::size_t stride = std::max<std::size_t>(1, (n + 999'999) / 1'000'000);
  std::vector<float> surface, all;
  surface.reserve(n / stride + 1);
  all.reserve(n / stride + 1);
  std::size_t k = 0;
  for (int y = 0; y < photo.height; ++y) {
    const float* row = photo.row(y);
    for (int x = 0; x < photo.width; ++x, ++k) {
      if (k % stride != 0) continue;
      const float* p = row + std::ptrdiff_t(x) * photo.channels;
      const float lum = 0.2126f * p[0] + 0.7152f * p[1] + 0.0722f * p[2];
      if (!std::isfinite(lum)) continue;
      all.push_back(lum);
      if (have_depth && std::isfinite(distance_m.row(y)[std::ptrdiff_t(x) * distance_m.channels]))
        surface.push_back(lum);
    }
  }
  std::vector<float>& pool = surface.size() >= std::max<std::size_t>(1, all.size() / 100) ? surface : all;
  ExposureRelativeSun out;
  out.surface_pixels = pool.size();
  if (!pool.empty()) {
    auto at = pool.begin() + std::ptrdiff_t(0.99 * double(pool.size() - 1));
    std::nth_element(pool.begin(), at, pool.end());
    out.bright_surface_luminance = std::max(0.0f, *at);
  }
  out.sky_luminance = std::max(
      0.0, 0.2126 * sky_radiance[0] + 0.7152 * sky_radiance[1] + 0.0722 * sky_radiance[2]);
  double e = std::numbers::pi * out.bright_surface_luminance;
  if (out.sky_luminance > 0 && std::isfinite(out.sky_luminance)) {
    const double pi_sky = std::numbers::pi * out.sky_luminance;
    e = std::clamp(e, 1.0 * pi_sky, 10.0 * pi_sky);
    out.sun_sky_ratio = e / pi_sky;
  }
  out.irradiance = {float(e), float(e), float(e)};
  return out;
}

}  // namespace mr::photo
