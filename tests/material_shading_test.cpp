// The microfacet BRDF of mr::Material (render/surface_shading) against closed forms and
// brute-force quadrature, shading of depth-map surfaces against analytic values, and the issue 7
// acceptance test for inverse rendering (photo/material/brdf_fit): spheres and planes rendered
// with known materials under known light, the materials recovered by fit_brdf.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "mr/error.h"
#include "mr/io.h"
#include "mr/material.h"
#include "photo/material/brdf_fit.h"
#include "render/surface_shading.h"

namespace mr {
namespace {

using render::Vec3f;
constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180;

// ---- An independent double-precision BRDF, written from the formulas in mr/material.h -------

using V3 = std::array<double, 3>;
double dot3(const V3& a, const V3& b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
V3 unit(const V3& a) {
  const double n = std::sqrt(dot3(a, a));
  return {a[0] / n, a[1] / n, a[2] / n};
}
Vec3f f3(const V3& a) {
  return {float(a[0]), float(a[1]), float(a[2])};
}
V3 from_angles(double theta, double phi) {
  return {std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)};
}

// Smith G2 from Lambda (Heitz 2014, eq. 99): G2 = 1 / (1 + Lambda(l) + Lambda(v)),
// Lambda(mu) = (-1 + sqrt(1 + alpha^2 tan^2 theta)) / 2.
double reference_g2(double mu_l, double mu_v, double roughness) {
  const double alpha = roughness * roughness;
  auto lambda = [&](double mu) {
    const double tan2 = (1 - mu * mu) / (mu * mu);
    return (-1 + std::sqrt(1 + alpha * alpha * tan2)) / 2;
  };
  return 1 / (1 + lambda(mu_l) + lambda(mu_v));
}

// f_r(l, v) cos(theta_l), independent of render/.
std::array<double, 3> reference_brdf_cosine(const Material& m, const V3& n, const V3& l,
                                            const V3& v) {
  const double nl = dot3(n, l), nv = dot3(n, v);
  if (nl <= 0 || nv <= 0) return {0, 0, 0};
  const V3 h = unit({l[0] + v[0], l[1] + v[1], l[2] + v[2]});
  const double a2 = std::pow(double(m.roughness), 4), nh = dot3(n, h);
  const double d = a2 / (kPi * std::pow(nh * nh * (a2 - 1) + 1, 2));
  const double f = m.specular_albedo + (1 - m.specular_albedo) * std::pow(1 - dot3(v, h), 5);
  const double spec = d * reference_g2(nl, nv, m.roughness) * f / (4 * nl * nv);
  return {(m.diffuse_albedo[0] / kPi + spec) * nl, (m.diffuse_albedo[1] / kPi + spec) * nl,
          (m.diffuse_albedo[2] / kPi + spec) * nl};
}

// Brute-force hemisphere integral of brdf_cosine (green channel) for a viewer at n.v = mu, by the
// midpoint rule in (theta, phi) over a fine grid (the lobe is symmetric in phi: [0, pi], doubled).
double brute_force_albedo(const Material& m, double mu, int n_theta, int n_phi) {
  const V3 n{0, 0, 1};
  const V3 v{std::sqrt(1 - mu * mu), 0, mu};
  double sum = 0;
  const double dt = 0.5 * kPi / n_theta, dp = kPi / n_phi;
  for (int i = 0; i < n_theta; ++i) {
    const double theta = (i + 0.5) * dt;
    double ring = 0;
    for (int j = 0; j < n_phi; ++j) {
      const V3 l = from_angles(theta, (j + 0.5) * dp);
      ring += render::brdf_cosine(m, f3(n), f3(l), f3(v))[1];
    }
    sum += ring * std::sin(theta);
  }
  return 2 * sum * dt * dp;
}

// ---- Closed forms -----------------------------------------------------------------------------

TEST(MaterialBrdf, GgxDistributionIsNormalised) {
  // integral of D(h) (n.h) over the hemisphere = 1; midpoint rule in theta, fine enough to
  // resolve the narrowest lobe (alpha = 0.01 rad wide at roughness 0.1).
  for (const double roughness : {0.1, 0.3, 0.5, 0.8, 1.0}) {
    const int steps = 200000;
    const double dt = 0.5 * kPi / steps;
    double sum = 0;
    for (int i = 0; i < steps; ++i) {
      const double t = (i + 0.5) * dt;
      sum += render::ggx_distribution(float(std::cos(t)), float(roughness)) * std::cos(t) *
             std::sin(t);
    }
    EXPECT_NEAR(2 * kPi * sum * dt, 1.0, 1e-3) << "roughness " << roughness;
  }
  EXPECT_EQ(render::ggx_distribution(-0.2f, 0.5f), 0.0f);
}

TEST(MaterialBrdf, SmithG2MatchesLambdaForm) {
  for (const double r : {0.05, 0.3, 0.7, 1.0})
    for (const double mu_l : {0.05, 0.3, 0.8, 1.0})
      for (const double mu_v : {0.1, 0.5, 0.99})
        EXPECT_NEAR(render::smith_g2(float(mu_l), float(mu_v), float(r)),
                    reference_g2(mu_l, mu_v, r), 1e-5)
            << r << " " << mu_l << " " << mu_v;
  EXPECT_EQ(render::smith_g2(0.0f, 0.5f, 0.5f), 0.0f);
}

TEST(MaterialBrdf, SchlickAtNormalAndGrazing) {
  for (const float f0 : {0.0f, 0.04f, 0.9f}) {
    EXPECT_NEAR(render::schlick_fresnel(f0, 1.0f), f0, 1e-7);    // 0 degrees
    EXPECT_NEAR(render::schlick_fresnel(f0, 0.0f), 1.0f, 1e-7);  // 90 degrees
  }
}

TEST(MaterialBrdf, MatchesIndependentFormulaAndIsReciprocal) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0, 1);
  const Material m{{0.3f, 0.5f, 0.7f}, 0.2f, 0.35f};
  const V3 n{0, 0, 1};
  int checked = 0;
  for (int k = 0; k < 500; ++k) {
    const V3 l = from_angles(std::acos(u(rng)), 2 * kPi * u(rng));
    const V3 v = from_angles(std::acos(u(rng)), 2 * kPi * u(rng));
    if (l[2] < 0.02 || v[2] < 0.02) continue;
    const Rgb lv = render::brdf_cosine(m, f3(n), f3(l), f3(v));
    const Rgb vl = render::brdf_cosine(m, f3(n), f3(v), f3(l));
    const auto ref = reference_brdf_cosine(m, n, l, v);
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(lv[c], ref[c], 1e-4 * ref[c] + 1e-6);
      // Helmholtz: f_r(l, v) = f_r(v, l).
      EXPECT_NEAR(lv[c] / l[2], vl[c] / v[2], 1e-4 * lv[c] / l[2]);
    }
    ++checked;
  }
  EXPECT_GT(checked, 400);
  // Below either horizon: nothing.
  EXPECT_EQ(render::brdf_cosine(m, f3(n), f3(V3{0, 0.6, -0.8}), f3(V3{0, 0, 1}))[0], 0.0f);
  EXPECT_EQ(render::brdf_cosine(m, f3(n), f3(V3{0, 0, 1}), f3(V3{0, 0.6, -0.8}))[0], 0.0f);
}

