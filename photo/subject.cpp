#include "photo/subject.h"

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>

#include "photo/display.h"
#include "photo/opencv_random.h"
#include "photo/sky_mask.h"

namespace mr::photo {

StandingSubject find_standing_subject(ConstImageView photo,
                                      const std::array<PixelPoint, 2>& horizon,
                                      const std::vector<std::uint8_t>& sky,
                                      const GroundMask& ground, const StandingSubjectOptions& o) {
  StandingSubject out;
  const int w = photo.width, h = photo.height;
  const std::size_t n = std::size_t(w) * h;
  if (!ground.valid || !ground.standing_subject || w < 8 || h < 8 || photo.channels < 1 ||
      sky.size() != n || ground.coloured.size() != n)
    return out;
  const double dx = horizon[1][0] - horizon[0][0];
  const double slope = std::abs(dx) > 1e-9 ? (horizon[1][1] - horizon[0][1]) / dx : 0.0;
  auto horizon_y = [&](double x) { return horizon[0][1] + (x - horizon[0][0]) * slope; };
  const double rise_px = o.min_rise_fraction * h;
  const int gap = std::max(2, int(std::lround(o.max_gap_fraction * h)));

  // The runs, and the candidate: the runs and what joins them low enough (or near enough to a
  // run above that: `above_band`, rows more than rise_px over the horizon).
  cv::Mat candidate(h, w, CV_8U, cv::Scalar(0)), runs(h, w, CV_8U, cv::Scalar(0)),
      above_band(h, w, CV_8U, cv::Scalar(0));
  std::vector<std::uint8_t> rising(std::size_t(w), 0);
  for (int x = 0; x < w; ++x) {
    int top = h, miss = 0;
    for (int y = h - 1; y >= 0; --y) {
      const std::size_t i = std::size_t(y) * w + x;
      if (sky[i]) break;
      if (!ground.coloured[i]) {
        top = y, miss = 0;
      } else if (++miss > gap) {
        break;
      }
    }
    rising[std::size_t(x)] = top < horizon_y(x) - rise_px;
    for (int y = top; y < h && rising[std::size_t(x)]; ++y) runs.at<std::uint8_t>(y, x) = 1;
  }
  // Hair and shoulders beside the runs, up to `reach` columns from them (GrabCut decides).
  const int reach = std::max(2, int(std::lround(o.reach_fraction * w)));
  for (int y = 0; y < h; ++y) {
    const std::uint8_t* r = runs.ptr<std::uint8_t>(y);
    std::vector<int> near(std::size_t(w), reach + 1);
    for (int x = 0, last = -reach - 2; x < w; ++x) {
      if (r[x]) last = x;
      near[std::size_t(x)] = std::min(near[std::size_t(x)], x - last);
    }
    for (int x = w - 1, last = w + reach + 1; x >= 0; --x) {
      if (r[x]) last = x;
      near[std::size_t(x)] = std::min(near[std::size_t(x)], last - x);
    }
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      const bool low = y > horizon_y(x) - rise_px;
      candidate.at<std::uint8_t>(y, x) =
          r[x] || (!sky[i] && !ground.coloured[i] && (low || near[std::size_t(x)] <= reach));
      above_band.at<std::uint8_t>(y, x) = !low;
    }
  }
  // Keeps the components of `m` that hold the bottom pixel of a rising column.
  auto joined_to_runs = [&](cv::Mat& m) {
    cv::Mat labels;
    const int count = cv::connectedComponents(m, labels, 8, CV_32S);
    std::vector<std::uint8_t> keep(std::size_t(count), 0);
    for (int x = 0; x < w; ++x)
      if (rising[std::size_t(x)] && m.at<std::uint8_t>(h - 1, x))
        keep[std::size_t(labels.at<int>(h - 1, x))] = 1;
    keep[0] = 0;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        m.at<std::uint8_t>(y, x) = keep[std::size_t(labels.at<int>(y, x))];
  };
  joined_to_runs(candidate);
  if (cv::countNonZero(candidate) == 0) return out;

