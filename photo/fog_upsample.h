// Private to libmr: fog rendered at a working size, brought to the photo's own size (issue 11,
// camera-size photos).
//
// An automatic fog's estimate (horizon, sky matte, depth, light) and its seam softening were
// tuned on photos about 1280 px across; on a 20 MP original the same steps cost ~225 bytes and
// ~3 s a megapixel and, with their pixel-sized rules, give another result (kleiber's haze: 0 %
// created edges at 1280 px, 0.044 % seen at that size when made from the 6028 px original). So
// the photo is estimated, rendered and softened at a working size, and only T and R are brought
// to the full size: by guided upsampling (He, Sun and Tang 2013, "Guided Image Filtering",
// with the colour guide; He and Sun 2015, "Fast Guided Filter": the local linear models are fit
// at the low resolution, their coefficients upsampled bilinearly and applied to the full-size
// guide). T and R are smooth where the depth is, and step where the photo has an outline: the
// fit at each working pixel writes them as a linear function of the photo's colour there, so
// the full-size step follows the full-size photo's outline, not the working grid's. The guided
// filter's paper shows the same use: refining a coarse dehazing transmission map to the photo. A
// model is only trusted within the values it was fit to: each result is clamped to the range of its
// four working-size neighbours (no overshoot, no halo).
#pragma once

#include "mr/image.h"

namespace mr::photo {

// Chosen on gallery/tune originals at full size (3-20 MP): radius 1-4 and epsilon 1e-6..1e-3
// changed the created edges of the worst (sunset_aitzol haze, a backlit ridge whose bright rim
// the guide takes for sky) only between 0.0070 and 0.0100 %; this pair gave the least. A larger
// window or a smaller epsilon follows colour edges more closely but copies more of the guide's
// texture into T where T is smooth.
struct FogUpsampleOptions {
  int radius = 2;         ///< the local models' window: (2 radius + 1)^2 working pixels
  double epsilon = 1e-3;  ///< their regularisation, in squared guide units (0..1 per channel)
};

/// `working_photo`, `working_transmittance`, `working_inscatter`: the photo (scene-linear, >= 3
/// channels) and its T and R (3 channels each) at the working size; `photo`: the same photo at
/// its own size. Writes the composite I T + R (the photo's channels; a 4th and more are copied)
/// into `composite`, and T and R into `transmittance` and `inscatter` unless those are empty
/// views (data == nullptr), all at the photo's size. Non-finite photo values count as black in
/// the guide. Throws mr::Error(size_mismatch) when the working images differ in size or an
/// output differs from the photo, (invalid_argument) on fewer than 3 channels or a working
/// size larger than the photo.
void upsample_fog(ConstImageView working_photo, ConstImageView working_transmittance,
                  ConstImageView working_inscatter, ConstImageView photo, ImageView composite,
                  ImageView transmittance, ImageView inscatter,
                  const FogUpsampleOptions& options = {});

}  // namespace mr::photo