TEST(MaterialBrdf, LambertWhiteFurnace) {
  // Albedo 1 under uniform unit radiance reflects 1: the diffuse part of the brute-force
  // hemisphere integral (kd = 1 minus kd = 0, F0 = 0) is 1 for every view angle.
  for (const double mu : {0.2, 0.7, 1.0}) {
    const Material white{{1, 1, 1}, 0.0f, 0.6f}, black{{0, 0, 0}, 0.0f, 0.6f};
    const double e =
        brute_force_albedo(white, mu, 400, 400) - brute_force_albedo(black, mu, 400, 400);
    EXPECT_NEAR(e, 1.0, 1e-3) << "n.v = " << mu;
  }
  // Through the shading path: an unoccluded point facing up sees the whole sky.
  render::SurfacePoint p;
  p.surface = true;
  p.normal = {0, 1, 0};
  p.view = f3(unit({0, 0.5, -1}));
  p.sky_visibility = 1;
  Lighting sky;
  sky.sky_radiance = Rgb{0.7f, 1.0f, 1.3f};
  const render::ShadingTerms t = render::shading_terms(p, sky, 0.6f);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(t.diffuse[c], (*sky.sky_radiance)[c], 1e-6);
}

// The same hemisphere integral over half vectors: l = reflect(v, h), dw_l = 4 (v.h) dw_h. The
// integrand is then peaked at h = n instead of squeezed against the horizon (at grazing view the
// reflected lobe of a glossy surface lies within a fraction of a degree above it, which no
// practical grid in l resolves). theta_h = (pi/2) s^2 with s on a uniform grid puts fine steps
// near the normal for the narrow lobes.
double brute_force_albedo_h(const Material& m, double mu, int n_s, int n_phi) {
  const V3 n{0, 0, 1};
  const V3 v{std::sqrt(1 - mu * mu), 0, mu};
  const double ds = 1.0 / n_s, dp = kPi / n_phi;
  double sum = 0;
  for (int i = 0; i < n_s; ++i) {
    const double sv = (i + 0.5) * ds, theta = 0.5 * kPi * sv * sv, dtheta = kPi * sv * ds;
    double ring = 0;
    for (int j = 0; j < n_phi; ++j) {
      const V3 h = from_angles(theta, (j + 0.5) * dp);
      const double vh = dot3(v, h);
      if (vh <= 0) continue;
      const V3 l = {2 * vh * h[0] - v[0], 2 * vh * h[1] - v[1], 2 * vh * h[2] - v[2]};
      if (l[2] <= 0) continue;
      ring += render::brdf_cosine(m, f3(n), f3(l), f3(v))[1] * 4 * vh;
    }
    sum += ring * std::sin(theta) * dtheta;
  }
  return 2 * sum * dp;
}

TEST(MaterialBrdf, DirectionalAlbedoTableMatchesBruteForce) {
  // E_spec = F0 a + b: F0 = 0 gives b, F0 = 1 gives a + b, against the half-vector quadrature
  // of brdf_cosine (1000 x 1000). Tolerance 0.01 absolute (1 % of the largest albedo): the
  // table's bilinear interpolation and its 1024-point quasi-Monte Carlo integration.
  double worst = 0;
  for (const double r : {0.05, 0.15, 0.3, 0.5, 0.8, 1.0})
    for (const double mu : {0.01, 0.05, 0.2, 0.5, 0.8, 1.0}) {
      const Material f0_zero{{0, 0, 0}, 0.0f, float(r)}, f0_one{{0, 0, 0}, 1.0f, float(r)};
      const double b = brute_force_albedo_h(f0_zero, mu, 1000, 1000);
      const double ab = brute_force_albedo_h(f0_one, mu, 1000, 1000);
      const render::SpecularAlbedo s = render::ggx_directional_albedo(float(mu), float(r));
      EXPECT_NEAR(s.bias, b, 0.01) << "roughness " << r << ", n.v " << mu;
      EXPECT_NEAR(s.scale + s.bias, ab, 0.01) << "roughness " << r << ", n.v " << mu;
      worst = std::max({worst, std::abs(s.bias - b), std::abs(s.scale + s.bias - ab)});
    }
  std::printf("directional albedo table vs brute force: largest |error| %.5f\n", worst);
  // The light-space quadrature agrees where it resolves the lobe (rough, away from grazing).
  for (const double mu : {0.3, 0.7, 1.0}) {
    const Material m{{0, 0, 0}, 1.0f, 0.6f};
    EXPECT_NEAR(brute_force_albedo(m, mu, 600, 600), brute_force_albedo_h(m, mu, 1000, 1000), 2e-3);
  }
}

TEST(MaterialBrdf, SpecularEnergyNeverExceedsOne) {
  // A white specular lobe (F0 = 1) reflects at most what it receives: a + b <= 1 (GGX with
  // single scattering loses energy at high roughness, never gains), and a, b >= 0. The
  // quadrature's own error is ~1e-3.
  for (int j = 0; j <= 49; ++j)
    for (int i = 0; i <= 100; ++i) {
      const float r = 0.02f + 0.98f * float(j) / 49, mu = float(i) / 100;
      const render::SpecularAlbedo s = render::ggx_directional_albedo(mu, r);
      ASSERT_GE(s.scale, 0) << r << " " << mu;
      ASSERT_GE(s.bias, 0) << r << " " << mu;
      ASSERT_LE(s.scale + s.bias, 1.0 + 2e-3) << r << " " << mu;
    }
  // And the directly integrated BRDF, at a roughness the grid resolves.
  for (const double mu : {0.1, 0.5, 1.0})
    EXPECT_LE(brute_force_albedo(Material{{0, 0, 0}, 1.0f, 0.4f}, mu, 600, 600), 1.0 + 1e-3);
}

