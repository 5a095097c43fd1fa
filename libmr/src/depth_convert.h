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

/// `v`: the stored value times DepthOptions::scale. `focal_baseline` = focal_px * baseline_m.
/// Returns +inf for no surface (NaN, inf, 0, negative, or a disparity at or below -doffs) and
/// counts it in no_surface; of those, NaN or negative stored values also in invalid (not a sky
/// encoding but a broken or mis-scaled map).
inline float stored_depth_to_distance(double v, const DepthOptions& options, const Camera& camera,
                                      double focal_baseline, int x, int y,
                                      std::size_t& no_surface, std::size_t& invalid) {
  double d = std::numeric_limits<double>::infinity();
  if (std::isfinite(v) && v > 0) {
    switch (options.kind) {
      case DepthKind::distance: d = v; break;
      case DepthKind::planar_z: d = v * camera.z_to_distance(x, y); break;
      case DepthKind::disparity: {
        const double disparity = v + options.doffs_px;
        d = disparity > 0 ? focal_baseline / disparity * camera.z_to_distance(x, y)
                          : std::numeric_limits<double>::infinity();
        break;
      }
    }
  }
  if (!std::isfinite(d) || !(d > 0)) {
    d = std::numeric_limits<double>::infinity();
    ++no_surface;
    if (std::isnan(v) || v < 0) ++invalid;
  }
  return float(d);
}

}  // namespace mr::detail
