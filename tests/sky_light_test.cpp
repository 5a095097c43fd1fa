// Sky light by direction (mr/sky_light.h, photo/sky_light.h; issue 11): the phase convolution
// of the environment against brute-force quadrature, a uniform environment against today's
// render (bit for bit) and against the closed form, and a sunset sky whose gradient survives
// haze with no created edge.
#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "mr/error.h"
#include "mr/estimate.h"
#include "mr/fog.h"
#include "mr/io.h"
#include "mr/scattering.h"
#include "mr/scene_json.h"
#include "mr/sky_light.h"
#include "photo/airlight.h"
#include "photo/clouds.h"
#include "photo/composite.h"
#include "photo/sky_light.h"
#include "photo/sky_mask.h"
#include "photo/sky_matte.h"
#include "render/physics/scattering.h"
#include "tests/display_luma.h"
#include "tests/flat_light_look.h"
#include "tests/gallery_look.h"

namespace mr {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kInf = std::numeric_limits<double>::infinity();

Vec3 normalized(Vec3 v) {
  const double n = std::sqrt(v.x * v.x + v.y * v.y + v.z * v.z);
  return {v.x / n, v.y / n, v.z / n};
}
double dot(const Vec3& a, const Vec3& b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}

// An analytic environment: a dark ground below the horizon, a sky from sunset orange at the
// horizon to blue at the zenith, and a bright glow around a low sun.
std::array<double, 3> analytic_env(const Vec3& w) {
  if (w.y < 0) return {0.06, 0.08, 0.05};
  const double t = std::sqrt(std::asin(std::min(1.0, w.y)) / (kPi / 2));
  const std::array<double, 3> orange{0.95, 0.45, 0.15}, blue{0.20, 0.35, 0.80};
  const Vec3 sun = direction_from_azimuth_elevation(30, 5);
  const double angle = std::acos(std::clamp(dot(w, sun), -1.0, 1.0));
  const double glow = 1.5 * std::exp(-angle * angle / (2 * 0.15 * 0.15));
  std::array<double, 3> out{};
  for (int c = 0; c < 3; ++c) out[c] = orange[c] + (blue[c] - orange[c]) * t + glow;
  return out;
}

// The environment's texels as the photo fills them: each texel's mean over 8 x 8 samples.
Image rasterize(int width, int height) {
  Image env(width, height, 3);
  constexpr int k = 8;
  for (int r = 0; r < height; ++r)
    for (int c = 0; c < width; ++c) {
      double sum[3] = {0, 0, 0}, weight = 0;
      for (int j = 0; j < k; ++j)
        for (int i = 0; i < k; ++i) {
          const double row = r + (j + 0.5) / k, col = c + (i + 0.5) / k;
          const Vec3 w = photo::latlong_direction(width, height, col, row);
          const double cos_el = std::sqrt(std::max(0.0, 1 - w.y * w.y));  // area weight
          const auto v = analytic_env(w);
          for (int ch = 0; ch < 3; ++ch) sum[ch] += cos_el * v[ch];
          weight += cos_el;
        }
      for (int ch = 0; ch < 3; ++ch) env.at(c, r, ch) = float(sum[ch] / weight);
    }
  return env;
}

// Brute force: integral of env(w') p(w . w') dw' in polar coordinates about w (theta from w),
// midpoint rule, fine enough to resolve the phase's peak.
std::array<double, 3> brute_force(const Vec3& w, double g) {
  const Vec3 helper = std::abs(w.y) < 0.9 ? Vec3{0, 1, 0} : Vec3{1, 0, 0};
  const Vec3 u = normalized({helper.y * w.z - helper.z * w.y, helper.z * w.x - helper.x * w.z,
                             helper.x * w.y - helper.y * w.x});
  const Vec3 v{w.y * u.z - w.z * u.y, w.z * u.x - w.x * u.z, w.x * u.y - w.y * u.x};
  constexpr int n_theta = 1200, n_phi = 480;
  std::array<double, 3> sum{};
  for (int i = 0; i < n_theta; ++i) {
    const double theta = (i + 0.5) * kPi / n_theta;
    const double p = render::physics::henyey_greenstein(g, std::cos(theta));
    const double d_omega = std::sin(theta) * (kPi / n_theta) * (2 * kPi / n_phi);
    for (int j = 0; j < n_phi; ++j) {
      const double phi = (j + 0.5) * 2 * kPi / n_phi;
      const double s = std::sin(theta), ct = std::cos(theta);
      const Vec3 d{ct * w.x + s * (std::cos(phi) * u.x + std::sin(phi) * v.x),
                   ct * w.y + s * (std::cos(phi) * u.y + std::sin(phi) * v.y),
                   ct * w.z + s * (std::cos(phi) * u.z + std::sin(phi) * v.z)};
      const auto e = analytic_env(d);
      for (int c = 0; c < 3; ++c) sum[c] += e[c] * p * d_omega;
    }
  }
  return sum;
}

TEST(SkyLight, ConvolutionMatchesBruteForceQuadrature) {
  // Tolerance: 0.5 % of the environment's range (about 2.5) at every tested direction, for the
  // looks' phases (dense g = 0.3, haze g = 0.6) and a sharper one; the map's own sampling of a
  // horizon step and a sun glow is what limits it.
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> az(-180, 180), el(-30, 80);
  for (const double g : {0.3, 0.6, 0.8}) {
    const photo::LatLongSizes sizes = photo::latlong_sizes_for(g);
    const Image env = rasterize(sizes.env_width, sizes.env_height);
    const Image conv = photo::convolve_henyey_greenstein(env, g, sizes.out_width, sizes.out_height);
    double worst = 0;
    std::vector<Vec3> dirs = {direction_from_azimuth_elevation(30, 5),  // the sun
                              direction_from_azimuth_elevation(30, 0.5),
                              direction_from_azimuth_elevation(-120, -3),
                              direction_from_azimuth_elevation(0, 89)};
    for (int i = 0; i < 12; ++i) dirs.push_back(direction_from_azimuth_elevation(az(rng), el(rng)));
    for (const Vec3& w : dirs) {
      const auto ref = brute_force(w, g);
      const auto got = photo::sample_latlong(conv, w);
      for (int c = 0; c < 3; ++c) worst = std::max(worst, std::abs(got[c] - ref[c]));
    }
    std::printf("g = %.1f: env %dx%d, convolved %dx%d, worst |error| %.4f (env range ~2.5)\n", g,
                sizes.env_width, sizes.env_height, sizes.out_width, sizes.out_height, worst);
    EXPECT_LT(worst, 0.005 * 2.5) << "g = " << g;
  }
}

// The scale's wide blurs (photo/sky_light.h, wide_gaussian_blur: three box filters and a small
// Gaussian above 4 px) against the Gaussian they stand for: an impulse's response keeps its
// sum, is symmetric, has the Gaussian's variance along each axis (within 0.5 %: the sampling of
// the small Gaussian) and nearly its shape: the L1 distance to the sampled Gaussian under 0.08
// (three equal boxes in the continuous limit: 0.073 in 2-D, 0.054 in 1-D, the Irwin-Hall
// density against the normal); a constant stays the constant (edges replicated).
TEST(SkyLight, WideBlurIsAGaussianOfTheSameVariance) {
  for (double sigma : {2.5, 6.0, 19.2, 40.0}) {
    const int n = int(12 * sigma) | 1, c = n / 2;
    cv::Mat impulse(n, n, CV_32F, cv::Scalar(0));
    impulse.at<float>(c, c) = 1;
    photo::wide_gaussian_blur(impulse, sigma);
    double sum = 0, var_x = 0, var_y = 0, asymmetry = 0, l1 = 0;
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const double v = impulse.at<float>(y, x);
        sum += v;
        var_x += v * (x - c) * (x - c);
        var_y += v * (y - c) * (y - c);
        asymmetry = std::max(asymmetry, std::abs(v - double(impulse.at<float>(n - 1 - y, x))));
        const double r2 = double(x - c) * (x - c) + double(y - c) * (y - c);
        l1 += std::abs(v - std::exp(-r2 / (2 * sigma * sigma)) / (2 * kPi * sigma * sigma));
      }
    std::printf(
        "wide blur, sigma %.1f px: sum %.6f, variance x %.2f y %.2f (sigma^2 %.2f), "
        "L1 to the Gaussian %.4f\n",
        sigma, sum, var_x, var_y, sigma * sigma, l1);
    EXPECT_NEAR(sum, 1, 1e-4);
    EXPECT_NEAR(var_x / (sigma * sigma), 1, 0.005);
    EXPECT_NEAR(var_y / (sigma * sigma), 1, 0.005);
    EXPECT_LT(asymmetry, 1e-7);
    EXPECT_LT(l1, 0.08);
    cv::Mat flat(n, n, CV_32FC3, cv::Scalar(0.25, 0.5, 2));
    photo::wide_gaussian_blur(flat, sigma);
    for (int y = 0; y < n; y += 7)
      for (int x = 0; x < n; x += 7) EXPECT_NEAR(flat.at<cv::Vec3f>(y, x)[2], 2.0f, 1e-5f);
  }
}

TEST(SkyLight, ConvolutionOfAConstantIsTheConstant) {
  Image env(64, 32, 3);
  for (float& v : env.pixels()) v = 0.37f;
  const Image conv = photo::convolve_henyey_greenstein(env, 0.6, 32, 16);
  for (float v : conv.pixels()) EXPECT_NEAR(v, 0.37f, 1e-6f);
}

// A level camera 1.6 m above flat ground: the sky above the horizon row (+inf), the ground's
// closed-form distance below.
constexpr int kW = 320, kH = 240;
const Camera kCamera = Camera::from_horizontal_fov(kW, kH, 60);

Image ground_plane_distance(const FogScene& scene) {
  Image d(kW, kH, 1);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const Vec3 w = scene.pose.ray_direction(kCamera, x, y);
      d.at(x, y, 0) = w.y < -1e-4 ? float(scene.pose.position_m.y / -w.y) : float(kInf);
    }
  return d;
}

FogScene haze_scene() {  // the gallery's haze look: 2 km visibility in a 1.5 km layer, g = 0.6
  FogScene s;
  const float sigma = float(extinction_from_visibility(2000));
  s.medium.sigma_t_per_m = {sigma, sigma, sigma};
  s.medium.g = 0.6;
  s.medium.layer_top_m = 1500;
  s.render.backend = Backend::cpu;
  return s;
}

FogScene all_sky_haze_scene() {  // looking up (pitch 25 degrees): every pixel is sky
  FogScene s = haze_scene();
  s.pose.pitch_deg = 25;
  return s;
}

bool same_bits(const Image& a, const Image& b) {
  return a.pixels().size() == b.pixels().size() &&
         std::memcmp(a.pixels().data(), b.pixels().data(), a.pixels().size() * sizeof(float)) == 0;
}

TEST(SkyLight, UniformEnvironmentReproducesTodaysResultExactly) {
  FogScene scene = haze_scene();
  const Rgb sky{0.61f, 0.66f, 0.74f};
  scene.lighting.sky_radiance = sky;
  const Image distance = ground_plane_distance(scene);
  Image photo(kW, kH, 3);  // sky and ground both exactly L_sky
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x)
      for (int c = 0; c < 3; ++c) photo.at(x, y, c) = sky[c];
  EXPECT_TRUE(sky_light_from_photo(photo, distance, kCamera, scene, sky).deviation.empty());
  FogScene by_direction = scene;
  by_direction.lighting.sky_by_direction = true;
  const FogLayers a = fog(photo, distance, kCamera, scene);
  const FogLayers b = fog(photo, distance, kCamera, by_direction);
  EXPECT_TRUE(same_bits(a.composite, b.composite));
  EXPECT_TRUE(same_bits(a.inscatter, b.inscatter));
  EXPECT_TRUE(same_bits(a.transmittance, b.transmittance));
}

TEST(SkyLight, UniformEnvironmentOfAnotherRadianceIsTheClosedForm) {
  // Sky and ground both L_env = 1.8 L_sky: L_in(w) = L_env in every direction, so R must be
  // albedo L_env (1 - exp(-sigma d)) (unbounded homogeneous fog: the sky's 1 - tau is 1).
  FogScene scene = haze_scene();
  scene.medium.layer_top_m = kInf;
  scene.medium.albedo = {0.9f, 0.95f, 1.0f};
  scene.lighting.sky_radiance = Rgb{0.5f, 0.55f, 0.6f};
  scene.lighting.sky_by_direction = true;
  const Rgb env{0.9f, 0.99f, 1.08f};
  const Image distance = ground_plane_distance(scene);
  Image photo(kW, kH, 3);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x)
      for (int c = 0; c < 3; ++c) photo.at(x, y, c) = env[c];
  const FogLayers f = fog(photo, distance, kCamera, scene);
  double worst = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x)
      for (int c = 0; c < 3; ++c) {
        const double d = distance.at(x, y, 0);
        const double one_minus_tau =
            std::isinf(d) ? 1.0 : -std::expm1(-double(scene.medium.sigma_t_per_m[c]) * d);
        const double expected = double(scene.medium.albedo[c]) * env[c] * one_minus_tau;
        worst = std::max(worst, std::abs(f.inscatter.at(x, y, c) - expected) / expected);
      }
  std::printf("uniform environment 1.8 L_sky: worst relative error of R %.2e\n", worst);
  EXPECT_LT(worst, 1e-5);
}

using test::linear;  // display-referred [0, 1] -> scene-linear (tests/gallery_look.h)
using test::linear_photo;

// A sunset photo: sunset orange at the horizon to blue at the top, a dark meadow below.
Image sunset_photo(const FogScene& scene) {
  Image photo(kW, kH, 3);
  const float orange[3] = {0.98f, 0.58f, 0.30f}, blue[3] = {0.35f, 0.52f, 0.85f};
  const float meadow[3] = {0.20f, 0.26f, 0.12f}, near[3] = {0.12f, 0.16f, 0.08f};
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const Vec3 w = scene.pose.ray_direction(kCamera, x, y);
      for (int c = 0; c < 3; ++c) {
        float v;
        if (w.y >= -1e-4) {
          const float t = std::clamp(float(std::asin(w.y) / 0.45), 0.0f, 1.0f);  // 26 deg
          v = orange[c] + (blue[c] - orange[c]) * t;
        } else {
          const float t = std::clamp(float(-w.y / 0.5), 0.0f, 1.0f);
          v = meadow[c] + (near[c] - meadow[c]) * t;
        }
        photo.at(x, y, c) = linear(v);
      }
    }
  return photo;
}

// The gallery's created-edge measure (gallery/measures.py): the fogged image's gradient of
// display luma more than twice the photo's plus 0.01; over the rows [0, rows).
double created_edge_fraction(const Image& photo, const Image& fogged, int rows) {
  const cv::Mat gp = test::forward_gradient(test::display_luma(photo)),
                gf = test::forward_gradient(test::display_luma(fogged));
  std::size_t created = 0;
  for (int y = 0; y < rows; ++y)
    for (int x = 0; x < gp.cols; ++x)
      created += gf.at<float>(y, x) > 2 * gp.at<float>(y, x) + 0.01f;
  return double(created) / double(std::size_t(rows) * gp.cols);
}

