// Private to libmr: one stored depth value to metres along the pixel's ray. Shared by
// depth_to_distance (whole maps) and the streaming fog pipeline (strips), so both give the
// same bits.
#pragma once

#include <cmath>
#include <cstddef>
#include <limits>

#include "mr/camera.h"
#include "mr/depth.h"

namespace mr::detail {

/// Per-map counts of depth_to_distance / the streaming reader (see DepthMap's fields).
struct DepthCounts {
  std::size_t no_surface = 0, invalid = 0, sky_threshold = 0, clamped = 0;
  DepthCounts operator+(const DepthCounts& o) const {
    return {no_surface + o.no_surface, invalid + o.invalid, sky_threshold + o.sky_threshold,
            clamped + o.clamped};
  }
};

/// `v`: the stored value times DepthOptions::scale. `focal_baseline` = focal_px * baseline_m.
/// Returns +inf for no surface (NaN, inf, 0, negative, a finite value at or above
/// DepthOptions::sky_depth_m for distance / z maps, or a disparity at or below -doffs) and
/// counts it in no_surface; of those, NaN or negative stored values also in invalid (not a sky
/// encoding but a broken or mis-scaled map) and sky-threshold codes in sky_threshold. Surfaces
/// beyond kMaxSurfaceDistanceM are clamped to it (counted in clamped).
inline float stored_depth_to_distance(double v, const DepthOptions& options, const Camera& camera,
                                      double focal_baseline, int x, int y, DepthCounts& count) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  double d = kInf;
  const bool sky_code = options.kind != DepthKind::disparity && std::isfinite(v) &&
                        v >= options.sky_depth_m;
  if (std::isfinite(v) && v > 0 && !sky_code) {
    switch (options.kind) {
      case DepthKind::distance: d = v; break;
      case DepthKind::planar_z: d = v * camera.z_to_distance(x, y); break;
      case DepthKind::disparity: {
        const double disparity = v + options.doffs_px;
        d = disparity > 0 ? focal_baseline / disparity * camera.z_to_distance(x, y) : kInf;
        break;
      }
    }
  }
  if (!std::isfinite(d) || !(d > 0)) {
    d = kInf;
    ++count.no_surface;
    if (std::isnan(v) || v < 0) ++count.invalid;
    if (sky_code) ++count.sky_threshold;
  } else if (d > kMaxSurfaceDistanceM) {
    d = kMaxSurfaceDistanceM;
    ++count.clamped;
  }
  return float(d);
}

}  // namespace mr::detail
