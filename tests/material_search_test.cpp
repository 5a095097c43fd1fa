// Issue 7, items 2-4: sample-image segmentation (photo/material/segments), the style statistics
// and distance (photo/material/style), the assignment objective (photo/material/
// material_objective) and Tabu search (photo/material/tabu_search), against closed forms,
// published CIELAB values and an exhaustive (brute-force) reference.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <random>
#include <set>
#include <vector>

#include "mr/error.h"
#include "mr/material.h"
#include "photo/material/material_objective.h"
#include "photo/material/segments.h"
#include "photo/material/style.h"
#include "photo/material/tabu_search.h"

namespace mr::photo {
namespace {

// Deterministic test randomness that does not depend on the standard library's distributions.
double uniform01(std::mt19937& rng) {
  return (rng() >> 8) * (1.0 / 16777216.0);
}
double uniform(std::mt19937& rng, double lo, double hi) {
  return lo + (hi - lo) * uniform01(rng);
}
double normal(std::mt19937& rng) {  // Box-Muller
  const double u1 = std::max(uniform01(rng), 1e-12), u2 = uniform01(rng);
  return std::sqrt(-2 * std::log(u1)) * std::cos(2 * 3.14159265358979323846 * u2);
}

double luminance(double r, double g, double b) {
  return 0.2126729 * r + 0.7151522 * g + 0.0721750 * b;
}

std::vector<std::int32_t> iota_pixels(int begin, int end) {
  std::vector<std::int32_t> v(end - begin);
  std::iota(v.begin(), v.end(), begin);
  return v;
}

// ---------------------------------------------------------------------------------------------
// Lab and style statistics

TEST(Style, LabOfKnownColours) {
  // Published CIELAB (D65) of the sRGB primaries and white (e.g. Lindbloom's calculator).
  const auto white = linear_rgb_to_lab(1, 1, 1);
  EXPECT_NEAR(white[0], 100, 0.01);
  EXPECT_NEAR(white[1], 0, 0.01);
  EXPECT_NEAR(white[2], 0, 0.01);
  struct Known {
    double rgb[3], lab[3];
  };
  for (const Known& k : {Known{{1, 0, 0}, {53.2408, 80.0925, 67.2032}},
                         Known{{0, 1, 0}, {87.7347, -86.1827, 83.1793}},
                         Known{{0, 0, 1}, {32.2970, 79.1875, -107.8602}}}) {
    const auto lab = linear_rgb_to_lab(k.rgb[0], k.rgb[1], k.rgb[2]);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(lab[c], k.lab[c], 0.1) << "channel " << c;
  }
  // Grey: a* = b* = 0 and L* = 116 Y^(1/3) - 16 above the linear toe, 24389/27 Y below it.
  const auto grey = linear_rgb_to_lab(0.18, 0.18, 0.18);
  EXPECT_NEAR(grey[0], 116 * std::cbrt(0.18) - 16, 1e-9);
  EXPECT_NEAR(grey[1], 0, 1e-9);
  EXPECT_NEAR(grey[2], 0, 1e-9);
  const auto dark = linear_rgb_to_lab(0.001, 0.001, 0.001);
  EXPECT_NEAR(dark[0], 24389.0 / 27 * 0.001, 1e-9);
}

// A random scene-linear image: grey-ish noise with some colour and a few bright pixels.
Image random_image(int w, int h, std::uint32_t seed) {
  std::mt19937 rng(seed);
  Image im(w, h, 3);
  for (float& v : im.pixels()) v = float(uniform(rng, 0, 0.6));
  for (int k = 0; k < w * h / 20; ++k) {
    const int i = int(rng() % std::uint32_t(w * h));
    for (int c = 0; c < 3; ++c) im.data()[3 * i + c] = float(uniform(rng, 0.8, 4));
  }
  return im;
}

void expect_equal_statistics(const StyleStatistics& a, const StyleStatistics& b) {
  EXPECT_EQ(a.count, b.count);
  for (int c = 0; c < 3; ++c) {
    EXPECT_EQ(a.lab_sum[c], b.lab_sum[c]);
    EXPECT_EQ(a.lab_sum_sq[c], b.lab_sum_sq[c]);
  }
  EXPECT_EQ(a.histogram, b.histogram);
  EXPECT_EQ(a.highlight_count, b.highlight_count);
  EXPECT_EQ(a.highlight_energy, b.highlight_energy);
  EXPECT_EQ(a.log_luminance_sum, b.log_luminance_sum);
  EXPECT_EQ(a.log_luminance_sum_sq, b.log_luminance_sum_sq);
}

TEST(Style, StatisticsOfAUnionAreTheSumExactly) {
  // Large enough that the parallel reduction splits it.
  const Image im = random_image(300, 200, 7);
  std::mt19937 rng(3);
  std::vector<std::int32_t> all = iota_pixels(0, 300 * 200), a, b;
  std::shuffle(all.begin(), all.end(), rng);
  for (const std::int32_t p : all) (rng() % 3 == 0 ? a : b).push_back(p);
  const StyleStatistics whole = style_statistics(im, all, 0.25);
  StyleStatistics ab = style_statistics(im, a, 0.25);
  ab += style_statistics(im, b, 0.25);
  StyleStatistics ba = style_statistics(im, b, 0.25);
  ba += style_statistics(im, a, 0.25);
  expect_equal_statistics(whole, ab);
  expect_equal_statistics(whole, ba);
  EXPECT_EQ(whole.count, 60000);
  EXPECT_GT(whole.highlight_count, 0);
  // An empty set adds nothing.
  StyleStatistics plus_empty = whole;
  plus_empty += style_statistics(im, {}, 0.25);
  plus_empty += StyleStatistics{};
  expect_equal_statistics(whole, plus_empty);
  // Same pixels in another order: the same sums, bit for bit.
  std::vector<std::int32_t> sorted = all;
  std::sort(sorted.begin(), sorted.end());
  expect_equal_statistics(whole, style_statistics(im, sorted, 0.25));
}

TEST(Style, DistanceIsZeroForEqualAndSymmetric) {
  const Image im = random_image(64, 64, 11), other = random_image(64, 64, 12);
  const auto px = iota_pixels(0, 64 * 64);
  const StyleStatistics s = style_statistics(im, px, 0.2), t = style_statistics(other, px, 0.3);
  EXPECT_EQ(style_distance(s, s), 0.0);
  EXPECT_EQ(style_distance(s, style_statistics(im, px, 0.2)), 0.0);
  // Twice the same pixels: the same distributions, so (up to OpenCV's sqrt(1 - BC) rounding) 0.
  StyleStatistics twice = s;
  twice += s;
  EXPECT_NEAR(style_distance(s, twice), 0.0, 1e-6);
  EXPECT_GT(style_distance(s, t), 0.01);
  EXPECT_NEAR(style_distance(s, t), style_distance(t, s), 1e-12);
  // Exposure normalisation: 4x brighter pixels with a 4x reference look the same.
  Image bright = im;
  for (float& v : bright.pixels()) v *= 4;
  EXPECT_NEAR(style_distance(s, style_statistics(bright, px, 0.8)), 0.0, 1e-6);
  // ... but not with the same reference.
  EXPECT_GT(style_distance(s, style_statistics(bright, px, 0.2)), 1.0);
}

// Flat grey pixels at luminance `y` with a little noise, `n` of them.
Image grey_patch(int n, double y, std::uint32_t seed, double chroma_a = 0) {
  std::mt19937 rng(seed);
  Image im(n, 1, 3);
  for (int i = 0; i < n; ++i) {
    const double v = y * (1 + 0.05 * normal(rng));
    im.at(i, 0, 0) = float(v * (1 + chroma_a));
    im.at(i, 0, 1) = float(v);
    im.at(i, 0, 2) = float(v);
  }
  return im;
}

TEST(Style, DistanceGrowsWithMeanShift) {
  const int n = 2000;
  const auto px = iota_pixels(0, n);
  const StyleStatistics sample = style_statistics(grey_patch(n, 0.18, 1), px, 0.18);
  double previous = -1;
  for (const double shift : {0.0, 0.05, 0.1, 0.2, 0.4, 0.8}) {
    // Reddening: the a* mean moves, and nothing else much.
    const double d =
        style_distance(sample, style_statistics(grey_patch(n, 0.18, 1, shift), px, 0.18));
    EXPECT_GT(d, previous) << "red shift " << shift;
    previous = d;
  }
  EXPECT_EQ(style_distance(sample, style_statistics(grey_patch(n, 0.18, 1, 0.0), px, 0.18)), 0.0);
  previous = -1;
  for (const double y : {0.18, 0.2, 0.25, 0.35, 0.5}) {
    const double d = style_distance(sample, style_statistics(grey_patch(n, y, 1), px, 0.18));
    EXPECT_GT(d, previous) << "luminance " << y;
    previous = d;
  }
}

TEST(Style, HighlightsCountedAndDistanceGrowsWithTheirSize) {
  const int n = 1000;
  const double reference = 0.2;
  const auto px = iota_pixels(0, n);
  const StyleStatistics sample = style_statistics(grey_patch(n, 0.2, 5), px, reference);
  EXPECT_EQ(sample.highlight_count, 0);
  double previous = -1;
  for (const int highlights : {0, 10, 30, 60, 120, 240}) {
    Image im = grey_patch(n, 0.2, 5);
    // Highlights of luminance 5 x reference: above the 2 x threshold by 3 (relative units).
    for (int i = 0; i < highlights; ++i)
      for (int c = 0; c < 3; ++c) im.at(i * (n / 240), 0, c) = float(5 * reference);
    const StyleStatistics s = style_statistics(im, px, reference);
    EXPECT_EQ(s.highlight_count, highlights);
    const double y_rel = luminance(1, 1, 1) * 5;  // float rounding of 1.0 * 5 * 0.2 / 0.2
    EXPECT_NEAR(s.highlight_energy, highlights * (y_rel - kHighlightLuminanceRatio),
                1e-4 * std::max(1, highlights));
    const double d = style_distance(sample, s);
    EXPECT_GT(d, previous) << highlights << " highlight pixels";
    previous = d;
  }
}

TEST(Style, ContrastIsTheDeviationOfLogLuminanceInStops) {
  // Half the pixels one stop under the reference, half one stop over: deviation 1 stop.
  Image im(100, 1, 3);
  for (int i = 0; i < 100; ++i)
    for (int c = 0; c < 3; ++c) im.at(i, 0, c) = i % 2 ? 0.5f : 0.125f;
  const StyleStatistics s = style_statistics(im, iota_pixels(0, 100), 0.25);
  const double m = s.log_luminance_sum / s.count;
  EXPECT_NEAR(m, std::log2(luminance(1, 1, 1)), 1e-5);
  EXPECT_NEAR(std::sqrt(s.log_luminance_sum_sq / s.count - m * m), 1.0, 1e-4);
}

TEST(Style, BadInput) {
  const Image im = random_image(8, 8, 1);
  const std::vector<std::int32_t> ok = {0, 1, 2}, outside = {0, 64};
  EXPECT_THROW(style_statistics(im, outside, 0.2), Error);
  EXPECT_THROW(style_statistics(im, std::vector<std::int32_t>{-1}, 0.2), Error);
  EXPECT_THROW(style_statistics(im, ok, 0), Error);
  EXPECT_THROW(style_statistics(im, ok, std::nan("")), Error);
  EXPECT_THROW(style_statistics(Image(4, 4, 1), ok, 0.2), Error);
  const StyleStatistics s = style_statistics(im, ok, 0.2);
  EXPECT_THROW(style_distance(s, style_statistics(im, {}, 0.2)), Error);
  EXPECT_THROW(style_distance(s, s, StyleWeights{-1, 1, 1, 1, 1}), Error);
  // Non-finite pixels are skipped, not propagated.
  Image nan_im = im;
  nan_im.at(0, 0, 1) = std::nanf("");
  const StyleStatistics skipped = style_statistics(nan_im, ok, 0.2);
  EXPECT_EQ(skipped.count, 2);
  EXPECT_TRUE(std::isfinite(skipped.lab_sum[0]));
}

// ---------------------------------------------------------------------------------------------
// Segmentation

struct Rectangles {
  Image image;
  std::vector<std::vector<char>> truth;  // per rectangle: 1 where the pixel belongs to it
};

// Three flat-coloured rectangles (left half; right top; right bottom) with 3 % noise.
Rectangles three_rectangles(int w, int h, std::uint32_t seed) {
  const double colours[3][3] = {{0.6, 0.1, 0.1}, {0.1, 0.5, 0.15}, {0.1, 0.15, 0.6}};
  Rectangles r{Image(w, h, 3), std::vector<std::vector<char>>(3, std::vector<char>(w * h, 0))};
  std::mt19937 rng(seed);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int k = x < w / 2 ? 0 : (y < h / 2 ? 1 : 2);
      r.truth[k][y * w + x] = 1;
      for (int c = 0; c < 3; ++c)
        r.image.at(x, y, c) = float(colours[k][c] * (1 + 0.03 * normal(rng)));
    }
  return r;
}

double iou(const Image& labels, int label, const std::vector<char>& truth) {
  double inter = 0, uni = 0;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    const bool a = labels.data()[i] == float(label), b = truth[i];
    inter += a && b;
    uni += a || b;
  }
  return uni > 0 ? inter / uni : 0;
}

