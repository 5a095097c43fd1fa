#include "photo/fog_upsample.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <vector>

#include "mr/error.h"
#include "photo/composite.h"

namespace mr::photo {

namespace {

// The guide: each channel log-encoded, 0 at black and 1 at scene-linear 1 (about how a display
// spaces them: 18 % grey at 0.48), finite above 1 (an HDR photo's highlights keep their edges).
constexpr float kGuideGain = 16.0f;
float guide_value(float linear) {
  if (!(linear > 0.0f)) return 0.0f;  // also NaN
  if (!std::isfinite(linear)) return 2.0f;
  return std::log1p(kGuideGain * linear) / std::log1p(kGuideGain);
}

float finite_or_zero(float v) {
  return std::isfinite(v) ? v : 0.0f;
}

std::string size_text(int w, int h) {
  return std::to_string(w) + "x" + std::to_string(h);
}

void check(ConstImageView working_photo, ConstImageView working_t, ConstImageView working_r,
           ConstImageView photo, ImageView composite, ImageView t, ImageView r) {
  if (working_photo.channels < 3 || photo.channels < 3 || working_t.channels != 3 ||
      working_r.channels != 3)
    throw Error(ErrorCode::invalid_argument,
                "upsample_fog: the photos need >= 3 channels, T and R exactly 3");
  for (ConstImageView v : {working_t, working_r})
    if (v.width != working_photo.width || v.height != working_photo.height)
      throw Error(ErrorCode::size_mismatch,
                  "upsample_fog: working T or R is " + size_text(v.width, v.height) +
                      ", the working photo " +
                      size_text(working_photo.width, working_photo.height));
  if (working_photo.width > photo.width || working_photo.height > photo.height ||
      working_photo.width < 1 || working_photo.height < 1)
    throw Error(ErrorCode::invalid_argument,
                "upsample_fog: the working size " +
                    size_text(working_photo.width, working_photo.height) +
                    " is not within the photo's " + size_text(photo.width, photo.height));
  auto same = [&](ConstImageView v, int channels, const char* what) {
    if (v.data == nullptr) return;
    if (v.width != photo.width || v.height != photo.height || v.channels != channels)
      throw Error(ErrorCode::size_mismatch, std::string("upsample_fog: the ") + what + " is " +
                                                size_text(v.width, v.height) + ", the photo " +
                                                size_text(photo.width, photo.height));
  };
  if (composite.data == nullptr)
    throw Error(ErrorCode::invalid_argument, "upsample_fog: no composite to write");
  same(composite, photo.channels, "composite");
  same(t, 3, "transmittance");
  same(r, 3, "inscatter");
}

// Where a full-size row or column falls on the working grid: the two working pixels around its
// centre and the weight of the second.
struct Tap {
  int lo, hi;
  float w;
};
std::vector<Tap> taps(int full, int working) {
  std::vector<Tap> out(full);
  const double s = double(working) / full;
  for (int i = 0; i < full; ++i) {
    const double f = std::clamp((i + 0.5) * s - 0.5, 0.0, double(working - 1));
    const int lo = std::min(int(f), working - 1);
    out[i] = {lo, std::min(lo + 1, working - 1), float(f - lo)};
  }
  return out;
}

}  // namespace

void upsample_fog(ConstImageView working_photo, ConstImageView working_t, ConstImageView working_r,
                  ConstImageView photo, ImageView composite, ImageView transmittance,
                  ImageView inscatter, const FogUpsampleOptions& options) {
  check(working_photo, working_t, working_r, photo, composite, transmittance, inscatter);
  const int w = working_photo.width, h = working_photo.height;

  // Working-size guide and targets. T is one target where its channels agree everywhere (grey
  // fog: the usual case, a third less to fit and hold).
  cv::Mat guide(h, w, CV_32FC3);
  bool grey_t = true;
  for (int y = 0; y < h && grey_t; ++y)
    for (int x = 0; x < w; ++x) {
      const float* t = working_t.pixel(x, y);
      if (!(t[0] == t[1] && t[1] == t[2])) {
        grey_t = false;
        break;
      }
    }
  const int n_targets = grey_t ? 4 : 6;  // T (1 or 3 channels), then R's 3
  std::vector<cv::Mat> target(n_targets);
  for (cv::Mat& m : target) m.create(h, w, CV_32F);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float* p = working_photo.pixel(x, y);
      guide.at<cv::Vec3f>(y, x) =
          cv::Vec3f(guide_value(p[0]), guide_value(p[1]), guide_value(p[2]));
      const float* t = working_t.pixel(x, y);
      const float* r = working_r.pixel(x, y);
      int k = 0;
      for (int c = 0; c < (grey_t ? 1 : 3); ++c) target[k++].at<float>(y, x) = finite_or_zero(t[c]);
      for (int c = 0; c < 3; ++c) target[k++].at<float>(y, x) = finite_or_zero(r[c]);
    }