TEST(MaterialBrdf, ValidateMaterialRanges) {
  EXPECT_NO_THROW(validate_material(Material{}));
  EXPECT_NO_THROW(validate_material(Material{{0, 1, 0.5f}, 1.0f, 0.02f}));
  auto code = [](const Material& m) {
    try {
      validate_material(m, "sample");
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("sample."), std::string::npos) << e.what();
      return e.code();
    }
    return ErrorCode::internal;
  };
  EXPECT_EQ(code(Material{{1.1f, 0.5f, 0.5f}, 0.04f, 0.5f}), ErrorCode::invalid_argument);
  EXPECT_EQ(code(Material{{0.5f, -0.1f, 0.5f}, 0.04f, 0.5f}), ErrorCode::invalid_argument);
  EXPECT_EQ(code(Material{{0.5f, 0.5f, NAN}, 0.04f, 0.5f}), ErrorCode::invalid_argument);
  EXPECT_EQ(code(Material{{0.5f, 0.5f, 0.5f}, 1.5f, 0.5f}), ErrorCode::invalid_argument);
  EXPECT_EQ(code(Material{{0.5f, 0.5f, 0.5f}, 0.04f, 0.01f}), ErrorCode::invalid_argument);
  EXPECT_EQ(code(Material{{0.5f, 0.5f, 0.5f}, 0.04f, INFINITY}), ErrorCode::invalid_argument);
  try {
    validate_material(Material{{0.5f, 0.5f, 0.5f}, 0.04f, 1.2f}, "m");
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("m.roughness = 1.2"), std::string::npos) << e.what();
  }
}

// ---- Synthetic scenes: analytic distance maps ------------------------------------------------

struct Sphere {
  V3 centre;
  double radius;
  int label;
};

struct SyntheticScene {
  Camera camera;
  CameraPose pose;
  Image distance_m;
  Image labels;  // 0: none, else the object's label
};

V3 to_v3(const Vec3& v) {
  return {v.x, v.y, v.z};
}

// A camera at (0, 1.6, 0); objects: spheres, an optional ground plane y = 0 (label
// `ground_label`, 0 = no ground) and an optional vertical rectangle z = wall_z.
struct SceneSpec {
  int width = 400, height = 240;
  double fov_deg = 60, pitch_deg = -10;
  std::vector<Sphere> spheres;
  int ground_label = 0;
  bool wall = false;
  double wall_z = 6, wall_half_width = 1, wall_height = 2;
  int wall_label = 0;
};

SyntheticScene make_scene(const SceneSpec& spec) {
  SyntheticScene s;
  s.camera = Camera::from_horizontal_fov(spec.width, spec.height, spec.fov_deg);
  s.pose.position_m = {0, 1.6, 0};
  s.pose.pitch_deg = spec.pitch_deg;
  s.distance_m = Image(spec.width, spec.height, 1);
  s.labels = Image(spec.width, spec.height, 1);
  const V3 o = to_v3(s.pose.position_m);
  for (int y = 0; y < spec.height; ++y)
    for (int x = 0; x < spec.width; ++x) {
      const V3 d = to_v3(s.pose.ray_direction(s.camera, x, y));
      double best = INFINITY;
      int label = 0;
      for (const Sphere& sp : spec.spheres) {
        const V3 oc = {sp.centre[0] - o[0], sp.centre[1] - o[1], sp.centre[2] - o[2]};
        const double b = dot3(d, oc), c = dot3(oc, oc) - sp.radius * sp.radius;
        const double disc = b * b - c;
        if (disc <= 0) continue;
        const double t = b - std::sqrt(disc);
        if (t > 0 && t < best) best = t, label = sp.label;
      }
      if (spec.ground_label && d[1] < 0) {
        const double t = -o[1] / d[1];
        if (t < best) best = t, label = spec.ground_label;
      }
      if (spec.wall && d[2] > 0) {
        const double t = (spec.wall_z - o[2]) / d[2];
        const double px = o[0] + t * d[0], py = o[1] + t * d[1];
        if (t < best && std::abs(px) <= spec.wall_half_width && py >= 0 && py <= spec.wall_height)
          best = t, label = spec.wall_label;
      }
      s.distance_m.at(x, y, 0) = float(best);
      s.labels.at(x, y, 0) = float(label);
    }
  return s;
}

Sun make_sun(double azimuth_deg, double elevation_deg, Rgb irradiance, double radius_deg = 0.27) {
  Sun sun;
  sun.direction_to_sun = direction_from_azimuth_elevation(azimuth_deg, elevation_deg);
  sun.irradiance = irradiance;
  sun.angular_radius_deg = radius_deg;
  return sun;
}

std::vector<std::int32_t> pixels_with_label(const Image& labels, int label) {
  std::vector<std::int32_t> out;
  for (int y = 0; y < labels.height(); ++y)
    for (int x = 0; x < labels.width(); ++x)
      if (labels.at(x, y, 0) == float(label)) out.push_back(y * labels.width() + x);
  return out;
}

// ---- Shading against analytic values ----------------------------------------------------------

