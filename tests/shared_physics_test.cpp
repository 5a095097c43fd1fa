// The shared physics (render/physics/*.h: one source, compiled as C++ for the CPU core and as
// GLSL for the Vulkan shaders) called directly from C++ against closed forms and numerical
// quadrature, so the shared header itself is tested, not only the renders built on it.
//
// Tolerances: quadratures 1e-9 relative (Simpson with enough intervals to be exact to ~1e-12
// on these smooth integrands); identities (telescoping sums, inverses) 1e-12 relative; the
// lamp's segment integral against quadrature 2e-3 relative with the normal preset's boundaries
// (its midpoint rule in angle, README "Integration"); statistics of hashed directions within 5
// standard errors.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <vector>

#include "render/physics/occlusion.h"
#include "render/physics/resolve.h"
#include "render/physics/scattering.h"
#include "scattering_scenes.h"

namespace mr {
namespace {

namespace ph = render::physics;
using ph::Float3;
using test::simpson;
constexpr double kInf = std::numeric_limits<double>::infinity();

TEST(SharedPhysics, HenyeyGreensteinIsNormalisedWithMeanCosineG) {
  for (double g : {-0.9, -0.5, 0.0, 0.3, 0.8, 0.95}) {
    // Over the sphere: 2 pi integral_{-1}^{1} p(mu) dmu (the forward peak is ~(1 - g)^2 wide:
    // 4e5 intervals resolve it).
    auto integral = [&](auto weight) {
      return simpson(
          [&](double mu) { return 2 * test::kPi * ph::henyey_greenstein(g, mu) * weight(mu); }, -1,
          1, 400000);
    };
    EXPECT_NEAR(integral([](double) { return 1.0; }), 1.0, g > 0.9 ? 1e-6 : 1e-9) << g;
    EXPECT_NEAR(integral([](double mu) { return mu; }), g, g > 0.9 ? 1e-6 : 1e-9) << g;
    EXPECT_NEAR(ph::henyey_greenstein(g, 0.3), test::hg(g, 0.3), 1e-15) << g;
  }
}

// A layer, height fog from 2 m with a 15 m scale height, rays up, down, level and steep.
ph::MediumShape height_fog() {
  ph::MediumShape m;
  m.bottom_m = -5;
  m.top_m = 60;
  m.base_m = 2;
  m.scale_m = 15;
  return m;
}

TEST(SharedPhysics, OpticalDepthMatchesQuadratureOfTheDensity) {
  const ph::MediumShape m = height_fog();
  ph::MediumShape homogeneous = m;
  homogeneous.scale_m = 0;
  const Float3 o{0.3, 5, -1};
  for (const ph::MediumShape& shape : {m, homogeneous})
    for (Float3 w : {Float3{0, 0.6, 0.8}, Float3{0, -0.28, 0.96}, Float3{0, 0, 1},
                     Float3{0.2, 0.97, 0.1}, Float3{0.1, -0.9, 0.2}}) {
      w = ph::normalize(w);
      const ph::RayDensity rd = ph::ray_density(shape, o, w);
      // Inside the layer the density is the unbounded formula; the layer's ends, found here
      // independently, bound the integral (the density jumps there).
      auto rho = [&](double t) {
        const double y = o.y + t * w.y;
        return shape.scale_m > 0 ? std::exp(-(y - shape.base_m) / shape.scale_m) : 1.0;
      };
      double enter = 0, exit = kInf;
      if (w.y != 0) {
        const double ta = (shape.bottom_m - o.y) / w.y, tb = (shape.top_m - o.y) / w.y;
        enter = std::max(0.0, std::min(ta, tb));
        exit = std::max(ta, tb);
      }
      for (double t0 : {0.0, 3.0, 20.0})
        for (double t1 : {5.0, 40.0, 150.0}) {
          if (!(t1 > t0)) continue;
          const double a = std::max(t0, enter), b = std::min(t1, exit);
          const double want = b > a ? simpson(rho, a, b, 20000) : 0.0;
          const double got = ph::optical_depth(rd, t0, t1);
          EXPECT_NEAR(got, want, 1e-9 * std::max(want, 1e-3))
              << "w " << w.x << "," << w.y << "," << w.z << " [" << t0 << ", " << t1 << "]";
          // Density along the ray is the density at the point.
          const double tm = 0.5 * (t0 + t1);
          EXPECT_NEAR(ph::density(rd, tm), ph::density_at(shape, o + tm * w), 1e-14);
        }
    }
}

TEST(SharedPhysics, OpticalDepthToInfinityAndItsInverse) {
  const ph::MediumShape m = height_fog();
  ph::MediumShape open = m;  // no layer: the closed form to infinity upward is k H / w_y
  open.bottom_m = -kInf;
  open.top_m = kInf;
  const Float3 o{0, 5, 0}, up = ph::normalize(Float3{0, 0.6, 0.8});
  const double k = std::exp(-(5 - 2.0) / 15);
  EXPECT_NEAR(ph::optical_depth(ph::ray_density(open, o, up), 0, kInf), k * 15 / 0.6,
              1e-12 * k * 15 / 0.6);
  EXPECT_TRUE(std::isinf(ph::optical_depth(ph::ray_density(open, o, {0, -0.6, 0.8}), 0, kInf)));
  for (const ph::MediumShape& shape : {m, open})
    for (Float3 w : {up, ph::normalize(Float3{0, -0.3, 1}), Float3{0, 0, 1}}) {
      const ph::RayDensity rd = ph::ray_density(shape, o, w);
      for (double t : {0.5, 7.0, 33.0}) {
        if (t > rd.t_exit) continue;
        const double od = ph::optical_depth(rd, 0, t);
        EXPECT_NEAR(ph::distance_at_optical_depth(rd, od), t, 1e-12 * t) << w.y << " " << t;
      }
    }
  // The series branch of (1 - exp(-a L)) / a joins the closed form.
  for (double x : {1e-10, 1e-9, 2e-9, 1e-6})
    EXPECT_NEAR(ph::exp_integral(x, 1.0), -std::expm1(-x) / x, 1e-15) << x;
}

TEST(SharedPhysics, SegmentWeightsTelescopeToTheSkyOnlyClosedForm) {
  // Sky light only: the march's segment weights sum to albedo (1 - tau(D)) (Koschmieder).
  const ph::MediumShape m = height_fog();
  const Float3 o{0, 1.6, 0}, w = ph::normalize(Float3{0.1, 0.05, 1});
  const ph::RayDensity rd = ph::ray_density(m, o, w);
  const Float3 sigma{0.03, 0.04, 0.05}, albedo{0.9, 0.8, 0.7};
  const double len = 300;
  const double od_total = ph::optical_depth(rd, 0, len);
  const double sigma_mean = (sigma.x + sigma.y + sigma.z) / 3;
  const int steps = 32;
  Float3 od{0, 0, 0}, tau{1, 1, 1}, sum{0, 0, 0};
  double ta = 0;
  for (int i = 1; i <= steps; ++i) {
    const double tb = i == steps
                          ? len
                          : ph::uniform_boundary(rd, i, steps, sigma_mean, sigma_mean * od_total,
                                                 -std::expm1(-sigma_mean * od_total), len);
    ASSERT_GT(tb, ta);
    sum += ph::advance_segment(od, tau, sigma, albedo, ph::optical_depth(rd, ta, tb));
    ta = tb;
  }
  const Float3 want = ph::sky_only_inscatter(ph::scaled_optical_depth(sigma, od_total), albedo);
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(sum[c], want[c], 1e-12 * want[c]) << c;
    EXPECT_NEAR(tau[c], std::exp(-sigma[c] * od_total), 1e-12) << c;
  }
  // Boundaries uniform in transmittance: each segment carries the same share of 1 - tau at
  // the mean extinction.
  const double first = ph::uniform_boundary(rd, 1, steps, sigma_mean, sigma_mean * od_total,
                                            -std::expm1(-sigma_mean * od_total), len);
  EXPECT_NEAR(-std::expm1(-sigma_mean * ph::optical_depth(rd, 0, first)),
              -std::expm1(-sigma_mean * od_total) / steps, 1e-12);
}

TEST(SharedPhysics, SunLitPiecesAddUpToTheSegment) {
  const ph::MediumShape m = height_fog();
  const ph::RayDensity rd = ph::ray_density(m, {0, 1.6, 0}, ph::normalize(Float3{0, 0.2, 1}));
  const Float3 sigma{0.05, 0.05, 0.06}, albedo{0.9, 0.9, 0.9}, tau_before{0.7, 0.7, 0.6};
  const double ta = 10, tb = 18, modulation = 0.8;
  Float3 od{0, 0, 0}, tau = tau_before;
  const Float3 weight =
      ph::advance_segment(od, tau, sigma, albedo, ph::optical_depth(rd, ta, tb) * modulation);
  // Lit throughout, as one piece or as three: the whole weight.
  const Float3 one = ph::sun_lit_weight(rd, ta, tb, ta, tb, true, true, true, modulation, weight,
                                        albedo, tau_before, sigma);
  const Float3 three = ph::sun_lit_weight(rd, ta, tb, 12, 15, true, true, true, modulation, weight,
                                          albedo, tau_before, sigma);
  // Only the middle piece: exp(-sigma od(ta, 12)) - exp(-sigma od(ta, 15)) of it.
  const Float3 middle = ph::sun_lit_weight(rd, ta, tb, 12, 15, false, true, false, modulation,
                                           weight, albedo, tau_before, sigma);
  for (int c = 0; c < 3; ++c) {
    EXPECT_EQ(one[c], weight[c]);
    EXPECT_NEAR(three[c], weight[c], 1e-12 * weight[c]);
    const double want = albedo[c] * tau_before[c] *
                        (std::exp(-sigma[c] * modulation * ph::optical_depth(rd, ta, 12)) -
                         std::exp(-sigma[c] * modulation * ph::optical_depth(rd, ta, 15)));
    EXPECT_NEAR(middle[c], want, 1e-12 * want);
  }
  EXPECT_DOUBLE_EQ(ph::sun_seen_fraction(ta, tb, 12, 15, false, true, false), 3.0 / 8.0);
  EXPECT_DOUBLE_EQ(ph::sun_seen_fraction(ta, tb, 12, 15, true, false, true), 5.0 / 8.0);
}

// The sun's light-path transmittance of a view-ray segment (issue 11, low sun in height fog):
// the segment's in-scatter-weighted mean of exp(-sigma od_sun), against Simpson (2000
// intervals) of integral rho tau_cam tau_sun dt / integral rho tau_cam dt with the optical depths
// in closed form written out here (height fog base 0, scale H: od_sun(y) = H (e^(-y/H) -
// e^(-top/H)) / sin(elevation)). Height fog with scale 12 m under a 40 m top, a sun at 8 deg,
// 90 m visibility (grey and coloured), noise modulation 1 and 0.7, view rays rising at 2.9 and
// 6.8 deg. Tolerances (relative) are the 4-point Gauss-Legendre rule's, per segment, about twice
// the worst measured: 60 m from the camera (tau_sun up to 4.4x across it) 1e-4 (measured 2.7e-5);
// 20..200 m (up to 9.4x) 1e-2 (4.9e-3); from 150 m to the layer top, up to 600 m (tau_sun
// 0.14 -> 0.99) 0.1 (5.4e-2: the rule's limit on a long segment; still between the ends' values,
// where one point value could fall anywhere). Where the sun's optical depth changes by at most
// 0.01 / sigma_t over the segment (a level ray: constant height), the value at the sample point,
// exactly.
TEST(SharedPhysics, SunPathTransmittanceIsTheSegmentsWeightedMean) {
  const double H = 12, top = 40, elevation = 8 * test::kPi / 180;
  ph::MediumShape m;
  m.bottom_m = -kInf;
  m.top_m = top;
  m.base_m = 0;
  m.scale_m = H;
  const Float3 sun{0, std::sin(elevation), std::cos(elevation)};
  const Float3 o{0, 1.6, 0};
  const double s90 = 3.912 / 90;
  double worst[3] = {0, 0, 0};  // per segment
  for (const Float3 sigma : {Float3{s90, s90, s90}, Float3{0.8 * s90, s90, 1.2 * s90}})
    for (const Float3 w : {ph::normalize(Float3{0.1, 0.05, 1}), ph::normalize(Float3{0, 0.12, 1})})
      for (const double modulation : {1.0, 0.7}) {
        const ph::RayDensity rd = ph::ray_density(m, o, w);
        const double t_top = (top - o.y) / w.y;
        for (int segment = 0; segment < 3; ++segment) {
          const double ta = segment == 0 ? 0.0 : (segment == 1 ? 20.0 : 150.0);
          const double tb = segment == 0 ? 60.0 : (segment == 1 ? 200.0 : 0.98 * t_top);
          const double tolerance = segment == 0 ? 1e-4 : (segment == 1 ? 1e-2 : 0.1);
          const double ts = ta + 0.37 * (tb - ta);
          const Float3 tau_sun =
              ph::sun_path_transmittance(m, rd, o, w, sun, ta, tb, o + w * ts, modulation, sigma);
          const double ya = o.y + ta * w.y;
          for (int c = 0; c < 3; ++c) {
            auto rho = [&](double t) { return std::exp(-(o.y + t * w.y) / H); };
            auto tau_cam = [&](double t) {  // from ta to t, closed form along the rising ray
              const double y = o.y + t * w.y;
              return std::exp(-sigma[c] * modulation * H * (std::exp(-ya / H) - std::exp(-y / H)) /
                              w.y);
            };
            auto tau_to_sun = [&](double t) {
              const double y = o.y + t * w.y;
              return std::exp(-sigma[c] * H * (std::exp(-y / H) - std::exp(-top / H)) /
                              std::sin(elevation));
            };
            const double num = simpson(
                [&](double t) { return rho(t) * tau_cam(t) * tau_to_sun(t); }, ta, tb, 2000);
            const double den = simpson([&](double t) { return rho(t) * tau_cam(t); }, ta, tb, 2000);
            const double want = num / den;
            worst[segment] = std::max(worst[segment], std::fabs(tau_sun[c] - want) / want);
            EXPECT_NEAR(tau_sun[c], want, tolerance * want) << ta << " " << tb << " " << c;
            // It is an average: between the ends' values.
            EXPECT_LT(tau_sun[c], tau_to_sun(tb));
            EXPECT_GT(tau_sun[c], tau_to_sun(ta));
          }
        }
      }
  std::printf("sun path transmittance vs Simpson, worst relative error: %.3g, %.3g, %.3g\n",
              worst[0], worst[1], worst[2]);
  // A level ray stays at one height: the sun's optical depth is constant, the point value.
  const Float3 level{0.3, 0, 1};
  const Float3 w = ph::normalize(level);
  const ph::RayDensity rd = ph::ray_density(m, o, w);
  const Float3 sigma{s90, s90, s90};
  const Float3 xs = o + w * 123.0;
  const Float3 point = ph::transmittance(sigma, ph::sun_path_optical_depth(m, xs, sun));
  const Float3 mean = ph::sun_path_transmittance(m, rd, o, w, sun, 20, 400, xs, 1.0, sigma);
  for (int c = 0; c < 3; ++c) EXPECT_EQ(mean[c], point[c]);
  EXPECT_NEAR(point[0],
              std::exp(-s90 * H * (std::exp(-1.6 / H) - std::exp(-top / H)) / std::sin(elevation)),
              1e-12);
}

TEST(SharedPhysics, LampSegmentsIntegrateTheGlow) {
  // Homogeneous fog, a point lamp 1.5 m off a 40 m view ray, no light-path attenuation:
  // R = integral albedo sigma tau(t) I p(w . l(t)) / r(t)^2 dt, against Simpson.
  ph::MediumShape m;
  m.bottom_m = -kInf;
  m.top_m = kInf;
  m.base_m = 0;
  m.scale_m = 0;
  const Float3 o{0, 0, 0}, w{0, 0, 1}, lamp{1.5, 0.2, 12};
  const ph::RayDensity rd = ph::ray_density(m, o, w);
  const Float3 sigma{0.05, 0.05, 0.05}, albedo{0.9, 0.9, 0.9}, intensity{60, 50, 40};
  const double g = 0.4, len = 40;
  const ph::LampOnRay lr = ph::lamp_on_ray(lamp, o, w, len);
  auto integrand = [&](double t) {
    const Float3 d = lamp - t * w;
    const double r2 = ph::dot(d, d);
    return 0.9 * 0.05 * std::exp(-0.05 * t) * ph::henyey_greenstein(g, d.z / std::sqrt(r2)) / r2;
  };
  const double want = simpson(integrand, 0, lr.tc, 200000) + simpson(integrand, lr.tc, len, 200000);
  // The core's boundaries: 32 uniform in transmittance and the lamp's 16 equiangular ones.
  std::vector<double> bounds = {0, len};
  const double od_total = ph::optical_depth(rd, 0, len);
  for (int i = 1; i < 32; ++i)
    bounds.push_back(
        ph::uniform_boundary(rd, i, 32, 0.05, 0.05 * od_total, -std::expm1(-0.05 * od_total), len));
  for (int i = 1; i < 16; ++i) bounds.push_back(ph::lamp_boundary(lr, i, 16));
  std::sort(bounds.begin(), bounds.end());
  Float3 sum{0, 0, 0};
  Float3 od{0, 0, 0}, tau{1, 1, 1};
  for (std::size_t i = 0; i + 1 < bounds.size(); ++i) {
    const double ta = bounds[i], tb = bounds[i + 1];
    const Float3 tau_before = tau;
    ph::advance_segment(od, tau, sigma, albedo, ph::optical_depth(rd, ta, tb));
    const double tm = ph::lamp_segment_t(lr, ta, tb);
    const Float3 l = ph::normalize(lamp - tm * w);
    sum += ph::lamp_inscatter(lr, rd, ta, tb, tm, 1.0, ph::henyey_greenstein(g, ph::dot(w, l)), 1.0,
                              0.0, albedo, sigma, tau_before, intensity);
  }
  for (int c = 0; c < 3; ++c)
    EXPECT_NEAR(sum[c], want * intensity[c], 2e-3 * want * intensity[c]) << c;
  EXPECT_NEAR(ph::atan_diff(0.3, 0.30001), std::atan(0.30001) - std::atan(0.3), 1e-16);
  EXPECT_NEAR(ph::atan_diff(-5, 7), std::atan(7.0) - std::atan(-5.0), 1e-15);
}

TEST(SharedPhysics, SpotConeJitterAndSurfaceFactor) {
  const double ci = std::cos(0.3), co = std::cos(0.5);
  EXPECT_EQ(ph::spot_cone(1.0, ci, co), 1.0);
  EXPECT_EQ(ph::spot_cone(ci, ci, co), 1.0);
  EXPECT_EQ(ph::spot_cone(co, ci, co), 0.0);
  EXPECT_NEAR(ph::spot_cone(0.5 * (ci + co), ci, co), 0.5, 1e-15);
  double previous = 0;
  for (int k = 0; k <= 100; ++k) {  // monotone in the angle
    const double v = ph::spot_cone(co + (ci - co) * k / 100.0, ci, co);
    EXPECT_GE(v, previous);
    previous = v;
  }
  double mean = 0;
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) {
      const double j = ph::pixel_jitter(x, y, 7);
      ASSERT_GE(j, 0.0);
      ASSERT_LT(j, 1.0);
      mean += j / 4096;
    }
  EXPECT_NEAR(mean, 0.5, 0.02);
  // S: ambient only -> 1; a sun carrying half the light, dimmed to 0.2 -> 0.6.
  const Float3 sky{0.1, 0.1, 0.1};
  const double ao = 0.8;
  Float3 direct{0, 0, 0}, fogged{0, 0, 0};
  EXPECT_EQ(ph::surface_factor(direct, fogged, sky, ao), (Float3{1, 1, 1}));
  const double ambient = test::kPi * 0.1 * ao;
  ph::add_surface_light(direct, fogged, {ambient, ambient, ambient}, {0.2, 0.2, 0.2});
  const Float3 s = ph::surface_factor(direct, fogged, sky, ao);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(s[c], 0.6, 1e-15);
}

