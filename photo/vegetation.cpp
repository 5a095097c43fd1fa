#include "photo/vegetation.h"

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <string>

#include "core/cv_bridge.h"
#include "mr/error.h"

namespace mr::photo {

namespace {

float median_of(std::vector<float>& v) {
  if (v.empty()) return 0;
  auto mid = v.begin() + std::ptrdiff_t(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

}  // namespace

Vegetation estimate_vegetation(ConstImageView photo, const std::array<PixelPoint, 2>& horizon,
                               const std::vector<std::uint8_t>& sky, const VegetationOptions& o) {
  const int w = photo.width, h = photo.height;
  const std::size_t n = std::size_t(w) * h;
  if (sky.size() != n)
    throw Error(ErrorCode::size_mismatch, "estimate_vegetation: the photo is " +
                                              std::to_string(w) + "x" + std::to_string(h) +
                                              " but the sky mask holds " +
                                              std::to_string(sky.size()) + " values");
  Vegetation out;
  out.width = w, out.height = h;
  out.vegetation.assign(n, 0);
  out.sky_gap.assign(n, 0);
  if (w < 8 || h < 8 || photo.channels < 1) return out;

  // Display-referred colour, luma and chromaticity.
  const cv::Mat src = detail::as_mat(photo);
  const int ch = photo.channels;
  cv::Mat luma(h, w, CV_32F), cr(h, w, CV_32F), cg(h, w, CV_32F);
  cv::Mat foliage_colour(h, w, CV_8U);
  for (int y = 0; y < h; ++y) {
    const float* row = src.ptr<float>(y);
    for (int x = 0; x < w; ++x) {
      float c[3];
      for (int k = 0; k < 3; ++k) {
        float v = row[std::ptrdiff_t(x) * ch + (ch >= 3 ? k : 0)];
        if (!std::isfinite(v)) v = 0;
        c[k] = std::pow(std::clamp(v, 0.0f, 1.0f), 1 / 2.2f);
      }
      luma.at<float>(y, x) = 0.2126f * c[0] + 0.7152f * c[1] + 0.0722f * c[2];
      // Foliage and bark: green, yellow, red or brown (blue the weakest channel, a little
      // saturated), or in shade (dark).
      const bool coloured =
          c[2] <= std::min(c[0], c[1]) + 0.02f &&
          std::max({c[0], c[1], c[2]}) - std::min({c[0], c[1], c[2]}) >= o.min_saturation;
      // 2: green (leaves in light), 1: other foliage colours and shade.
      foliage_colour.at<std::uint8_t>(y, x) =
          coloured && c[1] >= c[0] ? 2 : coloured || luma.at<float>(y, x) < o.max_shade_luma ? 1 : 0;
      const float s = c[0] + c[1] + c[2] + 1e-4f;
      cr.at<float>(y, x) = c[0] / s;
      cg.at<float>(y, x) = c[1] / s;
    }
  }
  // Fine-scale texture: |gradient| of the luma (central differences), and its box means.
  cv::Mat gx, gy, grad;
  cv::Sobel(luma, gx, CV_32F, 1, 0, 1, 0.5);
  cv::Sobel(luma, gy, CV_32F, 0, 1, 1, 0.5);
  cv::magnitude(gx, gy, grad);
  cv::Mat texture, local;
  const int win = std::max(3, o.texture_window_px | 1);
  cv::boxFilter(grad, texture, CV_32F, cv::Size(win, win));
  cv::boxFilter(grad, local, CV_32F, cv::Size(3, 3));

  // The open sky's colour: median luma and chromaticity over (a stride of) the sky mask.
  std::size_t sky_count = 0;
  for (const auto s : sky) sky_count += s != 0;
  const bool sky_model = double(sky_count) >= o.min_sky_fraction * double(n) && sky_count >= 64;
  float sky_luma = 0, sky_r = 0, sky_g = 0;
  if (sky_model) {
    const std::size_t stride = std::max<std::size_t>(1, sky_count / 200'000);
    std::vector<float> vl, vr, vg;
    std::size_t k = 0;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        if (sky[std::size_t(y) * w + x] && k++ % stride == 0) {
          vl.push_back(luma.at<float>(y, x));
          vr.push_back(cr.at<float>(y, x));
          vg.push_back(cg.at<float>(y, x));
        }
    sky_luma = median_of(vl), sky_r = median_of(vr), sky_g = median_of(vg);
  }
  auto sky_coloured = [&](int x, int y) {
    if (!sky_model || !(sky_luma > 0.05f)) return false;
    const float l = luma.at<float>(y, x) / sky_luma;
    if (!(l >= o.gap_min_luma && l <= o.gap_max_luma)) return false;
    return std::hypot(cr.at<float>(y, x) - sky_r, cg.at<float>(y, x) - sky_g) <= o.gap_max_chroma;
  };

  // Without an open sky there is nothing to see through trees, and a textured close-up or
  // interior (a coffee cup, a woven cloth) is better left to the structures' usual rule.
  if (!sky_model) return out;
  // Only under a blue sky: a grey or white sky's colour matches too much else (skin, a white
  // wall ringed by hair or texture were found as gaps on a portrait), and a rusty lattice tower
  // under a grey sky was taken for a tree (its haze got more created edges).
  const float sky_b = 1 - sky_r - sky_g;
  if (!(sky_b >= std::max(sky_r, sky_g) + o.min_sky_blueness)) return out;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      if (sky[i]) continue;
      if (texture.at<float>(y, x) >= o.min_texture && foliage_colour.at<std::uint8_t>(y, x) &&
          !sky_coloured(x, y)) {
        out.vegetation[i] = foliage_colour.at<std::uint8_t>(y, x);
        ++out.vegetation_pixels;
      }
    }

  // Sky seen through vegetation: smooth sky-coloured pixels above the horizon that the mask left
  // out, in components mostly ringed by vegetation.
  const double slope = (horizon[1][1] - horizon[0][1]) / std::max(1.0, horizon[1][0] - horizon[0][0]);
  auto above = [&](int x, int y) { return y < horizon[0][1] + (x - horizon[0][0]) * slope; };
  cv::Mat candidate(h, w, CV_8U, cv::Scalar(0)), colour(h, w, CV_8U, cv::Scalar(0));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      if (sky[i] || !above(x, y) || !sky_coloured(x, y)) continue;
      colour.at<std::uint8_t>(y, x) = 1;
      candidate.at<std::uint8_t>(y, x) = local.at<float>(y, x) <= o.gap_max_texture;
    }
  cv::Mat labels, stats, centroids;
  const int count = cv::connectedComponentsWithStats(candidate, labels, stats, centroids, 8, CV_32S);
  if (count <= 1) return out;
  const int r = std::max(1, o.ring_px);
  const cv::Mat disc = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r + 1, 2 * r + 1));
  cv::Mat label_f, grown;
  labels.convertTo(label_f, CV_32F);
  cv::dilate(label_f, grown, disc);  // each ring pixel takes the largest nearby label
  std::vector<std::size_t> ring(std::size_t(count), 0), ring_veg(std::size_t(count), 0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      if (candidate.at<std::uint8_t>(y, x) || sky[i]) continue;
      const int l = int(grown.at<float>(y, x));
      if (l <= 0) continue;
      ++ring[std::size_t(l)];
      ring_veg[std::size_t(l)] += out.vegetation[i] == 2;  // green: a rusty lattice rings sky too
    }
  std::vector<std::uint8_t> keep(std::size_t(count), 0);
  for (int l = 1; l < count; ++l)
    keep[std::size_t(l)] = ring[std::size_t(l)] >= 4 &&
                           double(ring_veg[std::size_t(l)]) >=
                               o.gap_min_vegetation_ring * double(ring[std::size_t(l)]);
  cv::Mat gap(h, w, CV_8U, cv::Scalar(0));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      gap.at<std::uint8_t>(y, x) = keep[std::size_t(labels.at<int>(y, x))];
  // The gaps' edges against the leaves are textured (the texture test left them out): grow the
  // gaps into sky-coloured pixels next to them, so the hole is as wide as the sky the photo
  // shows.
  const cv::Mat cross = cv::getStructuringElement(cv::MORPH_CROSS, cv::Size(3, 3));
  for (int it = 0; it < 2; ++it) {
    cv::Mat g2;
    cv::dilate(gap, g2, cross);
    gap = g2 & colour;
  }
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (gap.at<std::uint8_t>(y, x)) {
        const std::size_t i = std::size_t(y) * w + x;
        out.sky_gap[i] = 1;
        ++out.gap_pixels;
        if (out.vegetation[i]) out.vegetation[i] = 0, --out.vegetation_pixels;
      }
  return out;
}

}  // namespace mr::photo