TEST(SkyLight, SunsetGradientSurvivesHazeWithNoCreatedEdge) {
  FogScene scene = haze_scene();
  scene.pose.pitch_deg = 8;  // more sky than ground
  const Image distance = ground_plane_distance(scene);
  const Image photo = sunset_photo(scene);
  scene.lighting.sky_radiance = estimate_airlight(photo);  // as the looks: 'auto'
  FogScene by_direction = scene;
  by_direction.lighting.sky_by_direction = true;
  const FogLayers uniform = fog(photo, distance, kCamera, scene);
  const FogLayers lit = fog(photo, distance, kCamera, by_direction);
  if (const char* folder = std::getenv("MR_TEST_IMAGES"); folder && *folder) {  // to look at
    write_image(std::string(folder) + "/sunset_photo.png", photo);
    write_image(std::string(folder) + "/sunset_haze_uniform.png", uniform.composite);
    write_image(std::string(folder) + "/sunset_haze_by_direction.png", lit.composite);
  }
  // Warmth (R / B) of the fogged sky down the centre column, from the top row to the horizon.
  const int x = kW / 2;
  int horizon_row = 0;
  while (std::isinf(distance.at(x, horizon_row + 1, 0))) ++horizon_row;
  auto warmth = [&](const Image& img, int y) { return img.at(x, y, 0) / img.at(x, y, 2); };
  const double photo_top = warmth(photo, 0), photo_low = warmth(photo, horizon_row - 2);
  const double uni_top = warmth(uniform.composite, 0),
               uni_low = warmth(uniform.composite, horizon_row - 2);
  const double lit_top = warmth(lit.composite, 0), lit_low = warmth(lit.composite, horizon_row - 2);
  std::printf(
      "sky warmth R/B top -> horizon: photo %.3f -> %.3f, uniform sky light %.3f -> "
      "%.3f, by direction %.3f -> %.3f\n",
      photo_top, photo_low, uni_top, uni_low, lit_top, lit_low);
  // Uniform: the sky is one flat colour (the case); by direction: warmer toward the horizon,
  // every row at least as warm as the one above it (the photo's ordering kept).
  EXPECT_LT(std::abs(uni_low - uni_top), 0.02 * uni_top);
  EXPECT_GT(lit_low, 1.5 * lit_top);
  for (int y = 1; y < horizon_row - 1; ++y)
    EXPECT_GE(warmth(lit.composite, y), warmth(lit.composite, y - 1) * (1 - 1e-4)) << y;
  // Across the frame the sky is smooth: no created edge in it (the issue's target, 0.02 %).
  // (Below, the ground plane's fog rises steeply toward the horizon where this flat synthetic
  // meadow has no texture: that is the geometry's, with or without the sky light.)
  const double edges = created_edge_fraction(photo, lit.composite, horizon_row - 1);
  std::printf("created-edge pixels in the sky by direction %.4f %%, uniform %.4f %%\n", 100 * edges,
              100 * created_edge_fraction(photo, uniform.composite, horizon_row - 1));
  EXPECT_LE(edges, 2e-4);
}

// The gallery's created-edge measure and its haze / dense looks on an automatic estimate.
using test::fog_auto_look;
using test::gallery_created_edges;

using test::fog_auto_look_flat_light;
using test::fog_with_sky_light;

// `photo` fogged in `scene` (all_sky_haze_scene's, at `distance`), lit as the looks light it: by
// the photo's own sky ('auto', by direction, set on `scene`), with the brightness scale. Photo
// and result are written as <name>_photo.png and <name>_haze.png under MR_TEST_IMAGES.
FogLayers all_sky_haze_of(const Image& photo, const Image& distance, FogScene& scene,
                          const std::string& name) {
  scene.lighting.sky_by_direction = true;
  scene.lighting.sky_radiance = estimate_airlight(photo);
  FogLayers fogged = fog_with_sky_light(photo, distance, Image(), scene, true, kCamera);
  if (const char* folder = std::getenv("MR_TEST_IMAGES"); folder && *folder) {  // to look at
    const std::string f(folder);
    write_image(f + "/" + name + "_photo.png", photo);
    write_image(f + "/" + name + "_haze.png", fogged.composite);
  }
  return fogged;
}

// The sun bank look (gallery/looks/sun_bank.json): 90 m visibility, height fog (scale 12 m)
// under a 40 m top, g = 0.6, the sun at azimuth 20, elevation 8 degrees.
FogLayers fog_sun_bank_look(const Image& photo, const Camera& camera, const SceneEstimate& est) {
  FogScene sun = est.scene;
  const float sigma = float(extinction_from_visibility(90));
  sun.medium.sigma_t_per_m = {sigma, sigma, sigma};
  sun.medium.g = 0.6;
  sun.medium.height_fog = Medium::HeightFog{0.0, 12.0};
  sun.medium.layer_top_m = 40;
  sun.lighting.sun = Sun{direction_from_azimuth_elevation(20, 8), Rgb{3, 3, 3}, 0.27, true};
  sun.render.backend = Backend::cpu;
  sun.lighting.sky_by_direction = true;
  if (!sun.lighting.sky_radiance) sun.lighting.sky_radiance = estimate_airlight(photo);
  return fog(photo, est.geometry.distance_m, est.geometry.sky_alpha, camera, sun);
}

// Backlit clouds (class (a) of the held-out set at the end of the last session, rebuilt here
// without looking at it): an overcast sky with a bright region around a sun hidden behind dark
// clouds, light rays fanning down from it, the clouds' edges soft (a few pixels to tens), a
// dark land below. In haze the sky, seen through the whole layer, is the fog's own light (the
// phase-lobe average of the sky); a cloud must not stay a sharp dark shape against it.
constexpr int kBacklitW = 640, kBacklitH = 480;
cv::Mat backlit_clouds_display() {
  constexpr int w = kBacklitW, h = kBacklitH;
  cv::Mat m(h, w, CV_32FC3);
  // Dark clouds: ellipses with soft edges (blurred over ~6 px), one of them over the sun.
  cv::Mat cover(h, w, CV_32F, cv::Scalar(0));
  cv::ellipse(cover, cv::Point(110, 55), cv::Size(120, 34), 8, 0, 360, cv::Scalar(1), cv::FILLED);
  cv::ellipse(cover, cv::Point(425, 100), cv::Size(80, 30), -5, 0, 360, cv::Scalar(1), cv::FILLED);
  cv::ellipse(cover, cv::Point(585, 20), cv::Size(110, 34), 0, 0, 360, cv::Scalar(1), cv::FILLED);
  cv::ellipse(cover, cv::Point(230, 168), cv::Size(150, 16), 3, 0, 360, cv::Scalar(1), cv::FILLED);
  cv::GaussianBlur(cover, cover, cv::Size(0, 0), 6);
  const double sun_x = 0.66 * w, sun_y = 0.21 * h;
  const int ridge = int(0.48 * h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float t = float(y) / ridge;
      cv::Vec3f c = cv::Vec3f(0.50f, 0.57f, 0.68f) * (1 - t) + cv::Vec3f(0.74f, 0.73f, 0.72f) * t;
      const double dx = x - sun_x, dy = y - sun_y, r = std::hypot(dx, dy);
      const double glow = 0.5 * std::exp(-r * r / (2 * 75.0 * 75.0));
      // Rays: brighter spokes below the sun, fading with the distance from it.
      const double angle = std::atan2(dy, dx);
      const double rays = dy > 0 ? 0.10 * (0.5 + 0.5 * std::cos(14 * angle)) *
                                       std::pow(std::sin(angle), 2) * std::exp(-r / 180.0) *
                                       std::min(1.0, r / 40.0)
                                 : 0.0;
      c += cv::Vec3f(1.0f, 0.96f, 0.88f) * float(glow + rays);
      // The cloud's rim near the sun is lit (silver lining), its body dark.
      const float k = cover.at<float>(y, x);
      const cv::Vec3f body(0.26f, 0.27f, 0.31f);
      const cv::Vec3f rim = body + cv::Vec3f(0.6f, 0.58f, 0.5f) * float(std::exp(-r / 90.0));
      const float edge = 4 * k * (1 - k);
      const cv::Vec3f cloud = body * (1 - edge) + rim * edge;
      m.at<cv::Vec3f>(y, x) = c * (1 - k) + cloud * k;
    }
  // Dark land: a ridge line a little below the middle, textured.
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> grain(-0.04f, 0.04f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const double top = ridge + 8 * std::sin(x / 60.0) + 4 * std::sin(x / 17.0);
      if (y < top) continue;
      const float v = 0.12f + 0.03f * float(y - top) / h + grain(rng);
      m.at<cv::Vec3f>(y, x) = cv::Vec3f(v + 0.02f, v + 0.03f, v);
    }
  cv::GaussianBlur(m, m, cv::Size(0, 0), 0.7);  // a lens
  return m;
}

TEST(SkyLight, BacklitCloudsInHazeCreateNoEdge) {
  const cv::Mat display = backlit_clouds_display();
  constexpr int kW = kBacklitW, kH = kBacklitH;
  const Camera camera = Camera::from_horizontal_fov(kW, kH, 60);
  const Image photo = linear_photo(display);
  // The horizon along the land's lowest dips (as a user marks it, or lines find it): the
  // case is the clouds, not a misplaced horizon (a horizon estimated above the land's line puts
  // the sky under it on the ground; see the report in gallery/results/sky11_tune.md).
  Annotations horizon;
  horizon.horizon =
      std::array<PixelPoint, 2>{PixelPoint{0, 0.5 * kH}, PixelPoint{kW - 1.0, 0.5 * kH}};
  const SceneEstimate est = estimate_scene(photo, camera, horizon);
  std::size_t finite_above = 0;  // surfaces above the land: what the sky mask left out
  for (int y = 0; y < int(0.5 * kH); ++y)
    for (int x = 0; x < kW; ++x) finite_above += std::isfinite(est.geometry.distance_m.at(x, y, 0));
  // The dark cloud over the sun, ringed by the glow, held up by nothing: a cloud, kilometres
  // away, seen through the whole layer like the sky around it. Its sunlit rim makes its edge
  // steep (a mean gradient above the sky mask's texture limit) but smooth (a coherent ramp).
  std::size_t cloud = 0, cloud_sky = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x)
      if (std::pow((x - 425.0) / 70, 2) + std::pow((y - 100.0) / 22, 2) < 1) {
        ++cloud;
        cloud_sky += std::isinf(est.geometry.distance_m.at(x, y, 0));
      }
  const FogLayers haze = fog_auto_look(photo, camera, est, 2000, 1500, 0.6);
  const FogLayers dense = fog_auto_look(photo, camera, est, 60, 80, 0.3);
  Image haze_map, dense_map;
  const double e_haze = gallery_created_edges(photo, haze.composite, &haze_map);
  const double e_dense = gallery_created_edges(photo, dense.composite, &dense_map);
  if (const char* folder = std::getenv("MR_TEST_IMAGES"); folder && *folder) {  // to look at
    const std::string f(folder);
    write_image(f + "/backlit_photo.png", photo);
    write_image(f + "/backlit_haze.png", haze.composite);
    write_image(f + "/backlit_dense.png", dense.composite);
    write_image(f + "/backlit_haze_edges.png", haze_map);
    write_image(f + "/backlit_dense_edges.png", dense_map);
    Image alpha(kW, kH, 3);
    for (int y = 0; y < kH; ++y)
      for (int x = 0; x < kW; ++x) {
        const float d = est.geometry.distance_m.at(x, y, 0);
        const float v = std::isfinite(d) ? float(-std::expm1(-d / 200.0)) : 1.0f;
        alpha.at(x, y, 0) = v, alpha.at(x, y, 1) = est.geometry.sky_alpha.at(x, y, 0);
        alpha.at(x, y, 2) = v;
      }
    write_image(f + "/backlit_depth_alpha.png", alpha);
  }
  std::printf(
      "backlit clouds: %zu surface pixels in the upper half, the sun's cloud %.1f %% "
      "sky; created-edge pixels haze %.4f %%, dense %.4f %%\n",
      finite_above, 100.0 * double(cloud_sky) / double(cloud), 100 * e_haze, 100 * e_dense);
  // Before (the texture test on the mean gradient alone): 0 % of it sky, on the far billboard
  // 46 m away (haze transmittance 0.91: a dark shape under a veil that hides the sky around it).
  EXPECT_GE(double(cloud_sky), 0.9 * double(cloud));
  // The issue's target for dense fog and haze: at most 0.02 % of the pixels.
  EXPECT_LE(e_haze, 2e-4);
  EXPECT_LE(e_dense, 2e-4);
}

// The same photo with the horizon estimated (no annotations): a weak cue (a level horizon
// through a horizontal vanishing point, confidence 0.15) 34 px above the land's line cut the
// glow's lower part off the sky: below the guess it became structure standing on the land,
// left nearly clear by haze under the veil above (a flat bright patch with a hard upper edge:
// 0.077 % created edges). The sky is only ever above the horizon, so a weak horizon that open
// sky continues below (with no edge) is lowered under it.
TEST(SkyLight, BacklitCloudsUnderAWeakHorizonLowerIt) {
  constexpr int kW = kBacklitW, kH = kBacklitH;
  const Camera camera = Camera::from_horizontal_fov(kW, kH, 60);
  const cv::Mat display = backlit_clouds_display();
  const Image photo = linear_photo(display);
  const SceneEstimate est = estimate_scene(photo, camera, Annotations{});
  const FogLayers haze = fog_auto_look(photo, camera, est, 2000, 1500, 0.6);
  const FogLayers dense = fog_auto_look(photo, camera, est, 60, 80, 0.3);
  const double e_haze = gallery_created_edges(photo, haze.composite);
  const double e_dense = gallery_created_edges(photo, dense.composite);
  if (const char* folder = std::getenv("MR_TEST_IMAGES"); folder && *folder)
    write_image(std::string(folder) + "/backlit_auto_haze.png", haze.composite);
  std::printf(
      "backlit clouds, automatic horizon: %s; lowered %.0f px; created-edge pixels haze "
      "%.4f %%, dense %.4f %%\n",
      est.notes.front().c_str(), est.geometry.horizon_lowered_px, 100 * e_haze, 100 * e_dense);
  EXPECT_GT(est.geometry.horizon_lowered_px, 0.0);
  EXPECT_LE(e_haze, 2e-4);
  EXPECT_LE(e_dense, 2e-4);
}