TEST(SharedPhysics, HashAndNoise) {
  // lowbias32's avalanche: flipping one input bit flips about half of the output bits.
  double flips = 0;
  int n = 0;
  for (std::uint32_t x = 1; x < 20000; x += 7)
    for (int bit = 0; bit < 32; ++bit, ++n)
      flips += std::popcount(ph::hash32(x) ^ ph::hash32(x ^ (1u << bit)));
  EXPECT_NEAR(flips / n, 16.0, 0.1);
  EXPECT_EQ(ph::unit_float(0xFFFFFFFFu), 1.0 - 1.0 / 16777216.0);
  // Gradient noise vanishes on the lattice, stays within [-1, 1], is continuous and seeded.
  double sum = 0, sum2 = 0;
  int count = 0;
  for (int i = 0; i < 4000; ++i) {
    const Float3 p{0.37 * i, 0.11 * i - 3, 0.053 * i + 1};
    const double v = ph::gradient_noise(p, 5);
    ASSERT_LE(std::fabs(v), 1.0);
    EXPECT_NEAR(ph::gradient_noise(p + Float3{1e-7, 0, 0}, 5), v, 1e-6);
    sum += v;
    sum2 += v * v;
    ++count;
  }
  EXPECT_NEAR(sum / count, 0.0, 0.05);
  EXPECT_GT(sum2 / count, 0.01);
  EXPECT_EQ(ph::gradient_noise({3, -2, 7}, 5), 0.0);
  EXPECT_NE(ph::gradient_noise({3.5, -2.2, 7.1}, 5), ph::gradient_noise({3.5, -2.2, 7.1}, 6));
  EXPECT_EQ(ph::noise_modulation({1, 2, 3}, 0.0, 0.1, 4, 1), 1.0);
  for (int i = 0; i < 500; ++i)
    EXPECT_GE(ph::noise_modulation({0.7 * i, 1.3, -0.2 * i}, 1.5, 0.25, 3, 9), 0.0);
}

