#include "photo/airlight.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <vector>

#include "cv_bridge.h"

namespace mr::photo {

std::array<float, 3> estimate_airlight_dark_channel(ConstImageView photo,
                                                    const DarkChannelOptions& options) {
  // The estimate does not need every pixel of a 24 MP photo: area-average down to about
  // options.working_pixels first (the window and the 0.1 % are fractions, so they scale).
  cv::Mat small = detail::as_mat(photo);
  const double area = double(photo.width) * photo.height;
  if (area > options.working_pixels) {
    const double f = std::sqrt(options.working_pixels / area);
    cv::resize(small, small, cv::Size(), f, f, cv::INTER_AREA);
  } else {
    small = small.clone();  // continuous
  }
  const int w = small.cols, h = small.rows, channels = small.channels();
  cv::Mat dark(h, w, CV_32F);
  for (int y = 0; y < h; ++y) {
    float* d = dark.ptr<float>(y);
    const float* row = small.ptr<float>(y);
    for (int x = 0; x < w; ++x) {
      const float* p = row + std::ptrdiff_t(x) * channels;
      d[x] = std::min({p[0], p[1], p[2]});
    }
  }
  int window = int(std::lround(options.window_fraction * std::min(w, h)));
  window = std::max(3, window | 1);  // odd, at least 3
  cv::erode(dark, dark, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(window, window)));

  const std::size_t n = std::size_t(w) * h;
  const std::size_t keep = std::max<std::size_t>(1, std::size_t(double(n) * options.brightest_fraction));
  std::vector<std::uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  const float* dk = dark.ptr<float>(0);  // continuous: created above
  std::nth_element(order.begin(), order.begin() + (keep - 1), order.end(),
                   [&](std::uint32_t a, std::uint32_t b) { return dk[a] > dk[b]; });
  double sum[3] = {0, 0, 0};
  for (std::size_t i = 0; i < keep; ++i) {
    const float* p = small.ptr<float>(int(order[i] / w)) + std::ptrdiff_t(order[i] % w) * channels;
    for (int c = 0; c < 3; ++c) sum[c] += p[c];
  }
  return {float(sum[0] / keep), float(sum[1] / keep), float(sum[2] / keep)};
}

}  // namespace mr::photo
