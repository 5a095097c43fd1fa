// The Vulkan scattering backend (render/vulkan/, shaders/) on lavapipe (DESIGN.md section 7,
// "GPU = CPU"). Tolerances, all from the issue:
//  * closed forms: the CPU core's tests, run on the GPU with the CPU's tolerances (relative
//    error < 1e-3; lamp glow against numerical integration < 1e-2; the shadowed fraction of a
//    ray within one march step + 0.01; Koschmieder composite < 1e-5, transmittance < 1e-6);
//  * GPU vs CPU on the same scenes: mean relative error of T and of R below 1 %, and below 5 %
//    at the 99th percentile outside one-pixel bands at shadow edges;
//  * tiling: a forced small tile limit gives the same image as one tile (max difference 0);
//  * the validation layer reports nothing (every test).
// MR_TEST_IMAGES=<folder> writes each comparison's CPU and GPU T and R as PNGs.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <numbers>

#include "mr/error.h"
#include "mr/fog.h"
#include "mr/scattering.h"
#include "render/occluder_mesh.h"
#include "render/scattering_cpu.h"
#include "test_support.h"
#include "vulkan_test_support.h"

namespace mr {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr float kInf = std::numeric_limits<float>::infinity();

double hg(double g, double c) { return (1 - g * g) / (4 * kPi * std::pow(1 + g * g - 2 * g * c, 1.5)); }
double dot(const Vec3& a, const Vec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
Vec3 normalize(const Vec3& v) {
  const double n = std::sqrt(dot(v, v));
  return {v.x / n, v.y / n, v.z / n};
}
double simpson(const std::function<double(double)>& f, double a, double b, int n) {
  const double h = (b - a) / n;
  double s = f(a) + f(b);
  for (int i = 1; i < n; ++i) s += f(a + i * h) * (i % 2 ? 4 : 2);
  return s * h / 3;
}
Image constant_depth(const Camera& cam, float d) {
  Image im(cam.width, cam.height, 1, {"Z"});
  for (float& v : im.pixels()) v = d;
  return im;
}
Image ground_depth(const Camera& cam, const CameraPose& pose) {
  Image im(cam.width, cam.height, 1, {"Z"});
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const Vec3 w = pose.ray_direction(cam, x, y);
      im.at(x, y, 0) = w.y < -1e-6 ? float(-pose.position_m.y / w.y) : kInf;
    }
  return im;
}
FogScene base_scene() {
  FogScene s;
  s.medium.sigma_t_per_m = {0.02f, 0.02f, 0.02f};
  s.medium.albedo = {0.9f, 0.8f, 0.7f};
  s.medium.g = 0.4;
  s.lighting.sky_radiance = Rgb{0, 0, 0};
  s.render.quality = Quality::final;
  s.render.backend = Backend::vulkan;
  return s;
}

// A street: ground, a wall on the left (x = -3, 6 m high), a pillar, a far wall; sky above.
Image street_depth(const Camera& cam, const CameraPose& pose) {
  Image depth = ground_depth(cam, pose);
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const Vec3 w = pose.ray_direction(cam, x, y);
      float& d = depth.at(x, y, 0);
      if (w.x < 0) {
        const double t = -3.0 / w.x;
        if (pose.position_m.y + t * w.y < 6 && t < d) d = float(t);
      }
      if (w.z > 0) {
        const double t = (60 - pose.position_m.z) / w.z;
        if (pose.position_m.y + t * w.y < 14 && t < d) d = float(t);
      }
      // A pillar 1 m wide at x in [1, 2], z = 12, 8 m high.
      if (w.z > 0) {
        const double t = (12 - pose.position_m.z) / w.z;
        const double px = pose.position_m.x + t * w.x, py = pose.position_m.y + t * w.y;
        if (px > 1 && px < 2 && py < 8 && t < d) d = float(t);
      }
    }
  return depth;
}

class VulkanScattering : public ::testing::Test {
 protected:
  void SetUp() override {
    std::string why;
    backend_ = vktest::backend_or_null(&why);
    if (!backend_) GTEST_SKIP() << why;
  }
  void TearDown() override { vktest::expect_validation_clean(); }

