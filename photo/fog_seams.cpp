#include "photo/fog_seams.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "mr/error.h"
#include "photo/display.h"
#include "photo/opencv_contrib.h"
#include "photo/sky_light.h"
#include "photo/sky_matte.h"

namespace mr::photo {

namespace {

// gallery/measures.py's constants (CREATED_EDGE_RATIO, CREATED_EDGE_FLOOR, EDGE_BLUR_SIGMA_PX).
constexpr float kCreatedEdgeRatio = 2.0f;
constexpr float kCreatedEdgeFloor = 0.01f;  // display luma per pixel, after the blur
// The edge-aware smoother (cv::ximgproc fast global smoother, a weighted-least-squares fit
// guided by the photo in display-referred 8-bit): its smoothness grows with the longer side
// (lambda = (0.02 x side)^2, 256 at 800 px) and x4 each round; its weights fall by e for each
// kSigmaColor codes (of 255) of difference in the guide. At 20 it pulled a kite (gallery/tune
// kite, 150 px across a wide sky) into the sky's fog: the global fit leaks into small objects.
constexpr double kExtentOfLongerSide = 0.02;
constexpr double kSigmaColor = 10;
// The guide's texture removal (rolling guidance: 4 iterations, spatial sigma in px, range
// sigma in codes of 255).
constexpr double kTexturePx = 3;
constexpr double kTextureSigmaColor = 25;
constexpr int kMaxRounds = 3;

// The measure's edge strength of a display-luma picture: blur sigma 1 px (radius 3, edges
// replicated), central differences (one-sided at the borders' replicated pixels).
cv::Mat edge_strength(const cv::Mat& luma) {
  cv::Mat b;
  cv::GaussianBlur(luma, b, cv::Size(7, 7), 1.0, 1.0, cv::BORDER_REPLICATE);
  cv::Mat g(luma.rows, luma.cols, CV_32F);
  for (int y = 0; y < luma.rows; ++y) {
    const float* up = b.ptr<float>(std::max(0, y - 1));
    const float* row = b.ptr<float>(y);
    const float* down = b.ptr<float>(std::min(luma.rows - 1, y + 1));
    float* out = g.ptr<float>(y);
    for (int x = 0; x < luma.cols; ++x) {
      const int x0 = std::max(0, x - 1), x1 = std::min(luma.cols - 1, x + 1);
      out[x] = std::hypot(0.5f * (row[x1] - row[x0]), 0.5f * (down[x] - up[x]));
    }
  }
  return g;
}

// Display luma: Rec. 709 weights on the encoded values (the measure's), non-finite as black.
float luma_of(const float* rgb, float (*encode)(float)) {
  float e[3];
  for (int k = 0; k < 3; ++k) e[k] = std::isfinite(rgb[k]) ? encode(rgb[k]) : 0.0f;
  return 0.2126f * e[0] + 0.7152f * e[1] + 0.0722f * e[2];
}

// Display luma of C = I T + R.
cv::Mat composite_luma(ConstImageView photo, const cv::Mat& t, const cv::Mat& r,
                       float (*encode)(float)) {
  cv::Mat l(photo.height, photo.width, CV_32F);
  for (int y = 0; y < photo.height; ++y) {
    const cv::Vec3f* tr = t.ptr<cv::Vec3f>(y);
    const cv::Vec3f* rr = r.ptr<cv::Vec3f>(y);
    float* out = l.ptr<float>(y);
    for (int x = 0; x < photo.width; ++x) {
      const float* p = photo.pixel(x, y);
      float c[3];
      for (int k = 0; k < 3; ++k) c[k] = (std::isfinite(p[k]) ? p[k] : 0.0f) * tr[x][k] + rr[x][k];
      out[x] = luma_of(c, encode);
    }
  }
  return l;
}

// The created-edge pixels and how strong they are: the sum over them of the squared excess of
// the composite's gradient over the larger of twice the photo's and the floor. A round is
// judged by that energy, not by the count alone: a step spread into a ramp is fainter, but on a
// small frame (a guessed step of 0.27 luma in a 120 px frame) its ramp can stay above the floor
// over more pixels than the step covered, and a count-only test dropped every round there.
struct Created {
  cv::Mat mask;
  std::size_t count = 0;
  double energy = 0;
};

Created created_edges(const cv::Mat& photo_strength, const cv::Mat& composite_l) {
  const cv::Mat g = edge_strength(composite_l);
  Created c;
  c.mask = cv::Mat(g.rows, g.cols, CV_8U);
  for (int y = 0; y < g.rows; ++y) {
    const float* gp = photo_strength.ptr<float>(y);
    const float* gc = g.ptr<float>(y);
    std::uint8_t* m = c.mask.ptr<std::uint8_t>(y);
    for (int x = 0; x < g.cols; ++x) {
      const float excess = gc[x] - std::max(kCreatedEdgeRatio * gp[x], kCreatedEdgeFloor);
      m[x] = excess > 0 ? 255 : 0;
      if (excess > 0) {
        ++c.count;
        c.energy += double(excess) * double(excess);
      }
    }
  }
  return c;
}

// Where to soften, 0..1: the created pixels grown by `radius` (a disc), feathered by a Gaussian
// of half of it. A distance transform and box filters (photo/sky_light.h): O(1) a pixel, where a
// dilation by the disc and a direct Gaussian took 2.5 s at 12 MP (radius 80 px).
cv::Mat softening_weight(const cv::Mat& created_mask, int radius) {
  cv::Mat outside, weight;
  cv::bitwise_not(created_mask, outside);
  cv::distanceTransform(outside, weight, cv::DIST_L2, cv::DIST_MASK_PRECISE, CV_32F);
  cv::threshold(weight, weight, radius, 1.0, cv::THRESH_BINARY_INV);  // 1 within the radius
  wide_gaussian_blur(weight, 0.5 * radius);
  return weight;
}

void check(ConstImageView photo, ConstImageView t, ConstImageView r) {
  if (photo.channels < 3)
    throw Error(ErrorCode::invalid_argument, "soften_fog_seams: the photo has " +
                                                 std::to_string(photo.channels) +
                                                 " channel(s), needs 3");
  for (const ConstImageView* v : {&t, &r}) {
    if (v->channels != 3)
      throw Error(ErrorCode::invalid_argument,
                  std::string("soften_fog_seams: ") + (v == &t ? "transmittance" : "inscatter") +
                      " has " + std::to_string(v->channels) + " channel(s), needs 3");
    if (v->width != photo.width || v->height != photo.height)
      throw Error(ErrorCode::size_mismatch,
                  std::string("soften_fog_seams: ") + (v == &t ? "transmittance" : "inscatter") +
                      " is " + std::to_string(v->width) + "x" + std::to_string(v->height) +
                      ", the photo " + std::to_string(photo.width) + "x" +
                      std::to_string(photo.height));
  }
}

}  // namespace

SeamSoftening soften_fog_seams(ConstImageView photo, ImageView transmittance, ImageView inscatter,
                               const SeamDisplay& display) {
  check(photo, transmittance, inscatter);
  SeamSoftening result;
  const int w = photo.width, h = photo.height;
  if (w < 3 || h < 3) return result;

  // Working copies (CV_32FC3); a pixel whose T or R is not finite is held out.
  cv::Mat t(h, w, CV_32FC3), r(h, w, CV_32FC3), photo_l(h, w, CV_32F);
  cv::Mat held(h, w, CV_8U, cv::Scalar(0));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float* tp = transmittance.pixel(x, y);
      const float* rp = inscatter.pixel(x, y);
      bool finite = true;
      for (int k = 0; k < 3; ++k) finite = finite && std::isfinite(tp[k]) && std::isfinite(rp[k]);
      held.at<std::uint8_t>(y, x) = finite ? 0 : 1;
      const float* p = photo.pixel(x, y);
      for (int k = 0; k < 3; ++k) {
        t.at<cv::Vec3f>(y, x)[k] = finite ? tp[k] : 0.0f;
        r.at<cv::Vec3f>(y, x)[k] = finite ? rp[k] : 0.0f;
      }
      photo_l.at<float>(y, x) = luma_of(p, display.photo);
    }
  const cv::Mat photo_strength = edge_strength(photo_l);
  Created created = created_edges(photo_strength, composite_luma(photo, t, r, display.fogged));
  result.created_before = created.count;
  result.created_after = result.created_before;
  if (result.created_before == 0) return result;

