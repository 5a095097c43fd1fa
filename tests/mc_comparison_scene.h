// The scene on which the scattering core is compared with the brute-force Monte Carlo
// estimator (tests/mc_reference.*), shared by tests/mc_reference_test.cpp (the CPU core) and
// tests/vulkan_shared_physics_test.cpp (both backends, issue 14).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>

#include "mc_reference.h"
#include "mr/image.h"
#include "mr/scene.h"

namespace mr::test {

// Fewer samples where the code runs unoptimised or under AddressSanitizer (CI).
#if defined(__SANITIZE_ADDRESS__) || !defined(__OPTIMIZE__)
constexpr bool kMcSlowBuild = true;
#else
constexpr bool kMcSlowBuild = false;
#endif

// Ground, two boxes, a low sun straight ahead above a 6 m fog layer (long shadows and shafts
// toward the camera; the sky rays leave the layer), a point lamp in open air, sky in the upper
// part of the view. Homogeneous fog of 80 m visibility.
//
// Sensitivity of this reference (measured with the estimator, mean relative change of R):
//  * volumetric shadows off: 7 %; the lamp contributes about a third of R;
//  * the boxes' hidden faces (which the core cannot see in the depth map): replacing the boxes
//    by their camera-facing faces, or making them 0.5 m deeper or shallower, changes nothing
//    (< 0.01 %): with the sun straight ahead every sun ray that meets a box enters it through
//    its front face. (With the sun 15 degrees to the side, a face seen at a grazing angle
//    decides part of a shadow, and the reference moved by 0.2 % per 0.5 m of box depth.)
//  * the depth map's pixels: moving every silhouette outward by half a pixel's footprint
//    changes R by 0.6 % (the sun-only part by 5 %). A reconstruction from a 96 x 64 depth map
//    cannot locate an edge better than that, so part of the 1 % bar is spent on it.
struct ComparisonScene {
  Camera camera;
  FogScene scene;
  mcref::Geometry geometry;
  Image distance;
  mcref::Result reference;
  std::size_t sky_pixels = 0;
};

inline const ComparisonScene& comparison_scene() {
  static const ComparisonScene cs = [] {
    ComparisonScene c;
    c.camera = Camera::from_horizontal_fov(96, 64, 60);
    FogScene& s = c.scene;
    s.pose.position_m = {0, 1.6, 0};
    s.pose.pitch_deg = -7;
    const float sigma = float(3.912 / 80.0);
    s.medium.sigma_t_per_m = {sigma, sigma, sigma};
    s.medium.albedo = {0.9f, 0.9f, 0.9f};
    s.medium.g = 0.3;
    s.medium.layer_top_m = 6.0;
    s.lighting.sun = Sun{direction_from_azimuth_elevation(0, 12), {3, 3, 3}, 0.27};
    s.lighting.sky_radiance = Rgb{0.3f, 0.3f, 0.3f};
    Lamp lamp;
    lamp.position_m = {-1.0, 2.5, 8};
    lamp.intensity_per_sr = {50, 50, 50};
    s.lighting.lamps.push_back(lamp);
    s.render.seed = 1;
    c.geometry.ground = true;
    c.geometry.boxes.push_back({{0.5, 0, 9}, {3.0, 3.0, 11.5}});
    c.geometry.boxes.push_back({{-6.0, 0, 15}, {-2.0, 4.0, 19}});
    c.distance = mcref::distance_map(c.camera, s.pose, c.geometry);
    for (float d : c.distance.pixels()) c.sky_pixels += !std::isfinite(d);

    mcref::Settings st;
    st.batches = kMcSlowBuild ? 8 : 16;
    st.medium_samples = kMcSlowBuild ? 64 : 128;
    st.lamp_samples = kMcSlowBuild ? 32 : 64;
    st.seed = 12345;
    c.reference = mcref::render(c.distance, c.camera, s, c.geometry, st);
    return c;
  }();
  return cs;
}

struct McComparison {
  double mean_rel = 0, max_rel = 0, mean_rel_sky = 0, mean_rel_surface = 0;
  std::size_t n = 0, n_sky = 0;
};

inline McComparison compare_with_reference(const Image& core, const ComparisonScene& cs) {
  McComparison r;
  double sum = 0, sum_sky = 0;
  const Image& ref = cs.reference.inscatter;
  for (int y = 0; y < ref.height(); ++y)
    for (int x = 0; x < ref.width(); ++x) {
      const bool sky = !std::isfinite(cs.distance.at(x, y, 0));
      for (int c = 0; c < 3; ++c) {
        const double want = ref.at(x, y, c);
        if (!(want > 1e-4)) continue;
        const double got = core.at(x, y, c);
        const double rel = std::isfinite(got) ? std::fabs(got - want) / want : 1e9;
        sum += rel;
        ++r.n;
        r.max_rel = std::max(r.max_rel, rel);
        if (sky) sum_sky += rel, ++r.n_sky;
      }
    }
  r.mean_rel = r.n ? sum / double(r.n) : 0;
  r.mean_rel_sky = r.n_sky ? sum_sky / double(r.n_sky) : 0;
  r.mean_rel_surface = r.n > r.n_sky ? (sum - sum_sky) / double(r.n - r.n_sky) : 0;
  return r;
}

}  // namespace mr::test