TEST(Segments, ThreeNoisyRectanglesGiveThreeSegments) {
  const Rectangles r = three_rectangles(160, 120, 4);
  const Segmentation s = segment_image(r.image, nullptr);
  ASSERT_EQ(s.labels.width(), 160);
  ASSERT_EQ(s.labels.height(), 120);
  ASSERT_EQ(s.labels.channels(), 1);
  ASSERT_EQ(s.count, 3);
  std::set<int> matched;
  for (int k = 0; k < 3; ++k) {
    double best = 0;
    int best_label = -1;
    for (int l = 0; l < s.count; ++l)
      if (iou(s.labels, l, r.truth[k]) > best) best = iou(s.labels, l, r.truth[k]), best_label = l;
    std::printf("rectangle %d: segment %d, IoU %.4f\n", k, best_label, best);
    EXPECT_GT(best, 0.95) << "rectangle " << k;
    matched.insert(best_label);
  }
  EXPECT_EQ(matched.size(), 3u);

  // Deterministic, and independent of exposure (the merge works on exposure-normalised Lab).
  const Segmentation again = segment_image(r.image, nullptr);
  EXPECT_EQ(again.count, s.count);
  EXPECT_TRUE(std::equal(again.labels.pixels().begin(), again.labels.pixels().end(),
                         s.labels.pixels().begin()));
  Image dark = r.image;
  for (float& v : dark.pixels()) v *= 0.01f;
  const Segmentation dark_s = segment_image(dark, nullptr);
  ASSERT_EQ(dark_s.count, 3);
  for (int k = 0; k < 3; ++k) {
    double best = 0;
    for (int l = 0; l < 3; ++l) best = std::max(best, iou(dark_s.labels, l, r.truth[k]));
    EXPECT_GT(best, 0.95) << "dark rectangle " << k;
  }
}

