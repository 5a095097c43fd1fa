// Private to libmr: a display-referred copy of a scene-linear photo for OpenCV's image analysis
// (guides of edge-aware filters, GrabCut), which works on 8-bit pictures. Heavy header
// (OpenCV): include only in .cpp.
#pragma once

#include <opencv2/core/mat.hpp>

#include "mr/image.h"

namespace mr::photo {

/// CV_8UC3 at the photo's size: each of the first three channels (a one-channel photo's first
/// channel thrice) clamped to [0, 1], raised to 1 / 2.2 and rounded to 0-255; non-finite
/// values as 0.
cv::Mat display_rgb8(ConstImageView photo);

}  // namespace mr::photo
