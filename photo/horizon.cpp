#include "photo/horizon.h"

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <optional>
#include <random>
#include <string>

#include "core/cv_bridge.h"
#include "mr/error.h"
#include "photo/geometry.h"

namespace mr::photo {

namespace {

using V3 = std::array<double, 3>;
constexpr double kDeg = std::numbers::pi / 180.0;

V3 cross(const V3& a, const V3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double dot(const V3& a, const V3& b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
double norm(const V3& a) {
  return std::sqrt(dot(a, a));
}
std::optional<V3> unit(const V3& a) {
  const double n = norm(a);
  if (!(n > 1e-12) || !std::isfinite(n)) return std::nullopt;
  return V3{a[0] / n, a[1] / n, a[2] / n};
}

struct Segment {
  V3 line;        // unit great-circle normal of the segment (normalised image coordinates)
  V3 mid;         // midpoint (a, b, 1)
  double length;  // working-image pixels
};

// Sine of the image angle between the segment and the line from its midpoint to `vp`.
double angle_error_sin(const Segment& s, const V3& vp) {
  const V3 l = cross(s.mid, vp);
  const double n1 = std::hypot(s.line[0], s.line[1]), n2 = std::hypot(l[0], l[1]);
  if (!(n2 > 1e-12) || !(n1 > 1e-12)) return 1;  // the point lies on the segment's midpoint
  return std::abs(s.line[0] * l[1] - s.line[1] * l[0]) / (n1 * n2);
}

// The direction minimising sum w (line . v)^2 over the inliers (smallest eigenvector).
std::optional<V3> refine(const std::vector<Segment>& segs, const std::vector<int>& inliers) {
  cv::Matx33d m = cv::Matx33d::zeros();
  for (int i : inliers) {
    const V3& l = segs[i].line;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) m(r, c) += segs[i].length * l[r] * l[c];
  }
  cv::Mat values, vectors;
  if (!cv::eigen(cv::Mat(m), values, vectors)) return std::nullopt;
  return unit({vectors.at<double>(2, 0), vectors.at<double>(2, 1), vectors.at<double>(2, 2)});
}

std::vector<Segment> detect_segments(ConstImageView photo, const Camera& camera,
                                     const HorizonOptions& o, double& diagonal) {
  // Grey, display-referred (gamma 1/2.2 of the scene-linear mean), 8-bit, at most ~1 MP.
  const cv::Mat src = detail::as_mat(photo);
  cv::Mat grey(src.rows, src.cols, CV_32F);
  const int channels = photo.channels;
  for (int y = 0; y < src.rows; ++y) {
    const float* row = src.ptr<float>(y);
    float* g = grey.ptr<float>(y);
    for (int x = 0; x < src.cols; ++x) {
      const float* p = row + std::ptrdiff_t(x) * channels;
      float v = channels >= 3 ? 0.2126f * p[0] + 0.7152f * p[1] + 0.0722f * p[2] : p[0];
      if (!std::isfinite(v)) v = 0;
      g[x] = std::pow(std::clamp(v, 0.0f, 1.0f), 1 / 2.2f);
    }
  }
  double scale = 1;
  const double area = double(photo.width) * photo.height;
  if (area > o.working_pixels) {
    scale = std::sqrt(o.working_pixels / area);
    cv::resize(grey, grey, cv::Size(), scale, scale, cv::INTER_AREA);
  }
  cv::Mat grey8;
  grey.convertTo(grey8, CV_8U, 255.0);
  diagonal = std::hypot(double(grey8.cols), double(grey8.rows));
  std::vector<cv::Vec4f> lines;
  if (grey8.cols >= 8 && grey8.rows >= 8) {
    cv::Ptr<cv::LineSegmentDetector> lsd = cv::createLineSegmentDetector(cv::LSD_REFINE_STD);
    lsd->detect(grey8, lines);
  }
  const double sx = double(grey8.cols) / photo.width, sy = double(grey8.rows) / photo.height;
  auto normalised = [&](double x, double y) {
    // LSD: pixel centres at integers; to continuous full-resolution coordinates (edges at
    // integers), then normalised.
    return V3{((x + 0.5) / sx - camera.cx) / camera.focal_px,
              ((y + 0.5) / sy - camera.cy) / camera.focal_px, 1};
  };
  std::vector<Segment> segs;
  const double min_len = o.min_segment_fraction * diagonal;
  for (const auto& l : lines) {
    const double len = std::hypot(l[2] - l[0], l[3] - l[1]);
    if (!(len >= min_len)) continue;
    const V3 p = normalised(l[0], l[1]), q = normalised(l[2], l[3]);
    const auto line = unit(cross(p, q));
    if (!line) continue;
    segs.push_back({*line, {(p[0] + q[0]) / 2, (p[1] + q[1]) / 2, 1}, len});
  }
  return segs;
}

// Sequential RANSAC: the strongest vanishing point, its inliers removed, the next, ...
std::vector<VanishingPoint> find_vanishing_points(const std::vector<Segment>& all, double diagonal,
                                                  const HorizonOptions& o) {
  std::vector<VanishingPoint> out;
  std::vector<int> active(all.size());
  for (std::size_t i = 0; i < all.size(); ++i) active[i] = int(i);
  std::mt19937 rng(o.seed);
  const double thr = std::sin(o.inlier_angle_deg * kDeg);
  auto inliers_of = [&](const V3& vp, double& support) {
    std::vector<int> in;
    support = 0;
    for (int i : active)
      if (angle_error_sin(all[i], vp) < thr) in.push_back(i), support += all[i].length;
    support /= diagonal;
    return in;
  };
  while (int(out.size()) < o.max_vanishing_points && active.size() >= 2) {
    std::vector<double> cumulative(active.size());
    double total = 0;
    for (std::size_t k = 0; k < active.size(); ++k) cumulative[k] = total += all[active[k]].length;
    std::uniform_real_distribution<double> pick(0, total);
    auto draw = [&] {
      const auto it = std::lower_bound(cumulative.begin(), cumulative.end(), pick(rng));
      return active[std::min<std::size_t>(it - cumulative.begin(), active.size() - 1)];
    };
    double best_support = 0;
    std::optional<V3> best;
    for (int it = 0; it < o.ransac_iterations; ++it) {
      const int i = draw(), j = draw();
      if (i == j) continue;
      const auto vp = unit(cross(all[i].line, all[j].line));
      if (!vp) continue;
      double support = 0;
      inliers_of(*vp, support);
      if (support > best_support) best_support = support, best = vp;
    }
    if (!best || best_support < o.min_support) break;
    V3 vp = *best;
    double support = 0;
    std::vector<int> in = inliers_of(vp, support);
    for (int iter = 0; iter < 3 && in.size() >= 2; ++iter) {
      const auto r = refine(all, in);
      if (!r) break;
      double s2 = 0;
      std::vector<int> in2 = inliers_of(*r, s2);
      if (s2 < support * 0.95) break;
      vp = *r, support = s2, in = std::move(in2);
    }
    if (support < o.min_support || in.size() < 2) break;
    if (vp[2] < 0 || (vp[2] == 0 && vp[1] < 0)) vp = {-vp[0], -vp[1], -vp[2]};
    out.push_back({vp, support, int(in.size())});
    std::vector<int> rest;
    std::sort(in.begin(), in.end());
    for (int i : active)
      if (!std::binary_search(in.begin(), in.end(), i)) rest.push_back(i);
    active = std::move(rest);
  }
  return out;
}

// The horizon's two points from its great-circle normal n: n . (a, b, 1) = 0.
std::optional<std::array<PixelPoint, 2>> points_of(const Camera& camera, const V3& n) {
  if (!(std::abs(n[1]) > 1e-9)) return std::nullopt;
  std::array<PixelPoint, 2> pts;
  const double xs[2] = {0.0, double(camera.width - 1)};
  for (int i = 0; i < 2; ++i) {
    const double a = (xs[i] + 0.5 - camera.cx) / camera.focal_px;
    const double b = -(n[0] * a + n[2]) / n[1];
    pts[i] = {xs[i], b * camera.focal_px + camera.cy - 0.5};
  }
  try {
    pitch_roll_from_horizon(camera, pts);  // within 45 degrees of level, not far off the image
  } catch (const Error&) {
    return std::nullopt;
  }
  return pts;
}

double strength(double support) {
  return 1 - std::exp(-support / 1.5);
}

}  // namespace

const char* to_string(HorizonCue cue) noexcept {
  switch (cue) {
    case HorizonCue::none:
      return "none";
    case HorizonCue::horizontal_vps:
      return "horizontal_vps";
    case HorizonCue::horizontal_vp_and_zenith:
      return "horizontal_vp_and_zenith";
    case HorizonCue::zenith:
      return "zenith";
    case HorizonCue::horizontal_vp_level:
      return "horizontal_vp_level";
  }
  return "?";
}

AutoHorizon estimate_horizon(ConstImageView photo, const Camera& camera, const HorizonOptions& o) {
  if (photo.width != camera.width || photo.height != camera.height)
    throw Error(ErrorCode::size_mismatch, "horizon: photo is " + std::to_string(photo.width) + "x" +
                                              std::to_string(photo.height) + ", camera is " +
                                              std::to_string(camera.width) + "x" +
                                              std::to_string(camera.height));
  AutoHorizon out;
  {
    CameraPose level;
    out.points = horizon_of_pose(camera, level);
  }
  if (photo.width < 2 || photo.height < 2 || photo.channels < 1) return out;
  double diagonal = 1;
  const std::vector<Segment> segs = detect_segments(photo, camera, o, diagonal);
  out.segments = int(segs.size());
  out.vanishing_points = find_vanishing_points(segs, diagonal, o);

  // Classify: the zenith (vertical) is within 40 degrees of the image's b axis; horizontal
  // vanishing points are within 12 degrees of perpendicular to it (35 degrees of the a-forward
  // plane without a zenith; the focal length may be off, so not tighter).
  const VanishingPoint* zenith = nullptr;
  for (const auto& vp : out.vanishing_points)
    if (std::abs(vp.direction[1]) > std::cos(40 * kDeg) &&
        (!zenith || vp.support > zenith->support))
      zenith = &vp;
  std::vector<const VanishingPoint*> horizontal;
  for (const auto& vp : out.vanishing_points) {
    if (&vp == zenith) continue;
    const bool ok = zenith ? std::abs(dot(vp.direction, zenith->direction)) < std::sin(12 * kDeg)
                           : std::abs(vp.direction[1]) < std::sin(35 * kDeg);
    if (!ok) continue;
    // Not a weak echo of a stronger one: aliased or broken lines of the same family give a
    // second vanishing point near the first (the vanishing points come strongest first).
    bool echo = !horizontal.empty() && vp.support < 0.3 * horizontal.front()->support;
    for (const VanishingPoint* other : horizontal)
      echo |= std::abs(dot(other->direction, vp.direction)) > std::cos(10 * kDeg);
    if (!echo) horizontal.push_back(&vp);
  }
  // Two horizontal vanishing points at least 20 degrees apart (closer ones fix the line badly).
  bool separated = false;
  for (std::size_t i = 0; i < horizontal.size(); ++i)
    for (std::size_t j = i + 1; j < horizontal.size(); ++j)
      separated |=
          std::abs(dot(horizontal[i]->direction, horizontal[j]->direction)) < std::cos(20 * kDeg);
  if (zenith || separated) {
    // The great circle's normal n: least squares over n . d_i = 0 for the horizontal vanishing
    // points and n = z for the zenith, each weighted by its support: the smallest eigenvector
    // of sum w_i d_i d_i^T + w_z (I - z z^T). With the right focal length these agree; with a
    // wrong one the zenith and the horizontal points pull against each other, and the residual
    // lowers the confidence.
    cv::Matx33d m = cv::Matx33d::zeros();
    std::vector<double> supports;
    for (const VanishingPoint* vp : horizontal) {
      const V3& d = vp->direction;
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) m(r, c) += vp->support * d[r] * d[c];
      supports.push_back(vp->support);
    }
    if (zenith) {
      const V3& z = zenith->direction;
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) m(r, c) += zenith->support * ((r == c) - z[r] * z[c]);
      supports.push_back(zenith->support);
    }
    // Evidence: the mean support of the two strongest cues (the only one's for the zenith alone).
    std::sort(supports.rbegin(), supports.rend());
    const double evidence = supports.size() >= 2 ? (supports[0] + supports[1]) / 2 : supports[0];
    cv::Mat values, vectors;
    std::optional<V3> n;
    if (cv::eigen(cv::Mat(m), values, vectors))
      n = unit({vectors.at<double>(2, 0), vectors.at<double>(2, 1), vectors.at<double>(2, 2)});
    if (n) {
      if (auto pts = points_of(camera, *n)) {
        // Lines that give an implausible roll were not verticals or level ones: none of the
        // cues below is trusted then (a level line through a vanishing point of the same lines
        // would be as wrong).
        const double roll_deg = pitch_roll_from_horizon(camera, *pts).roll_deg;
        if (std::abs(roll_deg) > o.max_roll_deg) {
          out.rejected_roll_deg = roll_deg;
          return out;
        }
        double residual = 0;  // largest angle (degrees) between the fit and a cue
        for (const VanishingPoint* vp : horizontal)
          residual =
              std::max(residual, std::asin(std::min(1.0, std::abs(dot(*n, vp->direction)))) / kDeg);
        if (zenith)
          residual = std::max(
              residual, std::acos(std::min(1.0, std::abs(dot(*n, zenith->direction)))) / kDeg);
        double base = 0.5;  // zenith alone: right only with the right focal length
        out.cue = HorizonCue::zenith;
        if (separated) {
          out.cue = HorizonCue::horizontal_vps;
          base = zenith ? 0.9 : 0.75;
        } else if (!horizontal.empty()) {
          out.cue = HorizonCue::horizontal_vp_and_zenith;
          base = 0.7;
        }
        if (residual > 2) base *= residual > 5 ? 0.5 : 0.75;
        out.points = *pts;
        out.confidence = std::max(0.15, base * strength(evidence));
        return out;
      }
    }
  }
  if (!horizontal.empty() && std::abs(horizontal.front()->direction[2]) > 0.2) {
    const V3& d = horizontal.front()->direction;
    if (auto pts = points_of(camera, {0, 1, -d[1] / d[2]})) {
      out.points = *pts;
      out.cue = HorizonCue::horizontal_vp_level;
      out.confidence = std::max(0.12, 0.35 * strength(horizontal.front()->support));
      return out;
    }
  }
  return out;
}