TEST(Segments, LargeImageSegmentedOnAWorkingCopy) {
  // 0.72 MP: SLIC runs on a downscaled copy, labels come back at full size.
  const Rectangles r = three_rectangles(1200, 600, 8);
  const Segmentation s = segment_image(r.image, nullptr);
  ASSERT_EQ(s.labels.width(), 1200);
  ASSERT_EQ(s.count, 3);
  for (int k = 0; k < 3; ++k) {
    double best = 0;
    for (int l = 0; l < 3; ++l) best = std::max(best, iou(s.labels, l, r.truth[k]));
    EXPECT_GT(best, 0.95) << "rectangle " << k;
  }
}

TEST(Segments, InvalidMaskAndNonFinitePixelsAreRespected) {
  Rectangles r = three_rectangles(160, 120, 9);
  Image valid(160, 120, 1);
  for (int y = 0; y < 120; ++y)
    for (int x = 0; x < 160; ++x) valid.at(x, y, 0) = (x >= 30 && x < 42) ? 0.0f : 1.0f;
  r.image.at(100, 10, 1) = std::nanf("");
  valid.at(120, 100, 0) = std::nanf("");  // a NaN in the mask counts as invalid
  const Segmentation s = segment_image(r.image, &valid);
  EXPECT_EQ(s.labels.at(120, 100, 0), -1.0f);
  for (int y = 0; y < 120; ++y)
    for (int x = 0; x < 160; ++x) {
      const float l = s.labels.at(x, y, 0);
      if (valid.at(x, y, 0) == 0 || (x == 100 && y == 10)) {
        EXPECT_EQ(l, -1.0f) << x << "," << y;
      }
    }
  // The band cuts the left rectangle in two: 4 segments, none crossing the band.
  EXPECT_EQ(s.count, 4);
  std::set<int> left, right;
  for (int y = 0; y < 120; ++y) {
    for (int x = 0; x < 30; ++x) left.insert(int(s.labels.at(x, y, 0)));
    for (int x = 42; x < 80; ++x) right.insert(int(s.labels.at(x, y, 0)));
  }
  for (const int l : left) EXPECT_EQ(right.count(l), 0u) << "segment " << l << " crosses the mask";

  // All invalid: nothing.
  Image none(160, 120, 1);
  const Segmentation empty = segment_image(r.image, &none);
  EXPECT_EQ(empty.count, 0);
  for (const float l : empty.labels.pixels()) EXPECT_EQ(l, -1.0f);
}