TEST(MaterialShading, SunlitSphereAndPlaneMatchAnalyticShading) {
  SceneSpec spec;
  spec.spheres = {{{0.0, 1.2, 5.0}, 0.8, 1}};
  spec.ground_label = 2;
  const SyntheticScene s = make_scene(spec);
  Lighting light;
  light.sun = make_sun(150, 40, {3.0f, 2.8f, 2.5f}, 0);
  const render::SurfaceGeometry g =
      render::surface_geometry_from_depth(s.distance_m, s.camera, s.pose, light);
  const Material m{{0.6f, 0.4f, 0.3f}, 0.06f, 0.45f};
  const V3 sun = unit(to_v3(light.sun->direction_to_sun));
  const V3 centre = spec.spheres[0].centre;
  const V3 eye = to_v3(s.pose.position_m);
  // Two error sources, checked apart: (1) the shading given the pixel's normal, against the
  // independent double-precision BRDF, to float precision (1e-4 relative); (2) the normals the
  // distance map gives, against the analytic ones: within 0.5 degrees on the sphere (a sixth of
  // the ~3 degrees its surface turns between neighbouring pixels at n.v = 0.3; the estimate
  // differences neighbours) and 0.01 on the plane (exact up to float rounding).
  int sphere_checked = 0, ground_checked = 0;
  double worst_shading = 0, worst_normal_deg[3] = {0, 0, 0};
  for (int y = 0; y < spec.height; ++y)
    for (int x = 0; x < spec.width; ++x) {
      const int label = int(s.labels.at(x, y, 0));
      if (label == 0) continue;
      const V3 d = to_v3(s.pose.ray_direction(s.camera, x, y));
      const double t = s.distance_m.at(x, y, 0);
      const V3 p = {eye[0] + t * d[0], eye[1] + t * d[1], eye[2] + t * d[2]};
      const V3 n =
          label == 1 ? unit({p[0] - centre[0], p[1] - centre[1], p[2] - centre[2]}) : V3{0, 1, 0};
      const V3 v = {-d[0], -d[1], -d[2]};
      // Away from the sphere's silhouette (one-sided normals there) and terminator, and the
      // ground away from the sphere and its shadow.
      if (dot3(n, sun) < 0.15) continue;
      if (label == 1 && dot3(n, v) < 0.3) continue;
      if (label == 2) {
        // The sun's ray from the point passes the sphere at `miss` metres from its centre.
        const V3 pc = {centre[0] - p[0], centre[1] - p[1], centre[2] - p[2]};
        const double along = dot3(pc, sun), miss = std::sqrt(dot3(pc, pc) - along * along);
        if ((along > 0 && miss < spec.spheres[0].radius + 0.1) || std::abs(p[0]) < 1.0 || p[2] > 12)
          continue;
      }
      const V3 ng = {g.normal.at(x, y, 0), g.normal.at(x, y, 1), g.normal.at(x, y, 2)};
      const double angle = std::acos(std::min(1.0, dot3(n, ng))) / kDeg;
      worst_normal_deg[label] = std::max(worst_normal_deg[label], angle);
      EXPECT_LT(angle, label == 1 ? 0.5 : 0.01) << "pixel " << x << "," << y;
      const Rgb got = render::shade_pixel(m, g, light, x, y);
      const auto brdf = reference_brdf_cosine(m, unit(ng), sun, v);
      for (int c = 0; c < 3; ++c) {
        const double want = light.sun->irradiance[c] * brdf[c];
        EXPECT_NEAR(got[c], want, 1e-4 * want) << "pixel " << x << "," << y << " label " << label;
        worst_shading = std::max(worst_shading, std::abs(got[c] - want) / want);
      }
      ASSERT_EQ(g.sun_visibility.at(x, y, 0), 1.0f) << x << "," << y;
      (label == 1 ? sphere_checked : ground_checked)++;
    }
  EXPECT_GT(sphere_checked, 1000);
  EXPECT_GT(ground_checked, 1000);
  std::printf(
      "sunlit sphere/plane: %d + %d pixels, shading vs reference largest relative error %.2e; "
      "normals vs analytic largest %.4f deg (sphere), %.4f deg (plane)\n",
      sphere_checked, ground_checked, worst_shading, worst_normal_deg[1], worst_normal_deg[2]);
}

TEST(MaterialShading, SkyVisibilityOfAConvexSphereIsTheClosedForm) {
  // Nothing blocks the upper hemisphere of a point on a lone convex sphere's tangent plane, so
  // the traced occlusion must leave (1 + n.y) / 2 (within 0.02: estimated normals, and rays
  // grazing the faceted mesh next to the point).
  SceneSpec spec;
  spec.spheres = {{{0.0, 1.6, 4.0}, 1.0, 1}};
  const SyntheticScene s = make_scene(spec);
  Lighting light;
  light.sky_radiance = Rgb{1, 1, 1};
  const render::SurfaceGeometry g =
      render::surface_geometry_from_depth(s.distance_m, s.camera, s.pose, light);
  const V3 eye = to_v3(s.pose.position_m), centre = spec.spheres[0].centre;
  int checked = 0;
  for (int y = 0; y < spec.height; ++y)
    for (int x = 0; x < spec.width; ++x) {
      if (s.labels.at(x, y, 0) != 1) continue;
      const V3 d = to_v3(s.pose.ray_direction(s.camera, x, y));
      const double t = s.distance_m.at(x, y, 0);
      const V3 n = unit({eye[0] + t * d[0] - centre[0], eye[1] + t * d[1] - centre[1],
                         eye[2] + t * d[2] - centre[2]});
      if (-dot3(n, d) < 0.3) continue;
      EXPECT_NEAR(g.sky_visibility.at(x, y, 0), 0.5 * (1 + n[1]), 0.02) << x << "," << y;
      ++checked;
    }
  EXPECT_GT(checked, 3000);
}

