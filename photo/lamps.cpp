#include "photo/lamps.h"

#include <ceres/ceres.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <numbers>
#include <optional>
#include <string>

#include "core/vec3.h"
#include "mr/error.h"
#include "photo/ceres_options.h"
#include "photo/geometry.h"
#include "photo/illumination.h"
#include "render/depth_downsample.h"
#include "render/embree_scene.h"
#include "render/medium.h"
#include "render/occluder_mesh.h"
#include "render/physics/scattering.h"
#include "render/surface_shading.h"

namespace mr::photo {
namespace {

using vec3::cross;  // core/vec3.h
using vec3::dot;
using vec3::scale;
using vec3::sub;

Vec3 add(const Vec3& a, const Vec3& b) {
  return {a.x + b.x, a.y + b.y, a.z + b.z};
}
double luminance(const std::array<double, 3>& c) {
  return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
}

[[noreturn]] void fail(const std::string& message) {
  throw Error(ErrorCode::invalid_argument, message);
}

std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4g", v);
  return buf;
}

std::string lamp_name(std::size_t i) {
  return "lamp " + std::to_string(i);
}
std::string patch_name(std::size_t k) {
  return "lamp patch " + std::to_string(k);
}
const char* const kChannel[3] = {"R", "G", "B"};

/// One patch pixel: its radiance and, per lamp, g_i = V_i * (the Lambert radiance of unit
/// albedo under lamp i at unit intensity, from render::shading_terms) = V_i cos / (pi r^2).
struct Sample {
  std::array<double, 3> observed{};
  std::vector<double> g;
  std::size_t patch = 0;
};

/// Per lamp: nullopt for three free channels, else colour / luminance(colour) (one unknown).
using LampColour = std::optional<std::array<double, 3>>;

/// Residuals (model - observed) / m_c of one sample (the model in lamps.h), with analytic
/// Jacobians: the model is linear in the lamps' parameters and the patch's ambient term.
class ShadingCost : public ceres::CostFunction {
 public:
  ShadingCost(const Sample& sample, const std::vector<LampColour>& colours,
              const std::array<double, 3>& albedo, const std::array<double, 3>& inv_scale)
      : sample_(sample), colours_(colours), albedo_(albedo), inv_scale_(inv_scale) {
    set_num_residuals(3);
    for (const auto& c : colours_) mutable_parameter_block_sizes()->push_back(c ? 1 : 3);
    mutable_parameter_block_sizes()->push_back(3);  // the patch's ambient term
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const std::size_t n = colours_.size();
    for (int c = 0; c < 3; ++c) {
      const double k = albedo_[c] * inv_scale_[c];
      double model = parameters[n][c];
      for (std::size_t i = 0; i < n; ++i) {
        const double intensity =
            colours_[i] ? parameters[i][0] * (*colours_[i])[c] : parameters[i][c];
        model += albedo_[c] * sample_.g[i] * intensity;
      }
      residuals[c] = (model - sample_.observed[c]) * inv_scale_[c];
      if (!jacobians) continue;
      for (std::size_t i = 0; i < n; ++i) {
        if (!jacobians[i]) continue;
        if (colours_[i]) {
          jacobians[i][c] = k * sample_.g[i] * (*colours_[i])[c];
        } else {
          for (int cc = 0; cc < 3; ++cc) jacobians[i][c * 3 + cc] = cc == c ? k * sample_.g[i] : 0;
        }
      }
      if (jacobians[n])
        for (int cc = 0; cc < 3; ++cc) jacobians[n][c * 3 + cc] = cc == c ? inv_scale_[c] : 0;
    }
    return true;
  }

