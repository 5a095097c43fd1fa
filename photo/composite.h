// Private to libmr: C = I * T + R in scene-linear (DESIGN.md section 3, Composite).
#pragma once

#include "mr/image.h"

namespace mr::photo {

/// composite = photo (first 3 channels) * transmittance + inscatter, per channel; a 4th photo
/// channel (alpha) is copied. `composite` has the photo's channel count and size.
void composite(ConstImageView photo, ConstImageView transmittance, ConstImageView inscatter,
               ImageView composite);

}  // namespace mr::photo