TEST(Segments, TinyImages) {
  for (const int size : {1, 2, 3, 5}) {
    Image im(size, size, 3);
    for (float& v : im.pixels()) v = 0.3f;
    const Segmentation s = segment_image(im, nullptr);  // all below min_segment_pixels
    EXPECT_EQ(s.count, 0);
    EXPECT_EQ(s.labels.width(), size);
    for (const float l : s.labels.pixels()) EXPECT_EQ(l, -1.0f);
    SegmentOptions o;
    o.min_segment_pixels = 1;
    const Segmentation one = segment_image(im, nullptr, o);
    EXPECT_EQ(one.count, 1) << size << "x" << size;
    for (const float l : one.labels.pixels()) EXPECT_EQ(l, 0.0f);
  }
}

TEST(Segments, BadInput) {
  const Rectangles r = three_rectangles(40, 30, 1);
  Image wrong(20, 30, 1);
  try {
    segment_image(r.image, &wrong);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::size_mismatch);
  }
  EXPECT_THROW(segment_image(Image(), nullptr), Error);
  SegmentOptions o;
  o.min_segment_pixels = 0;
  EXPECT_THROW(segment_image(r.image, nullptr, o), Error);
  o = {};
  o.merge_lab_distance = -1;
  EXPECT_THROW(segment_image(r.image, nullptr, o), Error);
}

