// Private to libmr: the IEC 61966-2-1 sRGB encoding of one scene-linear value (clamped to
// [0, 1]), for the few places that need the display value without an OCIO processor (the depth
// network's input, the seam softening's view of the displayed fog, the 8-bit codes a photo was
// decoded from).
#pragma once

#include <algorithm>
#include <cmath>

namespace mr::detail {

inline float srgb_encode(float linear) {
  const float v = std::clamp(linear, 0.0f, 1.0f);
  return v <= 0.0031308f ? 12.92f * v : 1.055f * std::pow(v, 1.0f / 2.4f) - 0.055f;
}

}  // namespace mr::detail