// A storm's cloud deck over mountains under the level fall-back horizon (gallery/tune valendas,
// rebuilt from its description): a dark grey deck hangs from the top of the frame's left half
// and reaches below its middle row, where the fall-back puts the horizon; under it a pale sky
// runs down to a far, low ridge on the left; on the right a textured mountain rises above the
// middle to a peak. The mask clipped at the guess took the deck (held up by the guess) and the pale
// sky under it (cut off from the top border by the deck) for structures a few metres away: dense
// fog showed the guess as a step across the pale sky, the night look the deck as a dark block.
constexpr int kDeckW = 640, kDeckH = 426;
// With `tower`: no deck, but a smooth tower of its colour standing on the land through the guess.
cv::Mat storm_deck_display(bool tower = false) {
  constexpr int w = kDeckW, h = kDeckH;
  cv::Mat m(h, w, CV_32FC3);
  cv::Mat deck(h, w, CV_32F, cv::Scalar(0));
  if (tower) {
    cv::rectangle(deck, cv::Point(280, 90), cv::Point(339, h - 1), cv::Scalar(1), cv::FILLED);
  } else {
    cv::ellipse(deck, cv::Point(230, 60), cv::Size(200, 190), 0, 0, 360, cv::Scalar(1), cv::FILLED);
    cv::GaussianBlur(deck, deck, cv::Size(0, 0), 7);  // a cloud's soft edge
  }
  std::mt19937 rng(17);
  std::uniform_real_distribution<float> grain(-0.05f, 0.05f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      // A pale overcast sky, brightest at the low left, and the deck's smooth dark grey.
      const float t = float(y) / h;
      const cv::Vec3f sky = cv::Vec3f(0.70f, 0.69f, 0.64f) + cv::Vec3f(0.10f, 0.10f, 0.08f) * t;
      const float k = deck.at<float>(y, x);
      const cv::Vec3f cloud = cv::Vec3f(0.30f, 0.30f, 0.28f) +
                              cv::Vec3f(0.03f, 0.03f, 0.03f) * float(std::sin(x / 40.0 + y / 25.0));
      cv::Vec3f c = sky * (1 - k) + cloud * k;
      // The land: a far low ridge at the left (~70 % down), rising to a peak above the middle
      // at the right; a rough rock face, darker where nearer.
      const double ridge =
          x < 360 ? 0.70 * h + 6 * std::sin(x / 23.0)
                  : 0.70 * h - (x - 360) * (0.70 * h - 0.38 * h) / 200.0 + 5 * std::sin(x / 9.0);
      const double top = std::max(ridge, 0.38 * h + 0.9 * std::max(0, x - 560));
      if (y >= top) {
        const float v = 0.16f + 0.10f * float(y - top) / h + grain(rng);
        c = cv::Vec3f(v + 0.01f, v + 0.02f, v + 0.03f);
      }
      m.at<cv::Vec3f>(y, x) = c;
    }
  cv::GaussianBlur(m, m, cv::Size(0, 0), 0.7);  // a lens
  return m;
}

TEST(SkyLight, StormDeckUnderTheFallBackHorizonIsSky) {
  const Camera camera = Camera::from_horizontal_fov(kDeckW, kDeckH, 60);
  const Image photo = linear_photo(storm_deck_display());
  EstimateOptions before;
  before.sky_cut_by_a_guess = false;
  const SceneEstimate est = estimate_scene(photo, camera, Annotations{});
  const SceneEstimate est_before = estimate_scene(photo, camera, Annotations{}, before);
  // The deck's body (well inside its soft edge) and the pale sky under it at the left.
  auto sky_share = [&](const SceneEstimate& e, int x0, int x1, int y0, int y1) {
    std::size_t n = 0, sky = 0;
    for (int y = y0; y < y1; ++y)
      for (int x = x0; x < x1; ++x) ++n, sky += std::isinf(e.geometry.distance_m.at(x, y, 0));
    return double(sky) / double(n);
  };
  const double deck = sky_share(est, 20, 200, 20, 150),
               deck_before = sky_share(est_before, 20, 200, 20, 150);
  const double pale = sky_share(est, 20, 300, 272, 285),
               pale_before = sky_share(est_before, 20, 300, 272, 285);
  const FogLayers dense = fog_auto_look(photo, camera, est, 60, 80, 0.3);
  const FogLayers dense_before = fog_auto_look(photo, camera, est_before, 60, 80, 0.3);
  const FogLayers haze = fog_auto_look(photo, camera, est, 2000, 1500, 0.6);
  Image dense_map;
  const double e_dense = gallery_created_edges(photo, dense.composite, &dense_map);
  const double e_dense_before = gallery_created_edges(photo, dense_before.composite);
  const double e_haze = gallery_created_edges(photo, haze.composite);
  const FogLayers haze_before = fog_auto_look(photo, camera, est_before, 2000, 1500, 0.6);
  const double e_haze_before = gallery_created_edges(photo, haze_before.composite);
  if (const char* folder = std::getenv("MR_TEST_IMAGES"); folder && *folder) {  // to look at
    const std::string f(folder);
    write_image(f + "/storm_deck_photo.png", photo);
    write_image(f + "/storm_deck_haze_before.png", haze_before.composite);
    write_image(f + "/storm_deck_dense.png", dense.composite);
    write_image(f + "/storm_deck_dense_before.png", dense_before.composite);
    write_image(f + "/storm_deck_haze.png", haze.composite);
    write_image(f + "/storm_deck_dense_edges.png", dense_map);
  }
  std::printf(
      "storm deck, fall-back horizon lowered %.0f px (before %.0f px); sky share: deck %.3f "
      "(before %.3f), pale sky under it %.3f (before %.3f); created-edge pixels dense %.4f %% "
      "(before %.4f %%), haze %.4f %% (before %.4f %%)\n",
      est.geometry.horizon_lowered_px, est_before.geometry.horizon_lowered_px, deck, deck_before,
      pale, pale_before, 100 * e_dense, 100 * e_dense_before, 100 * e_haze, 100 * e_haze_before);
  EXPECT_GE(deck, 0.99);
  EXPECT_GE(pale, 0.99);
  EXPECT_GT(est.geometry.horizon_lowered_px, 0.0);
  EXPECT_LE(e_dense, 2e-4);
  EXPECT_LE(e_haze, 2e-4);
  // What the join mends: the deck was a surface before.
  EXPECT_LT(deck_before, 0.5);
}

// The join's other side: a smooth grey tower of the deck's colour rising from the land through
// the guess stands on the land in the probe too (it runs down to the frame's bottom), so it is
// in no sky component of the probe and nothing is joined: the estimate is the one without the
// join, the tower a surface.
TEST(SkyLight, AGreyTowerThroughTheFallBackHorizonIsNotJoinedToTheSky) {
  constexpr int w = kDeckW, h = kDeckH;
  const Camera camera = Camera::from_horizontal_fov(w, h, 60);
  const Image photo = linear_photo(storm_deck_display(/*tower=*/true));
  EstimateOptions without;
  without.sky_cut_by_a_guess = false;
  const SceneEstimate est = estimate_scene(photo, camera, Annotations{});
  const SceneEstimate est_without = estimate_scene(photo, camera, Annotations{}, without);
  std::size_t tower = 0, tower_finite = 0, differ = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float a = est.geometry.distance_m.at(x, y, 0),
                  b = est_without.geometry.distance_m.at(x, y, 0);
      differ += !(a == b || (std::isnan(a) && std::isnan(b)));
      if (x >= 290 && x < 330 && y >= 100 && y < 290) ++tower, tower_finite += std::isfinite(a);
    }
  std::printf(
      "grey tower through the guess: %zu of %zu tower pixels finite, %zu distances differ "
      "from the estimate without the join\n",
      tower_finite, tower, differ);
  EXPECT_EQ(tower_finite, tower);
  EXPECT_EQ(differ, 0u);
}

// A calm sea meeting the sky at a far, faint shore line (gallery/tune summer_1am; the held-out
// sea photos' class, rebuilt here without looking at them): a dusk sky from a pink glow at the
// horizon to blue above, the water its mirror image a little darker, with a thin dark line of
// far shore on the horizon. The horizon is annotated: the case is the water's distance, not
// the horizon. Near the horizon the ground's confidence ramps to 0 and the refinement filled
// the mirror-smooth water up to the shore's line with the nearer water's distance (~60 m from
// 1.6 m where the plane says several hundred): in haze the sky above the line, seen along the
// layer's slant path, became the fog's light while the water under it stayed nearly clear, a
// hard step over twice the photo's faint line.
constexpr int kSeaW = 640, kSeaH = 400;
Image sea_horizon_photo(int horizon_row) {
  Image photo(kSeaW, kSeaH, 3);
  auto sky = [&](double above) {  // display values, above = rows above the horizon
    const double t = std::clamp(above / horizon_row, 0.0, 1.0);
    const double glow = std::exp(-above / 25.0);
    return std::array<double, 3>{0.66 - 0.22 * glow - 0.06 * t, 0.64 - 0.28 * glow - 0.04 * t,
                                 0.78 - 0.30 * glow + 0.04 * t};
  };
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> ripple(-0.006f, 0.006f);
  for (int y = 0; y < kSeaH; ++y)
    for (int x = 0; x < kSeaW; ++x) {
      const double dy = y - horizon_row + 0.5;
      std::array<double, 3> c = dy < 0 ? sky(-dy) : sky(dy);
      if (dy >= 0)
        for (double& v : c) v = 0.9 * v + ripple(rng);
      // The far shore: a faint dark line two pixels thick just under the horizon (a shore a
      // few kilometres away lies less than a pixel below it from 1.6 m).
      if (dy >= 0 && dy < 2)
        for (double& v : c) v *= 0.92;
      for (int k = 0; k < 3; ++k) photo.at(x, y, k) = linear(float(std::clamp(c[k], 0.0, 1.0)));
    }
  cv::Mat m(kSeaH, kSeaW, CV_32FC3, photo.data());
  cv::GaussianBlur(m, m, cv::Size(0, 0), 0.7);  // a lens
  return photo;
}

TEST(SkyLight, SeaHorizonInHazeCreatesNoEdge) {
  const Camera camera = Camera::from_horizontal_fov(kSeaW, kSeaH, 60);
  constexpr int horizon_row = 220;
  const Image photo = sea_horizon_photo(horizon_row);
  Annotations horizon;
  horizon.horizon = std::array<PixelPoint, 2>{PixelPoint{0, double(horizon_row)},
                                              PixelPoint{kSeaW - 1.0, double(horizon_row)}};
  EstimateOptions before;
  before.sea_horizon = false;
  const SceneEstimate est = estimate_scene(photo, camera, horizon);
  const SceneEstimate est_before = estimate_scene(photo, camera, horizon, before);
  const FogLayers haze = fog_auto_look(photo, camera, est, 2000, 1500, 0.6);
  const FogLayers dense = fog_auto_look(photo, camera, est, 60, 80, 0.3);
  Image haze_map;
  const double e_haze = gallery_created_edges(photo, haze.composite, &haze_map);
  const double e_dense = gallery_created_edges(photo, dense.composite);
  // The defect the bound mends is the estimate's (the water's distance, checked below); in the
  // render it shows as a step under the flat sky light. The brightness scale (on by default
  // since haze15) darkens the sky's fog toward this photo's sky and hides the step as well, so
  // the "before" is measured under the flat light, and the default render of the estimate
  // without the bound is printed only.
  const double e_haze_before = gallery_created_edges(
      photo, fog_auto_look_flat_light(photo, camera, est_before, 2000, 1500, 0.6).composite);
  const double e_haze_before_scaled = gallery_created_edges(
      photo, fog_auto_look(photo, camera, est_before, 2000, 1500, 0.6).composite);
  if (const char* folder = std::getenv("MR_TEST_IMAGES"); folder && *folder) {  // to look at
    const std::string f(folder);
    write_image(f + "/sea_photo.png", photo);
    write_image(f + "/sea_haze.png", haze.composite);
    write_image(f + "/sea_haze_edges.png", haze_map);
  }
  const int x = kSeaW / 2;
  auto d = [&](const SceneEstimate& e, int below) {
    return e.geometry.distance_m.at(x, horizon_row + below, 0);
  };
  std::printf(
      "sea horizon: water 4 / 10 / 30 px below the horizon at %.0f / %.0f / %.0f m (without the "
      "bound %.0f / %.0f / %.0f m; plane %.0f / %.0f / %.0f m); created-edge pixels haze %.4f %% "
      "(without the bound %.4f %% under the flat sky light, %.4f %% with its brightness scale), "
      "dense %.4f %%\n",
      d(est, 4), d(est, 10), d(est, 30), d(est_before, 4), d(est_before, 10), d(est_before, 30),
      1.6 * camera.focal_px / 4.5, 1.6 * camera.focal_px / 10.5, 1.6 * camera.focal_px / 30.5,
      100 * e_haze, 100 * e_haze_before, 100 * e_haze_before_scaled, 100 * e_dense);
  // Without the bound the fog steps at the horizon along the whole width (0.5 % of the frame)
  // under the flat sky light.
  EXPECT_GT(e_haze_before, 2e-4);
  // The water farther than its plane near the horizon, its own distance further down.
  EXPECT_GT(d(est, 4), d(est_before, 4));
  // The issue's target for dense fog and haze: at most 0.02 % of the pixels.
  EXPECT_LE(e_haze, 2e-4);
  EXPECT_LE(e_dense, 2e-4);
}

// Uniform noise from rng blurred to a cloud's detail (sigmas in pixels), scaled to [0, 1].
cv::Mat cloud_noise(int h, int w, std::mt19937& rng, double sigma_x, double sigma_y) {
  std::uniform_real_distribution<float> uniform(0.0f, 1.0f);
  cv::Mat noise(h, w, CV_32F);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) noise.at<float>(y, x) = uniform(rng);
  cv::GaussianBlur(noise, noise, cv::Size(0, 0), sigma_x, sigma_y);
  cv::normalize(noise, noise, 0, 1, cv::NORM_MINMAX);
  return noise;
}

// A textured meadow below the horizon (`grain`: this pixel's noise).
cv::Vec3f meadow(int y, int horizon, int h, float grain) {
  const float v = 0.22f + 0.06f * float(y - horizon) / h + grain;
  return cv::Vec3f(v * 0.55f, v * 1.05f, v * 0.75f);
}

// A tree standing on the horizon: an 8 px trunk from `trunk_top` down, under an elliptical
// canopy (centre, radii in px) of textured green, marked in `canopy`.
struct Tree {
  int cx, cy, rx, ry, trunk_top;
};
void paint_tree(const Tree& t, int x, int y, std::uniform_real_distribution<float>& grain,
                std::mt19937& rng, cv::Vec3f& c, cv::Mat& canopy) {
  if (x >= t.cx - 4 && x < t.cx + 4 && y >= t.trunk_top) {
    c = cv::Vec3f(0.15f, 0.12f, 0.10f);
  } else if (std::pow(double(x - t.cx) / t.rx, 2) + std::pow(double(y - t.cy) / t.ry, 2) < 1) {
    const float v = 0.18f + grain(rng);
    c = cv::Vec3f(v * 0.6f, v * 1.4f, v * 0.7f);
    canopy.at<std::uint8_t>(y, x) = 1;
  }
}

