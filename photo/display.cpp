#include "photo/display.h"

#include <opencv2/core.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "core/cv_bridge.h"

namespace mr::photo {

cv::Mat display_rgb8(ConstImageView photo) {
  const int w = photo.width, h = photo.height;
  const cv::Mat src = detail::as_mat(photo);
  cv::Mat display(h, w, CV_8UC3);
  const int ch = photo.channels;
  for (int y = 0; y < h; ++y) {
    const float* row = src.ptr<float>(y);
    cv::Vec3b* d = display.ptr<cv::Vec3b>(y);
    for (int x = 0; x < w; ++x) {
      const float* p = row + std::ptrdiff_t(x) * ch;
      for (int c = 0; c < 3; ++c) {
        float v = p[ch >= 3 ? c : 0];
        if (!std::isfinite(v)) v = 0;
        d[x][c] =
            cv::saturate_cast<std::uint8_t>(255.0f * std::pow(std::clamp(v, 0.0f, 1.0f), 1 / 2.2f));
      }
    }
  }
  return display;
}

}  // namespace mr::photo
