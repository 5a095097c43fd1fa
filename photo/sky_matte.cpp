#include "photo/sky_matte.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "mr/error.h"

namespace mr::photo {

// An L2 distance transform with per-pixel labels.
std::vector<std::int32_t> nearest_source(int w, int h, const std::vector<std::uint8_t>& is_source) {
  cv::Mat src(h, w, CV_8U);  // 0 at the sources: distanceTransform measures to its zeros
  bool any = false;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const bool s = is_source[std::size_t(y) * w + x] != 0;
      src.at<std::uint8_t>(y, x) = s ? 0 : 1;
      any |= s;
    }
  if (!any) return {};
  cv::Mat dist, labels;
  cv::distanceTransform(src, dist, labels, cv::DIST_L2, cv::DIST_MASK_5, cv::DIST_LABEL_PIXEL);
  // Each source pixel carries its own label: map labels back to pixel indices.
  std::vector<std::int32_t> index_of_label;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (src.at<std::uint8_t>(y, x) == 0) {
        const int l = labels.at<int>(y, x);
        if (l >= int(index_of_label.size())) index_of_label.resize(std::size_t(l) + 1, -1);
        index_of_label[std::size_t(l)] = std::int32_t(std::size_t(y) * w + x);
      }
  std::vector<std::int32_t> out(std::size_t(w) * h, -1);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int l = labels.at<int>(y, x);
      if (l >= 0 && l < int(index_of_label.size())) out[std::size_t(y) * w + x] = index_of_label[l];
    }
  return out;
}

std::size_t apply_sky_matte(ConstImageView sky_alpha, ImageView transmittance,
                            ImageView inscatter) {
  const int w = sky_alpha.width, h = sky_alpha.height;
  if (sky_alpha.channels != 1 || transmittance.channels != 3 || inscatter.channels != 3)
    throw Error(ErrorCode::invalid_argument,
                "apply_sky_matte: expected a 1-channel matte and 3-channel T and R, found " +
                    std::to_string(sky_alpha.channels) + ", " +
                    std::to_string(transmittance.channels) + " and " +
                    std::to_string(inscatter.channels));
  if (transmittance.width != w || transmittance.height != h || inscatter.width != w ||
      inscatter.height != h)
    throw Error(ErrorCode::size_mismatch, "apply_sky_matte: the sky matte is " + std::to_string(w) +
                                              "x" + std::to_string(h) + ", the fog layers " +
                                              std::to_string(transmittance.width) + "x" +
                                              std::to_string(transmittance.height));
  const std::size_t n = std::size_t(w) * h;
  std::vector<std::uint8_t> sky(n, 0), surface(n, 0);
  bool mixed_any = false;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float a = sky_alpha.pixel(x, y)[0];
      const std::size_t i = std::size_t(y) * w + x;
      sky[i] = a >= 1.0f;
      surface[i] = a <= 0.0f;
      mixed_any |= a > 0.0f && a < 1.0f;
    }
  if (!mixed_any) return 0;
  const std::vector<std::int32_t> near_sky = nearest_source(w, h, sky);
  const std::vector<std::int32_t> near_surface = nearest_source(w, h, surface);
  if (near_sky.empty() || near_surface.empty()) return 0;
  // The sources are read from copies: a mixed pixel's new value must not feed another's.
  std::vector<float> t_src(n * 3), r_src(n * 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) {
        t_src[(std::size_t(y) * w + x) * 3 + c] = transmittance.pixel(x, y)[c];
        r_src[(std::size_t(y) * w + x) * 3 + c] = inscatter.pixel(x, y)[c];
      }
  std::size_t mixed = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float a = sky_alpha.pixel(x, y)[0];
      if (!(a > 0.0f && a < 1.0f)) continue;
      const std::size_t i = std::size_t(y) * w + x;
      const std::int32_t k = near_sky[i], s = near_surface[i];
      if (k < 0 || s < 0) continue;
      float* t = transmittance.pixel(x, y);
      float* r = inscatter.pixel(x, y);
      for (int c = 0; c < 3; ++c) {
        t[c] = (1 - a) * t_src[std::size_t(s) * 3 + c] + a * t_src[std::size_t(k) * 3 + c];
        r[c] = (1 - a) * r_src[std::size_t(s) * 3 + c] + a * r_src[std::size_t(k) * 3 + c];
      }
      ++mixed;
    }
  return mixed;
}