  static ScatteringLayers render(const Image& depth, const Camera& cam, FogScene s, Backend b) {
    s.render.backend = b;
    ScatteringLayers out = render_scattering(Image(), depth, cam, s);
    if (b == Backend::vulkan) {
      EXPECT_EQ(out.backend.rfind("vulkan", 0), 0u) << out.backend;
    }
    return out;
  }

  // GPU vs CPU on one scene with the bar.
  static vktest::Errors expect_matches_cpu(const std::string& name, const Image& depth, const Camera& cam,
                                           const FogScene& s) {
    const ScatteringLayers gpu = render(depth, cam, s, Backend::vulkan);
    const ScatteringLayers cpu = render(depth, cam, s, Backend::cpu);
    vktest::maybe_write_images(name, gpu, cpu);
    const vktest::Errors e = vktest::compare(gpu, cpu);
    std::printf("%s: T mean %.4f %% p99 %.4f %% max %.3f %% | R mean %.4f %% p99 %.4f %% max %.3f %% | "
                "edge band %zu of %zu px\n",
                name.c_str(), 100 * e.mean_t, 100 * e.p99_t, 100 * e.max_t, 100 * e.mean_r, 100 * e.p99_r,
                100 * e.max_r, e.edge_pixels, e.pixels);
    EXPECT_LT(e.mean_t, 0.01) << name;
    EXPECT_LT(e.mean_r, 0.01) << name;
    EXPECT_LT(e.p99_t, 0.05) << name;
    EXPECT_LT(e.p99_r, 0.05) << name;
    return e;
  }

  render::vulkan::Backend* backend_ = nullptr;
};

// ---- the CPU core's closed-form tests, on the GPU ---------------------------------------------

TEST_F(VulkanScattering, HomogeneousSunWithoutLightPathAttenuationIsClosedForm) {
  const Camera cam = Camera::from_horizontal_fov(40, 30, 60);
  FogScene s = base_scene();
  s.lighting.sun = Sun{normalize({0.3, 0.5, 0.8}), {3, 2.5, 2}, 0.0};
  s.render.light_path_attenuation = false;
  s.render.volumetric_shadows = false;
  s.render.quality = Quality::normal;
  s.render.gradient_acceleration = false;
  Image depth = constant_depth(cam, 60);
  for (int x = 0; x < cam.width; ++x) depth.at(x, 3, 0) = kInf;
  const ScatteringLayers out = render(depth, cam, s, Backend::vulkan);
  double worst = 0;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const Vec3 w = s.pose.ray_direction(cam, x, y);
      const double p = hg(s.medium.g, dot(w, s.lighting.sun->direction_to_sun));
      for (int c = 0; c < 3; ++c) {
        const double tau = std::exp(-s.medium.sigma_t_per_m[c] * double(depth.at(x, y, 0)));
        const double want = s.lighting.sun->irradiance[c] * p * s.medium.albedo[c] * (1 - tau);
        worst = std::max(worst, std::fabs(out.inscatter.at(x, y, c) - want) / want);
      }
    }
  EXPECT_LT(worst, 1e-3);
}

TEST_F(VulkanScattering, SunThroughAFogLayerWithLightPathAttenuation) {
  const Camera cam = Camera::from_horizontal_fov(32, 24, 50);
  FogScene s = base_scene();
  s.medium.layer_top_m = 30;
  s.lighting.sun = Sun{normalize({0.2, 0.6, -0.7}), {3, 3, 3}, 0.0};
  s.render.volumetric_shadows = false;
  const Image depth = constant_depth(cam, 80);
  const ScatteringLayers out = render(depth, cam, s, Backend::vulkan);
  const Vec3 l = s.lighting.sun->direction_to_sun;
  double worst = 0;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const Vec3 w = s.pose.ray_direction(cam, x, y);
      const double d = depth.at(x, y, 0);
      const double k = 1 - w.y / l.y;
      for (int c = 0; c < 3; ++c) {
        const double sigma = s.medium.sigma_t_per_m[c];
        const double want = s.medium.albedo[c] * 3.0 * hg(s.medium.g, dot(w, l)) *
                            std::exp(-sigma * (30 - s.pose.position_m.y) / l.y) * -std::expm1(-sigma * k * d) / k;
        worst = std::max(worst, std::fabs(out.inscatter.at(x, y, c) - want) / want);
      }
    }
  EXPECT_LT(worst, 1e-3);
}