// A blue sky graded to the horizon under cumulus: cover `envelope` (0-1) with cauliflower
// `noise`; a meadow below the horizon (the frame's middle) and a tree on it (marked in
// `canopy`); then a lens blur. The photo's display-referred colours.
cv::Mat cumulus_landscape(const cv::Mat& envelope, const cv::Mat& noise, std::mt19937& rng,
                          cv::Mat& canopy) {
  const int w = envelope.cols, h = envelope.rows, horizon = h / 2;
  cv::Mat display(h, w, CV_32FC3);
  std::uniform_real_distribution<float> grain(-0.05f, 0.05f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float t = float(y) / horizon;
      const cv::Vec3f sky =
          cv::Vec3f(0.12f, 0.30f, 0.72f) * (1 - t) + cv::Vec3f(0.45f, 0.60f, 0.85f) * t;
      const float cover =
          envelope.at<float>(y, x) * std::clamp(0.55f + 0.6f * noise.at<float>(y, x), 0.0f, 1.0f);
      const cv::Vec3f cloud =
          cv::Vec3f(0.93f, 0.94f, 0.97f) * (0.8f + 0.2f * noise.at<float>(y, x));
      cv::Vec3f c = sky * (1 - cover) + cloud * cover;
      if (y >= horizon)
        c = meadow(y, horizon, h, grain(rng));
      else
        paint_tree(Tree{90, 175, 34, 30, 200}, x, y, grain, rng, c, canopy);
      display.at<cv::Vec3f>(y, x) = c;
    }
  cv::GaussianBlur(display, display, cv::Size(0, 0), 0.7);  // a lens
  return display;
}

// The pixels above the horizon (the frame's middle) where `cover` exceeds 0.7, as a CV_8U mask.
cv::Mat cloud_mask(const cv::Mat& cover) {
  cv::Mat mask(cover.rows, cover.cols, CV_8U, cv::Scalar(0));
  for (int y = 0; y < cover.rows / 2; ++y)
    for (int x = 0; x < cover.cols; ++x)
      if (cover.at<float>(y, x) > 0.7f) mask.at<std::uint8_t>(y, x) = 1;
  return mask;
}

// A level horizon through the frame's middle, as a user marks it.
Annotations level_horizon(int w, int h) {
  Annotations a;
  a.horizon =
      std::array<PixelPoint, 2>{PixelPoint{0, 0.5 * h - 0.5}, PixelPoint{w - 1.0, 0.5 * h - 0.5}};
  return a;
}

// Clouds are not occluders (issue 11, sun bank look): a blue sky with a cumulus whose wispy,
// textured rim the sky mask leaves out (as kite's in the tuning half; the rim rings the core,
// so the whole cloud is left out), held up by nothing, above a building and a tree standing on
// the horizon, and a low sun just below the cloud. On the far billboard, refined (about 100 m
// here; kilometres for kite's fragments, but finite), the cloud was a floating occluder in the
// height fog: fragmented shafts and hard edges around it, and grazing shadow rays through its
// fragments (kite: 2.9 us a ray against 0.63 us). A cloud is kilometres away, above the fog
// layer: sky, seen through the fog like the sky around it. The building and the tree stand on
// the ground: they stay surfaces and occluders.
constexpr int kCloudW = 640, kCloudH = 480;
struct CloudScene {
  cv::Mat display;
  cv::Mat rim, building, canopy;  // CV_8U masks of the parts
};
CloudScene wispy_cloud_scene() {
  constexpr int w = kCloudW, h = kCloudH, horizon = h / 2;
  CloudScene s;
  s.display = cv::Mat(h, w, CV_32FC3);
  // The cloud: a bright core (a smooth ellipse) in a rim of wisps, streaks of fine noise.
  cv::Mat core(h, w, CV_32F, cv::Scalar(0)), envelope(h, w, CV_32F, cv::Scalar(0));
  cv::ellipse(core, cv::Point(500, 70), cv::Size(42, 20), 0, 0, 360, cv::Scalar(1), cv::FILLED);
  cv::GaussianBlur(core, core, cv::Size(0, 0), 3);
  cv::ellipse(envelope, cv::Point(490, 60), cv::Size(130, 60), -8, 0, 360, cv::Scalar(1),
              cv::FILLED);
  cv::GaussianBlur(envelope, envelope, cv::Size(0, 0), 12);
  std::mt19937 rng(11);
  const cv::Mat noise = cloud_noise(h, w, rng, 2.0, 1.2);  // fine, streaky
  s.rim = cv::Mat(h, w, CV_8U, cv::Scalar(0));
  s.building = cv::Mat(h, w, CV_8U, cv::Scalar(0));
  s.canopy = cv::Mat(h, w, CV_8U, cv::Scalar(0));
  std::uniform_real_distribution<float> grain(-0.05f, 0.05f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float t = float(y) / horizon;
      const cv::Vec3f sky =
          cv::Vec3f(0.12f, 0.30f, 0.72f) * (1 - t) + cv::Vec3f(0.45f, 0.60f, 0.85f) * t;
      const float e = envelope.at<float>(y, x), k = core.at<float>(y, x);
      const float wisp = e * std::clamp(2.5f * noise.at<float>(y, x) - 0.9f, 0.0f, 0.85f);
      const float cover = std::max(k, wisp);
      cv::Vec3f c = sky * (1 - cover) + cv::Vec3f(0.95f, 0.95f, 0.97f) * cover;
      if (e > 0.3f && k < 0.5f) s.rim.at<std::uint8_t>(y, x) = 1;
      if (y >= horizon) {
        c = meadow(y, horizon, h, grain(rng));
      } else if (x >= 70 && x < 160 && y >= 150) {  // a building: dark walls, lit windows
        const bool window = x >= 74 && x < 150 && (x - 70) % 18 > 9 && (y - 150) % 20 > 11;
        c = window ? cv::Vec3f(0.55f, 0.52f, 0.45f) : cv::Vec3f(0.20f, 0.19f, 0.18f);
        s.building.at<std::uint8_t>(y, x) = 1;
      } else {
        paint_tree(Tree{280, 185, 34, 26, 205}, x, y, grain, rng, c, s.canopy);
      }
      s.display.at<cv::Vec3f>(y, x) = c;
    }
  cv::GaussianBlur(s.display, s.display, cv::Size(0, 0), 0.7);  // a lens
  return s;
}

TEST(SkyLight, FloatingCloudsAreSkyNotOccluders) {
  const CloudScene scene = wispy_cloud_scene();
  constexpr int kW = kCloudW, kH = kCloudH;
  const Camera camera = Camera::from_horizontal_fov(kW, kH, 60);
  const Image photo = linear_photo(scene.display);
  const Annotations horizon = level_horizon(kW, kH);  // the case is the clouds, not the horizon
  const SceneEstimate est = estimate_scene(photo, camera, horizon);
  const Image& d = est.geometry.distance_m;
  std::size_t rim = 0, rim_sky = 0, building = 0, building_finite = 0, canopy = 0,
              canopy_finite = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const bool finite = std::isfinite(d.at(x, y, 0));
      if (scene.rim.at<std::uint8_t>(y, x)) ++rim, rim_sky += !finite;
      if (scene.building.at<std::uint8_t>(y, x)) ++building, building_finite += finite;
      if (scene.canopy.at<std::uint8_t>(y, x)) ++canopy, canopy_finite += finite;
    }
  // The matte is fractional only along a surface that remains (photo/sky_matte.h mixes each
  // such pixel with its nearest all-surface pixel's fog; one left along a cloud made sky would
  // mix in a far surface's): within the sky mask's band (radius 3 px here) plus a little.
  cv::Mat open_sky(kH, kW, CV_8U), to_surface;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) open_sky.at<std::uint8_t>(y, x) = !std::isfinite(d.at(x, y, 0));
  cv::distanceTransform(open_sky, to_surface, cv::DIST_L2, 3);
  std::size_t orphans = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const float a = est.geometry.sky_alpha.at(x, y, 0);
      orphans += a > 0 && a < 1 && to_surface.at<float>(y, x) > 8;
    }
  EXPECT_EQ(orphans, 0u);
  // The sun bank look: the sun at elevation 8 degrees is just below the cloud.
  const FogLayers lit = fog_sun_bank_look(photo, camera, est);
  // Before: the cloud's fragments, surfaces about 100 m away in the height fog, lit and
  // shadowed by the low sun, cut hard edges into the fogged sky around them.
  const double edges = gallery_created_edges(photo, lit.composite);
  // Dense fog and haze (no sun): the cloud is fogged as the sky around it is.
  const FogLayers haze = fog_auto_look(photo, camera, est, 2000, 1500, 0.6);
  const double e_haze = gallery_created_edges(photo, haze.composite);
  const double e_dense =
      gallery_created_edges(photo, fog_auto_look(photo, camera, est, 60, 80, 0.3).composite);
  if (const char* folder = std::getenv("MR_TEST_IMAGES"); folder && *folder) {  // to look at
    const std::string f(folder);
    write_image(f + "/clouds_photo.png", photo);
    write_image(f + "/clouds_sun_bank.png", lit.composite);
    write_image(f + "/clouds_haze.png", haze.composite);
    write_image(f + "/clouds_depth.png", test::depth_picture(d));
  }
  std::printf(
      "floating cloud: rim %.1f %% sky; building %.1f %%, canopy %.1f %% surface; sun "
      "bank: created-edge pixels %.4f %%; haze %.4f %%, dense %.4f %%\n",
      100.0 * double(rim_sky) / double(rim), 100.0 * double(building_finite) / double(building),
      100.0 * double(canopy_finite) / double(canopy), 100 * edges, 100 * e_haze, 100 * e_dense);
  // Before: 6.6 % of the rim sky (the core and the rim on the far billboard, refined to about
  // 100 m), 0.29 % created edges in the sun bank look. The building and the tree stand on the
  // ground: all surfaces, i.e. occluder triangles (render/occluder_mesh.h meshes every finite
  // pixel).
  EXPECT_GE(double(rim_sky), 0.98 * double(rim));
  EXPECT_EQ(building_finite, building);
  EXPECT_GE(double(canopy_finite), 0.98 * double(canopy));
  EXPECT_LE(edges, 2e-4);  // the issue's target for created edges, 0.02 %
  EXPECT_LE(e_haze, 2e-4);
  EXPECT_LE(e_dense, 2e-4);
}

// A hand-made map for the rule of photo/clouds.h: 120 x 60, blue sky (distance ratio infinite)
// above the horizon at row 40; `put` paints a surface (its ratio to the billboard, its colour).
struct CloudRuleMap {
  static constexpr int w = 120, h = 60, horizon = 40;
  Image photo{w, h, 3};
  std::vector<float> ratio =
      std::vector<float>(std::size_t(w) * h, std::numeric_limits<float>::infinity());
  std::vector<std::uint8_t> above = std::vector<std::uint8_t>(std::size_t(w) * h, 0);
  CloudRuleMap() {
    put(0, w, 0, h, std::numeric_limits<float>::infinity(), {0.1f, 0.25f, 0.7f});
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) above[std::size_t(y) * w + x] = y < horizon;
  }
  void put(int x0, int x1, int y0, int y1, float r, Rgb c) {
    for (int y = y0; y < y1; ++y)
      for (int x = x0; x < x1; ++x) {
        ratio[std::size_t(y) * w + x] = r;
        for (int k = 0; k < 3; ++k) photo.at(x, y, k) = c[k];
      }
  }
};

// The rule of photo/clouds.h on a hand-made map: sky above row 40, the ground below, and six
// surfaces above the horizon, two of them clouds.
TEST(SkyLight, FloatingCloudRule) {
  CloudRuleMap m;
  constexpr int w = CloudRuleMap::w, h = CloudRuleMap::h, horizon = CloudRuleMap::horizon;
  Image& photo = m.photo;
  std::vector<float>& ratio = m.ratio;
  std::vector<std::uint8_t>& above = m.above;
  std::vector<std::uint8_t> foliage;
  auto put = [&m](int x0, int x1, int y0, int y1, float r, Rgb c) { m.put(x0, x1, y0, y1, r, c); };
  put(0, w, horizon, h, 1.0f, {0.1f, 0.2f, 0.05f});   // the ground
  put(0, w, 0, 3, 1.0f, {0.3f, 0.3f, 0.3f});          // an eave along the top border
  put(5, 15, 20, horizon, 1.0f, {0.4f, 0.4f, 0.4f});  // a grey building on the horizon
  put(25, 40, 6, 15, 3.0f, {0.6f, 0.6f, 0.62f});      // a grey cloud, 3x the billboard
  put(50, 56, 10, 16, 1.5f, {0.8f, 0.05f, 0.05f});    // a red kite
  put(65, 80, 6, 12, 50.0f, {0.9f, 0.4f, 0.1f});      // an orange cloud, refined far
  put(85, 115, 24, 27, 1.0f, {0.35f, 0.35f, 0.35f});  // a deck on a pier
  put(98, 101, 27, horizon, 1.0f, {0.35f, 0.35f, 0.35f});
  const std::vector<std::uint8_t> cloud =
      photo::floating_clouds(photo.view(), ratio, above, foliage, {});
  auto at = [&](int x, int y) { return int(cloud[std::size_t(y) * w + x]); };
  EXPECT_EQ(at(60, 1), 0);   // the eave: ringed by the frame more than by the sky
  EXPECT_EQ(at(10, 35), 0);  // the building stands on the horizon
  EXPECT_EQ(at(30, 10), 1);  // grey, held up by nothing
  EXPECT_EQ(at(53, 12), 0);  // saturated, near
  EXPECT_EQ(at(70, 8), 1);   // joined to the sky by the refinement
  EXPECT_EQ(at(90, 25), 0);  // held up by its pier
  EXPECT_EQ(at(60, 45), 0);  // the ground
  // The grey cloud as foliage (a backlit branch): not a cloud.
  foliage.assign(ratio.size(), 0);
  for (int y = 6; y < 15; ++y)
    for (int x = 25; x < 40; ++x) foliage[std::size_t(y) * w + x] = 1;
  EXPECT_EQ(
      photo::floating_clouds(photo.view(), ratio, above, foliage, {})[std::size_t(10) * w + 30], 0);
}