// ---------------------------------------------------------------------------------------------
// MaterialObjective and region adjacency

Material material(float r, float g, float b, float spec, float rough) {
  Material m;
  m.diffuse_albedo = {r, g, b};
  m.specular_albedo = spec;
  m.roughness = rough;
  return m;
}

TEST(MaterialObjective, SmoothnessTermOnAChainInClosedForm) {
  const Image im = random_image(30, 10, 21);
  auto stats = [&](int begin) { return style_statistics(im, iota_pixels(begin, begin + 50), 0.2); };
  const StyleStatistics sample = stats(0);
  std::vector<std::vector<StyleStatistics>> region_stats = {
      {stats(50), stats(100)}, {stats(150), stats(200)}, {stats(250), stats(10)}};
  const Material k0 = material(0.2f, 0.3f, 0.4f, 0.04f, 0.5f);
  const Material k1 = material(0.7f, 0.1f, 0.2f, 0.5f, 0.1f);
  const double d2 = 0.5 * 0.5 + 0.2 * 0.2 + 0.2 * 0.2 + 0.46 * 0.46 + 0.4 * 0.4;  // |k1 - k0|^2
  const double w = 0.7;
  const MaterialObjective f(sample, region_stats, {k0, k1}, {{0, 1}, {1, 2}}, w);
  EXPECT_EQ(f.regions(), 3);
  EXPECT_EQ(f.candidates(), 2);
  auto style_of = [&](std::array<int, 3> a) {
    StyleStatistics v;
    for (int r = 0; r < 3; ++r) v += region_stats[r][a[r]];
    return style_distance(sample, v);
  };
  // (0, 1, 0): grad = (k0 - k1, 2 (k1 - k0), k0 - k1) -> 6 |d|^2.
  // (0, 0, 1): grad = (0, k0 - k1, k1 - k0) -> 2 |d|^2.  Uniform: 0.
  const std::array<std::pair<std::array<int, 3>, double>, 4> cases = {
      {{{0, 1, 0}, 6}, {{0, 0, 1}, 2}, {{1, 1, 1}, 0}, {{1, 0, 0}, 2}}};
  for (const auto& [a, factor] : cases) {
    const double expected = style_of(a) + w * factor * d2;
    EXPECT_NEAR(f(a), expected, 1e-5 * (1 + expected)) << a[0] << a[1] << a[2];
  }
  // Without smoothness the objective is the style distance alone.
  const MaterialObjective g(sample, region_stats, {k0, k1}, {{0, 1}, {1, 2}}, 0);
  EXPECT_EQ(g(std::array<int, 3>{0, 1, 0}), style_of({0, 1, 0}));
}

TEST(MaterialObjective, RegionAdjacencyOnASmallLabelImage) {
  // 1 1 2 2
  // 1 0 2 3
  // 4 4 0 3      (2 and 4 touch only diagonally)
  const float labels[12] = {1, 1, 2, 2, 1, 0, 2, 3, 4, 4, 0, 3};
  Image im(4, 3, 1);
  std::copy(labels, labels + 12, im.data());
  const auto pairs = region_adjacency(im, 4);
  const std::vector<std::pair<int, int>> expected = {{0, 1}, {0, 3}, {1, 2}};
  EXPECT_EQ(pairs, expected);
  EXPECT_TRUE(region_adjacency(im, 5).size() == 3);  // a region with no pixels touches nothing
  EXPECT_THROW(region_adjacency(im, 3), Error);      // label 4 > 3
  im.at(1, 1, 0) = 2.5f;
  EXPECT_THROW(region_adjacency(im, 4), Error);
}

