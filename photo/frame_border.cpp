#include "photo/frame_border.h"

#include <opencv2/core/mat.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>

#include "photo/display.h"

namespace mr::photo {

namespace {

using Colour = std::array<int, 3>;

// Line `i` of one side, inward from the edge: pixels j of its middle 90 %. `rgb` is the band of
// the frame along that side (the lines a border can reach), `frame_depth` the frame's size across
// the side.
struct Side {
  const cv::Mat& rgb;
  int side;  // 0 top, 1 bottom, 2 left, 3 right
  int frame_depth;

  int length() const { return side < 2 ? rgb.cols : rgb.rows; }
  int depth() const { return frame_depth; }
  Colour at(int i, int j) const {
    const int x = side == 2 ? i : side == 3 ? rgb.cols - 1 - i : j;
    const int y = side == 0 ? i : side == 1 ? rgb.rows - 1 - i : j;
    const cv::Vec3b p = rgb.at<cv::Vec3b>(y, x);
    return {p[0], p[1], p[2]};
  }
  int first() const { return length() / 20; }
  int last() const { return length() - length() / 20; }

  Colour median(int i) const {
    std::array<std::array<int, 256>, 3> histogram{};
    for (int j = first(); j < last(); ++j) {
      const Colour c = at(i, j);
      for (int k = 0; k < 3; ++k) ++histogram[std::size_t(k)][std::size_t(c[std::size_t(k)])];
    }
    const int half = (last() - first()) / 2;
    Colour m{};
    for (std::size_t k = 0; k < 3; ++k) {
      int seen = 0, v = 0;
      while (v < 255 && (seen += histogram[k][std::size_t(v)]) <= half) ++v;
      m[k] = v;
    }
    return m;
  }
  double fraction_near(int i, const Colour& ref, int codes) const {
    int near = 0;
    for (int j = first(); j < last(); ++j) {
      const Colour c = at(i, j);
      near += std::abs(c[0] - ref[0]) <= codes && std::abs(c[1] - ref[1]) <= codes &&
              std::abs(c[2] - ref[2]) <= codes;
    }
    return double(near) / std::max(1, last() - first());
  }
};

int border_lines(const Side& s, const FrameBorderOptions& o) {
  const int max_lines = std::min(int(std::floor(o.max_fraction * s.depth())),
                                 s.depth() / 2 - std::max(0, o.max_transition) - 1);
  if (max_lines < 1) return 0;
  const Colour ref = s.median(0);
  if (*std::max_element(ref.begin(), ref.end()) - *std::min_element(ref.begin(), ref.end()) >
      o.max_chroma_codes)
    return 0;
  int k = 0;
  while (k < max_lines && s.fraction_near(k, ref, o.uniform_codes) >= o.uniform_fraction) ++k;
  if (k == 0) return 0;
  for (int c = k; c <= k + std::max(0, o.max_transition) && c < s.depth() / 2; ++c)
    if (s.fraction_near(c, ref, o.uniform_codes) <= o.content_like_fraction) {
      // The scan's blurred edge: lines still ramping steeply to the picture's colour are the
      // border's (the picture's sky then touches the frame's top).
      int end = c;
      while (end < k + std::max(0, o.max_transition) && end + 1 < s.depth() / 2) {
        const Colour a = s.median(end), b = s.median(end + 1);
        int step = 0;
        for (std::size_t i = 0; i < 3; ++i) step = std::max(step, std::abs(a[i] - b[i]));
        if (step <= o.uniform_codes) break;
        ++end;
      }
      return end;
    }
  return 0;
}

}  // namespace

FrameBorder find_frame_border(ConstImageView photo, const FrameBorderOptions& o) {
  FrameBorder out;
  if (photo.width < 16 || photo.height < 16 || photo.channels < 1) return out;
  // Only the bands a border can reach are converted (the search reads at most its longest
  // border and the transition's lines, and never past the middle): the estimate asks once for
  // the sky mask and once for the depth, and a full-frame copy each time was most of the cost.
  const int w = photo.width, h = photo.height;
  auto band = [&](int dim) {
    return std::clamp(int(std::floor(o.max_fraction * dim)) + std::max(0, o.max_transition) + 1, 1,
                      dim / 2);
  };
  const int bh = band(h), bw = band(w);
  out.top = border_lines({display_rgb8(photo.sub({0, 0, w, bh})), 0, h}, o);
  out.bottom = border_lines({display_rgb8(photo.sub({0, h - bh, w, bh})), 1, h}, o);
  out.left = border_lines({display_rgb8(photo.sub({0, 0, bw, h})), 2, w}, o);
  out.right = border_lines({display_rgb8(photo.sub({w - bw, 0, bw, h})), 3, w}, o);
  return out;
}

}  // namespace mr::photo