// A 2 m x 2 m wall at z = 6 standing on the ground; the sun in front of the camera to the
// right (azimuth 45, elevation 30) throws the wall's shadow toward the camera's left. The ground's
// sun visibility is checked against the shadow's outline (exact 0 or 1 at least 0.1 m from it
// and, with `edge_px`, that many pixels from any pixel lit otherwise or not checked) and its sky
// visibility against a quadrature of the wall's form factor, with the visibility traced on at
// most `traced_pixels` pixels (SurfaceGeometryOptions::traced_pixel_budget).
void check_wall_shadow(std::size_t traced_pixels, int edge_px) {
  SceneSpec spec;
  spec.ground_label = 1;
  spec.wall = true;
  spec.wall_label = 2;
  const SyntheticScene s = make_scene(spec);
  Lighting light;
  light.sun = make_sun(45, 30, {3.0f, 3.0f, 3.0f}, 0);
  light.sky_radiance = Rgb{0.3f, 0.35f, 0.45f};
  Lighting sky_only = light;
  sky_only.sun.reset();
  render::SurfaceGeometryOptions options;
  options.traced_pixel_budget = traced_pixels;
  const render::SurfaceGeometry g =
      render::surface_geometry_from_depth(s.distance_m, s.camera, s.pose, light, options);
  const Material m{{0.5f, 0.5f, 0.5f}, 0.04f, 0.5f};
  const V3 sun = unit(to_v3(light.sun->direction_to_sun)), eye = to_v3(s.pose.position_m);
  // Per pixel: 1 in the wall's shadow, 0 lit, -1 not checked.
  std::vector<int> state(std::size_t(spec.width) * spec.height, -1);
  for (int y = 0; y < spec.height; ++y)
    for (int x = 0; x < spec.width; ++x) {
      if (s.labels.at(x, y, 0) != 1) continue;
      const V3 d = to_v3(s.pose.ray_direction(s.camera, x, y));
      const double t = s.distance_m.at(x, y, 0);
      const V3 p = {eye[0] + t * d[0], 0.0, eye[2] + t * d[2]};
      // Where the ray to the sun crosses the wall's plane, in wall coordinates.
      bool in_shadow = false;
      double margin = INFINITY;
      if (p[2] < spec.wall_z) {
        const double k = (spec.wall_z - p[2]) / sun[2];
        const double wx = p[0] + k * sun[0], wy = k * sun[1];
        in_shadow = std::abs(wx) < spec.wall_half_width && wy < spec.wall_height;
        margin = std::min(
            {std::abs(std::abs(wx) - spec.wall_half_width), std::abs(wy - spec.wall_height)});
      }
      // Skip shadow edges, and the ground at and behind the wall's foot, where the mesh joins
      // the wall to the ground beside it (their distances are continuous there).
      if (margin < 0.1 || p[2] > spec.wall_z - 0.2) continue;
      state[std::size_t(y) * spec.width + x] = in_shadow ? 1 : 0;
    }
  int shadowed = 0, lit = 0;
  double sky_traced = 0, sky_expected = 0;
  int sky_checked = 0;
  for (int y = 0; y < spec.height; ++y)
    for (int x = 0; x < spec.width; ++x) {
      const int here = state[std::size_t(y) * spec.width + x];
      if (here < 0) continue;
      bool near_other = false;
      for (int dy = -edge_px; dy <= edge_px && !near_other; ++dy)
        for (int dx = -edge_px; dx <= edge_px; ++dx) {
          const int nx = x + dx, ny = y + dy;
          if (nx >= 0 && ny >= 0 && nx < spec.width && ny < spec.height &&
              state[std::size_t(ny) * spec.width + nx] != here)
            near_other = true;
        }
      if (near_other) continue;
      const V3 d = to_v3(s.pose.ray_direction(s.camera, x, y));
      const double t = s.distance_m.at(x, y, 0);
      const V3 p = {eye[0] + t * d[0], 0.0, eye[2] + t * d[2]};
      const bool in_shadow = here == 1;
      if (in_shadow) {
        EXPECT_EQ(g.sun_visibility.at(x, y, 0), 0.0f) << x << "," << y;
        const Rgb got = render::shade_pixel(m, g, light, x, y);
        const Rgb sky = render::shade_pixel(m, g, sky_only, x, y);
        for (int c = 0; c < 3; ++c) EXPECT_EQ(got[c], sky[c]);
        // The wall hides part of the sky from the shadowed ground in front of it: 1 - the form
        // factor of the wall, by brute-force quadrature over the hemisphere (every 16th pixel).
        if (shadowed++ % 16 != 0) continue;
        double form_factor = 0;
        const int nt = 200, np = 400;
        for (int i = 0; i < nt; ++i) {
          const double th = (i + 0.5) * 0.5 * kPi / nt;
          for (int j = 0; j < np; ++j) {
            const double ph = (j + 0.5) * 2 * kPi / np;
            const V3 dir = {std::sin(th) * std::cos(ph), std::cos(th), std::sin(th) * std::sin(ph)};
            if (dir[2] <= 0) continue;
            const double k = (spec.wall_z - p[2]) / dir[2];
            if (std::abs(p[0] + k * dir[0]) <= spec.wall_half_width &&
                k * dir[1] <= spec.wall_height)
              form_factor += std::cos(th) * std::sin(th);
          }
        }
        form_factor *= (0.5 * kPi / nt) * (2 * kPi / np) / kPi;
        sky_traced += g.sky_visibility.at(x, y, 0);
        sky_expected += 1 - form_factor;
        ++sky_checked;
      } else {
        ASSERT_EQ(g.sun_visibility.at(x, y, 0), 1.0f) << x << "," << y;
        ++lit;
      }
    }
  EXPECT_GT(shadowed, 200);
  // The traced sky visibility (16 stratified rays per pixel) averaged over the shadowed pixels,
  // against the quadrature: within 0.02 (the per-pixel estimates scatter by ~0.1).
  EXPECT_NEAR(sky_traced / sky_checked, sky_expected / sky_checked, 0.02);
  std::printf("shadowed ground: mean sky visibility over %d pixels traced %.4f, quadrature %.4f\n",
              sky_checked, sky_traced / sky_checked, sky_expected / sky_checked);
  EXPECT_GT(lit, 2000);
  std::printf("wall shadow: %d shadowed and %d lit ground pixels checked\n", shadowed, lit);
}

TEST(MaterialShading, OccluderCastsSunShadowAndShadowedPixelsGetOnlySky) {
  check_wall_shadow(0, 0);
}

// The same scene traced 3 x coarser (400 x 240 pixels, a budget of a ninth of them): two coarse
// pixels away from the shadow's outline (the reach of a pixel's bilinear neighbours, and the
// coarse surface's own outline, up to a coarse pixel off) the sun visibility is the same 0 or 1,
// and the sky's the quadrature's.
TEST(MaterialShading, CoarseTraceKeepsShadowsAndSkyAwayFromShadowEdges) {
  constexpr std::size_t kBudget = 400 * 240 / 9 + 1;
  ASSERT_EQ(render::traced_visibility_factor(400, 240, kBudget), 3);
  check_wall_shadow(kBudget, 2 * 3);
}

TEST(MaterialShading, CoarseTraceFactor) {
  EXPECT_EQ(render::traced_visibility_factor(4000, 2675, 2000000), 3);  // 10.7 MP
  EXPECT_EQ(render::traced_visibility_factor(1280, 960, 2000000), 1);
  EXPECT_EQ(render::traced_visibility_factor(2000, 1000, 2000000), 1);  // at the budget
  EXPECT_EQ(render::traced_visibility_factor(2001, 1000, 2000000), 2);
  EXPECT_EQ(render::traced_visibility_factor(4000, 2675, 0), 1);  // no budget
  EXPECT_EQ(render::traced_visibility_factor(2, 5000000, 2000000),
            2);  // a strip: not below a pixel
  EXPECT_EQ(render::traced_visibility_factor(1, 5000000, 2000000), 1);
}

