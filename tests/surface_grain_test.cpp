// The surface term S of the transmittance map on smooth surfaces (DESIGN.md section 3): a
// sphere resting on open ground, lit by a sun from behind the camera in homogeneous fog, must
// show a T as smooth as the geometry, and as bright on average as the brute-force reference
// (tests/mc_reference.h, surface_reference: the exact geometry, many rays per pixel).
//
// The defect this guards against (issue surf16, gallery/results/insert_sheet.md): the core used
// 8 hashed ambient-occlusion rays per exact grid sample, independent from sample to sample, and
// interpolated the samples with their gradients, which turned the rays' noise into blotches a
// few grid cells wide: dark mottling on untextured inserted objects under sun and fog.
//
// Measures, on T's surface factor S = T / tau(camera, surface) (tau in closed form: the camera's
// transmittance varies fast near the horizon, smoothly, and is not what is measured), over the
// sunlit smooth parts (exact geometry: the sphere where the sun is more than 12 degrees above
// its horizon, the open ground around it; a margin of 3 pixels from any edge, silhouette or
// shadow):
//  * grain: RMS of S minus its local quadratic fit (7 x 7 pixels), relative to the region's
//    mean S: what a viewer sees as mottling, speckle or banding;
//  * bias: the region's mean S against the reference's, relative;
//  * blotch: the mean |blur(S) - blur(S_ref)| relative to the mean S_ref (sigma 2 px): errors
//    wider than the grain's scale (the reference's own noise, 2048 independent rays a pixel,
//    averages out there; its grain, printed, is that noise).
// MR_TEST_IMAGES=<folder>: S of the core and the reference as PNGs (x2).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "mc_reference.h"
#include "mr/io.h"
#include "mr/scattering.h"
#include "mr/scene.h"
#ifdef MR_SCATTERING_TEST_VULKAN
#include "vulkan_test_support.h"
#endif