TEST_F(VulkanScattering, KoschmiederReductionWithAmbientLightOnly) {
  const Camera cam = Camera::from_horizontal_fov(48, 32, 60);
  const Image photo = test::make_test_photo(48, 32);
  Image depth(48, 32, 1);
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 48; ++x) depth.at(x, y, 0) = y < 8 ? kInf : float(5 + 11 * x + 3 * y);
  FogScene s;
  s.medium.sigma_t_per_m = {0.01f, 0.015f, 0.02f};
  s.medium.albedo = {1, 1, 1};
  s.lighting.sky_radiance = Rgb{0.7f, 0.75f, 0.8f};
  s.render.backend = Backend::vulkan;
  ScatteringLayers layers;
  const FogLayers physical = fog(photo, depth, cam, s, &layers);
  EXPECT_EQ(layers.backend.rfind("vulkan", 0), 0u);
  FogParams k;
  k.sigma_t_per_m = s.medium.sigma_t_per_m;
  k.airlight = s.lighting.sky_radiance;
  const FogLayers koschmieder = fog(photo, depth, k);
  EXPECT_LT(test::max_abs_diff(physical.composite, koschmieder.composite), 1e-5);
  EXPECT_LT(test::max_abs_diff(physical.transmittance, koschmieder.transmittance), 1e-6);
}

TEST_F(VulkanScattering, SurfaceTermOfASunlitPlane) {
  const Camera cam = Camera::from_horizontal_fov(40, 30, 60);
  FogScene s = base_scene();
  s.pose.pitch_deg = -35;
  s.medium.layer_top_m = 20;
  s.lighting.sky_radiance = Rgb{0.2f, 0.25f, 0.3f};
  s.lighting.sun = Sun{direction_from_azimuth_elevation(30, 40), {3, 3, 3}, 0.27};
  s.render.quality = Quality::normal;
  const Image depth = ground_depth(cam, s.pose);
  const ScatteringLayers out = render(depth, cam, s, Backend::vulkan);
  const Vec3 l = normalize(s.lighting.sun->direction_to_sun);
  double worst = 0;
  int checked = 0;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const double d = depth.at(x, y, 0);
      if (std::isinf(d)) continue;
      for (int c = 0; c < 3; ++c) {
        const double sigma = s.medium.sigma_t_per_m[c];
        const double tau_sun = std::exp(-sigma * 20 / l.y);
        const double e = 3.0 * l.y, amb = kPi * (*s.lighting.sky_radiance)[c];
        const double want = std::exp(-sigma * d) * (e * tau_sun + amb) / (e + amb);
        worst = std::max(worst, std::fabs(out.transmittance.at(x, y, c) - want) / want);
      }
      EXPECT_EQ(out.sun_visibility.at(x, y, 0), 1.0f) << x << "," << y;
      ++checked;
    }
  EXPECT_GT(checked, 300);
  EXPECT_LT(worst, 1e-3);
}

