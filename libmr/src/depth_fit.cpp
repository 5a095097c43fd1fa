// Relative -> metric depth: scale and shift by iteratively reweighted least squares (Cauchy loss)
// on the relative residual, which is linear in (s, t) for both conventions (mr/depth_fit.h).
#include "mr/depth_fit.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "mr/error.h"

namespace mr {

namespace {

struct Sample {
  double a0, a1;  // residual e = a0 * s + a1 * t - 1
};

std::string pixel_name(int x, int y) { return "(" + std::to_string(x) + ", " + std::to_string(y) + ")"; }

std::string format(double v) {
  char text[32];
  std::snprintf(text, sizeof text, "%.4g", v);
  return text;
}

double median_abs(const std::vector<Sample>& samples, double s, double t, std::vector<double>& scratch) {
  scratch.resize(samples.size());
  for (std::size_t i = 0; i < samples.size(); ++i)
    scratch[i] = std::abs(samples[i].a0 * s + samples[i].a1 * t - 1.0);
  auto mid = scratch.begin() + std::ptrdiff_t(scratch.size() / 2);
  std::nth_element(scratch.begin(), mid, scratch.end());
  return *mid;
}

// Weighted least squares for (s, t) with weights from the residuals at (s0, t0): c <= 0
// unweighted; Cauchy 1 / (1 + (e/c)^2); Tukey's biweight (1 - (e/c)^2)^2 inside |e| < c, else 0.
// False when the system is singular.
enum class Loss { cauchy, tukey };
bool solve(const std::vector<Sample>& samples, double c, double s0, double t0, double& s, double& t,
           Loss loss = Loss::cauchy) {
  double m00 = 0, m01 = 0, m11 = 0, b0 = 0, b1 = 0;
  for (const Sample& q : samples) {
    double w = 1.0;
    if (c > 0) {
      const double e = (q.a0 * s0 + q.a1 * t0 - 1.0) / c;
      if (loss == Loss::cauchy) {
        w = 1.0 / (1.0 + e * e);
      } else {
        w = std::abs(e) < 1 ? (1 - e * e) * (1 - e * e) : 0.0;
        if (w == 0) continue;
      }
    }
    m00 += w * q.a0 * q.a0;
    m01 += w * q.a0 * q.a1;
    m11 += w * q.a1 * q.a1;
    b0 += w * q.a0;
    b1 += w * q.a1;
  }
  const double det = m00 * m11 - m01 * m01;
  if (!(det > 1e-12 * m00 * m11) || !std::isfinite(det)) return false;
  s = (b0 * m11 - b1 * m01) / det;
  t = (m00 * b1 - m01 * b0) / det;
  return std::isfinite(s) && std::isfinite(t);
}

}  // namespace

DepthFit fit_relative_depth(const Image& relative, const Image& reference_distance_m,
                            const DepthFitOptions& options) {
  if (relative.empty() || reference_distance_m.empty())
    throw Error(ErrorCode::invalid_argument, "fit_relative_depth: empty relative or reference map");
  const int w = relative.width(), h = relative.height();
  if (reference_distance_m.width() != w || reference_distance_m.height() != h)
    throw Error(ErrorCode::size_mismatch,
                "fit_relative_depth: relative map is " + std::to_string(w) + "x" + std::to_string(h) +
                    ", reference is " + std::to_string(reference_distance_m.width()) + "x" +
                    std::to_string(reference_distance_m.height()));
  if (options.camera && (options.camera->width != w || options.camera->height != h))
    throw Error(ErrorCode::size_mismatch,
                "fit_relative_depth: relative map is " + std::to_string(w) + "x" + std::to_string(h) +
                    ", camera is " + std::to_string(options.camera->width) + "x" +
                    std::to_string(options.camera->height));
  if (!(options.loss_scale > 0) || !std::isfinite(options.loss_scale))
    throw Error(ErrorCode::invalid_argument, "fit_relative_depth: loss_scale must be positive");
  if (!(options.inlier_threshold > 0) || !std::isfinite(options.inlier_threshold))
    throw Error(ErrorCode::invalid_argument, "fit_relative_depth: inlier_threshold must be positive");
  if (options.max_iterations < 1)
    throw Error(ErrorCode::invalid_argument, "fit_relative_depth: max_iterations must be at least 1");
  if (options.initial_scale.has_value() != options.initial_shift.has_value() ||
      (options.initial_scale && !(std::isfinite(*options.initial_scale) && std::isfinite(*options.initial_shift))))
    throw Error(ErrorCode::invalid_argument,
                "fit_relative_depth: initial_scale and initial_shift go together and must be finite");
  const bool inverse = options.kind == RelativeDepthKind::inverse_depth;
  auto ray_factor = [&](int x, int y) { return options.camera ? options.camera->z_to_distance(x, y) : 1.0; };

  // Validate, count the references, then keep at most ~500k of them (an even stride).
  std::size_t count = 0;
  double r_min = std::numeric_limits<double>::infinity(), r_max = -r_min;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float r = relative.at(x, y, 0), d = reference_distance_m.at(x, y, 0);
      if (!std::isfinite(r))
        throw Error(ErrorCode::invalid_argument,
                    "fit_relative_depth: relative map is not finite at pixel " + pixel_name(x, y));
      if (std::isnan(d) || d < 0)
        throw Error(ErrorCode::invalid_argument, "fit_relative_depth: reference distance " + format(d) +
                                                     " at pixel " + pixel_name(x, y) +
                                                     " (expected > 0, or 0 / +inf for none)");
      if (d > 0 && std::isfinite(d)) {
        ++count;
        r_min = std::min(r_min, double(r));
        r_max = std::max(r_max, double(r));
      }
    }
  const std::size_t min_refs = std::max<std::size_t>(options.min_reference_pixels, 2);
  if (count < min_refs)
    throw Error(ErrorCode::invalid_argument, "fit_relative_depth: " + std::to_string(count) +
                                                 " reference pixels, at least " + std::to_string(min_refs) +
                                                 " needed");
  if (!(r_max - r_min > 1e-9 * std::max(std::abs(r_max), std::abs(r_min))) || r_max == r_min)
    throw Error(ErrorCode::invalid_argument,
                "fit_relative_depth: the relative map does not vary over the reference pixels "
                "(value " + format(r_min) + "): scale and shift are not determined");
  constexpr std::size_t kMaxSamples = 500000;
  const std::size_t stride = (count + kMaxSamples - 1) / kMaxSamples;
  std::vector<Sample> samples;
  samples.reserve(count / stride + 1);
  std::size_t index = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const double d = reference_distance_m.at(x, y, 0);
      if (!(d > 0 && std::isfinite(d))) continue;
      if (index++ % stride != 0) continue;
      const double r = relative.at(x, y, 0), z = d / ray_factor(x, y);
      samples.push_back(inverse ? Sample{r * z, z} : Sample{r / z, 1.0 / z});
    }

  // IRLS with the Cauchy loss. Its scale starts from the residuals' spread (so a bad start or
  // plain least squares is not locked in by tiny weights) and shrinks monotonically to
  // options.loss_scale.
  DepthFit fit;
  double s = 0, t = 0;
  if (options.initial_scale) {
    s = *options.initial_scale;
    t = *options.initial_shift;
  } else if (!solve(samples, 0, 0, 0, s, t)) {
    throw Error(ErrorCode::invalid_argument,
                "fit_relative_depth: the reference pixels do not determine scale and shift");
  }
  std::vector<double> scratch;
  double c = std::numeric_limits<double>::infinity();
  for (int it = 0; it < options.max_iterations; ++it) {
    const double sigma = 1.4826 * median_abs(samples, s, t, scratch);
    const double previous_c = c;
    c = std::min(c, std::max(options.loss_scale, 3.0 * sigma));
    double s1, t1;
    if (!solve(samples, c, s, t, s1, t1))
      throw Error(ErrorCode::invalid_argument,
                  "fit_relative_depth: the reference pixels do not determine scale and shift");
    const double change = std::abs(s1 - s) / std::max(std::abs(s1), 1e-300) +
                          std::abs(t1 - t) / std::max(std::abs(s1) * std::max(std::abs(r_max), std::abs(r_min)), 1e-300);
    s = s1;
    t = t1;
    fit.iterations = it + 1;
    if (change < 1e-10 && c >= previous_c * (1 - 1e-9)) break;
  }
  // Refinement with Tukey's biweight, which gives the outliers no weight at all (the Cauchy loss
  // leaves them a little, which biases the slope when the depth range is narrow). Its cut-off
  // from the residuals' spread at the Cauchy solution; kept only if it stays well posed.
  {
    const double cut = std::max(options.loss_scale, 4.685 * 1.4826 * median_abs(samples, s, t, scratch));
    for (int it = 0; it < options.max_iterations; ++it) {
      double s1, t1;
      if (!solve(samples, cut, s, t, s1, t1, Loss::tukey)) break;
      const double change = std::abs(s1 - s) / std::max(std::abs(s1), 1e-300) +
                            std::abs(t1 - t) / std::max(std::abs(s1) * std::max(std::abs(r_max), std::abs(r_min)), 1e-300);
      s = s1;
      t = t1;
      ++fit.iterations;
      if (change < 1e-10) break;
    }
  }
  if (!(s > 0))
    throw Error(ErrorCode::invalid_argument,
                std::string("fit_relative_depth: fitted scale ") + format(s) + " is not positive: the map is " +
                    (inverse ? "not inverse depth (larger = nearer)" : "not depth (larger = farther)") +
                    ", or the reference contradicts it");
  fit.scale = s;
  fit.shift = t;
  fit.reference_pixels = count;

  // Residuals over all references (not only the kept samples).
  double sum2 = 0;
  scratch.clear();
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const double d = reference_distance_m.at(x, y, 0);
      if (!(d > 0 && std::isfinite(d))) continue;
      const double r = relative.at(x, y, 0), z = d / ray_factor(x, y);
      const double e = inverse ? (s * r + t) * z - 1.0 : (s * r + t) / z - 1.0;
      scratch.push_back(std::abs(e));
      if (std::abs(e) < options.inlier_threshold) {
        ++fit.inliers;
        sum2 += e * e;
      }
    }
  fit.rms_inlier_residual = fit.inliers ? std::sqrt(sum2 / double(fit.inliers)) : 0.0;
  auto mid = scratch.begin() + std::ptrdiff_t(scratch.size() / 2);
  std::nth_element(scratch.begin(), mid, scratch.end());
  fit.median_abs_residual = *mid;

  fit.distance_m = Image::uninitialized(w, h, 1, {"Z"});
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const double q = s * relative.at(x, y, 0) + t;
      const double z = inverse ? 1.0 / q : q;
      float& out = fit.distance_m.at(x, y, 0);
      if (q > 0 && std::isfinite(z)) {
        out = float(z * ray_factor(x, y));
        if (!std::isfinite(out) || out <= 0) out = std::numeric_limits<float>::infinity();
      } else {
        out = std::numeric_limits<float>::infinity();
      }
      if (std::isinf(out)) ++fit.non_positive_pixels;
    }
  return fit;
}

}  // namespace mr