  cv::Mat subject = candidate.clone();
  if (o.grabcut_pixels > 0) {
    // GrabCut only takes pixels away from the candidate: the far land around a head, which it
    // might take for the subject's colour (a dark coat and people in dark clothes far behind),
    // stays apart whatever it decides there.
    const double scale = std::min(1.0, std::sqrt(o.grabcut_pixels / double(n)));
    const cv::Size small(std::max(8, int(std::lround(w * scale))),
                         std::max(8, int(std::lround(h * scale))));
    const cv::Mat display = display_rgb8(photo);
    // The colours of the far land beside the head (neither the candidate, sky nor ground-
    // coloured), in 16 levels a channel: above the band a run may go on from the hair into far
    // land the hair touches, and a run pixel of a colour common there is left to GrabCut.
    std::vector<int> far_colours(4096, 0);
    int far_pixels = 0;
    auto bin = [&](const cv::Vec3b& p) { return (p[0] >> 4) << 8 | (p[1] >> 4) << 4 | p[2] >> 4; };
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const std::size_t i = std::size_t(y) * w + x;
        if (above_band.at<std::uint8_t>(y, x) && !candidate.at<std::uint8_t>(y, x) && !sky[i] &&
            !ground.coloured[i])
          ++far_colours[std::size_t(bin(display.at<cv::Vec3b>(y, x)))], ++far_pixels;
      }
    const int common = std::max(3, int(std::ceil(o.far_colour_fraction * far_pixels)));
    cv::Mat labels(h, w, CV_8U), kept(h, w, CV_8U, cv::Scalar(0));
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const std::size_t i = std::size_t(y) * w + x;
        const bool c = candidate.at<std::uint8_t>(y, x), run = c && runs.at<std::uint8_t>(y, x);
        const bool high = above_band.at<std::uint8_t>(y, x);
        const bool far_like =
            high && far_colours[std::size_t(bin(display.at<cv::Vec3b>(y, x)))] >= common;
        // Low down the runs are the subject, and what joins them is more likely the subject
        // (an arm, a lap); above, what only joins the runs is more likely the far land.
        kept.at<std::uint8_t>(y, x) = run && !far_like;
        labels.at<std::uint8_t>(y, x) = run && !far_like      ? cv::GC_FGD
                                        : run || (c && !high) ? cv::GC_PR_FGD
                                        : sky[i]              ? cv::GC_BGD
                                                              : cv::GC_PR_BGD;
      }
    cv::Mat small_display, small_labels;
    cv::resize(display, small_display, small, 0, 0, cv::INTER_AREA);
    cv::resize(labels, small_labels, small, 0, 0, cv::INTER_NEAREST);
    // GrabCut fits a colour model of 5 Gaussians to each side (k-means first): with fewer
    // pixels than a few per Gaussian on either side (a frame all subject) the candidate stays.
    constexpr int kMinSidePixels = 25;
    const int certain_fg = cv::countNonZero(small_labels == cv::GC_FGD);
    const int fg_side =
        cv::countNonZero((small_labels == cv::GC_FGD) | (small_labels == cv::GC_PR_FGD));
    const int bg_side = small_labels.rows * small_labels.cols - fg_side;
    bool cut = false;
    if (certain_fg > 0 && fg_side >= kMinSidePixels && bg_side >= kMinSidePixels) {
      cv::Mat bgd, fgd;
      const ReproducibleRandom reproducible;
      try {
        cv::grabCut(small_display, small_labels, cv::Rect(), bgd, fgd,
                    std::max(1, o.grabcut_iterations), cv::GC_INIT_WITH_MASK);
        cut = true;
      } catch (const cv::Exception&) {
        // Any refusal (an input OpenCV will not model) leaves the candidate as it is.
      }
    }
    if (cut) {
      cv::Mat fg = (small_labels == cv::GC_FGD) | (small_labels == cv::GC_PR_FGD), fg_full;
      cv::resize(fg, fg_full, cv::Size(w, h), 0, 0, cv::INTER_LINEAR);  // no blocks
      fg_full = fg_full >= 128;
      subject = candidate & (fg_full | kept);
    }
  }
  // A column whose run a few pixels of the ground's colour cut (teeth in a smile) is closed
  // over from its neighbours, not left a line of something else through the subject.
  cv::morphologyEx(subject, subject, cv::MORPH_CLOSE,
                   cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * gap + 1, 1)));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (sky[std::size_t(y) * w + x]) subject.at<std::uint8_t>(y, x) = 0;
  joined_to_runs(subject);
  out.pixels.assign(n, 0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      out.pixels[std::size_t(y) * w + x] = subject.at<std::uint8_t>(y, x) != 0;
  if (cv::countNonZero(subject) == 0) out.pixels.clear();
  return out;
}

}  // namespace mr::photo
