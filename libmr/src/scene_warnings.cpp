#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "mr/scattering.h"
#include "render/medium.h"

namespace mr {

std::vector<std::string> scene_warnings(const FogScene& scene) {
  std::vector<std::string> out;
  const Medium& m = scene.medium;
  if (scene.lighting.sun && scene.render.light_path_attenuation) {
    const Vec3& d = scene.lighting.sun->direction_to_sun;
    const double n = std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
    const render::Vec3d to_sun{d.x / n, d.y / n, d.z / n};
    const render::Vec3d camera{scene.pose.position_m.x, scene.pose.position_m.y,
                               scene.pose.position_m.z};
    const double sigma_min = std::min({m.sigma_t_per_m[0], m.sigma_t_per_m[1], m.sigma_t_per_m[2]});
    // The sun's transmittance down to the camera's height, in the clearest channel.
    const double od = sigma_min * render::RayDensity(m, camera, to_sun).optical_depth(0, INFINITY);
    if (od > 20) {
      const std::string how =
          std::isinf(od) ? "the fog has no top (homogeneous and unbounded above)"
                         : "its optical depth down to the camera is " + std::to_string(int(od));
      out.push_back("the sun's light cannot reach into this fog: " + how +
                    ", so the sun adds no light (only its surface term darkens lit surfaces); "
                    "give the fog a top (--layer bottom,top, medium.layer_top_m) or use height "
                    "fog (--height-fog, medium.height_fog)");
    }
  }
  return out;
}

}  // namespace mr