 private:
  const Sample& sample_;
  const std::vector<LampColour>& colours_;
  std::array<double, 3> albedo_, inv_scale_;
};

Vec3 point_at(const Image& distance_m, const Camera& camera, const CameraPose& pose, int x, int y) {
  return add(pose.position_m, scale(pose.ray_direction(camera, x, y), distance_m.at(x, y, 0)));
}

/// The occluder mesh of the distance map in an Embree scene, at most kMaxMeshPixels: a larger map
/// is reduced (render::downsample_distance_nearest) so the mesh of a 24 MP photo does not take
/// gigabytes; `step` is the reduction factor (1: full resolution).
constexpr double kMaxMeshPixels = 1.0e6;
struct Occluders {
  std::optional<render::OccluderScene> scene;
  int step = 1;
};
Occluders build_occluders(const Image& distance_m, const Camera& camera, const CameraPose& pose) {
  Occluders out;
  const double pixels = double(camera.width) * double(camera.height);
  out.step = pixels > kMaxMeshPixels ? int(std::ceil(std::sqrt(pixels / kMaxMeshPixels))) : 1;
  render::TriangleMesh mesh;
  if (out.step > 1) {
    const render::DownsampledDistance coarse =
        render::downsample_distance_nearest(distance_m.view(), camera, out.step);
    mesh = render::reconstruct_occluder_mesh(coarse.distance_m.view(), coarse.camera, pose);
  } else {
    mesh = render::reconstruct_occluder_mesh(distance_m.view(), camera, pose);
  }
  // Robust traversal, as render/surface_shading: each patch pixel's visibility is one ray, and
  // one slipping through a shared edge would light a pixel inside a shadow.
  render::OccluderSceneOptions options;
  options.robust = true;
  if (mesh.triangle_count() > 0) out.scene.emplace(std::move(mesh), options);
  return out;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

}  // namespace

Vec3 lift_lamp(const Image& distance_m, const Camera& camera, const CameraPose& pose,
               const LampMark& lamp, std::size_t index) {
  const std::string name = lamp_name(index);
  const double x = lamp.pixel[0], y = lamp.pixel[1];
  if (!std::isfinite(x) || !std::isfinite(y)) fail(name + ": the pixel is NaN or infinite");
  if (!std::isfinite(lamp.offset_m) || lamp.offset_m < 0)
    fail(name + ": offset_m must be finite and >= 0, found " + num(lamp.offset_m));
  const int w = distance_m.width(), h = distance_m.height();
  const std::string where = "pixel (" + num(x) + ", " + num(y) + ")";
  if (x < -0.5 || y < -0.5 || x > w - 0.5 || y > h - 0.5)
    fail(name + ": " + where + " is outside the " + std::to_string(w) + "x" + std::to_string(h) +
         " image");
  const int xi = std::clamp(int(std::lround(x)), 0, w - 1);
  const int yi = std::clamp(int(std::lround(y)), 0, h - 1);
  double d = distance_m.at(xi, yi, 0);
  if (std::isinf(d) && d > 0)
    fail(name + ": " + where +
         " shows the sky (no depth); a lamp is marked where the depth map has a surface");
  if (!std::isfinite(d) || !(d > 0))
    fail(name + ": " + where + " has no valid depth (" + num(d) + ")");
  // Bilinear where the four nearest pixel centres are finite and on one surface.
  const int x0 = std::clamp(int(std::floor(x)), 0, w - 1), x1 = std::min(x0 + 1, w - 1);
  const int y0 = std::clamp(int(std::floor(y)), 0, h - 1), y1 = std::min(y0 + 1, h - 1);
  const double q[4] = {distance_m.at(x0, y0, 0), distance_m.at(x1, y0, 0), distance_m.at(x0, y1, 0),
                       distance_m.at(x1, y1, 0)};
  const double lo = *std::min_element(q, q + 4), hi = *std::max_element(q, q + 4);
  if (std::isfinite(lo) && std::isfinite(hi) && lo > 0 && hi <= 1.1 * lo) {
    const double fx = std::clamp(x - x0, 0.0, 1.0), fy = std::clamp(y - y0, 0.0, 1.0);
    d = (q[0] * (1 - fx) + q[1] * fx) * (1 - fy) + (q[2] * (1 - fx) + q[3] * fx) * fy;
  }
  if (lamp.offset_m >= d)
    fail(name + ": offset_m (" + num(lamp.offset_m) + " m) is not less than the distance to the " +
         "surface at " + where + " (" + num(d) + " m): the lamp would be at or behind the camera");
  const Vec3 ray = pose.ray_direction(camera, x, y);
  return add(pose.position_m, scale(ray, d - lamp.offset_m));
}

bool surface_point(const Image& distance_m, const Camera& camera, const CameraPose& pose, int x,
                   int y, Vec3& position, Vec3& normal) {
  const int w = distance_m.width(), h = distance_m.height();
  if (x < 0 || y < 0 || x >= w || y >= h) return false;
  const double d0 = distance_m.at(x, y, 0);
  if (!std::isfinite(d0) || !(d0 > 0)) return false;
  auto usable = [&](int xx, int yy) {
    if (xx < 0 || yy < 0 || xx >= w || yy >= h) return false;
    const double d = distance_m.at(xx, yy, 0);
    return std::isfinite(d) && d > 0;
  };
  // One-sided difference toward the neighbour whose depth changes less.
  auto tangent = [&](int dx, int dy, Vec3& t) {
    const bool plus = usable(x + dx, y + dy), minus = usable(x - dx, y - dy);
    if (!plus && !minus) return false;
    bool use_plus = plus;
    if (plus && minus)
      use_plus = std::abs(distance_m.at(x + dx, y + dy, 0) - d0) <=
                 std::abs(distance_m.at(x - dx, y - dy, 0) - d0);
    const Vec3 p0 = point_at(distance_m, camera, pose, x, y);
    t = use_plus ? sub(point_at(distance_m, camera, pose, x + dx, y + dy), p0)
                 : sub(p0, point_at(distance_m, camera, pose, x - dx, y - dy));
    return true;
  };
  Vec3 tx, ty;
  if (!tangent(1, 0, tx) || !tangent(0, 1, ty)) return false;
  Vec3 n = cross(tx, ty);
  const double len = std::sqrt(dot(n, n));
  if (!(len > 0) || !std::isfinite(len)) return false;
  n = scale(n, 1.0 / len);
  position = point_at(distance_m, camera, pose, x, y);
  if (dot(n, sub(pose.position_m, position)) < 0) n = scale(n, -1.0);
  normal = n;
  return true;
}

LampFit fit_lamps(const Image& photo, const Image& distance_m, const Camera& camera,
                  const CameraPose& pose, const std::vector<LampMark>& lamps,
                  const std::vector<LampPatch>& patches, const LampFitOptions& options) {
  if (lamps.empty()) fail("lamp fit: no lamps were marked");
  if (patches.empty())
    fail(
        "lamp fit: no lamp patches were marked; the intensities are fitted to the shading of "
        "marked surfaces the lamps light");
  if (photo.width() != camera.width || photo.height() != camera.height ||
      distance_m.width() != camera.width || distance_m.height() != camera.height)
    throw Error(ErrorCode::size_mismatch, "lamp fit: photo " + std::to_string(photo.width()) + "x" +
                                              std::to_string(photo.height()) + ", distance map " +
                                              std::to_string(distance_m.width()) + "x" +
                                              std::to_string(distance_m.height()) + ", camera " +
                                              std::to_string(camera.width) + "x" +
                                              std::to_string(camera.height));
  if (photo.channels() < 3) fail("lamp fit: the photo needs RGB channels");
  if (distance_m.channels() != 1) fail("lamp fit: the distance map needs exactly one channel");
  if (!(options.robust_scale > 0) || !std::isfinite(options.robust_scale))
    fail("lamp fit: robust_scale must be > 0");
  if (!(options.max_negative_fraction >= 0) || !std::isfinite(options.max_negative_fraction))
    fail("lamp fit: max_negative_fraction must be >= 0");
  if (options.max_pixels_per_patch < 1) fail("lamp fit: max_pixels_per_patch must be >= 1");
  if (!options.initial_intensity.empty() && options.initial_intensity.size() != lamps.size())
    fail("lamp fit: initial_intensity has " + std::to_string(options.initial_intensity.size()) +
         " entries for " + std::to_string(lamps.size()) + " lamps");

  const std::size_t n = lamps.size();
  LampFit fit;
  std::vector<LampColour> colours(n);
  for (std::size_t i = 0; i < n; ++i) {
    fit.positions_m.push_back(lift_lamp(distance_m, camera, pose, lamps[i], i));
    if (const auto& c = lamps[i].color) {
      for (double v : *c)
        if (!std::isfinite(v) || v < 0)
          fail(lamp_name(i) + ": color components must be finite and >= 0");
      const double lum = luminance(*c);
      if (!(lum > 0)) fail(lamp_name(i) + ": color must not be black");
      colours[i] = std::array<double, 3>{(*c)[0] / lum, (*c)[1] / lum, (*c)[2] / lum};
    }
  }

  // The direct light is the shared shading code's (render/surface_shading.h): the Lambert term
  // of shading_terms for each lamp alone at unit intensity, i.e. the radiance of a unit-albedo
  // Lambertian surface, cos / (pi r^2) for a point lamp. The fit's unknowns multiply it.
  std::vector<Lighting> unit_light(n);
  for (std::size_t i = 0; i < n; ++i) {
    Lamp lamp;
    lamp.position_m = fit.positions_m[i];
    lamp.intensity_per_sr = {1, 1, 1};
    unit_light[i].lamps.push_back(lamp);
  }
  // Visibility: a shadow ray from each patch pixel to each lamp against the occluder mesh.
  Occluders occluders;
  std::vector<Vec3> shadow_target(n);
  if (options.shadows) {
    occluders = build_occluders(distance_m, camera, pose);
    for (std::size_t i = 0; i < n; ++i) {
      // A lamp marked on a wall or ceiling (offset_m ~ 0) sits on the mesh; its shadow rays end
      // a clearance in front of that surface (along its normal, toward the room), so the
      // surface the lamp hangs on does not hide it. The clearance covers the mesh's error
      // (MeshOptions::centre_tolerance, 1e-3 of the distance, and one coarse pixel's depth
      // step when the mesh is reduced).
      const Vec3& P = fit.positions_m[i];
      const double range = std::sqrt(dot(sub(P, pose.position_m), sub(P, pose.position_m)));
      const double clearance = 0.01 + 2e-3 * occluders.step * range;
      const int lx = std::clamp(int(std::lround(lamps[i].pixel[0])), 0, camera.width - 1);
      const int ly = std::clamp(int(std::lround(lamps[i].pixel[1])), 0, camera.height - 1);
      Vec3 X, nrm;
      if (!surface_point(distance_m, camera, pose, lx, ly, X, nrm))
        nrm = scale(pose.ray_direction(camera, lamps[i].pixel[0], lamps[i].pixel[1]), -1.0);
      shadow_target[i] = add(P, scale(nrm, clearance));
    }
  }
  std::vector<std::size_t> facing(n, 0), hidden(n, 0);

  // Gather the patch pixels.
  std::vector<Sample> samples;
  for (std::size_t k = 0; k < patches.size(); ++k) {
    const LampPatch& patch = patches[k];
    for (double a : patch.albedo)
      if (!(a > 0 && a <= 1)) fail(patch_name(k) + ": albedo must be in (0, 1], found " + num(a));
    if (patch.polygon.size() < 3) fail(patch_name(k) + ": the polygon needs at least 3 points");
    double x0 = 1e300, y0 = 1e300, x1 = -1e300, y1 = -1e300;
    for (const auto& p : patch.polygon) {
      if (!std::isfinite(p[0]) || !std::isfinite(p[1]))
        fail(patch_name(k) + ": a polygon point is NaN or infinite");
      x0 = std::min(x0, p[0]), x1 = std::max(x1, p[0]);
      y0 = std::min(y0, p[1]), y1 = std::max(y1, p[1]);
    }
    const int xa = std::max(0, int(std::floor(x0))),
              xb = std::min(camera.width - 1, int(std::ceil(x1)));
    const int ya = std::max(0, int(std::floor(y0))),
              yb = std::min(camera.height - 1, int(std::ceil(y1)));
    std::vector<std::array<int, 2>> pixels;
    for (int y = ya; y <= yb; ++y)
      for (int x = xa; x <= xb; ++x)
        if (inside_polygon(patch.polygon, x, y)) pixels.push_back({x, y});
    const std::size_t stride = std::max<std::size_t>(
        1, (pixels.size() + options.max_pixels_per_patch - 1) / options.max_pixels_per_patch);
    std::size_t used = 0;
    for (std::size_t j = 0; j < pixels.size(); j += stride) {
      const auto [x, y] = pixels[j];
      Vec3 X, nrm;
      if (!surface_point(distance_m, camera, pose, x, y, X, nrm)) continue;
      Sample s;
      s.patch = k;
      bool ok = true;
      for (int c = 0; c < 3; ++c) {
        s.observed[c] = photo.at(x, y, c);
        ok = ok && std::isfinite(s.observed[c]);
      }
      if (!ok) continue;
      render::SurfacePoint point;
      point.surface = true;
      const Vec3 view = scale(pose.ray_direction(camera, x, y), -1.0);
      point.normal = {float(nrm.x), float(nrm.y), float(nrm.z)};
      point.view = {float(view.x), float(view.y), float(view.z)};
      point.position_m = {float(X.x), float(X.y), float(X.z)};
      // Off the surface along its normal (as render/surface_shading and the scattering core),
      // so the pixel's own triangles do not shadow it; a reduced mesh sits up to a coarse
      // pixel's depth step nearer, hence the factor.
      const double distance = distance_m.at(x, y, 0);
      const Vec3 origin = add(X, scale(nrm, (1e-3 + 1e-3 * distance) * occluders.step));
      s.g.resize(n);
      for (std::size_t i = 0; i < n; ++i) {
        const Vec3 to = sub(fit.positions_m[i], X);
        if (!(dot(to, to) > 1e-12)) {
          ok = false;
          break;
        }
        s.g[i] = render::shading_terms(point, unit_light[i], 1.0f).diffuse[0];
        if (!(s.g[i] > 0)) {
          s.g[i] = 0;
          continue;
        }
        ++facing[i];
        if (occluders.scene) {
          const Vec3 d = sub(shadow_target[i], origin);
          if (occluders.scene->occluded({float(origin.x), float(origin.y), float(origin.z)},
                                        {float(d.x), float(d.y), float(d.z)}, 0.0f, 1.0f - 1e-4f)) {
            s.g[i] = 0;
            ++hidden[i];
          }
        }
      }
      if (!ok) continue;
      samples.push_back(std::move(s));
      ++used;
    }
    if (used == 0)
      fail(patch_name(k) + ": no pixel inside the polygon has a finite depth, a surface normal " +
           "and a finite photo value");
  }
  for (std::size_t i = 0; i < n; ++i) {
    double sum = 0;
    for (const auto& s : samples) sum += s.g[i];
    if (!(sum > 0))
      fail(lamp_name(i) +
           ": lights none of the marked patches (every patch pixel faces away from "
           "it" +
           std::string(hidden[i] > 0 ? " or the scene hides it from them" : "") +
           "); its intensity cannot be fitted");
    fit.shadowed_fraction.push_back(facing[i] ? double(hidden[i]) / double(facing[i]) : 0.0);
  }

  // Per-channel scale of the residuals: the median patch radiance.
  std::array<double, 3> med{}, mean_obs{}, inv_scale{};
  for (int c = 0; c < 3; ++c) {
    std::vector<double> v;
    for (const auto& s : samples) v.push_back(s.observed[c]), mean_obs[c] += s.observed[c];
    mean_obs[c] /= double(samples.size());
    med[c] = median(std::move(v));
  }
  const double top = std::max({med[0], med[1], med[2]});
  if (!(top > 0))
    fail("lamp fit: the lamp patches are black (median radiance <= 0 in every channel)");
  for (int c = 0; c < 3; ++c) inv_scale[c] = 1.0 / std::max(med[c], 1e-3 * top);

  // Start point.
  std::vector<std::vector<double>> params(n);
  std::array<double, 3> mean_lit{};  // mean over samples of rho * sum_i g_i
  for (const auto& s : samples) {
    double gsum = 0;
    for (double g : s.g) gsum += g;
    for (int c = 0; c < 3; ++c) mean_lit[c] += patches[s.patch].albedo[c] * gsum;
  }
  std::array<double, 3> start{};
  for (int c = 0; c < 3; ++c) start[c] = 0.5 * mean_obs[c] / (mean_lit[c] / double(samples.size()));
  for (std::size_t i = 0; i < n; ++i) {
    const std::array<double, 3> s0 =
        options.initial_intensity.empty() ? start : options.initial_intensity[i];
    for (double v : s0)
      if (!std::isfinite(v)) fail(lamp_name(i) + ": the initial intensity is NaN or infinite");
    params[i] =
        colours[i] ? std::vector<double>{luminance(s0)} : std::vector<double>(s0.begin(), s0.end());
  }
  std::vector<std::array<double, 3>> ambient(patches.size());
  for (auto& a : ambient)
    for (int c = 0; c < 3; ++c) a[c] = 0.5 * std::max(0.0, mean_obs[c]);

  auto intensity = [&](std::size_t i) {
    std::array<double, 3> out{};
    for (int c = 0; c < 3; ++c)
      out[c] = colours[i] ? params[i][0] * (*colours[i])[c] : params[i][c];
    return out;
  };

  // Three stages: squared loss; Cauchy without bounds (the contradiction check); Cauchy, >= 0.
  ceres::CauchyLoss cauchy(options.robust_scale);
  auto solve = [&](bool robust, bool bounded) {
    ceres::Problem::Options po;
    po.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    ceres::Problem problem(po);
    for (const auto& s : samples) {
      std::vector<double*> blocks;
      for (auto& p : params) blocks.push_back(p.data());
      blocks.push_back(ambient[s.patch].data());
      problem.AddResidualBlock(new ShadingCost(s, colours, patches[s.patch].albedo, inv_scale),
                               robust ? &cauchy : nullptr, blocks);
    }
    if (bounded) {
      for (auto& p : params)
        for (std::size_t j = 0; j < p.size(); ++j) {
          p[j] = std::max(0.0, p[j]);
          problem.SetParameterLowerBound(p.data(), int(j), 0.0);
        }
      for (std::size_t k = 0; k < ambient.size(); ++k) {
        if (!problem.HasParameterBlock(ambient[k].data())) continue;
        for (int c = 0; c < 3; ++c) {
          ambient[k][c] = std::max(0.0, ambient[k][c]);
          problem.SetParameterLowerBound(ambient[k].data(), c, 0.0);
        }
      }
    }
    const ceres::Solver::Options so = solver_options({.max_iterations = 200,
                                                      .function_tolerance = 1e-14,
                                                      .gradient_tolerance = 1e-14,
                                                      .parameter_tolerance = 1e-12});
    ceres::Solver::Summary summary;
    ceres::Solve(so, &problem, &summary);
    fit.iterations += int(summary.iterations.size());
    fit.converged = summary.termination_type == ceres::CONVERGENCE;
    if (!summary.IsSolutionUsable()) fail("lamp fit: Ceres failed: " + summary.message);
  };
  solve(false, false);
  solve(true, false);

  // Contradictory marks: the unconstrained fit needs light to be taken away.
  std::array<double, 3> largest{};
  for (std::size_t i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) largest[c] = std::max(largest[c], std::abs(intensity(i)[c]));
  for (std::size_t i = 0; i < n; ++i) {
    const auto I = intensity(i);
    for (int c = 0; c < 3; ++c)
      if (I[c] < -options.max_negative_fraction * largest[c])
        fail(lamp_name(i) + ": the marked patches need a negative intensity (" + num(I[c]) +
             " per sr in " + kChannel[c] +
             "): the shading contradicts a lamp there (is the "
             "lamp misplaced, a patch in shadow, or the light from somewhere else?)");
  }
  for (std::size_t k = 0; k < patches.size(); ++k)
    for (int c = 0; c < 3; ++c)
      if (ambient[k][c] < -options.max_negative_fraction * med[c])
        fail(patch_name(k) + ": needs a negative ambient term (" + num(ambient[k][c]) + " in " +
             kChannel[c] +
             "): the lamps' fall-off over it is steeper than the photo shows (is "
             "the albedo or a lamp's position wrong?)");
  solve(true, true);

  for (std::size_t i = 0; i < n; ++i) fit.intensity_per_sr.push_back(intensity(i));
  fit.ambient = ambient;
  std::vector<double> all;
  std::vector<double> patch_sq(patches.size(), 0.0);
  std::vector<std::size_t> patch_count(patches.size(), 0);
  double sq = 0;
  for (const auto& s : samples) {
    for (int c = 0; c < 3; ++c) {
      double model = ambient[s.patch][c];
      for (std::size_t i = 0; i < n; ++i)
        model += patches[s.patch].albedo[c] * s.g[i] * fit.intensity_per_sr[i][c];
      const double r = (model - s.observed[c]) * inv_scale[c];
      sq += r * r;
      patch_sq[s.patch] += r * r;
      all.push_back(std::abs(r));
    }
    patch_count[s.patch] += 3;
  }
  fit.pixels_used = samples.size();
  fit.rms_residual = std::sqrt(sq / double(all.size()));
  fit.median_abs_residual = median(std::move(all));
  for (std::size_t k = 0; k < patches.size(); ++k)
    fit.patch_rms_residual.push_back(std::sqrt(patch_sq[k] / double(patch_count[k])));
  return fit;
}

ExposureRelativeLamp exposure_relative_lamp(const Image& photo, const Image& distance_m,
                                            const Camera& camera, const CameraPose& pose,
                                            const Vec3& lamp_position_m,
                                            const std::array<float, 3>& colour) {
  if (photo.channels() < 3)
    throw Error(ErrorCode::invalid_argument, "lamp intensity 'auto': the photo must be RGB, has " +
                                                 std::to_string(photo.channels()) + " channels");
  for (const Image* im : {&photo, &distance_m})
    if (im->width() != camera.width || im->height() != camera.height)
      throw Error(ErrorCode::size_mismatch,
                  "lamp intensity 'auto': image is " + std::to_string(im->width()) + "x" +
                      std::to_string(im->height()) + ", camera is " + std::to_string(camera.width) +
                      "x" + std::to_string(camera.height));
  ExposureRelativeLamp out;
  out.bright_surface_luminance =
      exposure_relative_sun(photo.view(), distance_m.view(), {0.0f, 0.0f, 0.0f})
          .bright_surface_luminance;
  // The nearest surface point: a grid of at most about 250,000 pixels (a pixel's footprint is
  // far below the distances that matter).
  constexpr double kMinNearestM = 0.25;
  const int w = camera.width, h = camera.height;
  const int step = std::max(1, int(std::ceil(std::sqrt(double(w) * h / 250'000.0))));
  double nearest2 = INFINITY;
  for (int y = step / 2; y < h; y += step)
    for (int x = step / 2; x < w; x += step) {
      const float d = distance_m.at(x, y, 0);
      if (!std::isfinite(d) || !(d > 0)) continue;
      const Vec3 v = sub(point_at(distance_m, camera, pose, x, y), lamp_position_m);
      nearest2 = std::min(nearest2, dot(v, v));
    }
  if (std::isfinite(nearest2)) {
    out.nearest_surface_m = std::sqrt(nearest2);
  } else {
    const Vec3 v = sub(lamp_position_m, pose.position_m);
    out.nearest_surface_m = std::sqrt(dot(v, v));
  }
  out.nearest_surface_m = std::max(kMinNearestM, out.nearest_surface_m);
  const double intensity = std::numbers::pi * out.bright_surface_luminance * out.nearest_surface_m *
                           out.nearest_surface_m;
  const double lum = luminance({colour[0], colour[1], colour[2]});
  for (int c = 0; c < 3; ++c)
    out.intensity_per_sr[std::size_t(c)] =
        float(intensity *
              (lum > 0 && std::isfinite(lum) ? std::max(0.0f, colour[std::size_t(c)]) / lum : 1.0));
  return out;
}

double lamp_glow_phase_integral(double g, double alpha_rad) {
  // phi = alpha (pi / alpha)^u, u in [0, 1]: the forward peak of a strong g near phi = alpha is
  // resolved as finely as the broad rest (composite Simpson in u, 4096 intervals).
  const double alpha = std::clamp(alpha_rad, 1e-9, std::numbers::pi);
  if (alpha >= std::numbers::pi) return 0.0;
  const double log_ratio = std::log(std::numbers::pi / alpha);
  auto integrand = [&](double u) {
    const double phi = alpha * std::exp(u * log_ratio);
    return render::physics::henyey_greenstein(g, std::cos(phi)) * phi * log_ratio;
  };
  constexpr int kIntervals = 4096;
  double sum = integrand(0.0) + integrand(1.0);
  for (int i = 1; i < kIntervals; ++i)
    sum += (i % 2 ? 4.0 : 2.0) * integrand(double(i) / kIntervals);
  return sum / (3.0 * kIntervals);
}

ExposureRelativeLamp exposure_relative_lamp(const Image& photo, const Image& distance_m,
                                            const Camera& camera, const CameraPose& pose,
                                            const Vec3& lamp_position_m,
                                            const std::array<float, 3>& colour,
                                            const Medium& medium) {
  ExposureRelativeLamp out =
      exposure_relative_lamp(photo, distance_m, camera, pose, lamp_position_m, colour);
  const Vec3 to_lamp = sub(lamp_position_m, pose.position_m);
  const double lamp_distance_m = std::sqrt(dot(to_lamp, to_lamp));
  if (!(lamp_distance_m > 0) || !(out.bright_surface_luminance > 0)) return out;
  // The core's angular radius: kGlowCoreFraction of the frame's diagonal, through the focal
  // length (the angle a pixel spans at the principal point).
  const double diagonal_px = std::hypot(double(camera.width), double(camera.height));
  const double alpha_core = std::atan(kGlowCoreFraction * diagonal_px / camera.focal_px);
  // A lamp outside the frame shows no core: the frame's view ray nearest to it (on the frame's
  // border, as the angle to a point has no minimum inside the image rectangle then) bounds the
  // glow the photo can show.
  const Vec3 w = scale(to_lamp, 1.0 / lamp_distance_m);
  const auto [forward, right, up] = pose.axes();
  const double z = dot(w, forward);
  const double px = camera.cx + camera.focal_px * dot(w, right) / z - 0.5;
  const double py = camera.cy - camera.focal_px * dot(w, up) / z - 0.5;
  double alpha_frame = 0;
  if (!(z > 0 && px >= -0.5 && px <= camera.width - 0.5 && py >= -0.5 &&
        py <= camera.height - 0.5)) {
    double best_cos = -1;
    auto consider = [&](int x, int y) {
      best_cos = std::max(best_cos, dot(pose.ray_direction(camera, x, y), w));
    };
    for (int x = 0; x < camera.width; ++x) {
      consider(x, 0);
      consider(x, camera.height - 1);
    }
    for (int y = 0; y < camera.height; ++y) {
      consider(0, y);
      consider(camera.width - 1, y);
    }
    alpha_frame = std::acos(std::clamp(best_cos, -1.0, 1.0));
  }
  const double alpha = std::max(alpha_core, alpha_frame);
  const double b_m = lamp_distance_m * std::sin(alpha);
  // The largest density within b of the lamp (the core's rays pass no farther from it); the
  // smooth density depends on the height only, so a vertical line through the lamp holds it.
  double rho = 0;
  constexpr int kHeights = 33;
  for (int k = 0; k < kHeights; ++k) {
    const double dy = b_m * (2.0 * k / (kHeights - 1) - 1.0);
    rho = std::max(
        rho, render::density_at(medium, render::Vec3d{lamp_position_m.x, lamp_position_m.y + dy,
                                                      lamp_position_m.z}));
  }
  if (!(rho > 0)) return out;
  const double od_unit = render::RayDensity(medium, render::vec(pose.position_m), render::vec(w))
                             .optical_depth(0, lamp_distance_m);
  const double j = lamp_glow_phase_integral(medium.g, alpha);
  // The glow's luminance at alpha per unit luminance intensity, in the lamp's colour.
  const double lum = luminance({colour[0], colour[1], colour[2]});
  const double weights[3] = {0.2126, 0.7152, 0.0722};
  double glow_per_intensity = 0;
  for (int c = 0; c < 3; ++c) {
    const double chroma =
        lum > 0 && std::isfinite(lum) ? std::max(0.0f, colour[std::size_t(c)]) / lum : 1.0;
    const double sigma_t = medium.sigma_t_per_m[std::size_t(c)];
    const double t_cam = std::exp(-render::scaled_optical_depth(sigma_t, od_unit));
    glow_per_intensity += weights[c] * chroma * t_cam * medium.albedo[std::size_t(c)] * sigma_t;
  }
  glow_per_intensity *= rho * j / b_m;
  if (!(glow_per_intensity > 0) || !std::isfinite(glow_per_intensity)) return out;
  out.glow_bound_intensity = out.bright_surface_luminance / glow_per_intensity;
  const double intensity =
      luminance({out.intensity_per_sr[0], out.intensity_per_sr[1], out.intensity_per_sr[2]});
  if (intensity > out.glow_bound_intensity) {
    const double k = out.glow_bound_intensity / intensity;
    for (float& v : out.intensity_per_sr) v = float(v * k);
    out.glow_limited = true;
  }
  return out;
}

}  // namespace mr::photo