// The rule of photo/clouds.h for surfaces cut off by the frame (hand-made map): sky above row
// 40, the ground below; three corner pieces ringed more by the frame than by the sky.
TEST(SkyLight, FloatingCloudRuleAtTheFrame) {
  CloudRuleMap m;
  constexpr int w = CloudRuleMap::w, h = CloudRuleMap::h, horizon = CloudRuleMap::horizon;
  Image& photo = m.photo;
  std::vector<float>& ratio = m.ratio;
  std::vector<std::uint8_t>& above = m.above;
  std::vector<std::uint8_t> foliage;
  auto put = [&m](int x0, int x1, int y0, int y1, float r, Rgb c) { m.put(x0, x1, y0, y1, r, c); };
  put(0, w, horizon, h, 1.0f, {0.1f, 0.2f, 0.05f});  // the ground
  // Each a 20 x 20 square in a corner: its outline 40 px on the frame, 39 next to the sky.
  put(0, 20, 0, 20, 1.0f, {0.3f, 0.3f, 0.3f});     // a grey eave, near
  put(100, w, 0, 20, 1.2f, {0.7f, 0.75f, 0.9f});   // a white cumulus over blue sky
  put(50, 70, 0, 20, 40.0f, {0.9f, 0.45f, 0.2f});  // an orange cloud, refined far
  const std::vector<std::uint8_t> cloud =
      photo::floating_clouds(photo.view(), ratio, above, foliage, {});
  auto at = [&](int x, int y) { return int(cloud[std::size_t(y) * w + x]); };
  EXPECT_EQ(at(10, 10), 0);   // shaded, no sky's colour, an edge against the sky
  EXPECT_EQ(at(110, 10), 1);  // of the sky's colours
  EXPECT_EQ(at(60, 10), 1);   // joined to the sky by the refinement
  // The same cumulus as foliage (a backlit branch reaching into the frame): not a cloud.
  foliage.assign(ratio.size(), 0);
  for (int y = 0; y < 20; ++y)
    for (int x = 100; x < w; ++x) foliage[std::size_t(y) * w + x] = 1;
  EXPECT_EQ(
      photo::floating_clouds(photo.view(), ratio, above, foliage, {})[std::size_t(10) * w + 110],
      0);
}

// The rule of photo/clouds.h for clouds joined to what stands on the horizon (hand-made map):
// sky above row 40, the ground below; a white bank on the horizon with a tower rising from it
// into a cloud that hangs beside the tower, and a thin bluish deck on a pier.
TEST(SkyLight, FloatingCloudRuleForJoinedClouds) {
  CloudRuleMap m;
  constexpr int w = CloudRuleMap::w, h = CloudRuleMap::h, horizon = CloudRuleMap::horizon;
  std::vector<std::uint8_t> foliage;
  const Rgb white{0.8f, 0.82f, 0.9f}, shade{0.3f, 0.33f, 0.4f};
  m.put(0, w, horizon, h, 1.0f, {0.1f, 0.2f, 0.05f});  // the ground
  m.put(60, 115, 32, horizon, 1.0f, white);            // a bank on the horizon
  m.put(60, 64, 20, 32, 1.0f, white);                  // a tower rising from it
  m.put(60, 100, 8, 20, 1.2f, white);                  // a cloud on the tower, 12 px thick
  m.put(10, 12, 25, horizon, 1.0f, shade);             // a pier
  m.put(2, 40, 22, 25, 1.0f, shade);                   // its deck, 3 px thick, bluish
  const std::vector<std::uint8_t> cloud =
      photo::floating_clouds(m.photo.view(), m.ratio, m.above, foliage, {});
  auto at = [&](int x, int y) { return int(cloud[std::size_t(y) * w + x]); };
  EXPECT_EQ(at(90, 14), 1);  // hangs beside the tower: a cloud
  EXPECT_EQ(at(62, 14), 0);  // on the tower's columns: held up
  EXPECT_EQ(at(90, 36), 0);  // the bank stands on the horizon (its edge kept: ratio 1)
  EXPECT_EQ(at(30, 23), 0);  // the deck: thin
  EXPECT_EQ(at(11, 30), 0);  // the pier
  // Before (the rule off), the whole component was held up by the bank.
  photo::FloatingCloudOptions off;
  off.min_overhang_fraction = 0;
  EXPECT_EQ(photo::floating_clouds(m.photo.view(), m.ratio, m.above, foliage, {},
                                   off)[std::size_t(14) * w + 90],
            0);
  // The same cloud as foliage (a backlit crown on its trunk): not a cloud.
  foliage.assign(m.ratio.size(), 0);
  for (int y = 8; y < 20; ++y)
    for (int x = 60; x < 100; ++x) foliage[std::size_t(y) * w + x] = 1;
  EXPECT_EQ(photo::floating_clouds(m.photo.view(), m.ratio, m.above, foliage,
                                   {})[std::size_t(14) * w + 90],
            0);
  // Not clouds: the same shapes held up by an orange facade, a navy structure in its own
  // shade (bluish but saturated), and the white cloud as a lattice enclosing sky.
  CloudRuleMap o;
  const Rgb navy{0.03f, 0.08f, 0.3f};
  o.put(0, w, horizon, h, 1.0f, {0.1f, 0.2f, 0.05f});    // the ground
  o.put(5, 15, 20, horizon, 1.0f, {0.8f, 0.45f, 0.1f});  // an orange facade
  o.put(15, 35, 20, 32, 1.0f, white);                    // white, beside it
  o.put(40, 80, 32, horizon, 1.0f, white);               // a bank on the horizon
  o.put(40, 44, 20, 32, 1.0f, white);                    // a tower rising from it
  o.put(44, 80, 8, 20, 1.0f, navy);                      // navy, beside the tower
  o.put(85, 118, 32, horizon, 1.0f, white);              // a second bank and tower
  o.put(85, 89, 8, 32, 1.0f, white);
  o.put(89, 118, 8, 20, 1.0f, white);  // a white lattice: 2x2 holes of sky, every 4 px
  for (int y = 10; y < 18; y += 4)
    for (int x = 92; x < 116; x += 4)
      o.put(x, x + 2, y, y + 2, std::numeric_limits<float>::infinity(), {0.1f, 0.25f, 0.7f});
  const std::vector<std::uint8_t> none =
      photo::floating_clouds(o.photo.view(), o.ratio, o.above, {}, {});
  EXPECT_EQ(none[std::size_t(26) * w + 25], 0);   // held by the facade
  EXPECT_EQ(none[std::size_t(14) * w + 60], 0);   // saturated
  EXPECT_EQ(none[std::size_t(15) * w + 100], 0);  // a lattice
  // Without the holes it is a cloud: the lattice's holes are what refuse it.
  o.put(89, 118, 8, 20, 1.0f, white);
  EXPECT_EQ(
      photo::floating_clouds(o.photo.view(), o.ratio, o.above, {}, {})[std::size_t(15) * w + 100],
      1);
  // The navy as a grey cloud is one: its saturation is what refuses it.
  o.put(44, 80, 8, 20, 1.0f, white);
  EXPECT_EQ(
      photo::floating_clouds(o.photo.view(), o.ratio, o.above, {}, {})[std::size_t(14) * w + 60],
      1);
  // A bank resting on a known horizon, joined to the sky by the refinement (50x the
  // billboard), with a spire rising into it that keeps its edge (1x): the bank is sky, the
  // spire not; under a guessed horizon (it may cut the bank: a seam) neither.
  CloudRuleMap b;
  b.put(0, w, horizon, h, 1.0f, {0.1f, 0.2f, 0.05f});  // the ground
  b.put(20, 100, 25, horizon, 50.0f, white);           // the bank
  b.put(58, 62, 15, horizon, 1.0f, white);             // a white spire
  const std::vector<std::uint8_t> banked =
      photo::floating_clouds(b.photo.view(), b.ratio, b.above, {}, {});
  EXPECT_EQ(banked[std::size_t(30) * w + 40], 1);
  EXPECT_EQ(banked[std::size_t(20) * w + 60], 0);
  photo::FloatingCloudOptions guess;
  guess.guessed_horizon = true;
  EXPECT_EQ(photo::floating_clouds(b.photo.view(), b.ratio, b.above, {}, {},
                                   guess)[std::size_t(30) * w + 40],
            0);
  // Not joined (its edge against the sky kept: a grey wall): a surface.
  b.put(20, 58, 25, horizon, 1.0f, white);
  b.put(62, 100, 25, horizon, 1.0f, white);
  EXPECT_EQ(
      photo::floating_clouds(b.photo.view(), b.ratio, b.above, {}, {})[std::size_t(30) * w + 40],
      0);
}

// The joined-cloud rule and cables (gallery/tune bridge: white cable stays crossing at a clamp,
// cut off from the cables that rest on the horizon where the sky shows between them): a white
// pylon rising from the horizon, a white cable 4 px thick hanging from it across the sky, and
// a clamp 12 px across on the cable. The part beside the pylon's columns reached the radius of
// a cloud's body only at the clamp (a small part of its area is that deep); it was taken for a
// cloud and went into the sky (bridge's cables vanished in haze). A cloud's part is mostly body.
TEST(SkyLight, JoinedCloudRuleRefusesCablesThickOnlyAtAClamp) {
  CloudRuleMap m;
  constexpr int w = CloudRuleMap::w, h = CloudRuleMap::h, horizon = CloudRuleMap::horizon;
  const Rgb white{0.8f, 0.82f, 0.9f};
  m.put(0, w, horizon, h, 1.0f, {0.1f, 0.2f, 0.05f});  // the ground
  m.put(20, 24, 5, horizon, 1.0f, white);              // the pylon
  m.put(24, 110, 14, 18, 1.0f, white);                 // the cable
  m.put(70, 82, 10, 22, 1.0f, white);                  // the clamp
  const std::vector<std::uint8_t> cloud =
      photo::floating_clouds(m.photo.view(), m.ratio, m.above, {}, {});
  EXPECT_EQ(cloud[std::size_t(16) * w + 76], 0);   // the clamp
  EXPECT_EQ(cloud[std::size_t(16) * w + 100], 0);  // the cable beside it
  photo::FloatingCloudOptions before;
  before.min_overhang_body_fraction = 0;
  EXPECT_EQ(photo::floating_clouds(m.photo.view(), m.ratio, m.above, {}, {},
                                   before)[std::size_t(16) * w + 100],
            1);
  // A cloud 12 px thick hanging there instead is one (as FloatingCloudRuleForJoinedClouds').
  m.put(24, 110, 10, 22, 1.0f, white);
  EXPECT_EQ(
      photo::floating_clouds(m.photo.view(), m.ratio, m.above, {}, {})[std::size_t(16) * w + 100],
      1);
}

// The joined-cloud rule in a scene that is all bluish grey (airport_snow: snow, a terminal and
// its jet bridges under an overcast sky, where the rule took a 72 x 105 px block of jet bridges
// hanging beside the terminal's columns for a cloud): of the sky's colours is not enough, the
// part must be as smooth as a cloud (or bright white, a cumulus' sunlit detail).
TEST(SkyLight, JoinedCloudRuleRefusesTexturedBluishGreyStructures) {
  constexpr int w = CloudRuleMap::w, horizon = CloudRuleMap::horizon;
  const Rgb snow{0.55f, 0.6f, 0.7f}, steel{0.25f, 0.28f, 0.35f}, dark{0.05f, 0.06f, 0.08f};
  auto scene = [&](bool textured) {
    CloudRuleMap m;
    m.put(0, w, horizon, CloudRuleMap::h, 1.0f, snow);  // the snowy apron
    m.put(60, 115, 32, horizon, 1.0f, snow);            // a terminal on the horizon
    m.put(60, 64, 20, 32, 1.0f, steel);                 // a column rising from it
    m.put(64, 100, 8, 20, 1.0f, steel);                 // what hangs beside the column
    if (textured)  // jet bridges: dark bands 2 px wide every 4 px (every pixel bluish grey)
      for (int x = 64; x < 100; x += 4) m.put(x, x + 2, 8, 20, 1.0f, dark);
    return photo::floating_clouds(m.photo.view(), m.ratio, m.above, {}, {});
  };
  EXPECT_EQ(scene(false)[std::size_t(14) * w + 90], 1);  // smooth: a cloud, as before
  EXPECT_EQ(scene(true)[std::size_t(14) * w + 90], 0);   // textured: a structure
  EXPECT_EQ(scene(true)[std::size_t(14) * w + 91], 0);
}

// A cumulus cut off by the frame's bottom under a guessed horizon (issue 11, the sun bank look;
// kite's lower right cloud in the tuning half): an all-sky frame looking up, no horizon cue, so
// the level fall-back guess is lowered below the sky it cut, to the frame's bottom; a white
// cumulus with a textured rim (which the sky mask leaves out) in the lower right corner, cut off
// by the frame's bottom and right border. Reaching the frame's bottom, it "stood" on it: a
// surface on the far billboard, a cloud-shaped occluder in the low sun's height fog. Nobody saw
// ground there: it is sky.
constexpr int kCutW = 640, kCutH = 400;
cv::Mat cut_cloud_display(cv::Mat* cloud_mask) {
  constexpr int w = kCutW, h = kCutH;
  cv::Mat m(h, w, CV_32FC3);
  cv::Mat envelope(h, w, CV_32F, cv::Scalar(0));
  cv::ellipse(envelope, cv::Point(610, 420), cv::Size(90, 110), -20, 0, 360, cv::Scalar(1),
              cv::FILLED);
  cv::GaussianBlur(envelope, envelope, cv::Size(0, 0), 6);
  std::mt19937 rng(13);
  const cv::Mat noise = cloud_noise(h, w, rng, 1.5, 1.5);  // a cumulus' cauliflower detail
  *cloud_mask = cv::Mat(h, w, CV_8U, cv::Scalar(0));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float t = float(y) / h;  // deep blue overhead, paler toward the frame's bottom
      const cv::Vec3f sky =
          cv::Vec3f(0.10f, 0.24f, 0.62f) * (1 - t) + cv::Vec3f(0.22f, 0.40f, 0.78f) * t;
      const float e = envelope.at<float>(y, x);
      const float cover = e * std::clamp(0.55f + 0.6f * noise.at<float>(y, x), 0.0f, 1.0f);
      const cv::Vec3f cloud =
          cv::Vec3f(0.93f, 0.94f, 0.97f) * (0.8f + 0.2f * noise.at<float>(y, x));
      m.at<cv::Vec3f>(y, x) = sky * (1 - cover) + cloud * cover;
      if (e > 0.7f) cloud_mask->at<std::uint8_t>(y, x) = 1;
    }
  cv::GaussianBlur(m, m, cv::Size(0, 0), 0.7);  // a lens
  return m;
}

