// Test scene shared by the occluder surface's Embree tests (tests/quad_scene_test.cpp,
// tests/surface_grid_test.cpp): a depth map with discontinuities, creases and sky.
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>

#include "mr/camera.h"
#include "mr/image.h"
#include "mr/scene.h"

namespace mr::test {

// 240x160, 70 degrees across, eye height 1.6 m pitched down 8 degrees: ground y = 0 with a
// wall (z = 12 m, x in [-3, 2], 4 m high) and a gently curved mound, so the mesh has
// discontinuities (the wall's outline), fanned pixels (the mound's creases) and sky.
struct WallAndMound {
  Camera camera = Camera::from_horizontal_fov(240, 160, 70);
  CameraPose pose;
  Image distance_m{240, 160, 1};
};

inline WallAndMound wall_and_mound() {
  WallAndMound in;
  in.pose.position_m = {0, 1.6, 0};
  in.pose.pitch_deg = -8;
  for (int y = 0; y < in.camera.height; ++y)
    for (int x = 0; x < in.camera.width; ++x) {
      const Vec3 w = in.pose.ray_direction(in.camera, x, y);
      double t = std::numeric_limits<double>::infinity();
      if (w.y < 0) {
        // Ground with a mound: y = 0.8 exp(-r^2 / 8) around (4, 0, 8), found by marching.
        double lo = 0, hi = 1.6 / -w.y;
        auto above = [&](double s) {
          const double px = s * w.x, pz = s * w.z, py = 1.6 + s * w.y;
          const double r2 = (px - 4) * (px - 4) + (pz - 8) * (pz - 8);
          return py > 0.8 * std::exp(-r2 / 8);
        };
        for (double s = 0.05; s < hi; s += 0.05)
          if (!above(s)) {
            hi = s;
            break;
          }
        lo = std::max(0.0, hi - 0.05);
        for (int k = 0; k < 40; ++k) (above(0.5 * (lo + hi)) ? lo : hi) = 0.5 * (lo + hi);
        t = 0.5 * (lo + hi);
      }
      if (w.z > 0) {
        const double tw = 12 / w.z, px = tw * w.x, py = 1.6 + tw * w.y;
        if (px >= -3 && px <= 2 && py >= 0 && py <= 4 && tw < t) t = tw;
      }
      in.distance_m.at(x, y, 0) = float(t);
    }
  return in;
}

}  // namespace mr::test