std::size_t trim_matte_spill(ConstImageView photo, std::vector<float>& alpha) {
  const int w = photo.width, h = photo.height;
  const std::size_t n = std::size_t(w) * h;
  if (alpha.size() != n)
    throw Error(ErrorCode::size_mismatch, "trim_matte_spill: the photo is " + std::to_string(w) +
                                              "x" + std::to_string(h) + " but the matte holds " +
                                              std::to_string(alpha.size()) + " values");
  if (w < 3 || h < 3 || photo.channels < 1) return 0;
  // A sharp edge: the sky side reaches kFirmSky within kFirmReachPx of the pixel, and the
  // binary sky (alpha >= 0.5) within kEdgeReachPx. A soft edge (a blurred leaf: a ramp ten or
  // more pixels wide) has no firm sky that near, and its unmixed values are noisy (hue and
  // texture of the leaves): trimming pixels in its ramp leaves cliffs in the matte.
  constexpr float kFirmSky = 0.9f;
  constexpr double kFirmReachPx = 3.5, kEdgeReachPx = 2.5;
  // And a plain surface (alpha 0) beyond the ramp within kSurfaceReachPx: F is then the colour
  // of the surface right there. A thin member (a lattice's 1-3 px steel, a cable) lies wholly
  // inside the band; its nearest plain surface is some other structure, and trimming it would
  // set a member at its own distance, clear, against the sky's opaque haze (rocket's towers).
  constexpr double kSurfaceReachPx = 4.5;
  // SkyMask's contrast thresholds (display-referred, about 8 and 20 codes of 255), on luma.
  constexpr float kNoEdge = 0.03f, kEdge = 0.08f;
  // How near the surface's colour (along F -> B) a pixel must be to show the surface only.
  constexpr float kBeyond = 0.1f;
  std::vector<std::uint8_t> sky(n), surface(n), half_sky(n), firm_sky(n);
  bool spill = false;
  for (std::size_t i = 0; i < n; ++i) {
    sky[i] = alpha[i] >= 1.0f;
    surface[i] = alpha[i] <= 0.0f;
    half_sky[i] = alpha[i] >= 0.5f;
    firm_sky[i] = alpha[i] >= kFirmSky;
    spill |= alpha[i] > 0.0f && alpha[i] < 0.5f;
  }
  if (!spill) return 0;
  const std::vector<std::int32_t> near_sky = nearest_source(w, h, sky);
  const std::vector<std::int32_t> near_surface = nearest_source(w, h, surface);
  const std::vector<std::int32_t> near_half_sky = nearest_source(w, h, half_sky);
  const std::vector<std::int32_t> near_firm_sky = nearest_source(w, h, firm_sky);
  if (near_sky.empty() || near_surface.empty() || near_half_sky.empty() || near_firm_sky.empty())
    return 0;
  auto within = [w](std::int32_t j, int x, int y, double reach) {
    return j >= 0 && std::hypot(double(j % w - x), double(j / w - y)) <= reach;
  };
  cv::Mat linear(h, w, CV_32FC3), mean;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float* p = photo.pixel(x, y);
      cv::Vec3f v;
      for (int c = 0; c < 3; ++c) {
        const float u = p[photo.channels >= 3 ? c : 0];
        v[c] = std::isfinite(u) ? std::clamp(u, 0.0f, 1.0f) : 0.0f;
      }
      linear.at<cv::Vec3f>(y, x) = v;
    }
  cv::blur(linear, mean, cv::Size(3, 3));
  // The trimmed value of each surface-side pixel of a plain edge (-1: none): its alpha moved
  // to its projection on F -> B, weighted by the contrast.
  const std::vector<float> original = alpha;
  std::vector<float> trimmed(n, -1.0f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      const float a = alpha[i];
      if (!(a > 0.0f && a < 0.5f)) continue;
      const std::int32_t k = near_sky[i], f = near_surface[i];
      if (k < 0 || !within(f, x, y, kSurfaceReachPx)) continue;
      const cv::Vec3f B = mean.at<cv::Vec3f>(k / w, k % w);
      const cv::Vec3f F = mean.at<cv::Vec3f>(f / w, f % w);
      const cv::Vec3f I = linear.at<cv::Vec3f>(y, x);
      const cv::Vec3f BF = B - F;
      const float norm2 = BF.dot(BF);
      // The step in display luma: only an edge the photo shows in brightness takes a sharp
      // matte. Where the two sides differ in hue but hardly in luma (a dark steel leg against a
      // dark blue dusk sky), the photo's luma is smooth across the edge, and a crisp silhouette
      // against the haze's brighter, neutral sky is a luma step the photo does not have; the
      // guided ramp's softness is kinder there.
      auto luma = [](const cv::Vec3f& v) {
        return 0.2126f * std::pow(v[0], 1 / 2.2f) + 0.7152f * std::pow(v[1], 1 / 2.2f) +
               0.0722f * std::pow(v[2], 1 / 2.2f);
      };
      const float contrast = std::abs(luma(B) - luma(F));
      const float t = std::clamp((contrast - kNoEdge) / (kEdge - kNoEdge), 0.0f, 1.0f);
      if (!(t > 0) || !(norm2 > 0)) continue;
      const float projection = (I - F).dot(BF) / norm2;
      if (projection > kBeyond) continue;  // some of the sky's colour: the guided ramp stands
      const float wt = t * t * (3 - 2 * t);
      const float v = wt * std::max(projection, 0.0f) + (1 - wt) * a;
      if (v < a) trimmed[i] = v;
    }
  // Seeds: the pixels next to a sharp edge. Then the ramp's tail outward from them: a pixel
  // next to a trimmed one whose alpha was at least its own (the same ramp, falling away from
  // the sky), up to kMaxSpillPx rows of it.
  constexpr int kMaxSpillPx = 6;
  std::vector<std::uint8_t> done(n, 0);
  std::vector<std::size_t> front;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      if (trimmed[i] >= 0.0f && within(near_half_sky[i], x, y, kEdgeReachPx) &&
          within(near_firm_sky[i], x, y, kFirmReachPx))
        front.push_back(i), done[i] = 1;
    }
  std::size_t lowered = 0;
  for (int step = 0; !front.empty(); ++step) {
    for (const std::size_t i : front) alpha[i] = trimmed[i], ++lowered;
    if (step == kMaxSpillPx) break;
    std::vector<std::size_t> next;
    for (const std::size_t i : front) {
      const int x = int(i % std::size_t(w)), y = int(i / std::size_t(w));
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int u = x + dx, v = y + dy;
          if (u < 0 || v < 0 || u >= w || v >= h) continue;
          const std::size_t j = std::size_t(v) * w + u;
          if (done[j] || !(trimmed[j] >= 0.0f) || original[j] > original[i]) continue;
          done[j] = 1;
          next.push_back(j);
        }
    }
    front = std::move(next);
  }
  return lowered;
}

}  // namespace mr::photo