TEST_F(VulkanScattering, SurfaceTermOfALamplitPlane) {
  const Camera cam = Camera::from_horizontal_fov(40, 30, 60);
  FogScene s = base_scene();
  s.pose.pitch_deg = -35;
  s.lighting.sky_radiance = Rgb{0.05f, 0.05f, 0.05f};
  Lamp lamp;
  lamp.position_m = {0.5, 3.0, 6.0};
  lamp.intensity_per_sr = {40, 30, 20};
  s.lighting.lamps = {lamp};
  s.render.quality = Quality::draft;
  const Image depth = ground_depth(cam, s.pose);
  const ScatteringLayers out = render(depth, cam, s, Backend::vulkan);
  double worst = 0;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const double d = depth.at(x, y, 0);
      if (std::isinf(d)) continue;
      const Vec3 w = s.pose.ray_direction(cam, x, y);
      const Vec3 p{s.pose.position_m.x + d * w.x, s.pose.position_m.y + d * w.y, s.pose.position_m.z + d * w.z};
      const Vec3 to{lamp.position_m.x - p.x, lamp.position_m.y - p.y, lamp.position_m.z - p.z};
      const double r2 = dot(to, to), r = std::sqrt(r2), cos_i = to.y / r;
      for (int c = 0; c < 3; ++c) {
        const double sigma = s.medium.sigma_t_per_m[c];
        const double e = lamp.intensity_per_sr[c] * cos_i / r2;
        const double amb = kPi * 0.05;
        const double want = std::exp(-sigma * d) * (e * std::exp(-sigma * r) + amb) / (e + amb);
        worst = std::max(worst, std::fabs(out.transmittance.at(x, y, c) - want) / want);
      }
    }
  EXPECT_LT(worst, 1e-3);
}

TEST_F(VulkanScattering, PointLampGlowMatchesNumericalIntegration) {
  const Camera cam = Camera::from_horizontal_fov(48, 36, 50);
  FogScene s = base_scene();
  s.medium.sigma_t_per_m = {0.05f, 0.05f, 0.05f};
  s.medium.g = 0.3;
  Lamp lamp;
  lamp.position_m = {0.8, 1.9, 12};
  lamp.intensity_per_sr = {60, 50, 40};
  s.lighting.lamps = {lamp};
  s.render.volumetric_shadows = false;
  s.render.quality = Quality::normal;
  const Image depth = constant_depth(cam, 40);
  const ScatteringLayers out = render(depth, cam, s, Backend::vulkan);
  double max_r = 0;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) max_r = std::max(max_r, double(out.inscatter.at(x, y, 0)));
  double worst = 0;
  int glow = 0;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      if (out.inscatter.at(x, y, 0) < 0.05 * max_r) continue;
      ++glow;
      const Vec3 w = s.pose.ray_direction(cam, x, y);
      const Vec3 o = s.pose.position_m;
      for (int c = 0; c < 3; ++c) {
        const double sigma = s.medium.sigma_t_per_m[c];
        auto integrand = [&](double t) {
          const Vec3 to{lamp.position_m.x - o.x - t * w.x, lamp.position_m.y - o.y - t * w.y,
                        lamp.position_m.z - o.z - t * w.z};
          const double r2 = dot(to, to), r = std::sqrt(r2);
          return std::exp(-sigma * t) * s.medium.albedo[c] * sigma * hg(s.medium.g, dot(w, to) / r) *
                 lamp.intensity_per_sr[c] / r2 * std::exp(-sigma * r);
        };
        const double want = simpson(integrand, 0, 40, 40000);
        worst = std::max(worst, std::fabs(out.inscatter.at(x, y, c) - want) / want);
      }
    }
  EXPECT_GT(glow, 20);
  EXPECT_LT(worst, 1e-2);
}

