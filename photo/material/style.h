// Private to libmr: the material "style" of a set of pixels (seed 002 eq. 4.6 extended, issue 7):
// colour statistics in CIELAB (mean, standard deviation, histogram), highlight size and strength,
// and contrast; kept as additive sufficient statistics so that the style of a union of regions
// is the sum of theirs (the Tabu search evaluates thousands of assignments).
#pragma once
#include <array>
#include <cstdint>
#include <span>
#include <vector>
#include "mr/image.h"

namespace mr::photo {

/// Additive statistics of a set of pixels. Combine with +=.
struct StyleStatistics {
  double count = 0;
  std::array<double, 3> lab_sum{};     ///< L*, a*, b*
  std::array<double, 3> lab_sum_sq{};
  std::vector<double> histogram;       ///< joint-free per-channel histograms, see .cpp for bins
  double highlight_count = 0;          ///< pixels brighter than the highlight threshold
  double highlight_energy = 0;         ///< their summed luminance above the threshold
  double log_luminance_sum = 0, log_luminance_sum_sq = 0;  ///< for contrast
  StyleStatistics& operator+=(const StyleStatistics& other);
};

/// CIELAB (D65 white, Y_n = 1) of scene-linear Rec.709/sRGB-primaries RGB: CIE XYZ by the
/// IEC 61966-2-1 matrix (the shipped OCIO config defines no XYZ space), then the CIE 1976 formula.
std::array<double, 3> linear_rgb_to_lab(double r, double g, double b);

/// Bins per Lab channel of StyleStatistics::histogram (L* in [0, 100], a*, b* in [-100, 100];
/// values outside go to the end bins). The histogram holds L*, then a*, then b* bins.
inline constexpr int kStyleHistogramBins = 32;

/// A pixel is a highlight when its exposure-normalised luminance exceeds this multiple of
/// `reference_luminance` (see style.cpp for why a fixed ratio and not a median).
inline constexpr double kHighlightLuminanceRatio = 2.0;

/// Statistics of the pixels of scene-linear RGB `image` listed in `pixels` (y * width + x).
/// `reference_luminance` normalises exposure (pass the mean luminance of the image's own
/// surfaces) so that a sample and a target shot at different exposures compare by look.
/// Non-finite pixels are skipped. Throws mr::Error(invalid_argument) for an index outside the
/// image, an image with fewer than 3 channels, or a reference_luminance that is not positive.
StyleStatistics style_statistics(const Image& image, std::span<const std::int32_t> pixels,
                                 double reference_luminance);

struct StyleWeights {
  double mean = 1, deviation = 1, histogram = 1, highlight = 1, contrast = 1;
};

/// Style difference E(S, V) >= 0 between two sets: |mu_S - mu_V|^2 + |sigma_S - sigma_V|^2 (Lab,
/// scaled) + histogram distance (OpenCV's Bhattacharyya, in [0, 1]) + highlight size/strength
/// difference + contrast difference, weighted. 0 for equal statistics.
double style_distance(const StyleStatistics& sample, const StyleStatistics& synthesized,
                      const StyleWeights& weights = {});

}  // namespace mr::photo
