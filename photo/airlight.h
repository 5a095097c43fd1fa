// Private to libmr: airlight (fog colour) estimated from a photo with the dark channel prior.
#pragma once

#include <array>

#include "mr/image.h"

namespace mr::photo {

struct DarkChannelOptions {
  /// Min-filter window as a fraction of the image's shorter side; He et al. use 15 px on
  /// ~600 px images (0.025). At least 3 px.
  double window_fraction = 0.025;
  double brightest_fraction = 0.001;  ///< fraction of dark-channel pixels to average (0.1 %)
  /// Larger photos are area-averaged down to about this many pixels first.
  double working_pixels = 1.0e6;
};

/// Mean colour of the photo's pixels with the brightest dark channel (He et al. 2009; Foggy
/// Cityscapes). `photo` is scene-linear with >= 3 channels.
std::array<float, 3> estimate_airlight_dark_channel(ConstImageView photo,
                                                    const DarkChannelOptions& options = {});

}  // namespace mr::photo