TEST(MaterialObjective, BadInput) {
  const Image im = random_image(10, 10, 2);
  const StyleStatistics s = style_statistics(im, iota_pixels(0, 20), 0.2);
  const Material m = material(0.5f, 0.5f, 0.5f, 0.04f, 0.5f);
  EXPECT_THROW(MaterialObjective(s, {}, {m}, {}, 0.1), Error);
  EXPECT_THROW(MaterialObjective(s, {{s}}, {}, {}, 0.1), Error);
  EXPECT_THROW(MaterialObjective(s, {{s, s}}, {m}, {}, 0.1), Error);          // sizes
  EXPECT_THROW(MaterialObjective(s, {{s}, {s}}, {m}, {{1, 0}}, 0.1), Error);  // not i < j
  EXPECT_THROW(MaterialObjective(s, {{s}, {s}}, {m}, {{0, 2}}, 0.1), Error);  // out of range
  EXPECT_THROW(MaterialObjective(s, {{s}}, {m}, {}, -1), Error);
  EXPECT_THROW(MaterialObjective(s, {{s}}, {material(2, 0, 0, 0, 0.5f)}, {}, 0.1), Error);
  const MaterialObjective f(s, {{s}, {s}}, {m}, {{0, 1}}, 0.1);
  EXPECT_THROW(f(std::vector<int>{0}), Error);
  EXPECT_THROW(f(std::vector<int>{0, 1}), Error);
  EXPECT_EQ(f(std::vector<int>{0, 0}), style_distance(s, [&] {
              StyleStatistics v = s;
              v += s;
              return v;
            }()));
}

// ---------------------------------------------------------------------------------------------
// Tabu search

// A random MaterialObjective: `n` regions, `m` candidates. Each candidate has a base colour,
// roughness-dependent highlight fraction and noise; a region sees it under its own shading
// factor. Statistics are measured on a synthetic image, as the facade measures renders.
MaterialObjective random_material_objective(int n, int m, std::mt19937& rng) {
  const int per_set = 40;
  const int sets = n * m + 1;
  Image im(per_set, sets, 3);
  const double reference = 0.2;
  std::vector<Material> candidates;
  std::vector<std::array<double, 3>> base(m);
  std::vector<double> highlight_fraction(m);
  for (int c = 0; c < m; ++c) {
    for (double& v : base[c]) v = uniform(rng, 0.02, 0.6);
    highlight_fraction[c] = uniform(rng, 0, 0.2);
    candidates.push_back(material(float(uniform(rng, 0, 1)), float(uniform(rng, 0, 1)),
                                  float(uniform(rng, 0, 1)), float(uniform(rng, 0, 1)),
                                  float(uniform(rng, 0.05, 1))));
  }
  auto fill_row = [&](int row, const std::array<double, 3>& colour, double shade, double hl) {
    for (int i = 0; i < per_set; ++i) {
      const bool highlight = uniform01(rng) < hl;
      const double noise = 1 + 0.1 * normal(rng);
      for (int c = 0; c < 3; ++c)
        im.at(i, row, c) = float(highlight ? uniform(rng, 0.5, 3) : colour[c] * shade * noise);
    }
  };
  std::array<double, 3> sample_colour;
  for (double& v : sample_colour) v = uniform(rng, 0.02, 0.6);
  fill_row(0, sample_colour, 1, uniform(rng, 0, 0.2));
  for (int r = 0; r < n; ++r) {
    const double shade = uniform(rng, 0.5, 1.5);
    for (int c = 0; c < m; ++c) fill_row(1 + r * m + c, base[c], shade, highlight_fraction[c]);
  }
  auto row_stats = [&](int row) {
    return style_statistics(im, iota_pixels(row * per_set, (row + 1) * per_set), reference);
  };
  std::vector<std::vector<StyleStatistics>> region_stats(n);
  for (int r = 0; r < n; ++r)
    for (int c = 0; c < m; ++c) region_stats[r].push_back(row_stats(1 + r * m + c));
  std::vector<std::pair<int, int>> adjacency;
  for (int i = 0; i < n; ++i)
    for (int j = i + 1; j < n; ++j)
      if (uniform01(rng) < 0.5) adjacency.emplace_back(i, j);
  return MaterialObjective(row_stats(0), std::move(region_stats), std::move(candidates),
                           std::move(adjacency), uniform(rng, 0, 2));
}

// A random generic objective: unary plus dense pairwise tables (a random pairwise MRF energy).
AssignmentObjective random_pairwise_objective(int n, int m, std::mt19937& rng) {
  std::vector<double> unary(n * m), pairwise(n * n * m * m);
  for (double& v : unary) v = normal(rng);
  for (double& v : pairwise) v = normal(rng) * 0.7;
  return [=](std::span<const int> a) {
    double f = 0;
    for (int i = 0; i < n; ++i) {
      f += unary[i * m + a[i]];
      for (int j = i + 1; j < n; ++j) f += pairwise[((i * n + j) * m + a[i]) * m + a[j]];
    }
    return f;
  };
}