TEST_F(VulkanScattering, HalfPlaneShadowedFractionWithinOneMarchStep) {
  const Camera cam = Camera::from_horizontal_fov(64, 48, 70);
  FogScene s;
  s.medium.sigma_t_per_m = {1e-4f, 1e-4f, 1e-4f};
  s.medium.g = 0;
  s.lighting.sky_radiance = Rgb{0, 0, 0};
  const double a = 0.5;
  s.lighting.sun = Sun{{std::sin(a), std::cos(a), 0}, {1, 1, 1}, 0.0};
  s.render.light_path_attenuation = false;
  s.render.gradient_acceleration = false;
  const int steps = 64;
  s.render.march_steps = steps;
  Image depth(cam.width, cam.height, 1, {"Z"});
  const Vec3 o = s.pose.position_m;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const Vec3 w = s.pose.ray_direction(cam, x, y);
      double d = (40 - o.z) / w.z;
      if (w.y > 0) {
        const double t_roof = (5 - o.y) / w.y;
        if (o.x + t_roof * w.x < 0 && t_roof < d) d = t_roof;
      }
      depth.at(x, y, 0) = float(d);
    }
  auto roof_visible = [&](double hx, double hz) {
    const Vec3 rel{hx - o.x, 5 - o.y, hz - o.z};
    if (rel.z <= 0) return false;
    const int ix = int(std::floor(cam.cx + cam.focal_px * rel.x / rel.z));
    const int iy = int(std::floor(cam.cy - cam.focal_px * rel.y / rel.z));
    if (ix < 0 || iy < 0 || ix >= cam.width || iy >= cam.height) return false;
    const Vec3 w = s.pose.ray_direction(cam, ix, iy);
    if (w.y <= 0) return false;
    const double t_roof = (5 - o.y) / w.y;
    return o.x + t_roof * w.x < 0 && std::fabs(depth.at(ix, iy, 0) - t_roof) < 1e-3 * t_roof;
  };
  const ScatteringLayers lit = render(depth, cam, s, Backend::vulkan);
  vktest::maybe_write_images("half_plane", lit, render(depth, cam, s, Backend::cpu));
  FogScene unshadowed = s;
  unshadowed.render.volumetric_shadows = false;
  const ScatteringLayers open = render(depth, cam, unshadowed, Backend::vulkan);
  int partial = 0;
  for (int y = 0; y < cam.height; y += 3)
    for (int x = 0; x < cam.width; x += 3) {
      const Vec3 w = s.pose.ray_direction(cam, x, y);
      const double d = depth.at(x, y, 0);
      const int n = 100000;
      int lit_count = 0;
      for (int i = 0; i < n; ++i) {
        const double t = d * (i + 0.5) / n;
        const double px = o.x + t * w.x, py = o.y + t * w.y, pz = o.z + t * w.z;
        const double hx = px + (5 - py) * std::tan(a);
        lit_count += !(py < 5 && hx < 0 && roof_visible(hx, pz));
      }
      const double want = double(lit_count) / n;
      const double got = lit.inscatter.at(x, y, 1) / open.inscatter.at(x, y, 1);
      if (want > 0.05 && want < 0.95) ++partial;
      EXPECT_NEAR(got, want, 1.0 / steps + 0.01) << x << "," << y;
    }
  EXPECT_GT(partial, 20);
}

TEST_F(VulkanScattering, GradientAccelerationErrorIsSmall) {
  const Camera cam = Camera::from_horizontal_fov(96, 64, 60);
  FogScene s = base_scene();
  s.pose.pitch_deg = -5;
  s.lighting.sun = Sun{direction_from_azimuth_elevation(-60, 25), {3, 3, 3}, 0.27};
  s.lighting.sky_radiance = Rgb{0.3f, 0.3f, 0.35f};
  s.render.quality = Quality::normal;
  const Image depth = street_depth(cam, s.pose);
  const ScatteringLayers fast = render(depth, cam, s, Backend::vulkan);
  s.render.gradient_acceleration = false;
  const ScatteringLayers exact = render(depth, cam, s, Backend::vulkan);
  EXPECT_LT(fast.timings.exact_pixels, exact.timings.exact_pixels / 2);
  EXPECT_EQ(exact.timings.exact_pixels, std::size_t(cam.width * cam.height));
  double sum = 0, worst = 0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < exact.inscatter.pixels().size(); ++i) {
    const double e = exact.inscatter.pixels()[i];
    const double err = std::fabs(fast.inscatter.pixels()[i] - e) / e;
    sum += err;
    worst = std::max(worst, err);
    ++n;
  }
  EXPECT_LT(sum / n, 5e-3);
  EXPECT_LT(worst, 5e-2);
}

// ---- GPU vs CPU on the same scenes --------------------------------------------------------------

