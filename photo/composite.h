// Private to libmr: C = I * T + R in scene-linear (DESIGN.md section 3, Composite).
#pragma once

#include "mr/image.h"

namespace mr::photo {

/// One pixel of it: c = i * t + r for the 3 colour channels, i's further channels (alpha)
/// copied; i and c have `channels` values.
inline void composite_pixel(const float* i, const float* t, const float* r, float* c,
                            int channels) {
  for (int k = 0; k < 3; ++k) c[k] = i[k] * t[k] + r[k];
  for (int k = 3; k < channels; ++k) c[k] = i[k];
}

/// composite = photo (first 3 channels) * transmittance + inscatter, per channel; a 4th photo
/// channel (alpha) is copied. `composite` has the photo's channel count and size.
void composite(ConstImageView photo, ConstImageView transmittance, ConstImageView inscatter,
               ImageView composite);

}  // namespace mr::photo