// Per pixel, the coarse trace changes only the occluders' share: the surface, normals, view and
// positions are the full trace's bit for bit, the tangent plane's cut-off per pixel (a pixel
// facing away from the sun has none), and each surface's mean visibility the full trace's.
TEST(MaterialShading, CoarseTraceChangesOnlyTheOccludersShare) {
  SceneSpec spec;
  spec.ground_label = 1;
  spec.wall = true;
  spec.wall_label = 2;
  spec.spheres = {{{-1.2, 0.5, 4.5}, 0.5, 3}};
  const SyntheticScene s = make_scene(spec);
  Lighting light;
  light.sun = make_sun(45, 30, {3.0f, 3.0f, 3.0f});
  light.sky_radiance = Rgb{0.3f, 0.35f, 0.45f};
  render::SurfaceGeometryOptions options;
  const render::SurfaceGeometry full =
      render::surface_geometry_from_depth(s.distance_m, s.camera, s.pose, light, options);
  options.traced_pixel_budget = 400 * 240 / 9 + 1;
  const render::SurfaceGeometry coarse =
      render::surface_geometry_from_depth(s.distance_m, s.camera, s.pose, light, options);
  auto same = [](const Image& a, const Image& b) {
    return std::equal(a.pixels().begin(), a.pixels().end(), b.pixels().begin(), b.pixels().end());
  };
  EXPECT_TRUE(same(full.surface, coarse.surface));
  EXPECT_TRUE(same(full.normal, coarse.normal));
  EXPECT_TRUE(same(full.distance_m, coarse.distance_m));
  const V3 sun = unit(to_v3(light.sun->direction_to_sun));
  for (int label = 1; label <= 3; ++label) {
    double sun_full = 0, sun_coarse = 0, sky_full = 0, sky_coarse = 0, sun_differs = 0;
    int n = 0, n_sun = 0;
    for (int y = 0; y < spec.height; ++y)
      for (int x = 0; x < spec.width; ++x) {
        if (s.labels.at(x, y, 0) != float(label) || !(full.surface.at(x, y, 0) > 0)) continue;
        const V3 normal = {full.normal.at(x, y, 0), full.normal.at(x, y, 1),
                           full.normal.at(x, y, 2)};
        if (dot3(normal, sun) <= -0.01) {
          EXPECT_EQ(coarse.sun_visibility.at(x, y, 0), 0.0f);
        }
        sky_full += full.sky_visibility.at(x, y, 0);
        sky_coarse += coarse.sky_visibility.at(x, y, 0);
        ++n;
        // (Grazing the sun, the full trace's rays clip the pixel's neighbouring triangles: the
        // sphere's terminator is darker traced per pixel than from coarser pixels facing it.)
        if (std::abs(dot3(normal, sun)) < 0.1) continue;
        sun_full += full.sun_visibility.at(x, y, 0);
        sun_coarse += coarse.sun_visibility.at(x, y, 0);
        sun_differs +=
            std::abs(full.sun_visibility.at(x, y, 0) - coarse.sun_visibility.at(x, y, 0));
        ++n_sun;
      }
    ASSERT_GT(n_sun, 1000) << "label " << label;
    std::printf(
        "label %d, %d px (%d off the terminator): mean sun visibility full %.4f coarse "
        "%.4f (mean |difference| %.4f), sky full %.4f coarse %.4f\n",
        label, n, n_sun, sun_full / n_sun, sun_coarse / n_sun, sun_differs / n_sun, sky_full / n,
        sky_coarse / n);
    EXPECT_NEAR(sun_coarse / n_sun, sun_full / n_sun, 0.01) << "label " << label;
    EXPECT_NEAR(sky_coarse / n, sky_full / n, 0.01) << "label " << label;
    // Only the outlines of the shadows differ.
    EXPECT_LT(sun_differs / n_sun, 0.03) << "label " << label;
  }
}

TEST(MaterialShading, ShadeRegionsChecksItsInputs) {
  SceneSpec spec;
  spec.width = 64;
  spec.height = 48;
  spec.ground_label = 1;
  const SyntheticScene s = make_scene(spec);
  Lighting light;
  light.sky_radiance = Rgb{1, 1, 1};
  const render::SurfaceGeometry g =
      render::surface_geometry_from_depth(s.distance_m, s.camera, s.pose, light);
  const std::vector<Material> ok{Material{}};
  Image out(64, 48, 3), small(32, 48, 3), labels_small(32, 48, 1);
  EXPECT_NO_THROW(render::shade_regions(g, light, s.labels, ok, out));
  EXPECT_GT(out.at(10, 40, 1), 0.0f);
  EXPECT_EQ(out.at(10, 2, 1), 0.0f);  // sky pixels are left as they were
  try {
    render::shade_regions(g, light, labels_small, ok, out);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::size_mismatch);
  }
  EXPECT_THROW(render::shade_regions(g, light, s.labels, ok, small), Error);
  const std::vector<Material> bad{Material{{0.5f, 0.5f, 0.5f}, 0.04f, 0.0f}};
  EXPECT_THROW(render::shade_regions(g, light, s.labels, bad, out), Error);
  // A distance map of the wrong size.
  const Camera other = Camera::from_horizontal_fov(32, 48, 60);
  try {
    render::surface_geometry_from_depth(s.distance_m, other, s.pose, light);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::size_mismatch);
  }
}

// ---- Acceptance: inverse rendering of synthetic spheres and planes ---------------------------

struct NamedMaterial {
  const char* name;
  Material material;
};
const std::vector<NamedMaterial> kMaterials = {
    {"matte", {{0.65f, 0.45f, 0.30f}, 0.04f, 0.85f}},
    {"glossy plastic", {{0.10f, 0.25f, 0.60f}, 0.08f, 0.25f}},
    {"rough metal", {{0.05f, 0.04f, 0.03f}, 0.85f, 0.50f}},
};
const Material kGround{{0.35f, 0.33f, 0.30f}, 0.04f, 0.6f};

// Adds multiplicative Gaussian noise of `relative` standard deviation per pixel and channel.
void add_noise(Image& image, double relative, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g(0, relative);
  for (float& v : image.pixels()) v = float(v * (1 + g(rng)));
}

struct Recovery {
  double diffuse = 0, specular = 0, roughness = 0;
};

Recovery check_recovery(const std::string& what, const Material& truth, const photo::BrdfFit& fit,
                        double seconds) {
  Recovery e;
  for (int c = 0; c < 3; ++c)
    e.diffuse = std::max(
        e.diffuse, double(std::abs(fit.material.diffuse_albedo[c] - truth.diffuse_albedo[c])));
  e.specular = std::abs(fit.material.specular_albedo - truth.specular_albedo);
  e.roughness = std::abs(fit.material.roughness - truth.roughness);
  std::printf(
      "%-42s true kd (%.3f %.3f %.3f) F0 %.3f r %.3f | fit kd (%.4f %.4f %.4f) F0 %.4f r %.4f | "
      "rel.rms %.4f, %d px, %d it, %.2f s\n",
      what.c_str(), truth.diffuse_albedo[0], truth.diffuse_albedo[1], truth.diffuse_albedo[2],
      truth.specular_albedo, truth.roughness, fit.material.diffuse_albedo[0],
      fit.material.diffuse_albedo[1], fit.material.diffuse_albedo[2], fit.material.specular_albedo,
      fit.material.roughness, fit.relative_rms, fit.pixels_used, fit.iterations, seconds);
  // The issue 7 acceptance bounds.
  EXPECT_LE(e.diffuse, 0.03) << what;
  EXPECT_LE(e.specular, 0.05) << what;
  EXPECT_LE(e.roughness, 0.1) << what;
  return e;
}

