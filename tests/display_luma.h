// Display-referred luma (Rec. 709 weights on gamma-2.2 values of the clamped scene-linear RGB),
// the image gallery/measures.py measures created edges on; shared by the tests of real photos,
// the sky mask and the automatic geometry.
#pragma once

#include <opencv2/core.hpp>

#include <algorithm>
#include <cmath>

#include "mr/image.h"

namespace mr::test {

inline cv::Mat display_luma(const Image& img) {
  cv::Mat l(img.height(), img.width(), CV_32F);
  const double weights[3] = {0.2126, 0.7152, 0.0722};
  for (int y = 0; y < img.height(); ++y)
    for (int x = 0; x < img.width(); ++x) {
      double v = 0;
      for (int c = 0; c < 3; ++c)
        v += weights[c] * std::pow(std::clamp(img.at(x, y, c), 0.0f, 1.0f), 1 / 2.2f);
      l.at<float>(y, x) = float(v);
    }
  return l;
}

}  // namespace mr::test
