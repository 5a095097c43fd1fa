#include "photo/airlight.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <vector>

#include "core/cv_bridge.h"

namespace mr::photo {

namespace {

// Rec.709 / sRGB primaries, D65 white (IEC 61966-2-1).
constexpr double kRgbToXyz[3][3] = {{0.4123908, 0.3575843, 0.1804808},
                                    {0.2126390, 0.7151687, 0.0721923},
                                    {0.0193308, 0.1191948, 0.9505322}};
constexpr double kXyzToRgb[3][3] = {{3.2409699, -1.5373832, -0.4986108},
                                    {-0.9692436, 1.8759675, 0.0415551},
                                    {0.0556301, -0.2039770, 1.0569715}};
// D65 in CIE 1976 u'v' (x 0.3127, y 0.3290).
constexpr double kD65u = 4 * 0.3127 / (-2 * 0.3127 + 12 * 0.3290 + 3);
constexpr double kD65v = 9 * 0.3290 / (-2 * 0.3127 + 12 * 0.3290 + 3);

struct Luv {
  double Y, u, v;
};

// Y and u'v' of a linear Rec.709 colour; black or a colour whose XYZ sum is not positive has
// no chromaticity and is reported as D65.
Luv to_luv(const std::array<float, 3>& rgb) {
  double xyz[3];
  for (int i = 0; i < 3; ++i)
    xyz[i] = kRgbToXyz[i][0] * rgb[0] + kRgbToXyz[i][1] * rgb[1] + kRgbToXyz[i][2] * rgb[2];
  const double d = xyz[0] + 15 * xyz[1] + 3 * xyz[2];
  if (!(d > 0) || !std::isfinite(d)) return {xyz[1], kD65u, kD65v};
  return {xyz[1], 4 * xyz[0] / d, 9 * xyz[1] / d};
}

// CIELAB C*ab of the chromaticity (u', v') at Y = 1, D65 white.
double chroma_ab_of_uv(double u, double v) {
  const double xyz[3] = {9 * u / (4 * v), 1.0, (12 - 3 * u - 20 * v) / (4 * v)};
  double white[3];
  for (int i = 0; i < 3; ++i) white[i] = kRgbToXyz[i][0] + kRgbToXyz[i][1] + kRgbToXyz[i][2];
  auto f = [](double t) {
    constexpr double d = 6.0 / 29.0;
    return t > d * d * d ? std::cbrt(t) : t / (3 * d * d) + 4.0 / 29.0;
  };
  const double fx = f(xyz[0] / white[0]), fy = f(xyz[1] / white[1]), fz = f(xyz[2] / white[2]);
  return std::hypot(500 * (fx - fy), 200 * (fy - fz));
}

}  // namespace

double chroma_ab(const std::array<float, 3>& rgb) {
  const Luv c = to_luv(rgb);
  if (!(c.Y > 0) || !std::isfinite(c.Y)) return 0;
  return chroma_ab_of_uv(c.u, c.v);
}

double delta_uv_from_d65(const std::array<float, 3>& rgb) {
  const Luv c = to_luv(rgb);
  return std::hypot(c.u - kD65u, c.v - kD65v);
}

std::array<float, 3> neutral_fog_colour(const std::array<float, 3>& rgb, const NeutralPrior& prior) {
  const Luv c = to_luv(rgb);
  if (!(c.Y > 0) || !std::isfinite(c.Y)) return {0.0f, 0.0f, 0.0f};  // no light, no colour
  // Unit directions from D65 along the locus, toward 4000 K and toward 10000 K (u'v').
  auto uv_of_xy = [](double x, double y) {
    const double d = -2 * x + 12 * y + 3;
    return std::array<double, 2>{4 * x / d - kD65u, 9 * y / d - kD65v};
  };
  static const std::array<double, 2> warm = [&] {
    auto d = uv_of_xy(0.3805, 0.3768);
    const double n = std::hypot(d[0], d[1]);
    return std::array<double, 2>{d[0] / n, d[1] / n};
  }();
  static const std::array<double, 2> cool = [&] {
    auto d = uv_of_xy(0.2807, 0.2884);
    const double n = std::hypot(d[0], d[1]);
    return std::array<double, 2>{d[0] / n, d[1] / n};
  }();
  const double du = c.u - kD65u, dv = c.v - kD65v;
  const bool is_warm = du * warm[0] + dv * warm[1] > 0;
  const std::array<double, 2>& dir = is_warm ? warm : cool;
  const double along = std::max(0.0, du * dir[0] + dv * dir[1]);
  const double pu = du - along * dir[0], pv = dv - along * dir[1];
  const double across = std::hypot(pu, pv);
  const double along_limit = is_warm ? prior.warm_limit : prior.cool_limit;
  auto soft_limit = [&](double x, double limit) {
    const double knee = prior.knee_fraction * limit;
    if (x <= knee) return x;
    if (!(limit > knee)) return limit;
    return knee + (limit - knee) * std::tanh((x - knee) / (limit - knee));
  };
  const double along2 = soft_limit(along, along_limit), across2 = soft_limit(across, prior.off_locus_limit);
  const double s = across > 0 ? across2 / across : 0.0;
  double du2 = along2 * dir[0] + s * pu, dv2 = along2 * dir[1] + s * pv;
  // The chroma cap: scale the offset toward D65 until C*ab is within prior.max_chroma_ab.
  bool capped = false;
  if (chroma_ab_of_uv(kD65u + du2, kD65v + dv2) > prior.max_chroma_ab) {
    double lo = 0, hi = 1;
    for (int i = 0; i < 40; ++i) {
      const double mid = 0.5 * (lo + hi);
      (chroma_ab_of_uv(kD65u + mid * du2, kD65v + mid * dv2) > prior.max_chroma_ab ? hi : lo) = mid;
    }
    du2 *= lo;
    dv2 *= lo;
    capped = true;
  }
  if (along2 == along && across2 == across && !capped) return rgb;  // a plausible light: as it is
  const double u = kD65u + du2, v = kD65v + dv2;
  // u'v' + Y back to XYZ: X = Y 9u / 4v, Z = Y (12 - 3u - 20v) / 4v.
  const double X = c.Y * 9 * u / (4 * v), Z = c.Y * (12 - 3 * u - 20 * v) / (4 * v);
  const double xyz[3] = {X, c.Y, Z};
  std::array<float, 3> out{};
  for (int i = 0; i < 3; ++i)
    out[i] = float(std::max(
        0.0, kXyzToRgb[i][0] * xyz[0] + kXyzToRgb[i][1] * xyz[1] + kXyzToRgb[i][2] * xyz[2]));
  return out;
}

std::array<float, 3> estimate_airlight_dark_channel(ConstImageView photo,
                                                    const DarkChannelOptions& options) {
  // The estimate does not need every pixel of a 24 MP photo: area-average down to about
  // options.working_pixels first (the window and the 0.1 % are fractions, so they scale).
  cv::Mat small = detail::as_mat(photo);
  const double area = double(photo.width) * photo.height;
  if (area > options.working_pixels) {
    const double f = std::sqrt(options.working_pixels / area);
    cv::resize(small, small, cv::Size(), f, f, cv::INTER_AREA);
  } else {
    small = small.clone();  // continuous
  }
  const int w = small.cols, h = small.rows, channels = small.channels();
  cv::Mat dark(h, w, CV_32F);
  for (int y = 0; y < h; ++y) {
    float* d = dark.ptr<float>(y);
    const float* row = small.ptr<float>(y);
    for (int x = 0; x < w; ++x) {
      const float* p = row + std::ptrdiff_t(x) * channels;
      d[x] = std::min({p[0], p[1], p[2]});
    }
  }
  int window = int(std::lround(options.window_fraction * std::min(w, h)));
  window = std::max(3, window | 1);  // odd, at least 3
  cv::erode(dark, dark, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(window, window)));

  const std::size_t n = std::size_t(w) * h;
  const std::size_t keep = std::max<std::size_t>(1, std::size_t(double(n) * options.brightest_fraction));
  std::vector<std::uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  const float* dk = dark.ptr<float>(0);  // continuous: created above
  std::nth_element(order.begin(), order.begin() + (keep - 1), order.end(),
                   [&](std::uint32_t a, std::uint32_t b) { return dk[a] > dk[b]; });
  double sum[3] = {0, 0, 0};
  for (std::size_t i = 0; i < keep; ++i) {
    const float* p = small.ptr<float>(int(order[i] / w)) + std::ptrdiff_t(order[i] % w) * channels;
    for (int c = 0; c < 3; ++c) sum[c] += p[c];
  }
  const std::array<float, 3> mean{float(sum[0] / keep), float(sum[1] / keep),
                                  float(sum[2] / keep)};
  return options.apply_neutral_prior ? neutral_fog_colour(mean, options.prior) : mean;
}

}  // namespace mr::photo