TEST_F(VulkanScattering, MatchesCpuOnClosedFormScenes) {
  {
    const Camera cam = Camera::from_horizontal_fov(40, 30, 60);
    FogScene s = base_scene();
    s.pose.pitch_deg = -35;
    s.medium.layer_top_m = 20;
    s.lighting.sky_radiance = Rgb{0.2f, 0.25f, 0.3f};
    s.lighting.sun = Sun{direction_from_azimuth_elevation(30, 40), {3, 3, 3}, 0.27};
    s.render.quality = Quality::normal;
    expect_matches_cpu("sunlit_plane", ground_depth(cam, s.pose), cam, s);
  }
  {
    const Camera cam = Camera::from_horizontal_fov(48, 36, 50);
    FogScene s = base_scene();
    s.medium.sigma_t_per_m = {0.05f, 0.05f, 0.05f};
    Lamp lamp;
    lamp.position_m = {0.8, 1.9, 12};
    lamp.intensity_per_sr = {60, 50, 40};
    s.lighting.lamps = {lamp};
    s.render.volumetric_shadows = false;
    s.render.quality = Quality::normal;
    expect_matches_cpu("lamp_glow", constant_depth(cam, 40), cam, s);
  }
}

TEST_F(VulkanScattering, MatchesCpuOnASunlitStreetWithShafts) {
  const Camera cam = Camera::from_horizontal_fov(96, 64, 60);
  FogScene s = base_scene();
  s.pose.pitch_deg = -5;
  s.lighting.sun = Sun{direction_from_azimuth_elevation(-60, 25), {3, 3, 3}, 0.27};
  s.lighting.sky_radiance = Rgb{0.3f, 0.3f, 0.35f};
  for (Quality q : {Quality::normal, Quality::final}) {
    s.render.quality = q;
    expect_matches_cpu(q == Quality::normal ? "street_normal" : "street_final", street_depth(cam, s.pose), cam, s);
  }
}

TEST_F(VulkanScattering, MatchesCpuWithLampsShadowsAndHeightFog) {
  const Camera cam = Camera::from_horizontal_fov(96, 64, 70);
  FogScene s = base_scene();
  s.pose.pitch_deg = -8;
  s.medium.sigma_t_per_m = {0.03f, 0.035f, 0.04f};
  s.medium.height_fog = Medium::HeightFog{0.0, 6.0};
  s.lighting.sky_radiance = Rgb{0.02f, 0.02f, 0.03f};
  Lamp a;
  a.position_m = {-1.5, 4.0, 9.0};
  a.intensity_per_sr = {80, 70, 50};
  Lamp b;
  b.position_m = {4.0, 3.0, 20.0};
  b.intensity_per_sr = {40, 50, 80};
  b.spot_direction = {0, -1, 0.2};
  b.inner_angle_deg = 25;
  b.outer_angle_deg = 40;
  s.lighting.lamps = {a, b};
  s.render.quality = Quality::normal;
  expect_matches_cpu("lamps_street", street_depth(cam, s.pose), cam, s);
}

TEST_F(VulkanScattering, MatchesCpuWithNoiseAndSky) {
  const Camera cam = Camera::from_horizontal_fov(80, 48, 60);
  FogScene s = base_scene();
  s.pose.pitch_deg = 2;
  s.medium.noise.amplitude = 0.6;
  s.medium.noise.scale_m = 8;
  s.medium.layer_top_m = 40;
  s.lighting.sky_radiance = Rgb{0.4f, 0.45f, 0.5f};
  s.lighting.sun = Sun{direction_from_azimuth_elevation(20, 15), {2, 2, 2}, 0.27};
  s.render.quality = Quality::normal;
  expect_matches_cpu("noise_sky", street_depth(cam, s.pose), cam, s);
}

// ---- tiling ---------------------------------------------------------------------------------------