// Improved Perlin noise's 12 gradients written out as a table (the CPU core's noise before it
// was shared), independently of physics::noise_grad's bit arithmetic.
double table_gradient_noise(const Float3& p, std::uint32_t seed) {
  const double fx = std::floor(p.x), fy = std::floor(p.y), fz = std::floor(p.z);
  const double dx = p.x - fx, dy = p.y - fy, dz = p.z - fz;
  auto grad = [&](int cx, int cy, int cz, double rx, double ry, double rz) {
    const double table[12] = {rx + ry, -rx + ry, rx - ry, -rx - ry, rx + rz, -rx + rz,
                              rx - rz, -rx - rz, ry + rz, -ry + rz, ry - rz, -ry - rz};
    return table[ph::hash3(cx, cy, cz, seed) % 12u];
  };
  auto fade = [](double t) { return t * t * t * (t * (t * 6 - 15) + 10); };
  auto lerp = [](double a, double b, double t) { return a + (b - a) * t; };
  double c[2][2][2];
  for (int k = 0; k < 2; ++k)
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i < 2; ++i)
        c[k][j][i] = grad(int(fx) + i, int(fy) + j, int(fz) + k, dx - i, dy - j, dz - k);
  const double u = fade(dx), v = fade(dy), w = fade(dz);
  return lerp(lerp(lerp(c[0][0][0], c[0][0][1], u), lerp(c[0][1][0], c[0][1][1], u), v),
              lerp(lerp(c[1][0][0], c[1][0][1], u), lerp(c[1][1][0], c[1][1][1], u), v), w);
}