TEST(TabuSearch, FindsTheBruteForceOptimumOnRandomInstances) {
  std::mt19937 rng(2024);
  int instances = 0, found = 0, material_instances = 0, material_found = 0;
  long tabu_evaluations = 0, brute_evaluations = 0;
  for (int k = 0; k < 400; ++k) {
    const int n = 3 + k % 4;        // 3..6 regions
    const int m = 2 + (k / 4) % 4;  // 2..5 candidates
    const bool material_kind = k % 2 == 0;
    AssignmentObjective f;
    if (material_kind) {
      auto objective = std::make_shared<MaterialObjective>(random_material_objective(n, m, rng));
      f = [objective](std::span<const int> a) { return (*objective)(a); };
    } else {
      f = random_pairwise_objective(n, m, rng);
    }
    TabuOptions options;
    options.seed = 1000 + k;
    const TabuResult tabu = tabu_search(n, m, f, options);
    const TabuResult brute = brute_force_search(n, m, f);
    ASSERT_EQ(tabu.assignment.size(), std::size_t(n));
    // Reported objective is the objective of the reported assignment.
    EXPECT_EQ(tabu.objective, f(tabu.assignment));
    // Best-so-far never increases, and ends at the result.
    ASSERT_FALSE(tabu.best_history.empty());
    for (std::size_t i = 1; i < tabu.best_history.size(); ++i)
      ASSERT_LE(tabu.best_history[i], tabu.best_history[i - 1])
          << "instance " << k << " step " << i;
    EXPECT_EQ(tabu.best_history.back(), tabu.objective);
    for (std::size_t i = 1; i < brute.best_history.size(); ++i)
      ASSERT_LE(brute.best_history[i], brute.best_history[i - 1]);
    EXPECT_EQ(brute.evaluations, long(std::pow(m, n) + 0.5));
    EXPECT_GE(tabu.objective, brute.objective);  // nothing beats exhaustive search
    const bool optimal =
        tabu.objective <= brute.objective + 1e-12 * (1 + std::abs(brute.objective));
    if (!optimal)
      std::printf(
          "not optimal: instance %d (%d regions, %d candidates, %s): tabu %.6g vs brute "
          "force %.6g after %zu iterations, %ld evaluations\n",
          k, n, m, material_kind ? "MaterialObjective" : "pairwise", tabu.objective,
          brute.objective, tabu.best_history.size() - 1, tabu.evaluations);
    ++instances;
    found += optimal;
    material_instances += material_kind;
    material_found += material_kind && optimal;
    tabu_evaluations += tabu.evaluations;
    brute_evaluations += brute.evaluations;
  }
  const double rate = double(found) / instances;
  std::printf(
      "Tabu search found the brute-force optimum in %d / %d instances (%.1f %%); "
      "MaterialObjective %d / %d, pairwise %d / %d; evaluations %ld tabu vs %ld brute\n",
      found, instances, 100 * rate, material_found, material_instances, found - material_found,
      instances - material_instances, tabu_evaluations, brute_evaluations);
  EXPECT_GE(instances, 400);
  EXPECT_GE(rate, 0.95);
}

TEST(TabuSearch, MinimiseAssignmentIsExhaustiveUpToItsLimitAndTabuAbove) {
  // Up to the limit: brute force's assignment and objective, its history shortened to the
  // improvements (never increasing, ending at the objective). Above it: Tabu search's result
  // for the same options, bit for bit.
  std::mt19937 rng(31);
  for (int k = 0; k < 20; ++k) {
    const int n = 3 + k % 3, m = 3 + k % 4;
    const MaterialObjective objective = random_material_objective(n, m, rng);
    const AssignmentObjective f = [&](std::span<const int> a) { return objective(a); };
    TabuOptions options;
    options.seed = 50 + k;
    const double count = std::pow(m, n);
    const TabuResult all = minimise_assignment(n, m, f, options, count);
    const TabuResult brute = brute_force_search(n, m, f);
    EXPECT_TRUE(all.exhaustive);
    EXPECT_EQ(all.assignment, brute.assignment);
    EXPECT_EQ(all.objective, brute.objective);
    EXPECT_EQ(all.evaluations, brute.evaluations);
    ASSERT_FALSE(all.best_history.empty());
    EXPECT_EQ(all.best_history.front(), brute.best_history.front());
    for (std::size_t i = 1; i < all.best_history.size(); ++i)
      EXPECT_LT(all.best_history[i], all.best_history[i - 1]);
    EXPECT_EQ(all.best_history.back(), all.objective);
    EXPECT_LE(all.best_history.size(), brute.best_history.size());

    const TabuResult above = minimise_assignment(n, m, f, options, count - 1);
    const TabuResult tabu = tabu_search(n, m, f, options);
    EXPECT_FALSE(above.exhaustive);
    EXPECT_EQ(above.assignment, tabu.assignment);
    EXPECT_EQ(above.objective, tabu.objective);
    EXPECT_EQ(above.best_history, tabu.best_history);
  }
  // The default limit enumerates 8 candidates over 5 regions, not over 6.
  const AssignmentObjective zero = [](std::span<const int>) { return 0.0; };
  EXPECT_TRUE(minimise_assignment(5, 8, zero).exhaustive);
  EXPECT_FALSE(minimise_assignment(6, 8, zero).exhaustive);
  EXPECT_THROW(minimise_assignment(0, 3, zero), Error);
}