TEST(SkyLight, CloudCutOffByTheFrameUnderAGuessedHorizonIsSky) {
  constexpr int kW = kCutW, kH = kCutH;
  cv::Mat cloud_mask;
  const cv::Mat display = cut_cloud_display(&cloud_mask);
  const Camera camera = Camera::from_horizontal_fov(kW, kH, 60);
  const Image photo = linear_photo(display);
  const SceneEstimate est = estimate_scene(photo, camera, Annotations{});
  const Image& d = est.geometry.distance_m;
  std::size_t cloud = 0, cloud_sky = 0, finite = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      finite += std::isfinite(d.at(x, y, 0));
      if (cloud_mask.at<std::uint8_t>(y, x)) ++cloud, cloud_sky += !std::isfinite(d.at(x, y, 0));
    }
  const FogLayers lit = fog_sun_bank_look(photo, camera, est);
  const double e_sun = gallery_created_edges(photo, lit.composite);
  const FogLayers haze = fog_auto_look(photo, camera, est, 2000, 1500, 0.6);
  const double e_haze = gallery_created_edges(photo, haze.composite);
  const double e_dense =
      gallery_created_edges(photo, fog_auto_look(photo, camera, est, 60, 80, 0.3).composite);
  if (const char* folder = std::getenv("MR_TEST_IMAGES"); folder && *folder) {  // to look at
    const std::string f(folder);
    write_image(f + "/cut_cloud_photo.png", photo);
    write_image(f + "/cut_cloud_sun_bank.png", lit.composite);
    write_image(f + "/cut_cloud_haze.png", haze.composite);
  }
  std::printf(
      "cloud cut off by the frame (%s; lowered %.0f px): %.1f %% of it sky, %zu surface "
      "pixels; created-edge pixels sun bank %.4f %%, haze %.4f %%, dense %.4f %%\n",
      est.notes.front().c_str(), est.geometry.horizon_lowered_px,
      100.0 * double(cloud_sky) / double(cloud), finite, 100 * e_sun, 100 * e_haze, 100 * e_dense);
  ASSERT_EQ(est.geometry.horizon_source, EstimateSource::fallback);
  ASSERT_GE(est.geometry.horizon[0][1], kH - 1.0);  // the case: lowered to the frame's bottom
  EXPECT_GE(double(cloud_sky), 0.98 * double(cloud));
  EXPECT_LE(e_sun, 2e-4);  // the issue's target for created edges, 0.02 %
  EXPECT_LE(e_haze, 2e-4);
  EXPECT_LE(e_dense, 2e-4);
}

// The rule of photo/clouds.h under a guessed horizon below the frame (hand-made map: all of it
// above the horizon, sky around six surfaces cut off by the frame's bottom).
TEST(SkyLight, FloatingCloudRuleUnderAGuessedHorizon) {
  constexpr int w = 120, h = 60;
  constexpr float kSky = std::numeric_limits<float>::infinity();
  Image photo(w, h, 3);
  std::vector<float> ratio(std::size_t(w) * h, kSky);
  std::vector<std::uint8_t> above(ratio.size(), 1), standing(ratio.size(), 0), foliage;
  auto put = [&](int x0, int x1, int y0, int y1, float r, Rgb c) {
    for (int y = y0; y < y1; ++y)
      for (int x = x0; x < x1; ++x) {
        ratio[std::size_t(y) * w + x] = r;
        for (int k = 0; k < 3; ++k) photo.at(x, y, k) = c[k];
      }
  };
  put(0, w, 0, h, kSky, {0.1f, 0.25f, 0.7f});     // blue sky
  put(5, 25, 40, h, 1.0f, {0.8f, 0.82f, 0.9f});   // a white cumulus, 400 px (5.6 %)
  put(30, 50, 40, h, 1.0f, {0.8f, 0.82f, 0.9f});  // the same, standing on ground seen
  for (int x = 30; x < 50; ++x) standing[std::size_t(h - 1) * w + x] = 1;
  put(55, 75, 40, h, 1.0f, {0.4f, 0.4f, 0.4f});   // grey concrete: not a sky's colours
  put(80, 82, 20, h, 1.0f, {0.3f, 0.33f, 0.4f});  // a bluish post: 2 columns
  put(88, 100, 40, h, 1.0f, {0.1f, 0.4f, 0.2f});  // foliage
  for (int y = 40; y < h; ++y)
    for (int x = 88; x < 100; ++x) photo.at(x, y, 2) = 0.5f;  // bluish, but foliage
  foliage.assign(ratio.size(), 0);
  for (int y = 40; y < h; ++y)
    for (int x = 88; x < 100; ++x) foliage[std::size_t(y) * w + x] = 1;
  put(105, 115, 30, 45, 1.0f, {0.8f, 0.82f, 0.9f});  // a floating cloud
  photo::FloatingCloudOptions guessed;
  guessed.guessed_horizon = true;
  const std::vector<std::uint8_t> cloud =
      photo::floating_clouds(photo.view(), ratio, above, foliage, standing, guessed);
  auto at = [&](int x, int y) { return int(cloud[std::size_t(y) * w + x]); };
  EXPECT_EQ(at(15, 50), 1);   // cut off by the frame, 20 columns on its bottom
  EXPECT_EQ(at(40, 50), 0);   // stands on ground seen
  EXPECT_EQ(at(65, 50), 0);   // grey
  EXPECT_EQ(at(81, 50), 0);   // a post: 2 columns (< 2 % of the width)
  EXPECT_EQ(at(94, 50), 0);   // foliage
  EXPECT_EQ(at(110, 40), 1);  // floating: as without a guess
  // A measured horizon below the frame: the frame's bottom holds the cumulus up.
  const std::vector<std::uint8_t> measured =
      photo::floating_clouds(photo.view(), ratio, above, foliage, standing);
  EXPECT_EQ(measured[std::size_t(50) * w + 15], 0);
  EXPECT_EQ(measured[std::size_t(40) * w + 110], 1);
}

// Clouds cut off by the frame are not occluders either (issue 11, the sun bank look; the lead's
// streak fans on held-out photos, rebuilt here without looking at them): a blue sky with a
// cumulus filling its top right corner, cut off by the top and right borders, its cauliflower
// texture too rough for the sky mask, the sun bank's low sun just behind its lower part, and a
// tree standing on the horizon. Ringed more by the frame than by the sky (48 %), the cloud was
// held to be an eave or a deck seen from below: a surface on the far billboard, about 65 m
// away. Under the low sun its fragments cast specks and streaks into the fogged sky (sun bank
// created edges 0.028 %), and in haze it stayed unveiled under the veiled sky (0.19 %). It is of
// the sky's colours: sky. The tree stays a surface and an occluder.
constexpr int kCornerW = 640, kCornerH = 480;
struct CornerCloudScene {
  cv::Mat display;
  cv::Mat cloud, canopy;  // CV_8U masks of the parts
};
CornerCloudScene corner_cloud_scene() {
  constexpr int w = kCornerW, h = kCornerH;
  CornerCloudScene s;
  // The cloud: a cumulus filling the top right corner (rows 0-200 at the right border), the
  // look's sun (azimuth 20, elevation 8 degrees: about pixel (522, 157)) behind its lower part,
  // cut off by the top and right borders along more of its outline than the sky rings.
  cv::Mat envelope(h, w, CV_32F, cv::Scalar(0));
  cv::ellipse(envelope, cv::Point(w, 0), cv::Size(280, 200), 0, 0, 360, cv::Scalar(1), cv::FILLED);
  cv::GaussianBlur(envelope, envelope, cv::Size(0, 0), 6);
  std::mt19937 rng(29);
  const cv::Mat noise = cloud_noise(h, w, rng, 1.5, 1.5);  // a cumulus' cauliflower detail
  s.canopy = cv::Mat(h, w, CV_8U, cv::Scalar(0));
  s.display = cumulus_landscape(envelope, noise, rng, s.canopy);
  s.cloud = cloud_mask(envelope);
  return s;
}

// A painted scene estimated as the photo under a 60-degree camera and a level horizon through
// its middle, as a user marks it (the cases are the clouds, not the horizon).
struct LevelEstimate {
  Camera camera;
  Image photo;
  SceneEstimate est;
};
LevelEstimate estimate_under_level_horizon(const cv::Mat& display) {
  const Camera camera = Camera::from_horizontal_fov(display.cols, display.rows, 60);
  Image photo = linear_photo(display);
  SceneEstimate est = estimate_scene(photo, camera, level_horizon(display.cols, display.rows));
  return {camera, std::move(photo), std::move(est)};
}

// The fraction of `mask`'s pixels whose distance is infinite (sky) or finite (a surface).
double sky_fraction(const cv::Mat& mask, const Image& distance_m, bool finite = false) {
  std::size_t in = 0, hits = 0;
  for (int y = 0; y < mask.rows; ++y)
    for (int x = 0; x < mask.cols; ++x)
      if (mask.at<std::uint8_t>(y, x))
        ++in, hits += std::isfinite(distance_m.at(x, y, 0)) == finite;
  return double(hits) / double(in);
}

TEST(SkyLight, CloudsCutOffByTheFrameAreSkyNotOccluders) {
  const CornerCloudScene scene = corner_cloud_scene();
  const auto [camera, photo, est] = estimate_under_level_horizon(scene.display);
  const Image& d = est.geometry.distance_m;
  const double cloud_sky = sky_fraction(scene.cloud, d);
  const double canopy_surface = sky_fraction(scene.canopy, d, true);
  const FogLayers lit = fog_sun_bank_look(photo, camera, est);
  const double e_sun = gallery_created_edges(photo, lit.composite);
  const test::GalleryLooks looks = test::haze_and_dense_looks(photo, camera, est, "corner_cloud");
  const double e_haze = looks.haze_edges, e_dense = looks.dense_edges;
  if (const char* folder = std::getenv("MR_TEST_IMAGES"); folder && *folder) {  // to look at
    const std::string f(folder);
    write_image(f + "/corner_cloud_sun_bank.png", lit.composite);
    write_image(f + "/corner_cloud_depth.png", test::depth_picture(d));
  }
  std::printf(
      "cloud cut off by the frame: %.1f %% sky; canopy %.1f %% surface; created-edge "
      "pixels sun bank %.4f %%, haze %.4f %%, dense %.4f %%\n",
      100 * cloud_sky, 100 * canopy_surface, 100 * e_sun, 100 * e_haze, 100 * e_dense);
  EXPECT_GE(cloud_sky, 0.98);
  EXPECT_GE(canopy_surface, 0.98);
  EXPECT_LE(e_sun, 2e-4);  // the issue's target for created edges, 0.02 %
  EXPECT_LE(e_haze, 2e-4);
  EXPECT_LE(e_dense, 2e-4);
}

// Clouds joined to a cloud that stands on the horizon are not occluders either (issue 11, the
// sun bank's streak fans from clouds high in the sky; rebuilt here without looking at the
// photos that showed them): a blue sky, a low cumulus bank sitting on the horizon at the
// right, a band of cloud rising from it to the left and on to a cumulus high in the sky, the
// look's low sun (about pixel (522, 157)) just behind the high cumulus' lower part, and a tree
// standing on the horizon. Their cauliflower texture is too rough for the sky mask; joined
// (8-connected) to the bank, which meets the horizon, the high cumulus was held up with it: a
// surface on the far billboard, casting shafts fanning down from it under the low sun. It hangs
// in the sky beside what rises from the horizon: sky. The bank, standing on the horizon, and
// the tree stay surfaces.
constexpr int kJoinedW = 640, kJoinedH = 480;
struct JoinedCloudScene {
  cv::Mat display;
  cv::Mat high, bank, canopy;  // CV_8U masks of the parts
};
JoinedCloudScene joined_cloud_scene() {
  constexpr int w = kJoinedW, h = kJoinedH;
  JoinedCloudScene s;
  cv::Mat high(h, w, CV_32F, cv::Scalar(0)), low(h, w, CV_32F, cv::Scalar(0));
  cv::ellipse(high, cv::Point(540, 115), cv::Size(115, 50), 0, 0, 360, cv::Scalar(1), cv::FILLED);
  cv::ellipse(low, cv::Point(470, 250), cv::Size(200, 50), 0, 0, 360, cv::Scalar(1), cv::FILLED);
  cv::Mat envelope = cv::max(high, low);
  // The band joining them: from the bank's top at x 330 up to the high cumulus' left end.
  cv::ellipse(envelope, cv::Point(385, 165), cv::Size(75, 16), -40, 0, 360, cv::Scalar(1),
              cv::FILLED);
  cv::GaussianBlur(envelope, envelope, cv::Size(0, 0), 6);
  cv::GaussianBlur(high, high, cv::Size(0, 0), 6);
  cv::GaussianBlur(low, low, cv::Size(0, 0), 6);
  std::mt19937 rng(31);
  const cv::Mat noise = cloud_noise(h, w, rng, 1.5, 1.5);  // a cumulus' cauliflower detail
  s.canopy = cv::Mat(h, w, CV_8U, cv::Scalar(0));
  s.display = cumulus_landscape(envelope, noise, rng, s.canopy);
  s.high = cloud_mask(high);
  s.bank = cloud_mask(low);
  return s;
}

TEST(SkyLight, CloudsJoinedToACloudOnTheHorizonAreSkyNotOccluders) {
  const JoinedCloudScene scene = joined_cloud_scene();
  constexpr int kW = kJoinedW, kH = kJoinedH;
  const auto [camera, photo, est] = estimate_under_level_horizon(scene.display);
  const Image& d = est.geometry.distance_m;
  const double high_sky = sky_fraction(scene.high, d), bank_sky = sky_fraction(scene.bank, d),
               canopy_surface = sky_fraction(scene.canopy, d, true);
  // The created-edge measure (gallery/measures.py) on the whole frame, and away from the bank
  // (the pixels more than 12 px from it: the measure's blur and gradient reach 4 px): the high
  // cumulus, the band and the sky around them. With the hanging clouds alone sky, the bank on
  // the far billboard stayed nearly clear in haze under the veiled sky: 0.030 % on the whole
  // frame, 0.000 % away from it.
  cv::Mat away_from_bank;
  {
    cv::Mat not_bank = scene.bank == 0;
    cv::Mat to_bank;
    cv::distanceTransform(not_bank, to_bank, cv::DIST_L2, 3);
    away_from_bank = to_bank > 12.0f;
  }
  auto away_fraction = [&](const Image& map) {
    std::size_t created = 0, pixels = 0;
    for (int y = 0; y < kH; ++y)
      for (int x = 0; x < kW; ++x)
        if (away_from_bank.at<std::uint8_t>(y, x))
          ++pixels, created += map.at(x, y, 0) == 1.0f && map.at(x, y, 1) == 0.0f;
    return double(created) / double(pixels);
  };
  const FogLayers lit = fog_sun_bank_look(photo, camera, est);
  const FogLayers haze = fog_auto_look(photo, camera, est, 2000, 1500, 0.6);
  const FogLayers dense = fog_auto_look(photo, camera, est, 60, 80, 0.3);
  Image sun_map, haze_map, dense_map;
  const double e_sun = gallery_created_edges(photo, lit.composite, &sun_map);
  const double e_haze = gallery_created_edges(photo, haze.composite, &haze_map);
  const double e_dense = gallery_created_edges(photo, dense.composite, &dense_map);
  const double a_sun = away_fraction(sun_map), a_haze = away_fraction(haze_map),
               a_dense = away_fraction(dense_map);
  if (const char* folder = std::getenv("MR_TEST_IMAGES"); folder && *folder) {  // to look at
    const std::string f(folder);
    write_image(f + "/joined_cloud_photo.png", photo);
    write_image(f + "/joined_cloud_sun_bank.png", lit.composite);
    write_image(f + "/joined_cloud_sun_bank_edges.png", sun_map);
    write_image(f + "/joined_cloud_haze.png", haze.composite);
    write_image(f + "/joined_cloud_haze_edges.png", haze_map);
    write_image(f + "/joined_cloud_depth.png", test::depth_picture(d));
  }
  std::printf(
      "clouds joined to a cloud on the horizon: high cumulus %.1f %% sky, bank %.1f %% sky; "
      "canopy %.1f %% surface; created-edge pixels (whole frame / away from the bank) sun bank "
      "%.4f / %.4f %%, haze %.4f / %.4f %%, dense %.4f / %.4f %%\n",
      100 * high_sky, 100 * bank_sky, 100 * canopy_surface, 100 * e_sun, 100 * a_sun, 100 * e_haze,
      100 * a_haze, 100 * e_dense, 100 * a_dense);
  // Before: 0.0 % of the high cumulus sky, 0.4 % of the bank; sun bank 0.305 % created edges
  // on the whole frame (shafts fanning from the high cumulus), haze 0.218 %.
  EXPECT_GE(high_sky, 0.98);
  // The bank rests on a known horizon, grey, bluish and joined to the sky by the refinement:
  // sky (97.2 %; a few of its pixels the refinement left near the billboard stay).
  EXPECT_GE(bank_sky, 0.95);
  EXPECT_LE(e_haze, 2e-4);
  EXPECT_GE(canopy_surface, 0.98);
  EXPECT_LE(e_sun, 2e-4);  // the issue's target for created edges, 0.02 %
  EXPECT_LE(a_haze, 2e-4);
  EXPECT_LE(a_dense, 2e-4);
  EXPECT_LE(e_dense, 2e-4);
}

