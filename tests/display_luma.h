// Display-referred luma (Rec. 709 weights on gamma-2.2 values of the clamped scene-linear RGB),
// the image gallery/measures.py measures created edges on, and that measure's gradient; shared by
// the tests of real photos, the sky mask, the sky light and the automatic geometry.
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

// Per pixel: the larger forward difference (right, down) of a single-channel map; the gradient
// of gallery/measures.py's created-edge measure.
inline cv::Mat forward_gradient(const cv::Mat& l) {
  cv::Mat g(l.rows, l.cols, CV_32F, cv::Scalar(0));
  for (int y = 0; y < l.rows; ++y)
    for (int x = 0; x < l.cols; ++x) {
      float v = 0;
      if (x + 1 < l.cols) v = std::max(v, std::abs(l.at<float>(y, x + 1) - l.at<float>(y, x)));
      if (y + 1 < l.rows) v = std::max(v, std::abs(l.at<float>(y + 1, x) - l.at<float>(y, x)));
      g.at<float>(y, x) = v;
    }
  return g;
}

}  // namespace mr::test