std::optional<FocalFromVanishingPoints> estimate_focal_px(ConstImageView photo,
                                                          const Camera& camera,
                                                          const FocalOptions& fo,
                                                          const HorizonOptions& o) {
  if (photo.width != camera.width || photo.height != camera.height)
    throw Error(ErrorCode::size_mismatch, "focal: photo is " + std::to_string(photo.width) + "x" +
                                              std::to_string(photo.height) + ", camera is " +
                                              std::to_string(camera.width) + "x" +
                                              std::to_string(camera.height));
  if (photo.width < 2 || photo.height < 2 || photo.channels < 1) return std::nullopt;
  double diagonal = 1;
  const std::vector<Segment> segs = detect_segments(photo, camera, o, diagonal);
  const std::vector<VanishingPoint> vps = find_vanishing_points(segs, diagonal, o);
  // Image positions relative to the principal point, pixels; points near infinity (parallel
  // lines in the image) constrain nothing and are left out.
  struct Point {
    double x, y, support;
  };
  std::vector<Point> pts;
  const double limit = 20.0 * std::max(camera.width, camera.height);
  for (const auto& vp : vps) {
    const auto& d = vp.direction;
    if (!(std::abs(d[2]) > 1e-9)) continue;
    const Point p{camera.focal_px * d[0] / d[2], camera.focal_px * d[1] / d[2], vp.support};
    if (std::hypot(p.x, p.y) < limit) pts.push_back(p);
  }
  const double f_min = 0.5 * camera.width / std::tan(0.5 * fo.max_fov_deg * kDeg);
  const double f_max = 0.5 * camera.width / std::tan(0.5 * fo.min_fov_deg * kDeg);
  auto pair_focal = [](const Point& a, const Point& b) -> std::optional<double> {
    const double f2 = -(a.x * b.x + a.y * b.y);
    if (!(f2 > 0)) return std::nullopt;
    return std::sqrt(f2);
  };
  std::optional<FocalFromVanishingPoints> best;
  auto consider = [&](double f, double confidence, int count) {
    if (!(f >= f_min && f <= f_max) || confidence < fo.min_confidence) return;
    if (!best || confidence > best->confidence)
      best = FocalFromVanishingPoints{f, confidence, count};
  };
  for (std::size_t i = 0; i < pts.size(); ++i)
    for (std::size_t j = i + 1; j < pts.size(); ++j)
      for (std::size_t k = j + 1; k < pts.size(); ++k) {
        const auto a = pair_focal(pts[i], pts[j]), b = pair_focal(pts[j], pts[k]),
                   c = pair_focal(pts[i], pts[k]);
        if (!a || !b || !c) continue;
        const double mean = std::cbrt(*a * *b * *c);
        const double spread =
            std::max({std::abs(*a - mean), std::abs(*b - mean), std::abs(*c - mean)}) / mean;
        if (spread > fo.max_spread) continue;
        const double weakest = std::min({pts[i].support, pts[j].support, pts[k].support});
        consider(mean, 0.9 * strength(weakest), 3);
      }
  if (!best && pts.size() >= 2) {
    if (const auto f = pair_focal(pts[0], pts[1]))
      consider(*f, 0.5 * strength(std::min(pts[0].support, pts[1].support)), 2);
  }
  return best;
}

