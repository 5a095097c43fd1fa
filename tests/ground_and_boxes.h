// Test scenes made of a ground plane (y = 0) and axis-aligned boxes standing on it or above it,
// traced analytically: the distances a depth map of them holds.
#pragma once

#include <algorithm>
#include <limits>
#include <utility>
#include <vector>

#include "mr/vec3.h"

namespace mr::test {

struct Box {
  Vec3 min_m, max_m;
};

/// Distance along unit ray w from o to the ground y = 0 or the nearest box (inf: sky).
inline double trace_ground_and_boxes(const std::vector<Box>& boxes, const Vec3& o, const Vec3& w) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  double best = w.y < 0 ? -o.y / w.y : kInf;
  for (const Box& b : boxes) {
    const double lo[3] = {b.min_m.x, b.min_m.y, b.min_m.z},
                 hi[3] = {b.max_m.x, b.max_m.y, b.max_m.z};
    const double oo[3] = {o.x, o.y, o.z}, ww[3] = {w.x, w.y, w.z};
    double t_enter = -kInf, t_exit = kInf;
    for (int a = 0; a < 3; ++a) {
      if (ww[a] == 0) {
        if (oo[a] < lo[a] || oo[a] > hi[a]) t_enter = kInf;
        continue;
      }
      double t0 = (lo[a] - oo[a]) / ww[a], t1 = (hi[a] - oo[a]) / ww[a];
      if (t0 > t1) std::swap(t0, t1);
      t_enter = std::max(t_enter, t0);
      t_exit = std::min(t_exit, t1);
    }
    if (t_enter <= t_exit && t_enter > 0) best = std::min(best, t_enter);
  }
  return best;
}

}  // namespace mr::test