TEST(SkyLight, NeedsThePhoto) {
  FogScene scene = haze_scene();
  scene.lighting.sky_radiance = Rgb{0.5f, 0.5f, 0.5f};
  scene.lighting.sky_by_direction = true;
  EXPECT_THROW(render_scattering(Image(), ground_plane_distance(scene), kCamera, scene), Error);
}

TEST(SkyLight, SceneDocumentField) {
  FogScene scene;
  for (const std::optional<bool> v :
       {std::optional<bool>{}, std::optional<bool>{true}, std::optional<bool>{false}}) {
    scene.lighting.sky_by_direction = v;
    const FogScene back = scene_from_json(scene_to_json(scene));
    EXPECT_EQ(back.lighting.sky_by_direction, v);
  }
  EXPECT_THROW(scene_from_json(R"({"format": "libmr-scene", "version": 2,
                                   "lighting": {"sky_by_direction": "yes"}})"),
               Error);
}

// Issue 11, class 2 of gallery/results/haze11b_tune.md (helper haze14): a hue edge becoming a
// luma edge at the sky. A tree of brown leaves 12 m away against a deep blue sky of about the
// leaves' luma: in haze the sky behind it is seen through the whole layer (T ~ 0) and took the
// fog's flat, neutral light, much brighter than the deep blue, while the leaves stay nearly
// clear (T ~ 0.98); the photo's edge, mostly hue, became a luma step. The geometry is exact
// (the tree's coverage from 4 x 4 samples a pixel: its matte and, at half coverage, its
// distance), so the case is the sky light alone.

struct TreeScene {
  Image photo, distance, alpha;
};
TreeScene leaves_against_a_deep_blue_sky(const FogScene& scene) {  // all sky behind the tree
  std::mt19937 rng(14);
  std::uniform_real_distribution<double> unit(0, 1);
  std::vector<std::array<double, 3>> leaves;  // x, y, radius (pixels)
  for (int i = 0; i < 70; ++i)
    leaves.push_back({105 + 110 * unit(rng), 35 + 70 * unit(rng), 6 + 9 * unit(rng)});
  auto covered = [&](double x, double y) {
    if (x >= 156 && x < 166 && y >= 90) return true;  // the trunk, down to the ground
    for (const auto& l : leaves)
      if (std::hypot(x - l[0], y - l[1]) < l[2]) return true;
    return false;
  };
  std::uniform_real_distribution<float> grain(-0.035f, 0.035f);
  TreeScene t{Image(kW, kH, 3), ground_plane_distance(scene), Image(kW, kH, 1)};
  constexpr double kTreeDistanceM = 12;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      int n = 0;
      for (int j = 0; j < 4; ++j)
        for (int i = 0; i < 4; ++i) n += covered(x + (i + 0.5) / 4, y + (j + 0.5) / 4);
      const double cover = n / 16.0;
      const Vec3 w = scene.pose.ray_direction(kCamera, x, y);
      const bool sky = std::isinf(t.distance.at(x, y, 0));
      // Deep blue sky, lighter toward the horizon (display luma 0.33 .. 0.40); dark olive ground.
      const float up = std::clamp(float(w.y / 0.5), 0.0f, 1.0f);
      const std::array<float, 3> back =
          sky ? std::array<float, 3>{0.28f - 0.12f * up, 0.43f - 0.09f * up, 0.80f - 0.06f * up}
              : std::array<float, 3>{0.22f + grain(rng), 0.24f + grain(rng), 0.14f};
      // Brown leaves of about the sky's luma (0.35), textured.
      const float g = grain(rng);
      const std::array<float, 3> leaf{0.52f + g, 0.33f + g, 0.15f + 0.5f * g};
      for (int c = 0; c < 3; ++c)
        t.photo.at(x, y, c) =
            float(cover * linear(leaf[c]) + (1 - cover) * linear(std::clamp(back[c], 0.0f, 1.0f)));
      if (cover >= 0.5) t.distance.at(x, y, 0) = float(kTreeDistanceM);
      t.alpha.at(x, y, 0) = sky ? float(1 - cover) : 0.0f;  // the sky's share of the pixel
    }
  return t;
}

// The haze look over the leaves, looking up (no ground in the frame), lit as the looks are
// ('auto': the dark channel's airlight) with the sky light by direction.
struct LeavesInHaze {
  FogScene scene;
  TreeScene t;
};
LeavesInHaze leaves_in_haze() {
  LeavesInHaze l{haze_scene(), {}};
  l.scene.pose.pitch_deg = 25;
  l.t = leaves_against_a_deep_blue_sky(l.scene);
  l.scene.lighting.sky_by_direction = true;
  l.scene.lighting.sky_radiance = estimate_airlight(l.t.photo);
  return l;
}

TEST(SkyLight, HueEdgeAgainstADeepBlueSkyStaysAHueEdgeInHaze) {
  FogScene scene = haze_scene();
  scene.pose.pitch_deg = 25;  // looking up: no ground in the frame (its horizon is another case)
  const TreeScene t = leaves_against_a_deep_blue_sky(scene);
  scene.lighting.sky_by_direction = true;
  scene.lighting.sky_radiance = estimate_airlight(t.photo);
  Image map_before, map_after;
  const FogLayers fog_before =
      fog_with_sky_light(t.photo, t.distance, t.alpha, scene, false, kCamera);
  const FogLayers fog_after =
      fog_with_sky_light(t.photo, t.distance, t.alpha, scene, true, kCamera);
  const double e_before = test::gallery_created_edges(t.photo, fog_before.composite, &map_before);
  const double e_after = test::gallery_created_edges(t.photo, fog_after.composite, &map_after);
  if (const char* folder = std::getenv("MR_TEST_IMAGES"); folder && *folder) {  // to look at
    const std::string f(folder);
    write_image(f + "/leaves_photo.png", t.photo);
    write_image(f + "/leaves_haze_before.png", fog_before.composite);
    write_image(f + "/leaves_haze_after.png", fog_after.composite);
    write_image(f + "/leaves_edges_before.png", map_before);
    write_image(f + "/leaves_edges_after.png", map_after);
  }
  std::printf("leaves against a deep blue sky, haze: created-edge pixels %.4f %% -> %.4f %%\n",
              100 * e_before, 100 * e_after);
  EXPECT_GT(e_before, 2e-4);  // the class reproduced
  EXPECT_LE(e_after, 2e-4);   // the issue's target
}

// Issue 11: a deep blue sky seen through haze turned slate grey (the light's colour went
// through the neutral prior, whose cool end is 10000 K daylight, C* 21, while the scale brought
// it to the blue's luma: gallery/tune palace and kite). Haze lit by a clear sky and no sun takes
// part of that sky's colour: the light's hue moves half way toward the photo's own sky around
// the pixel at the same display luma, bounded to the chroma of every automatic fog colour
// (33.6, under the gallery's 36.1). Where the sky is seen through the whole layer (T < 0.01
// here, 25-45 degrees up) the fogged sky keeps a muted blue of the photo's luma.
TEST(SkyLight, DeepBlueSkyThroughHazeKeepsSomeOfItsBlueAtItsLuma) {
  const auto [scene, t] = leaves_in_haze();
  const FogLayers fog = fog_with_sky_light(t.photo, t.distance, t.alpha, scene, true, kCamera);
  const SkyLight light =
      sky_light_from_photo(t.photo, t.distance, kCamera, scene, *scene.lighting.sky_radiance);
  ASSERT_FALSE(light.tint.empty());
  EXPECT_EQ(light.tint.channels(), 3);
  // The same render with the scale alone (the tint cleared), as fog_with_sky_light composes it.
  SkyLight scale_only = light;
  scale_only.tint = Image();
  Image scale_only_composite(kW, kH, 3);
  {
    FogScene plain = scene;
    plain.lighting.sky_by_direction = false;
    ScatteringLayers layers = render_scattering(t.photo, t.distance, kCamera, plain);
    add_sky_light(scale_only, scene.medium, kCamera, scene.pose, layers.optical_depth,
                  layers.inscatter);
    photo::apply_sky_matte(t.alpha.view(), layers.transmittance.view(), layers.inscatter.view());
    photo::composite(t.photo.view(), layers.transmittance.view(), layers.inscatter.view(),
                     scale_only_composite.view());
  }
  const cv::Mat scale_only_luma = test::display_luma(scale_only_composite);
  // The open sky left of the tree (leaves from x = 90 on), away from the frame's top rows.
  const cv::Mat photo_display_luma = test::display_luma(t.photo);
  const cv::Mat fog_display_luma = test::display_luma(fog.composite);
  std::array<double, 3> photo_sum{}, fog_sum{};
  double photo_luma = 0, fog_luma = 0, fog_luma_scale_only = 0;
  int n = 0;
  for (int y = 10; y < 40; ++y)
    for (int x = 10; x < 70; ++x) {
      ASSERT_TRUE(std::isinf(t.distance.at(x, y, 0)));
      for (int c = 0; c < 3; ++c) {
        photo_sum[c] += t.photo.at(x, y, c);
        fog_sum[c] += fog.composite.at(x, y, c);
      }
      photo_luma += photo_display_luma.at<float>(y, x);
      fog_luma += fog_display_luma.at<float>(y, x);
      fog_luma_scale_only += scale_only_luma.at<float>(y, x);
      ++n;
    }
  auto mean = [&](const std::array<double, 3>& s) {
    return std::array<float, 3>{float(s[0] / n), float(s[1] / n), float(s[2] / n)};
  };
  const double photo_chroma = photo::chroma_ab(mean(photo_sum));
  // The fog's colour is the light's (the composite adds the photo's sky times T ~ 0.005).
  std::array<double, 3> light_sum{}, scale_only_sum{};
  for (int y = 10; y < 40; ++y)
    for (int x = 10; x < 70; ++x) {
      const Vec3 w = scene.pose.ray_direction(kCamera, x, y);
      const Rgb d = light.deviation_at(w, x, y), d_scale_only = scale_only.deviation_at(w, x, y);
      for (int c = 0; c < 3; ++c) {
        light_sum[c] += light.sky_radiance[c] + d[c];
        scale_only_sum[c] += light.sky_radiance[c] + d_scale_only[c];
      }
    }
  const double fog_chroma = photo::chroma_ab(mean(light_sum));
  const double scale_only_chroma = photo::chroma_ab(mean(scale_only_sum));
  const std::array<float, 3> f = mean(fog_sum);
  std::printf(
      "deep blue sky through haze: C* photo %.1f -> fog %.1f (%.1f without the tint; "
      "%.3f %.3f %.3f); display luma %.3f -> %.3f (%.3f without the tint)\n",
      photo_chroma, fog_chroma, scale_only_chroma, f[0], f[1], f[2], photo_luma / n, fog_luma / n,
      fog_luma_scale_only / n);
  EXPECT_GT(photo_chroma, 40);                   // a deep blue
  EXPECT_GT(fog_chroma, scale_only_chroma + 5);  // bluer than through the neutral prior alone
  EXPECT_LE(fog_chroma, 33.6 + 0.1);             // within every automatic fog colour's bound
  EXPECT_GT(f[2], 1.5 * f[0]);                   // blue, not another hue
  // The tint leaves the display luma the scale gives (the photo's, up to the scale's knee).
  EXPECT_NEAR(fog_luma / n, fog_luma_scale_only / n, 0.005);
  EXPECT_NEAR(fog_luma / n, photo_luma / n, 0.05 * photo_luma / n);
}

// The render asks for the brightness scale by default (helper haze15: mr::fog, and through
// sky_light_from_photo's default the streamed `mr fog` too): the leaves of the test above, fogged
// by mr::fog as `mr fog` does, keep their hue edge (before haze15 the render left the light
// flat: 0.42 % created edges).
TEST(SkyLight, TheRenderScalesTheSkyLightToThePhotosSkyByDefault) {
  const auto [scene, t] = leaves_in_haze();
  const SkyLight light =
      sky_light_from_photo(t.photo, t.distance, kCamera, scene, *scene.lighting.sky_radiance);
  EXPECT_FALSE(light.scale.empty());
  const FogLayers fogged = fog(t.photo, t.distance, t.alpha, kCamera, scene);
  const double e = test::gallery_created_edges(t.photo, fogged.composite);
  std::printf("leaves against a deep blue sky, mr::fog's haze: created-edge pixels %.4f %%\n",
              100 * e);
  EXPECT_LE(e, 2e-4);  // the issue's target
}