photo::BrdfFit timed_fit(const Image& radiance, const render::SurfaceGeometry& g,
                         const Lighting& light, const std::vector<std::int32_t>& pixels,
                         double& seconds) {
  const auto t0 = std::chrono::steady_clock::now();
  photo::BrdfFit fit = photo::fit_brdf(radiance, g, light, pixels);
  seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return fit;
}

// Three spheres (one per material) above a ground plane, all rendered with shade_regions.
// `geometry` is what the fit sees: from the distance map. With `analytic_normals` the image is
// rendered with the exact normals of the spheres and the ground instead of the estimated ones,
// so the fit works against a model that differs from the image's (by the ~0.1-0.3 degree
// errors of normals estimated from depth), as it would on a real photo.
struct SphereSet {
  SyntheticScene scene;
  render::SurfaceGeometry geometry;
  Image image;
};

SphereSet render_sphere_set(const Lighting& light, bool analytic_normals) {
  SceneSpec spec;
  spec.width = 480;
  spec.height = 270;
  spec.spheres = {
      {{-1.45, 0.9, 5.0}, 0.65, 1}, {{0.0, 0.9, 5.0}, 0.65, 2}, {{1.45, 0.9, 5.0}, 0.65, 3}};
  spec.ground_label = 4;
  SphereSet set;
  set.scene = make_scene(spec);
  set.geometry = render::surface_geometry_from_depth(set.scene.distance_m, set.scene.camera,
                                                     set.scene.pose, light);
  render::SurfaceGeometry rendered = set.geometry;
  if (analytic_normals) {
    for (int y = 0; y < spec.height; ++y)
      for (int x = 0; x < spec.width; ++x) {
        const int label = int(set.scene.labels.at(x, y, 0));
        if (label == 0) continue;
        V3 n{0, 1, 0};
        if (label <= 3) {
          const V3& c = spec.spheres[std::size_t(label) - 1].centre;
          const Vec3f p = render::surface_point(rendered, x, y).position_m;
          n = unit({p[0] - c[0], p[1] - c[1], p[2] - c[2]});
        }
        for (int k = 0; k < 3; ++k) rendered.normal.at(x, y, k) = float(n[k]);
      }
  }
  std::vector<Material> materials;
  for (const auto& m : kMaterials) materials.push_back(m.material);
  materials.push_back(kGround);
  set.image = Image(spec.width, spec.height, 3);
  render::shade_regions(rendered, light, set.scene.labels, materials, set.image);
  return set;
}

void write_png_if_asked(const Image& image, const std::string& name) {
  const char* dir = std::getenv("MR_MATERIAL_PNG_DIR");
  if (!dir) return;
  std::filesystem::create_directories(dir);
  write_image(std::filesystem::path(dir) / name, image);
}

void fit_sphere_set(const std::string& lighting_name, const Lighting& light, bool with_noise,
                    bool analytic_normals = false) {
  SphereSet set = render_sphere_set(light, analytic_normals);
  if (with_noise) add_noise(set.image, 0.01, 42);
  const std::string variant =
      std::string(analytic_normals ? ", exact normals" : "") + (with_noise ? ", 1% noise" : "");
  std::string file = "spheres_" + lighting_name + (analytic_normals ? "_exact_normals" : "") +
                     (with_noise ? "_noise" : "") + ".png";
  std::replace(file.begin(), file.end(), '+', '_');
  write_png_if_asked(set.image, file);
  for (std::size_t k = 0; k < kMaterials.size(); ++k) {
    const auto pixels = pixels_with_label(set.scene.labels, int(k) + 1);
    ASSERT_GT(pixels.size(), 4000u);
    double seconds = 0;
    const photo::BrdfFit fit = timed_fit(set.image, set.geometry, light, pixels, seconds);
    check_recovery("sphere, " + lighting_name + variant + ", " + kMaterials[k].name,
                   kMaterials[k].material, fit, seconds);
    if (!with_noise && !analytic_normals) {
      EXPECT_LT(fit.relative_rms, 1e-3);
    }
  }
}

Lighting sun_and_sky() {
  Lighting light;
  light.sun = make_sun(150, 35, {3.0f, 2.85f, 2.6f});
  light.sky_radiance = Rgb{0.25f, 0.3f, 0.4f};
  return light;
}

Lighting lamp_and_sky() {
  Lighting light;
  Lamp lamp;
  lamp.position_m = {0.8, 2.6, 3.2};
  lamp.intensity_per_sr = {40, 37, 32};
  light.lamps.push_back(lamp);
  light.sky_radiance = Rgb{0.05f, 0.05f, 0.06f};
  return light;
}

TEST(MaterialInverseRendering, SpheresUnderSunAndSky) {
  fit_sphere_set("sun+sky", sun_and_sky(), false);
}
TEST(MaterialInverseRendering, SpheresUnderSunAndSkyWithNoise) {
  fit_sphere_set("sun+sky", sun_and_sky(), true);
}
TEST(MaterialInverseRendering, SpheresUnderSunAndSkyRenderedWithExactNormals) {
  fit_sphere_set("sun+sky", sun_and_sky(), true, true);
}
TEST(MaterialInverseRendering, SpheresUnderLampAndSky) {
  fit_sphere_set("lamp+sky", lamp_and_sky(), false);
}
TEST(MaterialInverseRendering, SpheresUnderLampAndSkyWithNoise) {
  fit_sphere_set("lamp+sky", lamp_and_sky(), true);
}

// A ground plane seen with the sun ahead (its glare in view), one material per image.
void fit_planes(bool with_noise) {
  SceneSpec spec;
  spec.width = 400;
  spec.height = 240;
  spec.pitch_deg = -25;
  spec.ground_label = 1;
  const SyntheticScene s = make_scene(spec);
  Lighting light;
  light.sun = make_sun(10, 25, {3.0f, 2.85f, 2.6f});
  light.sky_radiance = Rgb{0.25f, 0.3f, 0.4f};
  const render::SurfaceGeometry g =
      render::surface_geometry_from_depth(s.distance_m, s.camera, s.pose, light);
  const auto pixels = pixels_with_label(s.labels, 1);
  for (const auto& m : kMaterials) {
    Image image(spec.width, spec.height, 3);
    const std::vector<Material> one{m.material};
    render::shade_regions(g, light, s.labels, one, image);
    if (with_noise) add_noise(image, 0.01, 7);
    std::string file = std::string("plane_") + m.name + (with_noise ? "_noise" : "") + ".png";
    std::replace(file.begin(), file.end(), ' ', '_');
    write_png_if_asked(image, file);
    double seconds = 0;
    const photo::BrdfFit fit = timed_fit(image, g, light, pixels, seconds);
    check_recovery(std::string("plane, sun+sky") + (with_noise ? ", 1% noise, " : ", ") + m.name,
                   m.material, fit, seconds);
  }
}

