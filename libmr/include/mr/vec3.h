// mr::Vec3 and mr::Rgb: the small value types of the world frame (mr/scene.h) and of colours,
// in a header of their own so that the core types that need only them (mr/material_model.h,
// mr/objects.h) do not form an include cycle with mr/scene.h.
#pragma once

#include <array>

#include "mr/export.h"

namespace mr {

using Rgb = std::array<float, 3>;

struct MR_API Vec3 {
  double x = 0, y = 0, z = 0;
};

}  // namespace mr
