// Private to libmr: splitting a sample image into segments of one material each (SLIC
// superpixels from opencv-contrib's ximgproc, merged by colour with their neighbours).
#pragma once
#include <vector>
#include "mr/image.h"

namespace mr::photo {

struct SegmentOptions {
  double superpixel_size_px = 0;  ///< 0: from the image size (about 400 superpixels)
  double merge_lab_distance = 8;  ///< neighbours closer than this in CIELAB (mean colour) merge
  int min_segment_pixels = 256;   ///< smaller segments are dropped (label -1)
};

struct Segmentation {
  Image labels;    ///< 1 channel, the image's size: 0..count-1, or -1 (dropped, sky, invalid)
  int count = 0;
};

/// Segments scene-linear RGB `photo`; pixels where `valid` (1 channel, same size, optional: null
/// = all) is 0 get -1. Deterministic.
Segmentation segment_image(const Image& photo, const Image* valid, const SegmentOptions& options = {});

}  // namespace mr::photo