  // The local linear models (He et al.'s guided filter with a colour guide): in each window
  // q = a . I + b, a = (Sigma + eps U)^-1 cov(I, p), b = mean(p) - a . mean(I); then each
  // pixel's coefficients averaged over the windows that hold it.
  const cv::Size box(2 * options.radius + 1, 2 * options.radius + 1);
  auto mean = [&](const cv::Mat& m) {
    cv::Mat out;
    cv::boxFilter(m, out, CV_32F, box, cv::Point(-1, -1), true, cv::BORDER_REFLECT);
    return out;
  };
  std::vector<cv::Mat> g(3);
  cv::split(guide, g);
  std::array<cv::Mat, 3> mean_i;
  for (int c = 0; c < 3; ++c) mean_i[c] = mean(g[c]);
  // Sigma's six distinct entries: rr rg rb gg gb bb.
  const int pairs[6][2] = {{0, 0}, {0, 1}, {0, 2}, {1, 1}, {1, 2}, {2, 2}};
  std::array<cv::Mat, 6> sigma;
  for (int e = 0; e < 6; ++e) {
    const int i = pairs[e][0], j = pairs[e][1];
    sigma[e] = mean(g[i].mul(g[j])) - mean_i[i].mul(mean_i[j]);
  }
  // Per target: 4 coefficient planes (a_r, a_g, a_b, b), averaged.
  std::vector<std::array<cv::Mat, 4>> coef(n_targets);
  const float eps = float(options.epsilon);
  for (int k = 0; k < n_targets; ++k) {
    const cv::Mat mean_p = mean(target[k]);
    std::array<cv::Mat, 3> cov;
    for (int c = 0; c < 3; ++c) cov[c] = mean(g[c].mul(target[k])) - mean_i[c].mul(mean_p);
    std::array<cv::Mat, 4> ab;
    for (cv::Mat& m : ab) m.create(h, w, CV_32F);
    tbb::parallel_for(tbb::blocked_range<int>(0, h), [&](const tbb::blocked_range<int>& rows) {
      for (int y = rows.begin(); y < rows.end(); ++y)
        for (int x = 0; x < w; ++x) {
          const double rr = sigma[0].at<float>(y, x) + eps, rg = sigma[1].at<float>(y, x),
                       rb = sigma[2].at<float>(y, x), gg = sigma[3].at<float>(y, x) + eps,
                       gb = sigma[4].at<float>(y, x), bb = sigma[5].at<float>(y, x) + eps;
          // The symmetric 3x3 inverse by cofactors (eps > 0 keeps it positive definite).
          const double c00 = gg * bb - gb * gb, c01 = gb * rb - rg * bb, c02 = rg * gb - gg * rb;
          const double c11 = rr * bb - rb * rb, c12 = rb * rg - rr * gb, c22 = rr * gg - rg * rg;
          const double det = rr * c00 + rg * c01 + rb * c02;
          const double v0 = cov[0].at<float>(y, x), v1 = cov[1].at<float>(y, x),
                       v2 = cov[2].at<float>(y, x);
          const double a0 = (c00 * v0 + c01 * v1 + c02 * v2) / det;
          const double a1 = (c01 * v0 + c11 * v1 + c12 * v2) / det;
          const double a2 = (c02 * v0 + c12 * v1 + c22 * v2) / det;
          ab[0].at<float>(y, x) = float(a0);
          ab[1].at<float>(y, x) = float(a1);
          ab[2].at<float>(y, x) = float(a2);
          ab[3].at<float>(y, x) =
              float(mean_p.at<float>(y, x) - a0 * mean_i[0].at<float>(y, x) -
                    a1 * mean_i[1].at<float>(y, x) - a2 * mean_i[2].at<float>(y, x));
        }
    });
    for (int c = 0; c < 4; ++c) coef[k][c] = mean(ab[c]);
  }
  guide.release();
  for (cv::Mat& m : g) m.release();

  // Full size: the coefficients bilinearly at each pixel, applied to its own guide colour, the
  // result kept within its four working neighbours' values.
  const std::vector<Tap> tx = taps(photo.width, w), ty = taps(photo.height, h);
  tbb::parallel_for(
      tbb::blocked_range<int>(0, photo.height), [&](const tbb::blocked_range<int>& rows) {
        for (int y = rows.begin(); y < rows.end(); ++y) {
          const Tap row = ty[y];
          for (int x = 0; x < photo.width; ++x) {
            const Tap col = tx[x];
            const float* p = photo.pixel(x, y);
            const float i0 = guide_value(p[0]), i1 = guide_value(p[1]), i2 = guide_value(p[2]);
            const float w00 = (1 - row.w) * (1 - col.w), w01 = (1 - row.w) * col.w,
                        w10 = row.w * (1 - col.w), w11 = row.w * col.w;
            float q[6];
            for (int k = 0; k < n_targets; ++k) {
              auto at = [&](const cv::Mat& m) {
                return w00 * m.at<float>(row.lo, col.lo) + w01 * m.at<float>(row.lo, col.hi) +
                       w10 * m.at<float>(row.hi, col.lo) + w11 * m.at<float>(row.hi, col.hi);
              };
              const float v =
                  at(coef[k][0]) * i0 + at(coef[k][1]) * i1 + at(coef[k][2]) * i2 + at(coef[k][3]);
              const cv::Mat& m = target[k];
              const float a = m.at<float>(row.lo, col.lo), b = m.at<float>(row.lo, col.hi),
                          c = m.at<float>(row.hi, col.lo), d = m.at<float>(row.hi, col.hi);
              q[k] = std::clamp(v, std::min({a, b, c, d}), std::max({a, b, c, d}));
            }
            const float t[3] = {q[0], grey_t ? q[0] : q[1], grey_t ? q[0] : q[2]};
            const float* r = q + (grey_t ? 1 : 3);
            composite_pixel(p, t, r, composite.pixel(x, y), photo.channels);
            if (transmittance.data) std::copy(t, t + 3, transmittance.pixel(x, y));
            if (inscatter.data) std::copy(r, r + 3, inscatter.pixel(x, y));
          }
        }
      });
}

}  // namespace mr::photo