TEST(MaterialInverseRendering, PlanesUnderSunAndSky) {
  fit_planes(false);
}
TEST(MaterialInverseRendering, PlanesUnderSunAndSkyWithNoise) {
  fit_planes(true);
}

// The ambiguity the dielectric prior is for: a flat ground under a uniform overcast sky only.
// Every pixel sees the same light from nearly the same angle, so a rough specular lobe and a
// brighter diffuse albedo explain the image about equally well; the prior picks the dielectric.
TEST(MaterialInverseRendering, DielectricPriorResolvesDiffuseSpecularAmbiguity) {
  SceneSpec spec;
  spec.width = 200;
  spec.height = 120;
  spec.pitch_deg = -25;
  spec.ground_label = 1;
  const SyntheticScene s = make_scene(spec);
  Lighting light;
  light.sky_radiance = Rgb{0.8f, 0.8f, 0.85f};
  const render::SurfaceGeometry g =
      render::surface_geometry_from_depth(s.distance_m, s.camera, s.pose, light);
  const auto pixels = pixels_with_label(s.labels, 1);
  const Material truth{{0.55f, 0.45f, 0.35f}, 0.04f, 0.9f};
  Image image(spec.width, spec.height, 3);
  render::shade_regions(g, light, s.labels, std::vector<Material>{truth}, image);
  add_noise(image, 0.01, 11);
  const photo::BrdfFit with_prior = photo::fit_brdf(image, g, light, pixels);
  photo::BrdfFitOptions no_prior;
  no_prior.dielectric_prior_weight = 0;
  const photo::BrdfFit without = photo::fit_brdf(image, g, light, pixels, no_prior);
  std::printf("  overcast plane without the prior: kd (%.4f %.4f %.4f) F0 %.4f r %.4f, rel.rms %.4f\n",
              without.material.diffuse_albedo[0], without.material.diffuse_albedo[1],
              without.material.diffuse_albedo[2], without.material.specular_albedo,
              without.material.roughness, without.relative_rms);
  // Roughness is not observable here (no highlight in view): check the albedos only.
  for (int c = 0; c < 3; ++c)
    EXPECT_NEAR(with_prior.material.diffuse_albedo[c], truth.diffuse_albedo[c], 0.03) << c;
  EXPECT_NEAR(with_prior.material.specular_albedo, truth.specular_albedo, 0.05);
  // The prior costs the fit nothing it can see: the residual stays at the noise level.
  EXPECT_LT(with_prior.relative_rms, 0.012);
  photo::BrdfFitOptions bad;
  bad.dielectric_prior_weight = -1;
  EXPECT_THROW(photo::fit_brdf(image, g, light, pixels, bad), Error);
}

TEST(MaterialInverseRendering, RobustLossResistsOutliers) {
  // 5 % of the glossy sphere's pixels tripled (specks, mis-segmented pixels): the Cauchy loss
  // keeps the issue 7 bounds; plain least squares, shown for comparison, is pulled off further.
  const Lighting light = sun_and_sky();
  SphereSet set = render_sphere_set(light, false);
  const auto pixels = pixels_with_label(set.scene.labels, 2);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0, 1);
  for (const std::int32_t i : pixels)
    if (u(rng) < 0.05)
      for (int c = 0; c < 3; ++c) set.image.data()[std::size_t(i) * 3 + c] *= 3;
  photo::BrdfFitOptions plain;
  plain.robust = false;
  const photo::BrdfFit robust_fit = photo::fit_brdf(set.image, set.geometry, light, pixels);
  const photo::BrdfFit plain_fit = photo::fit_brdf(set.image, set.geometry, light, pixels, plain);
  const Recovery r = check_recovery("sphere, 5% outliers, robust, glossy plastic",
                                    kMaterials[1].material, robust_fit, 0);
  const Material& truth = kMaterials[1].material;
  std::printf("  plain least squares: kd (%.4f %.4f %.4f) F0 %.4f r %.4f\n",
              plain_fit.material.diffuse_albedo[0], plain_fit.material.diffuse_albedo[1],
              plain_fit.material.diffuse_albedo[2], plain_fit.material.specular_albedo,
              plain_fit.material.roughness);
  double plain_diffuse = 0;
  for (int c = 0; c < 3; ++c)
    plain_diffuse =
        std::max(plain_diffuse,
                 double(std::abs(plain_fit.material.diffuse_albedo[c] - truth.diffuse_albedo[c])));
  EXPECT_LT(r.diffuse, plain_diffuse);
}

TEST(MaterialInverseRendering, TooFewPixelsIsAnError) {
  SceneSpec spec;
  spec.width = 64;
  spec.height = 48;
  spec.ground_label = 1;
  const SyntheticScene s = make_scene(spec);
  const Lighting light = sun_and_sky();
  const render::SurfaceGeometry g =
      render::surface_geometry_from_depth(s.distance_m, s.camera, s.pose, light);
  Image image(64, 48, 3);
  render::shade_regions(g, light, s.labels, std::vector<Material>{kGround}, image);
  auto code = [&](std::vector<std::int32_t> pixels) {
    try {
      photo::fit_brdf(image, g, light, pixels);
    } catch (const Error& e) {
      return e.code();
    }
    return ErrorCode::internal;
  };
  const auto ground = pixels_with_label(s.labels, 1);
  ASSERT_GT(ground.size(), 100u);
  EXPECT_EQ(code({ground.begin(), ground.begin() + 15}), ErrorCode::invalid_argument);
  EXPECT_EQ(code({}), ErrorCode::invalid_argument);
  // Sky pixels do not count.
  std::vector<std::int32_t> sky_and_few = pixels_with_label(s.labels, 0);
  sky_and_few.insert(sky_and_few.end(), ground.begin(), ground.begin() + 10);
  EXPECT_EQ(code(sky_and_few), ErrorCode::invalid_argument);
  EXPECT_EQ(code({-1, 0, 1}), ErrorCode::invalid_argument);
  EXPECT_EQ(code({64 * 48}), ErrorCode::invalid_argument);
  Image wrong(32, 48, 3);
  try {
    photo::fit_brdf(wrong, g, light, ground);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::size_mismatch);
  }
  // 16 good pixels are enough.
  EXPECT_NO_THROW(photo::fit_brdf(image, g, light,
                                  std::vector<std::int32_t>(ground.begin(), ground.begin() + 16)));
}

}  // namespace
}  // namespace mr