TEST(TabuSearch, SameSeedSameResult) {
  std::mt19937 rng(5);
  const MaterialObjective objective = random_material_objective(6, 4, rng);
  const AssignmentObjective f = [&](std::span<const int> a) { return objective(a); };
  for (const std::uint32_t seed : {1u, 2u, 77u}) {
    TabuOptions o;
    o.seed = seed;
    o.restarts = 2;
    const TabuResult a = tabu_search(6, 4, f, o), b = tabu_search(6, 4, f, o);
    EXPECT_EQ(a.assignment, b.assignment);
    EXPECT_EQ(a.objective, b.objective);
    EXPECT_EQ(a.best_history, b.best_history);
    EXPECT_EQ(a.evaluations, b.evaluations);
  }
}

TEST(TabuSearch, EscapesALocalMinimumThatTrapsGreedyDescent) {
  // f = 0 at all-ones (the optimum), 1 at all-zeros; in between, every step away from all-zeros
  // costs more until it is a single step from the optimum: descent from all-zeros is stuck.
  const int n = 5;
  const AssignmentObjective f = [](std::span<const int> a) {
    int ones = 0;
    for (const int v : a) ones += v;
    if (ones == 5) return 0.0;
    return 1.0 + ones;
  };
  TabuOptions o;
  o.seed = 3;
  o.tenure = n - 1;  // the walk back down is tabu for long enough to climb over the ridge
  const TabuResult r = tabu_search(n, 2, f, o);
  EXPECT_EQ(r.objective, 0.0);
  EXPECT_EQ(r.assignment, std::vector<int>(n, 1));
}

TEST(TabuSearch, SeparableObjectiveHasAKnownOptimum) {
  // f = sum_i (a_i - t_i)^2 has its only minimum, 0, at a = t.
  const std::vector<int> target = {3, 0, 6, 2, 5, 1, 4, 6};
  const AssignmentObjective f = [&](std::span<const int> a) {
    double sum = 0;
    for (std::size_t i = 0; i < a.size(); ++i) sum += double(a[i] - target[i]) * (a[i] - target[i]);
    return sum;
  };
  const TabuResult tabu = tabu_search(8, 7, f);
  EXPECT_EQ(tabu.assignment, target);
  EXPECT_EQ(tabu.objective, 0.0);
  EXPECT_LT(tabu.evaluations, 2000);  // of 7^8 = 5.8 million
  const TabuResult brute = brute_force_search(4, 7, [&](std::span<const int> a) {
    return f(std::vector<int>{a[0], a[1], a[2], a[3], 5, 1, 4, 5});
  });
  EXPECT_EQ(brute.assignment, (std::vector<int>{3, 0, 6, 2}));
  EXPECT_EQ(brute.objective, 1.0);  // the fixed 8th entry is off by one
  EXPECT_EQ(brute.evaluations, 7 * 7 * 7 * 7);
}

TEST(TabuSearch, OneValueAndOneVariable) {
  const AssignmentObjective f = [](std::span<const int> a) { return double(a[0]) * 2 - 3; };
  const TabuResult one = tabu_search(1, 1, f);
  EXPECT_EQ(one.assignment, std::vector<int>{0});
  EXPECT_EQ(one.objective, -3.0);
  const TabuResult r = tabu_search(1, 4, f);
  EXPECT_EQ(r.assignment, std::vector<int>{0});
  EXPECT_EQ(r.objective, -3.0);
}

TEST(TabuSearch, BadInput) {
  const AssignmentObjective f = [](std::span<const int>) { return 0.0; };
  for (const auto& [n, m] : std::vector<std::pair<int, int>>{{0, 3}, {3, 0}, {-1, 2}, {2, -5}}) {
    try {
      tabu_search(n, m, f);
      FAIL() << n << " " << m;
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::invalid_argument);
    }
    EXPECT_THROW(brute_force_search(n, m, f), Error);
  }
  TabuOptions o;
  o.patience = 0;
  EXPECT_THROW(tabu_search(3, 3, f, o), Error);
  EXPECT_THROW(tabu_search(3, 3, AssignmentObjective{}), Error);
  EXPECT_THROW(brute_force_search(40, 8, f), Error);  // too many to enumerate
  const AssignmentObjective nan = [](std::span<const int>) { return std::nan(""); };
  EXPECT_THROW(tabu_search(3, 3, nan), Error);
}

}  // namespace
}  // namespace mr::photo