Silhouette find_silhouette(ConstImageView photo, const std::vector<std::uint8_t>& sky,
                           const SilhouetteOptions& options) {
  Silhouette result;
  const int w = photo.width, h = photo.height;
  if (w < 1 || h < 8 || photo.channels < 3 || sky.size() != std::size_t(w) * std::size_t(h))
    return result;
  // Display-referred luma; what is not finite counts as black.
  std::vector<float> luma(std::size_t(w) * h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float* p = photo.pixel(x, y);
      const double l = 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
      luma[std::size_t(y) * w + x] =
          std::isfinite(l) ? float(std::pow(std::clamp(l, 0.0, 1.0), 1 / 2.2)) : 0.0f;
    }
  auto median = [](std::vector<float>& v) {
    if (v.empty()) return 0.0;
    std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(v.size() / 2), v.end());
    return double(v[v.size() / 2]);
  };
  std::vector<float> sky_luma;
  for (std::size_t i = 0; i < luma.size(); ++i)
    if (sky[i]) sky_luma.push_back(luma[i]);
  if (sky_luma.empty()) sky_luma.assign(luma.begin(), luma.begin() + w);
  const double land_max =
      std::min(options.max_land_luma, options.max_land_to_sky * median(sky_luma));
  // A sky too dark to show land against it (a night), or a frame dark along its top as well
  // (a letterboxed film still's bars): no silhouette.
  std::vector<float> top_row(luma.begin(), luma.begin() + w);
  if (!(land_max >= options.min_land_luma) || median(top_row) <= land_max) return result;
  std::vector<int> top;  // per column with land at the bottom: the skyline's row
  std::vector<float> land_luma, above_luma;
  const int band = std::max(2, int(std::ceil(options.edge_band * h)));
  for (int x = 0; x < w; ++x) {
    if (!(luma[std::size_t(h - 1) * w + x] <= land_max)) continue;
    int y = h - 1, gap = 0, skyline = h - 1;
    for (; y >= 0; --y) {
      if (luma[std::size_t(y) * w + x] <= land_max) {
        skyline = y, gap = 0;
      } else if (++gap > options.max_gap_px) {
        break;
      }
    }
    top.push_back(skyline);
    for (int r = skyline; r < h && r < skyline + band; ++r)
      land_luma.push_back(luma[std::size_t(r) * w + x]);
    for (int r = std::max(0, skyline - band); r < skyline; ++r)
      above_luma.push_back(luma[std::size_t(r) * w + x]);
  }
  result.land_columns = double(top.size()) / w;
  if (result.land_columns < options.min_land_columns) return result;
  std::nth_element(top.begin(), top.begin() + std::ptrdiff_t(top.size() / 2), top.end());
  const int skyline = top[top.size() / 2];
  if (h - 1 - skyline < options.min_land_height * h) return result;
  const double land = median(land_luma), above = median(above_luma);
  result.contrast = above / std::max(land, 1e-4);
  if (above < options.min_above_luma || result.contrast < options.min_contrast) return result;
  result.skyline_row = skyline;
  cv::Mat dark(h, w, CV_8U), labels;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      dark.at<std::uint8_t>(y, x) = luma[std::size_t(y) * w + x] <= land_max;
  const int n = cv::connectedComponents(dark, labels, 8, CV_32S);
  std::vector<std::uint8_t> on_bottom(std::size_t(n), 0);
  for (int x = 0; x < w; ++x) on_bottom[std::size_t(labels.at<int>(h - 1, x))] = 1;
  on_bottom[0] = 0;
  result.land.assign(std::size_t(w) * h, 0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      result.land[std::size_t(y) * w + x] = on_bottom[std::size_t(labels.at<int>(y, x))];
  result.column_skyline.assign(std::size_t(w), -1);
  for (int x = 0; x < w; ++x)
    for (int y = 0; y < h; ++y)
      if (result.land[std::size_t(y) * w + x]) {
        result.column_skyline[std::size_t(x)] = y;
        break;
      }
  cv::Mat open(h, w, CV_8U), open_labels;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) open.at<std::uint8_t>(y, x) = !result.land[std::size_t(y) * w + x];
  const int m = cv::connectedComponents(open, open_labels, 8, CV_32S);
  std::vector<std::uint8_t> joined(std::size_t(m), 0);
  for (int y = 0; y < skyline; ++y)
    for (int x = 0; x < w; ++x) joined[std::size_t(open_labels.at<int>(y, x))] = 1;
  joined[0] = 0;
  result.sky_alpha.assign(std::size_t(w) * h, 0.0f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      if (joined[std::size_t(open_labels.at<int>(y, x))])
        result.sky_alpha[i] = float(std::clamp((luma[i] - land_max) / land_max, 0.0, 1.0));
    }
  return result;
}