TEST_F(VulkanScattering, TilesGiveTheSameImage) {
  const Camera cam = Camera::from_horizontal_fov(96, 64, 60);
  FogScene s = base_scene();
  s.pose.pitch_deg = -5;
  s.lighting.sun = Sun{direction_from_azimuth_elevation(-60, 25), {3, 3, 3}, 0.27};
  s.lighting.sky_radiance = Rgb{0.3f, 0.3f, 0.35f};
  Lamp lamp;
  lamp.position_m = {-1.0, 3.0, 8.0};
  s.lighting.lamps = {lamp};
  s.render.quality = Quality::normal;
  const Image depth = street_depth(cam, s.pose);
  const Image normals = render::estimate_normals(depth.view(), cam, s.pose);
  const render::TriangleMesh mesh = render::reconstruct_occluder_mesh(depth.view(), cam, s.pose);
  render::CoreInputs in;
  in.camera = &cam;
  in.scene = &s;
  in.distance_m = depth.view();
  in.normals = normals.view();
  in.sky_radiance = *s.lighting.sky_radiance;
  struct Out {
    Image t{96, 64, 3}, r{96, 64, 3}, v{96, 64, 1}, od{96, 64, 3};
    render::CoreOutputs core() { return {t.view(), r.view(), v.view(), od.view()}; }
  };
  Out one, tiled;
  render::CoreOutputs c1 = one.core(), c2 = tiled.core();
  render::vulkan::BackendTimings t1, t2;
  backend_->render(in, &mesh, c1, {}, &t1);
  render::vulkan::BackendOptions small;
  small.max_tile_pixels = 23 * 17;  // odd sizes: tiles not aligned with the grid
  backend_->render(in, &mesh, c2, small, &t2);
  EXPECT_EQ(t1.tiles, 1);
  EXPECT_GT(t2.tiles, 8);
  EXPECT_EQ(test::max_abs_diff(one.t, tiled.t), 0.0);
  EXPECT_EQ(test::max_abs_diff(one.r, tiled.r), 0.0);
  EXPECT_EQ(test::max_abs_diff(one.v, tiled.v), 0.0);
  EXPECT_EQ(test::max_abs_diff(one.od, tiled.od), 0.0);
  EXPECT_EQ(c1.exact_pixels, c2.exact_pixels);
  EXPECT_EQ(c1.interpolated_pixels, c2.interpolated_pixels);
}

TEST_F(VulkanScattering, DeterministicAndTimed) {
  const Camera cam = Camera::from_horizontal_fov(64, 48, 60);
  FogScene s = base_scene();
  s.lighting.sun = Sun{direction_from_azimuth_elevation(60, 20), {3, 3, 3}, 0.27};
  s.lighting.sky_radiance = Rgb{0.3f, 0.3f, 0.3f};
  s.medium.noise.amplitude = 0.5;
  s.render.quality = Quality::normal;
  const Image depth = street_depth(cam, s.pose);
  const ScatteringLayers a = render(depth, cam, s, Backend::vulkan);
  const ScatteringLayers b = render(depth, cam, s, Backend::vulkan);
  EXPECT_EQ(test::max_abs_diff(a.inscatter, b.inscatter), 0.0);
  EXPECT_EQ(test::max_abs_diff(a.transmittance, b.transmittance), 0.0);
  for (float v : a.inscatter.pixels()) ASSERT_TRUE(std::isfinite(v) && v >= 0);
  EXPECT_GT(a.timings.gpu_scatter_s, 0.0);
  EXPECT_GT(a.timings.shadow_maps_s, 0.0);
  EXPECT_GT(a.timings.upload_s, 0.0);
  EXPECT_GT(a.timings.download_s, 0.0);
  EXPECT_EQ(a.timings.tiles, 1);
}

TEST_F(VulkanScattering, AutomaticSkipsSoftwareDevices) {
  if (!backend_->device().cpu_implementation) GTEST_SKIP() << "a hardware device: auto picks it";
  const Camera cam = Camera::from_horizontal_fov(16, 12, 60);
  FogScene s = base_scene();
  s.render.backend = Backend::automatic;
  const ScatteringLayers out = render_scattering(Image(), constant_depth(cam, 10), cam, s);
  EXPECT_EQ(out.backend, "cpu");
  EXPECT_NE(out.backend_notice.find("software"), std::string::npos) << out.backend_notice;
}

}  // namespace
}  // namespace mr
