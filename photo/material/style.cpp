// The style statistics of seed 002 eq. 4.6 (mean, deviation and histogram of CIELAB), extended by
// highlight size/strength and contrast (issue 7), as additive sums.
//
// Exactness: every per-pixel contribution is rounded to a fixed binary quantum before it is
// summed, so each double holds an integer multiple of that quantum and every sum is exact (no
// rounding) while it stays below 2^53 quanta. Summation order then does not matter: the
// statistics of a union equal the sum of the parts' statistics bit for bit, and the parallel
// reduction is deterministic. The quanta (2^-16 for Lab, 2^-10 for squared Lab, ...) are far below
// anything visible and leave room for ~10^8..10^10 pixels.
#include "photo/material/style.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <string>

#include "mr/error.h"

namespace mr::photo {

namespace {

// IEC 61966-2-1 (sRGB) linear RGB -> CIE XYZ, D65. The builtin OCIO config (libmr/data/config.ocio)
// has no XYZ colour space, and its reference space is exactly linear Rec.709/D65, so this matrix is
// the conversion OCIO would apply; the white point is taken as the matrix's row sums so that
// RGB (1, 1, 1) maps to a* = b* = 0 exactly.
constexpr double kRgbToXyz[3][3] = {{0.4124564, 0.3575761, 0.1804375},
                                    {0.2126729, 0.7151522, 0.0721750},
                                    {0.0193339, 0.1191920, 0.9503041}};
constexpr double kWhite[3] = {kRgbToXyz[0][0] + kRgbToXyz[0][1] + kRgbToXyz[0][2],
                              kRgbToXyz[1][0] + kRgbToXyz[1][1] + kRgbToXyz[1][2],
                              kRgbToXyz[2][0] + kRgbToXyz[2][1] + kRgbToXyz[2][2]};

// Exposure normalisation maps the reference luminance to middle grey (L* ~ 49.5), so typical
// surfaces land mid-scale in Lab and highlights keep headroom above L* = 100.
constexpr double kMiddleGrey = 0.18;
// Floor for log luminance (2^-16 of the reference: 16 stops below), so black pixels count as
// very dark instead of -inf.
constexpr double kLogFloor = 1.0 / 65536.0;

// Scales that make the terms of style_distance comparable (each is 1 at a clearly visible
// difference): 10 CIELAB units of mean or deviation, 5 % of the area in highlights, a factor e in
// highlight strength, half a stop of contrast.
constexpr double kLabScale = 10.0;
constexpr double kHighlightFractionScale = 0.05;
constexpr double kContrastScaleStops = 0.5;

constexpr double kHistLo[3] = {0, -100, -100};
constexpr double kHistHi[3] = {100, 100, 100};

double lab_f(double t) {
  constexpr double delta = 6.0 / 29.0;
  return t > delta * delta * delta ? std::cbrt(t) : t / (3 * delta * delta) + 4.0 / 29.0;
}

// Rounds to a multiple of 2^-bits (see the top of the file). Scaling by a power of two is exact.
template <int bits>
double fixed(double x) {
  constexpr double scale = double(1ull << bits);
  return std::nearbyint(x * scale) * (1.0 / scale);
}

StyleStatistics empty_statistics() {
  StyleStatistics s;
  s.histogram.assign(3 * kStyleHistogramBins, 0.0);
  return s;
}

}  // namespace

std::array<double, 3> linear_rgb_to_lab(double r, double g, double b) {
  double f[3];
  for (int i = 0; i < 3; ++i) {
    const double v = kRgbToXyz[i][0] * r + kRgbToXyz[i][1] * g + kRgbToXyz[i][2] * b;
    f[i] = lab_f(v / kWhite[i]);
  }
  return {116 * f[1] - 16, 500 * (f[0] - f[1]), 200 * (f[1] - f[2])};
}

StyleStatistics& StyleStatistics::operator+=(const StyleStatistics& other) {
  if (histogram.size() < other.histogram.size()) histogram.resize(other.histogram.size(), 0.0);
  for (std::size_t i = 0; i < other.histogram.size(); ++i) histogram[i] += other.histogram[i];
  count += other.count;
  for (int c = 0; c < 3; ++c) {
    lab_sum[c] += other.lab_sum[c];
    lab_sum_sq[c] += other.lab_sum_sq[c];
  }
  highlight_count += other.highlight_count;
  highlight_energy += other.highlight_energy;
  log_luminance_sum += other.log_luminance_sum;
  log_luminance_sum_sq += other.log_luminance_sum_sq;
  return *this;
}

StyleStatistics style_statistics(const Image& image, std::span<const std::int32_t> pixels,
                                 double reference_luminance) {
  if (image.channels() < 3)
    throw Error(ErrorCode::invalid_argument, "style_statistics: image has " +
                                                 std::to_string(image.channels()) +
                                                 " channel(s), expected RGB");
  if (!(reference_luminance > 0) || !std::isfinite(reference_luminance))
    throw Error(ErrorCode::invalid_argument,
                "style_statistics: reference_luminance must be positive and finite, got " +
                    std::to_string(reference_luminance));
  const std::int64_t n_pixels = std::int64_t(image.pixel_count());
  for (const std::int32_t p : pixels)
    if (p < 0 || p >= n_pixels)
      throw Error(ErrorCode::invalid_argument, "style_statistics: pixel index " +
                                                   std::to_string(p) + " outside the " +
                                                   std::to_string(image.width()) + "x" +
                                                   std::to_string(image.height()) + " image");
  const double exposure = kMiddleGrey / reference_luminance;
  const int channels = image.channels();
  const float* data = image.data();

  auto accumulate = [&](const tbb::blocked_range<std::size_t>& range, StyleStatistics s) {
    for (std::size_t i = range.begin(); i != range.end(); ++i) {
      const float* px = data + std::size_t(pixels[i]) * channels;
      if (!std::isfinite(px[0]) || !std::isfinite(px[1]) || !std::isfinite(px[2])) continue;
      // Negative scene-linear values are noise or out-of-gamut; they have no look of their own.
      const double rgb[3] = {std::max(0.0f, px[0]) * exposure, std::max(0.0f, px[1]) * exposure,
                             std::max(0.0f, px[2]) * exposure};
      const std::array<double, 3> lab = linear_rgb_to_lab(rgb[0], rgb[1], rgb[2]);
      s.count += 1;
      for (int c = 0; c < 3; ++c) {
        const double v = fixed<16>(lab[c]);
        s.lab_sum[c] += v;
        s.lab_sum_sq[c] += fixed<10>(v * v);
        const double t = (lab[c] - kHistLo[c]) / (kHistHi[c] - kHistLo[c]);
        const int bin =
            std::clamp(int(std::floor(t * kStyleHistogramBins)), 0, kStyleHistogramBins - 1);
        s.histogram[c * kStyleHistogramBins + bin] += 1;
      }
      // Luminance relative to the reference (1 = a typical surface of this image).
      const double y_rel =
          (kRgbToXyz[1][0] * rgb[0] + kRgbToXyz[1][1] * rgb[1] + kRgbToXyz[1][2] * rgb[2]) /
          kMiddleGrey;
      // Highlights: a fixed ratio to the reference luminance rather than e.g. the region's
      // median, because a median is not additive and because a region that is all highlight
      // (a mirror-like candidate) must count as such instead of redefining its own threshold.
      if (y_rel > kHighlightLuminanceRatio) {
        s.highlight_count += 1;
        s.highlight_energy += fixed<16>(y_rel - kHighlightLuminanceRatio);
      }
      const double log_y = fixed<20>(std::log2(std::max(y_rel, kLogFloor)));
      s.log_luminance_sum += log_y;
      s.log_luminance_sum_sq += fixed<16>(log_y * log_y);
    }
    return s;
  };
  return tbb::parallel_reduce(tbb::blocked_range<std::size_t>(0, pixels.size(), 16384),
                              empty_statistics(), accumulate,
                              [](StyleStatistics a, const StyleStatistics& b) { return a += b; });
}

namespace {

struct Derived {
  double mean[3], deviation[3];
  double highlight_fraction, highlight_strength, contrast;
};

Derived derive(const StyleStatistics& s, const char* which) {
  if (!(s.count > 0))
    throw Error(ErrorCode::invalid_argument,
                std::string("style_distance: the ") + which + " statistics hold no pixels");
  Derived d{};
  for (int c = 0; c < 3; ++c) {
    d.mean[c] = s.lab_sum[c] / s.count;
    d.deviation[c] = std::sqrt(std::max(0.0, s.lab_sum_sq[c] / s.count - d.mean[c] * d.mean[c]));
  }
  d.highlight_fraction = s.highlight_count / s.count;
  // Mean excess over the threshold, in units of the threshold.
  d.highlight_strength = s.highlight_count > 0
                             ? s.highlight_energy / s.highlight_count / kHighlightLuminanceRatio
                             : 0.0;
  const double m = s.log_luminance_sum / s.count;
  d.contrast = std::sqrt(std::max(0.0, s.log_luminance_sum_sq / s.count - m * m));
  return d;
}

double histogram_distance(const StyleStatistics& a, const StyleStatistics& b) {
  const std::size_t bins = std::size_t(3) * kStyleHistogramBins;
  if (a.histogram.size() != bins || b.histogram.size() != bins)
    throw Error(ErrorCode::invalid_argument,
                "style_distance: histograms must have " + std::to_string(bins) + " bins");
  // OpenCV's formula, sqrt(1 - BC), turns the last-bit rounding of BC = 1 into ~1e-8; identical
  // histograms are exactly 0 apart by definition.
  if (a.histogram == b.histogram) return 0;
  double total = 0;
  for (int c = 0; c < 3; ++c) {
    // OpenCV normalises by the histograms' sums itself (HISTCMP_BHATTACHARYYA, in [0, 1]).
    cv::Mat ha(1, kStyleHistogramBins, CV_32F), hb(1, kStyleHistogramBins, CV_32F);
    for (int i = 0; i < kStyleHistogramBins; ++i) {
      ha.at<float>(i) = float(a.histogram[c * kStyleHistogramBins + i]);
      hb.at<float>(i) = float(b.histogram[c * kStyleHistogramBins + i]);
    }
    // Identical histograms can come out as a tiny positive number (1 - sum rounded); clamp.
    total += std::clamp(cv::compareHist(ha, hb, cv::HISTCMP_BHATTACHARYYA), 0.0, 1.0);
  }
  return total / 3;
}

}  // namespace

double style_distance(const StyleStatistics& sample, const StyleStatistics& synthesized,
                      const StyleWeights& weights) {
  for (const double w :
       {weights.mean, weights.deviation, weights.histogram, weights.highlight, weights.contrast})
    if (!(w >= 0) || !std::isfinite(w))
      throw Error(ErrorCode::invalid_argument,
                  "style_distance: weights must be finite and >= 0, got " + std::to_string(w));
  const Derived s = derive(sample, "sample"), v = derive(synthesized, "synthesized");
  auto sq = [](double x) { return x * x; };
  double mean = 0, deviation = 0;
  for (int c = 0; c < 3; ++c) {
    mean += sq((s.mean[c] - v.mean[c]) / kLabScale);
    deviation += sq((s.deviation[c] - v.deviation[c]) / kLabScale);
  }
  const double highlight =
      sq((s.highlight_fraction - v.highlight_fraction) / kHighlightFractionScale) +
      sq(std::log1p(s.highlight_strength) - std::log1p(v.highlight_strength));
  const double contrast = sq((s.contrast - v.contrast) / kContrastScaleStops);
  double result = weights.mean * mean + weights.deviation * deviation +
                  weights.highlight * highlight + weights.contrast * contrast;
  if (weights.histogram > 0) result += weights.histogram * histogram_distance(sample, synthesized);
  return result;
}

}  // namespace mr::photo