std::vector<double> receding_skyline(const std::vector<int>& column_skyline,
                                     double reach_fraction) {
  const int w = int(column_skyline.size());
  std::vector<double> top(column_skyline.begin(), column_skyline.end());
  for (int x = 1; x < w; ++x)
    if (top[std::size_t(x)] < 0) top[std::size_t(x)] = top[std::size_t(x - 1)];
  for (int x = w - 2; x >= 0; --x)
    if (top[std::size_t(x)] < 0) top[std::size_t(x)] = top[std::size_t(x + 1)];
  if (w == 0 || top[0] < 0) return {};
  const int reach = std::max(1, int(std::lround(reach_fraction * w)));
  std::vector<double> median(top.size()), out(top.size());
  std::vector<double> window;
  for (int x = 0; x < w; ++x) {
    window.assign(top.begin() + std::max(0, x - reach),
                  top.begin() + std::min(w - 1, x + reach) + 1);
    std::nth_element(window.begin(), window.begin() + std::ptrdiff_t(window.size() / 2),
                     window.end());
    median[std::size_t(x)] = window[window.size() / 2];
  }
  for (int x = 0; x < w; ++x) {
    double sum = 0;
    const int a = std::max(0, x - reach), b = std::min(w - 1, x + reach);
    for (int t = a; t <= b; ++t) sum += median[std::size_t(t)];
    out[std::size_t(x)] = sum / (b - a + 1);
  }
  return out;
}

}  // namespace mr::photo