TEST(SharedPhysics, GradientNoiseIsImprovedPerlinNoise) {
  for (int i = 0; i < 3000; ++i) {
    const Float3 p{0.731 * i - 40, 0.173 * i + 0.5, -0.291 * i};
    EXPECT_EQ(ph::gradient_noise(p, 11), table_gradient_noise(p, 11)) << i;
  }
}

TEST(SharedPhysics, AmbientOcclusionRaysAreCosineWeighted) {
  // The set's moments: E[cos theta] = 2/3, E[cos^2 theta] = 1/2 for cosine weighting; the set
  // is a midpoint rule in u1 = sin^2 theta, exact for cos^2 and within 2e-5 for cos at 256 rays.
  const Float3 n = ph::normalize(Float3{0.3, 0.8, -0.52});
  Float3 t1, t2;
  ph::ao_frame(n, Float3{0, 0, -1}, t1, t2);
  EXPECT_NEAR(ph::dot(t1, n), 0.0, 1e-15);
  EXPECT_NEAR(ph::dot(t2, n), 0.0, 1e-15);
  EXPECT_NEAR(ph::dot(t1, t2), 0.0, 1e-15);
  EXPECT_NEAR(ph::dot(t1, t1), 1.0, 1e-15);
  EXPECT_NEAR(ph::dot(t2, t2), 1.0, 1e-15);
  const int rays = 256;
  for (const std::uint32_t seed : {1u, 2u, 77u}) {
    const std::uint32_t stream = ph::ao_stream(seed);
    double c1 = 0, c2 = 0;
    Float3 mean{0, 0, 0};
    for (int i = 0; i < rays; ++i) {
      const Float3 d = ph::ao_direction(stream, i, rays, 1, n, t1, t2);
      ASSERT_NEAR(ph::dot(d, d), 1.0, 1e-12);
      const double c = ph::dot(d, n);
      ASSERT_GE(c, 0.0);
      c1 += c;
      c2 += c * c;
      mean += d;
    }
    EXPECT_NEAR(c1 / rays, 2.0 / 3.0, 2e-5);
    EXPECT_NEAR(c2 / rays, 0.5, 1e-12);
    // Low discrepancy in angle too: the mean direction lies along n (tangential parts < 1 %).
    EXPECT_NEAR(ph::dot(mean, t1) / rays, 0.0, 1e-2);
    EXPECT_NEAR(ph::dot(mean, t2) / rays, 0.0, 1e-2);
  }
}