  // A pixel held out takes its nearest finite neighbour's T and R for the filter's sake (it is
  // never written back), so no made-up value spreads from it.
  if (cv::countNonZero(held) > 0) {
    std::vector<std::uint8_t> finite_px(std::size_t(w) * h);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) finite_px[std::size_t(y) * w + x] = !held.at<std::uint8_t>(y, x);
    const std::vector<std::int32_t> nearest = nearest_source(w, h, finite_px);
    if (nearest.empty()) return result;  // no finite fog at all
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        if (held.at<std::uint8_t>(y, x)) {
          const std::int32_t n = nearest[std::size_t(y) * w + x];
          t.at<cv::Vec3f>(y, x) = t.at<cv::Vec3f>(n / w, n % w);
          r.at<cv::Vec3f>(y, x) = r.at<cv::Vec3f>(n / w, n % w);
        }
  }

  // The guide without its fine texture (rolling guidance, Zhang et al. 2014: grains of a few
  // pixels go, outlines stay), so the smoother crosses a textured stretch (a far city's
  // rooftops) as it crosses a flat one, and stops at an object's outline.
  cv::Mat guide;
  contrib::rolling_guidance_filter(display_rgb8(photo), guide, -1, kTextureSigmaColor, kTexturePx,
                                   4);
  const cv::Mat t0 = t.clone(), r0 = r.clone();
  const double extent = std::max(2.0, kExtentOfLongerSide * std::max(w, h));
  double lambda = extent * extent;
  const int radius = std::max(2, int(std::lround(extent)));
  for (int round = 0; round < kMaxRounds && result.created_after > 0; ++round) {
    // The band to soften: the created pixels grown by the smoother's extent, feathered over
    // half of it.
    const cv::Mat weight = softening_weight(created.mask, radius);
    cv::Mat t_smooth, r_smooth;
    contrib::fast_global_smoother_filter(guide, t, t_smooth, lambda, kSigmaColor);
    contrib::fast_global_smoother_filter(guide, r, r_smooth, lambda, kSigmaColor);
    cv::Mat t_next = t.clone(), r_next = r.clone();
    for (int y = 0; y < h; ++y) {
      const float* wr = weight.ptr<float>(y);
      const std::uint8_t* cr = created.mask.ptr<std::uint8_t>(y);
      cv::Vec3f* tr = t_next.ptr<cv::Vec3f>(y);
      cv::Vec3f* rr = r_next.ptr<cv::Vec3f>(y);
      const cv::Vec3f* ts = t_smooth.ptr<cv::Vec3f>(y);
      const cv::Vec3f* rs = r_smooth.ptr<cv::Vec3f>(y);
      for (int x = 0; x < w; ++x) {
        const float a = cr[x] ? 1.0f : std::min(1.0f, wr[x]);
        if (a <= 0) continue;
        for (int k = 0; k < 3; ++k) {
          tr[x][k] = std::clamp(tr[x][k] + a * (ts[x][k] - tr[x][k]), 0.0f, 1.0f);
          rr[x][k] = std::max(0.0f, rr[x][k] + a * (rs[x][k] - rr[x][k]));
        }
      }
    }
    // A round that does not weaken the created edges is dropped; the next one smooths harder.
    Created next =
        created_edges(photo_strength, composite_luma(photo, t_next, r_next, display.fogged));
    ++result.rounds;
    if (next.energy < created.energy) {
      t = t_next, r = r_next, created = std::move(next);
      result.created_after = created.count;
    }
    lambda *= 4;
  }

  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      if (held.at<std::uint8_t>(y, x)) continue;
      const cv::Vec3f& tn = t.at<cv::Vec3f>(y, x);
      const cv::Vec3f& rn = r.at<cv::Vec3f>(y, x);
      if (tn == t0.at<cv::Vec3f>(y, x) && rn == r0.at<cv::Vec3f>(y, x)) continue;
      ++result.pixels_changed;
      for (int k = 0; k < 3; ++k) {
        transmittance.at(x, y, k) = tn[k];
        inscatter.at(x, y, k) = rn[k];
      }
    }
  return result;
}

}  // namespace mr::photo