namespace mr {
namespace {

#ifdef MR_SCATTERING_TEST_VULKAN
constexpr Backend kBackend = Backend::vulkan;
constexpr const char* kBackendName = "vulkan";
#else
constexpr Backend kBackend = Backend::cpu;
constexpr const char* kBackendName = "cpu";
#endif

// Fewer reference rays where the code runs unoptimised or under AddressSanitizer (CI); the
// bars stay the same.
#if defined(__SANITIZE_ADDRESS__) || !defined(__OPTIMIZE__)
constexpr int kReferenceRays = 512;
#else
constexpr int kReferenceRays = 2048;
#endif

struct GrainScene {
  Camera camera = Camera::from_horizontal_fov(192, 144, 50);
  FogScene scene;
  mcref::Geometry geometry;
  Image distance;
  mcref::SurfaceResult reference;
  std::vector<unsigned char> sphere, ground;  // the measured regions (row-major)
};

GrainScene make_grain_scene() {
  GrainScene g;
  FogScene& s = g.scene;
  s.pose.position_m = {0, 1.6, 0};
  s.pose.pitch_deg = -8;
  // Homogeneous fog of 150 m visibility with no top (mr insert --visibility 150m): the sun's
  // path out of the fog is infinite, so S is the ambient share of the surface's light alone and
  // reads the ambient occlusion undiluted.
  const float sigma = float(3.912 / 150.0);
  s.medium.sigma_t_per_m = {sigma, sigma, sigma};
  s.medium.albedo = {0.9f, 0.9f, 0.9f};
  s.lighting.sun = Sun{direction_from_azimuth_elevation(155, 35), {3.0f, 2.9f, 2.7f}, 0.27};
  s.lighting.sky_radiance = Rgb{0.30f, 0.34f, 0.42f};
  s.render.quality = Quality::normal;
  g.geometry.ground = true;
  g.geometry.spheres.push_back(mcref::Sphere{{0.3, 1.4, 8.0}, 1.4});
  g.distance = mcref::distance_map(g.camera, s.pose, g.geometry);
  g.reference = mcref::surface_reference(g.distance, g.camera, s, g.geometry, kReferenceRays);

  const int w = g.camera.width, h = g.camera.height;
  std::vector<int> kind(std::size_t(w) * h, 0);  // 0 other, 1 sphere lit, 2 ground lit
  const Vec3 l = s.lighting.sun->direction_to_sun;
  const double l_len = std::sqrt(l.x * l.x + l.y * l.y + l.z * l.z);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const Vec3 o = s.pose.position_m;
      const Vec3 d = s.pose.ray_direction(g.camera, x, y);
      const mcref::Geometry::Hit hit = g.geometry.first_hit_info(o, d);
      if (g.reference.sun_visibility.at(x, y, 0) < 1.0f) continue;
      const Vec3& n = hit.normal;
      const double cos_i = (n.x * l.x + n.y * l.y + n.z * l.z) / l_len;
      if (hit.kind == mcref::Geometry::Hit::Kind::sphere && cos_i > std::sin(12 * M_PI / 180))
        kind[std::size_t(y) * w + x] = 1;
      if (hit.kind == mcref::Geometry::Hit::Kind::ground) kind[std::size_t(y) * w + x] = 2;
    }
  constexpr int kMargin = 3;
  g.sphere.assign(kind.size(), 0);
  g.ground.assign(kind.size(), 0);
  for (int y = kMargin; y < h - kMargin; ++y)
    for (int x = kMargin; x < w - kMargin; ++x) {
      const int k = kind[std::size_t(y) * w + x];
      if (k == 0) continue;
      bool interior = true;
      for (int j = -kMargin; j <= kMargin && interior; ++j)
        for (int i = -kMargin; i <= kMargin && interior; ++i)
          interior = kind[std::size_t(y + j) * w + std::size_t(x + i)] == k;
      if (interior) (k == 1 ? g.sphere : g.ground)[std::size_t(y) * w + x] = 1;
    }
  return g;
}

// S = T / tau(camera, surface), the channels' mean (homogeneous fog: tau = exp(-sigma d)).
std::vector<double> surface_factor(const Image& t, const GrainScene& g) {
  std::vector<double> v(std::size_t(t.width()) * t.height(), 0.0);
  for (int y = 0; y < t.height(); ++y)
    for (int x = 0; x < t.width(); ++x) {
      const double d = g.distance.at(x, y, 0);
      if (!std::isfinite(d)) continue;
      double sum = 0;
      for (int c = 0; c < 3; ++c)
        sum += t.at(x, y, c) / std::exp(-double(g.scene.medium.sigma_t_per_m[c]) * d);
      v[std::size_t(y) * t.width() + x] = sum / 3;
    }
  return v;
}

void write_surface_factor(const std::vector<double>& v, int w, int h, const std::string& name) {
  const char* dir = std::getenv("MR_TEST_IMAGES");
  if (!dir || !*dir) return;
  std::filesystem::create_directories(dir);
  Image image(w, h, 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) image.at(x, y, c) = float(2 * v[std::size_t(y) * w + x]);
  WriteOptions linear;
  linear.colorspace = "data";
  write_image(std::filesystem::path(dir) / ("grain_" + name + "_S_x2.exr"), image, linear);
}

// Gaussian blur (sigma 2 px) over the region's pixels only (normalised convolution).
std::vector<double> region_blur(const std::vector<double>& v, const std::vector<unsigned char>& in,
                                int w, int h) {
  constexpr int kRadius = 6;
  constexpr double kSigma = 2.0;
  std::vector<double> out(v.size(), 0.0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      if (!in[std::size_t(y) * w + x]) continue;
      double sum = 0, weight = 0;
      for (int j = std::max(0, y - kRadius); j <= std::min(h - 1, y + kRadius); ++j)
        for (int i = std::max(0, x - kRadius); i <= std::min(w - 1, x + kRadius); ++i) {
          const std::size_t k = std::size_t(j) * w + i;
          if (!in[k]) continue;
          const double wt =
              std::exp(-((i - x) * (i - x) + (j - y) * (j - y)) / (2 * kSigma * kSigma));
          sum += wt * v[k];
          weight += wt;
        }
      out[std::size_t(y) * w + x] = sum / weight;
    }
  return out;
}

// S minus its local quadratic fit: the 7-point quadratic Savitzky-Golay smoother along x, then
// along y (exact for any quadratic in x and y, so the smooth shading's curvature, steep near
// the terminator, leaves no residual; white noise keeps 94 % of its RMS). Only for pixels whose
// 7 x 7 window lies on their own surface (kMargin = 3).
std::vector<double> quadratic_residual(const std::vector<double>& v,
                                       const std::vector<unsigned char>& in, int w, int h) {
  constexpr double kC[7] = {-2 / 21.0, 3 / 21.0, 6 / 21.0, 7 / 21.0, 6 / 21.0, 3 / 21.0, -2 / 21.0};
  std::vector<double> out(v.size(), 0.0);
  for (int y = 3; y < h - 3; ++y)
    for (int x = 3; x < w - 3; ++x) {
      if (!in[std::size_t(y) * w + x]) continue;
      double smooth = 0;
      for (int j = -3; j <= 3; ++j)
        for (int i = -3; i <= 3; ++i)
          smooth += kC[j + 3] * kC[i + 3] * v[std::size_t(y + j) * w + std::size_t(x + i)];
      out[std::size_t(y) * w + x] = v[std::size_t(y) * w + x] - smooth;
    }
  return out;
}

struct Smoothness {
  int pixels = 0;
  double grain = 0, bias = 0, blotch = 0, reference_grain = 0;
};

Smoothness measure(const std::vector<double>& v, const std::vector<double>& r,
                   const std::vector<unsigned char>& in, int w, int h) {
  const std::vector<double> bv = region_blur(v, in, w, h), br = region_blur(r, in, w, h);
  const std::vector<double> qv = quadratic_residual(v, in, w, h),
                            qr = quadratic_residual(r, in, w, h);
  Smoothness m;
  double sum_v = 0, sum_r = 0, hp = 0, hp_ref = 0, low = 0;
  for (std::size_t k = 0; k < v.size(); ++k) {
    if (!in[k]) continue;
    ++m.pixels;
    sum_v += v[k];
    sum_r += r[k];
    hp += qv[k] * qv[k];
    hp_ref += qr[k] * qr[k];
    low += std::fabs(bv[k] - br[k]);
  }
  const double mean_v = sum_v / m.pixels, mean_r = sum_r / m.pixels;
  m.grain = std::sqrt(hp / m.pixels) / mean_v;
  m.reference_grain = std::sqrt(hp_ref / m.pixels) / mean_r;
  m.bias = (mean_v - mean_r) / mean_r;
  m.blotch = low / m.pixels / mean_r;
  return m;
}

// Bars: grain below 0.5 % of S, mean within 1 % of the reference, blotches (errors wider than the
// grain) below 1 %. Measured (CPU): before, with 8 hashed AO rays per sample, normal: sphere
// grain 1.41 %, blotch 2.31 %; ground 0.62 %, 0.86 %; draft sphere 1.64 %, 3.01 %. With one
// consistent set (8 rays, 32 where partly occluded), normal: sphere 0.12 %, 0.68 %, bias
// +0.59 %; ground 0.21 %, 0.82 %, bias +0.76 % (the occluder mesh's sphere has no back half: a
// little less occlusion around it); draft sphere 0.30 %, 0.58 %. The reference's own grain, its
// independent per-pixel noise, is 0.47 % on the sphere and 0.24 % on the ground.
// The Vulkan backend marches its AO rays in screen space (scattering_common.glsl): a ray that
// grazes the sphere's silhouette hits or misses by whole pixel steps, which leaves isolated
// samples in the ground's halo (grain 0.67 % there, 0.15 % on the sphere; before: 0.87 %,
// 1.65 %), so its grain bar is 0.8 %; its other bars are the CPU's.
#ifdef MR_SCATTERING_TEST_VULKAN
constexpr double kGrainBar = 8e-3;
#else
constexpr double kGrainBar = 5e-3;
#endif
TEST(SurfaceGrain, SunlitSphereAndGroundInFogAreSmooth) {
#ifdef MR_SCATTERING_TEST_VULKAN
  vktest::configure_environment();
  std::string why;
  if (!vktest::backend_or_null(&why)) GTEST_SKIP() << why;
#endif
  const GrainScene g = make_grain_scene();
  for (const Quality quality : {Quality::draft, Quality::normal}) {
    FogScene s = g.scene;
    s.render.quality = quality;
    s.render.backend = kBackend;
    const ScatteringLayers out = render_scattering(Image(), g.distance, g.camera, s);
    EXPECT_EQ(out.backend.rfind(kBackendName, 0), 0u) << out.backend;
    const char* name = quality == Quality::draft ? "draft" : "normal";
    const int w = g.camera.width, h = g.camera.height;
    const std::vector<double> core = surface_factor(out.transmittance, g),
                              reference = surface_factor(g.reference.transmittance, g);
    write_surface_factor(core, w, h, std::string(kBackendName) + "_" + name);
    if (quality == Quality::normal) write_surface_factor(reference, w, h, "reference");
    for (const bool on_sphere : {true, false}) {
      const Smoothness m = measure(core, reference, on_sphere ? g.sphere : g.ground, w, h);
      std::printf(
          "[ Grain    ] %s %s, %s: %d pixels, grain %.3f %% (reference %.3f %%), bias "
          "%+.3f %%, blotch %.3f %%\n",
          kBackendName, name, on_sphere ? "sphere" : "ground", m.pixels, 100 * m.grain,
          100 * m.reference_grain, 100 * m.bias, 100 * m.blotch);
      EXPECT_GT(m.pixels, on_sphere ? 1500 : 8000);
      EXPECT_LT(m.grain, kGrainBar) << name << (on_sphere ? " sphere" : " ground");
      EXPECT_LT(std::fabs(m.bias), 1e-2) << name << (on_sphere ? " sphere" : " ground");
      EXPECT_LT(m.blotch, 1e-2) << name << (on_sphere ? " sphere" : " ground");
    }
  }
}

}  // namespace
}  // namespace mr