// Issue surf16: the AO ray set is one per render, in a frame that turns continuously with the
// normal, so nearby samples with nearly equal normals trace nearly equal rays. A normal turned
// by 1e-3 rad moves every ray by less than 3e-3 rad, also across n.z = 0 (where the
// branchless basis alone flips: a side wall's estimated normals straddle it), and at any angle
// up to 138 degrees from the pole (the normals below). The seed turns the set (another render).
TEST(SharedPhysics, AmbientOcclusionRaysTurnContinuouslyWithTheNormal) {
  const Float3 pole{0, 0, -1};
  const std::uint32_t stream = ph::ao_stream(1);
  const int rays = 8;
  auto max_turn = [&](Float3 a, Float3 b) {
    Float3 a1, a2, b1, b2;
    ph::ao_frame(a, pole, a1, a2);
    ph::ao_frame(b, pole, b1, b2);
    double worst = 0;
    for (int i = 0; i < rays; ++i) {
      const Float3 da = ph::ao_direction(stream, i, rays, 1, a, a1, a2);
      const Float3 db = ph::ao_direction(stream, i, rays, 1, b, b1, b2);
      worst = std::max(worst, ph::length(da - db));
    }
    return worst;
  };
  const double kEps = 1e-3;
  // Side walls facing +x and -x, ground, a wall facing the camera, and normals all around.
  for (const Float3 n0 : {Float3{1, 0, 0}, Float3{-1, 0, 0}, Float3{0, 1, 0}, Float3{0, 0, -1},
                          Float3{0.6, 0.5, 0}, Float3{-0.3, 0.2, 0.4}}) {
    const Float3 n = ph::normalize(n0);
    const Float3 across_z_a = ph::normalize(n + Float3{0, 0, 0.5 * kEps});
    const Float3 across_z_b = ph::normalize(n - Float3{0, 0, 0.5 * kEps});
    EXPECT_LT(max_turn(across_z_a, across_z_b), 3 * kEps) << n.x << " " << n.y << " " << n.z;
    const Float3 tilted = ph::normalize(n + Float3{kEps, -kEps, 0} * 0.7);
    EXPECT_LT(max_turn(n, tilted), 3 * kEps) << n.x << " " << n.y << " " << n.z;
  }
  // Another seed turns the set.
  const Float3 n{0, 1, 0};
  Float3 t1, t2;
  ph::ao_frame(n, pole, t1, t2);
  EXPECT_GT(ph::length(ph::ao_direction(stream, 0, rays, 1, n, t1, t2) -
                       ph::ao_direction(ph::ao_stream(2), 0, rays, 1, n, t1, t2)),
            1e-3);
}

