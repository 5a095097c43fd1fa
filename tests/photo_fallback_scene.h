// The surface term's photo fallback scene (issue 13, section 3), shared by the CPU core's test
// against the exact geometry (mc_reference_test.cpp) and the Vulkan backend's
// (vulkan_photo_fallback_test.cpp): ground and two boxes and a thin post under a sun from the
// front-right, 25 degrees up, in a 6 m fog layer; the photo is what that geometry looks like
// (albedo times the exact sun and sky light), so where the occluder mesh misplaces a shadow's
// edge or a silhouette shades itself, the photo shows the surface sunlit.
#pragma once

#include <cmath>
#include <functional>

#include "mc_reference.h"
#include "mr/scene.h"
#include "test_support.h"

namespace mr::test {

struct PhotoFallbackScene {
  Camera camera = Camera::from_horizontal_fov(96, 64, 60);
  FogScene scene;
  mcref::Geometry geometry;
  Image distance;
  mcref::SurfaceResult reference;  ///< the surface term of the exact geometry
  Image photo;
};

/// surface_rays: the reference's rays per pixel (sun disk and AO).
inline PhotoFallbackScene photo_fallback_scene(int surface_rays) {
  PhotoFallbackScene f;
  FogScene& s = f.scene;
  s.pose.position_m = {0, 1.6, 0};
  s.pose.pitch_deg = -7;
  const float sigma = float(3.912 / 60.0);
  s.medium.sigma_t_per_m = {sigma, sigma, sigma};
  s.medium.albedo = {0.9f, 0.9f, 0.9f};
  s.medium.layer_top_m = 6.0;
  s.lighting.sun = Sun{direction_from_azimuth_elevation(35, 25), {3, 3, 3}, 0.27};
  s.lighting.sky_radiance = Rgb{0.2f, 0.2f, 0.2f};
  mcref::Geometry& g = f.geometry;
  g.ground = true;
  g.boxes.push_back({{0.5, 0, 9}, {3.0, 3.0, 11.5}});
  g.boxes.push_back({{-6.0, 0, 15}, {-2.0, 4.0, 19}});
  g.boxes.push_back({{-1.0, 0, 6}, {-0.6, 5.0, 6.4}});  // a thin post
  const Camera& cam = f.camera;
  f.distance = mcref::distance_map(cam, s.pose, g);
  f.reference = mcref::surface_reference(f.distance, cam, s, g, surface_rays);
  // The photo: a smooth albedo (0.3..0.7) times the light the exact geometry receives.
  const Image pattern = make_test_photo(cam.width, cam.height);
  f.photo = Image(cam.width, cam.height, 3);
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x)
      for (int c = 0; c < 3; ++c) {
        const double albedo = 0.3 + 0.4 * pattern.at(x, y, c);
        f.photo.at(x, y, c) =
            std::isfinite(f.distance.at(x, y, 0))
                ? float(albedo * (f.reference.direct.at(x, y, c) + f.reference.ambient.at(x, y, c)))
                : 1.0f;
      }
  return f;
}

/// The composite's error from T alone, sum |I (T - T_ref)| / sum I T_ref over surface pixels,
/// where `only` (if given) says which pixels count: in the error, and in the normalisation too
/// unless normalise_by_only is false (then a part of the whole image's error).
inline double composite_error_from_t(const Image& photo, const Image& t, const Image& t_ref,
                                     const Image& distance,
                                     const std::function<bool(int, int)>& only,
                                     bool normalise_by_only = true) {
  double err = 0, total = 0;
  for (int y = 0; y < photo.height(); ++y)
    for (int x = 0; x < photo.width(); ++x) {
      if (!std::isfinite(distance.at(x, y, 0))) continue;
      const bool counts = !only || only(x, y);
      if (!counts && normalise_by_only) continue;
      for (int c = 0; c < 3; ++c) {
        if (counts) err += std::fabs(photo.at(x, y, c) * (t.at(x, y, c) - t_ref.at(x, y, c)));
        total += photo.at(x, y, c) * t_ref.at(x, y, c);
      }
    }
  return total > 0 ? err / total : 0;
}

}  // namespace mr::test