// A dark cloud's flat body beside the bright glow around a hidden sun, all sky: the sky's
// brightness is never mixed across the cloud's edge (a plain blur mixed the two: the body near
// its edge brightened, the glow dimmed, each a new gradient). The body, darker than the fog's
// light, keeps its own brightness; the glow, brighter, is not dimmed (all sky, it rises toward
// the photo's own glow: photo/sky_light.h).
TEST(SkyLight, DarkCloudBesideItsGlowKeepsItsBrightnessInHaze) {
  FogScene scene = all_sky_haze_scene();
  const Image distance = ground_plane_distance(scene);
  Image photo(kW, kH, 3);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> grain(-0.01f, 0.01f);
  auto cloud_cover = [](double x, double y) {  // a soft-edged ellipse (about 3 px ramp)
    const double r = std::hypot((x - 120) / 70, (y - 55) / 28);
    return std::clamp((1.0 - r) * 28 / 3 + 0.5, 0.0, 1.0);
  };
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      std::array<float, 3> c;
      if (std::isinf(distance.at(x, y, 0))) {
        const double glow = 0.45 * std::exp(-std::pow(std::hypot(x - 175.0, y - 60.0) / 70, 2));
        const std::array<float, 3> sky{float(0.52 + glow), float(0.58 + 0.95 * glow),
                                       float(0.70 + 0.85 * glow)};
        const float k = float(cloud_cover(x, y));
        const std::array<float, 3> body{0.25f, 0.26f, 0.30f};
        for (int i = 0; i < 3; ++i) c[i] = sky[i] * (1 - k) + body[i] * k;
      } else {
        c = {0.20f + grain(rng), 0.22f + grain(rng), 0.15f};
      }
      for (int i = 0; i < 3; ++i) photo.at(x, y, i) = linear(std::clamp(c[i], 0.0f, 1.0f));
    }
  scene.lighting.sky_by_direction = true;
  scene.lighting.sky_radiance = estimate_airlight(photo);
  const FogLayers fog_before = fog_with_sky_light(photo, distance, Image(), scene, false, kCamera);
  const FogLayers fog_after = fog_with_sky_light(photo, distance, Image(), scene, true, kCamera);
  auto lum = [](const Image& img, int x, int y) {  // display luma
    auto e = [&](int c) { return std::pow(std::clamp(img.at(x, y, c), 0.0f, 1.0f), 1 / 2.2f); };
    return 0.2126 * e(0) + 0.7152 * e(1) + 0.0722 * e(2);
  };
  // Pixels 4-8 px inside the body along its edge, and 4-8 px outside it in the glow: the
  // fogged sky's display luma against the photo's there (in haze the sky is all fog, T ~ 0).
  double worst_before = 0, worst_after = 0, glow_dimmed = 0, glow_rise = 0;
  std::size_t body = 0, glow = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const double r = std::hypot((x - 120.0) / 70, (y - 55.0) / 28);
      const double px = (r - 1) * 28;  // about the distance from the edge in pixels (minor axis)
      const bool in_body = px > -8 && px < -4, in_glow = px > 4 && px < 8 && x > 150;
      if (!in_body && !in_glow) continue;
      body += in_body, glow += in_glow;
      const double p = lum(photo, x, y), b = lum(fog_before.composite, x, y);
      const double a = lum(fog_after.composite, x, y);
      if (in_body) {
        worst_before = std::max(worst_before, std::abs(b / p - 1));
        worst_after = std::max(worst_after, std::abs(a / p - 1));
      } else {
        glow_dimmed = std::max(glow_dimmed, 1 - a / b);
        glow_rise = std::max(glow_rise, a / b - 1);
      }
    }
  const double e_before = test::gallery_created_edges(photo, fog_before.composite);
  const double e_after = test::gallery_created_edges(photo, fog_after.composite);
  if (const char* folder = std::getenv("MR_TEST_IMAGES"); folder && *folder) {  // to look at
    const std::string f(folder);
    write_image(f + "/cloud_glow_photo.png", photo);
    write_image(f + "/cloud_glow_haze_before.png", fog_before.composite);
    write_image(f + "/cloud_glow_haze_after.png", fog_after.composite);
  }
  std::printf(
      "dark cloud beside its glow (%zu body, %zu glow pixels): the body's worst luma change "
      "from the photo %.3f -> %.3f, the glow dimmed from before by %.4f, brightened by at "
      "most %.4f; created-edge pixels %.4f %% -> %.4f %%\n",
      body, glow, worst_before, worst_after, glow_dimmed, glow_rise, 100 * e_before, 100 * e_after);
  ASSERT_GT(body, 100u);
  ASSERT_GT(glow, 100u);
  EXPECT_GT(worst_before, 0.3);  // the flat fog: the body much brighter
  EXPECT_LT(worst_after, 0.1);   // the body keeps its own brightness up to its edge
  // The glow is not dimmed by the body beside it (all sky, far from any surface, it may rise
  // toward the photo's own glow: SkyLight.WhiteCloudsDeepInABlueSkyKeepTheirBrightnessInHaze).
  EXPECT_LT(glow_dimmed, 1e-3);
  EXPECT_LE(e_after, 2e-4);
}

// White clouds deep in a blue sky, far from any surface (looking up: all sky), in haze. Held at
// the flat light (the scale only darkened), a white cloud turned into a grey patch at the mean
// sky's luma, a storm where the photo had a bright day (gallery/tune's kite, god_rays): deep in
// the sky the light now follows the sky's own luma, pixel by pixel (photo/sky_light.h), so the
// cloud keeps most of its brightness and its rim is the photo's own, no sharper. The old code:
// the cloud's centre at display luma 0.578 of the photo's 0.939 (now 0.770).
TEST(SkyLight, WhiteCloudsDeepInABlueSkyKeepTheirBrightnessInHaze) {
  FogScene scene = all_sky_haze_scene();
  const Image distance = ground_plane_distance(scene);
  Image photo(kW, kH, 3);
  constexpr double kCloudX = 90, kCloudY = 110, kCloudRadius = 70;  // pixels
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      ASSERT_TRUE(std::isinf(distance.at(x, y, 0)));
      const double r = std::hypot(x - kCloudX, y - kCloudY) / kCloudRadius;
      const double k = std::clamp((1.0 - r) * 6 + 0.5, 0.0, 1.0);  // a rim of ~12 px
      const std::array<double, 3> blue{0.20, 0.40, 0.72}, white{0.93, 0.94, 0.96};
      for (int i = 0; i < 3; ++i)
        photo.at(x, y, i) = linear(float(blue[i] + (white[i] - blue[i]) * k));
    }
  const FogLayers fogged = all_sky_haze_of(photo, distance, scene, "white_cloud");
  const cv::Mat photo_luma = test::display_luma(photo);
  const cv::Mat fog_luma = test::display_luma(fogged.composite);
  double photo_centre = 0, fog_centre = 0, photo_blue = 0, fog_blue = 0;
  int n_centre = 0, n_blue = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const double r = std::hypot(x - kCloudX, y - kCloudY) / kCloudRadius;
      if (r < 0.3) {
        photo_centre += photo_luma.at<float>(y, x), fog_centre += fog_luma.at<float>(y, x);
        ++n_centre;
      } else if (x > 250) {
        photo_blue += photo_luma.at<float>(y, x), fog_blue += fog_luma.at<float>(y, x);
        ++n_blue;
      }
    }
  const double e = test::gallery_created_edges(photo, fogged.composite);
  std::printf(
      "white cloud deep in a blue sky, haze: the cloud's centre display luma %.3f -> %.3f, "
      "the blue far from it %.3f -> %.3f; created-edge pixels %.4f %%\n",
      photo_centre / n_centre, fog_centre / n_centre, photo_blue / n_blue, fog_blue / n_blue,
      100 * e);
  ASSERT_GT(n_centre, 100);
  ASSERT_GT(n_blue, 100);
  EXPECT_GT(fog_centre / n_centre, 0.8 * photo_centre / n_centre);   // the cloud stays white
  EXPECT_LT(fog_centre / n_centre, 1.02 * photo_centre / n_centre);  // never above the photo's
  EXPECT_NEAR(fog_blue / n_blue, photo_blue / n_blue, 0.05 * photo_blue / n_blue);
  EXPECT_LE(e, 2e-4);  // the issue's target
}

// A glow around a hidden sun fades into a darker sky, all sky: where the photo's sky is darker
// than the fog's light the scale darkens the light to it, where brighter it keeps the light.
// A hard limit at "only ever darker" cut the fogged sky's gradient along the contour where the
// two are equal: the slope of its luma fell to nothing from one row to the next, a Mach band
// that drew a bright arc through the haze of gallery/tune's sunset_aitzol (and held-out
// canyon_dusk). Measured down the glow's centre column: the largest change of the fogged
// luma's slope (over 6 rows) from one window to the next, against its largest slope: the photo
// 0.16 (its Gaussian glow's curvature), the hard limit 0.81 (the slope falls to a seventh
// within 6 rows), the knee (photo/sky_light.cpp, soft_limit_to_one) 0.35. A wider knee
// brightens more of a deep blue sky toward the light and brings back the leaves' edges of
// HueEdgeAgainstADeepBlueSkyStaysAHueEdgeInHaze (knee 0.4: 0.0195 %, 0.5: 0.039 %).
TEST(SkyLight, GlowBrighterThanTheLightFadesIntoTheScaledSkyWithoutAKink) {
  FogScene scene = all_sky_haze_scene();
  const Image distance = ground_plane_distance(scene);
  Image photo(kW, kH, 3);
  constexpr double kGlowX = 160, kGlowY = 200, kGlowRadius = 90;  // pixels
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const double glow =
          0.5 * std::exp(-std::pow(std::hypot(x - kGlowX, y - kGlowY) / kGlowRadius, 2));
      const std::array<float, 3> c{float(0.35 + 1.1 * glow), float(0.45 + glow),
                                   float(0.62 + 0.8 * glow)};
      for (int i = 0; i < 3; ++i) photo.at(x, y, i) = linear(std::clamp(c[i], 0.0f, 1.0f));
    }
  const FogLayers fogged = all_sky_haze_of(photo, distance, scene, "glow");
  auto lum = [](const Image& img, int x, int y) {  // display luma
    auto e = [&](int c) { return std::pow(std::clamp(img.at(x, y, c), 0.0f, 1.0f), 1 / 2.2f); };
    return 0.2126 * e(0) + 0.7152 * e(1) + 0.0722 * e(2);
  };
  // Slopes over kRows rows (the render's march jitter changes single rows' slopes by ~40 %).
  auto kink = [&](const Image& img) {
    constexpr int kRows = 6;
    const int x = int(kGlowX);
    double slope = 0, change = 0;
    for (int y = kRows; y + kRows < kH; ++y) {
      const double up = (lum(img, x, y) - lum(img, x, y - kRows)) / kRows;
      const double down = (lum(img, x, y + kRows) - lum(img, x, y)) / kRows;
      slope = std::max(slope, std::abs(down));
      change = std::max(change, std::abs(down - up));
    }
    return change / slope;
  };
  // The scale must act in the frame (the sky darker than the light at the top) and leave it
  // (the glow brighter): otherwise there is no contour to test.
  const SkyLight light =
      sky_light_from_photo(photo, distance, kCamera, scene, *scene.lighting.sky_radiance);
  ASSERT_FALSE(light.scale.empty());
  float lowest = 1, highest = 0;
  for (int y = 0; y < kH; ++y) {
    lowest = std::min(lowest, light.scale.at(int(kGlowX), y, 0));
    highest = std::max(highest, light.scale.at(int(kGlowX), y, 0));
  }
  const double k_photo = kink(photo), k_fog = kink(fogged.composite);
  std::printf(
      "glow into a darker sky, haze: scale %.3f .. %.3f down the column; largest "
      "change of slope / largest slope: photo %.3f, fogged %.3f\n",
      lowest, highest, k_photo, k_fog);
  EXPECT_LT(lowest, 0.8f);
  EXPECT_GT(highest, 0.999f);
  EXPECT_LT(k_fog, 0.4);  // 0.81 with the hard limit, 0.35 with the knee
}
// In fog (visibility under 1 km) the light has scattered from the whole dome: the photo's sky
// brightness behind each pixel must not pattern it. With the scale at full weight, dense fog
// under a deep blue sky with leaves turned into a dark "storm" of the sky's own luma
// (gallery/tune/kite, summer_1am); in haze (2 km) the scale still applies.
TEST(SkyLight, DenseFogTakesTheWholeDomesLightNotTheSkyBehindEachPixel) {
  EXPECT_EQ(sky_brightness_scale_weight(Medium{}), 0.0);  // 150 m visibility
  auto weight_at = [](double visibility_m) {
    Medium m;
    const float sigma = float(extinction_from_visibility(visibility_m));
    m.sigma_t_per_m = {sigma, sigma, sigma};
    return sky_brightness_scale_weight(m);
  };
  EXPECT_EQ(weight_at(60), 0.0);
  EXPECT_NEAR(weight_at(500), 0.0, 1e-6);  // float sigma_t round trip
  EXPECT_NEAR(weight_at(500 * std::sqrt(2.0)), 0.5, 1e-6);  // log-linear: no step on a slider
  EXPECT_NEAR(weight_at(1000), 1.0, 1e-6);
  EXPECT_EQ(weight_at(2000), 1.0);
  Medium clear;
  clear.sigma_t_per_m = {0, 0, 0};
  EXPECT_EQ(sky_brightness_scale_weight(clear), 1.0);

  FogScene haze = haze_scene();
  haze.pose.pitch_deg = 25;
  const TreeScene t = leaves_against_a_deep_blue_sky(haze);
  haze.lighting.sky_by_direction = true;
  haze.lighting.sky_radiance = estimate_airlight(t.photo);
  FogScene dense = haze;  // the gallery's dense look: 60 m visibility, an 80 m layer, g = 0.3
  const float sigma = float(extinction_from_visibility(60));
  dense.medium.sigma_t_per_m = {sigma, sigma, sigma};
  dense.medium.layer_top_m = 80;
  dense.medium.g = 0.3;
  EXPECT_FALSE(sky_light_from_photo(t.photo, t.distance, kCamera, haze, *haze.lighting.sky_radiance)
                   .scale.empty());
  EXPECT_TRUE(
      sky_light_from_photo(t.photo, t.distance, kCamera, dense, *dense.lighting.sky_radiance)
          .scale.empty());
  // Dense fog with the photo's brightness asked for is the flat light's render, bit for bit.
  const FogLayers flat = fog_with_sky_light(t.photo, t.distance, t.alpha, dense, false, kCamera);
  const FogLayers scaled = fog_with_sky_light(t.photo, t.distance, t.alpha, dense, true, kCamera);
  EXPECT_TRUE(same_bits(flat.composite, scaled.composite));
  // In haze the scale still darkens the sky's fog toward the photo's deep blue.
  const FogLayers haze_flat =
      fog_with_sky_light(t.photo, t.distance, t.alpha, haze, false, kCamera);
  const FogLayers haze_scaled =
      fog_with_sky_light(t.photo, t.distance, t.alpha, haze, true, kCamera);
  double darker = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x)
      if (std::isinf(t.distance.at(x, y, 0)))
        darker = std::max(
            darker, double(haze_flat.composite.at(x, y, 1) - haze_scaled.composite.at(x, y, 1)));
  std::printf("haze: the scale darkens the sky's fog by up to %.4f (linear green)\n", darker);
  EXPECT_GT(darker, 0.01);
}

}  // namespace
}  // namespace mr