TEST(SharedPhysics, GradientInterpolationIsExactForLinearValues) {
  // Four corners of a 3 x 3 cell with the value and gradients of f = 2 + 0.5 x - 0.25 y: every
  // pixel in between gets f exactly; the weights are a partition of unity.
  auto f = [](double x, double y) { return 2 + 0.5 * x - 0.25 * y; };
  const int cx[4] = {0, 3, 0, 3}, cy[4] = {0, 0, 3, 3};
  for (int y = 0; y <= 3; ++y)
    for (int x = 0; x <= 3; ++x) {
      double acc = 0, wsum = 0;
      for (int k = 0; k < 4; ++k) {
        const double w = ph::corner_weight(k, x / 3.0, y / 3.0);
        wsum += w;
        acc += w * ph::extrapolate(f(cx[k], cy[k]), 0.5, -0.25, x - cx[k], y - cy[k]);
      }
      EXPECT_NEAR(wsum, 1.0, 1e-15);
      EXPECT_NEAR(acc, f(x, y), 1e-14);
    }
  double sum = 0;
  int slopes = 0;
  ph::add_slope(sum, slopes, 1.0, 2.0, 3.0);
  ph::add_slope(sum, slopes, 1.0, 0.5, -3.0);
  EXPECT_NEAR(ph::mean_slope(sum, slopes), 0.25, 1e-15);
  EXPECT_EQ(ph::mean_slope(0, 0), 0.0);
  EXPECT_TRUE(ph::depth_continuous(10.5, 10));
  EXPECT_FALSE(ph::depth_continuous(11.5, 10));
  EXPECT_TRUE(ph::depth_continuous(kInf, kInf));
  EXPECT_FALSE(ph::depth_continuous(kInf, 10));
  EXPECT_TRUE(ph::cell_has_edge(0.5, 0.8, 1, 1));
  EXPECT_TRUE(ph::cell_has_edge(1, 1, 1, 1.3));
  EXPECT_FALSE(ph::cell_has_edge(0.9, 1, 1, 1.2));
}

}  // namespace
}  // namespace mr
