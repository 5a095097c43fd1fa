// Single-photo estimation facade (mr/estimate.h) over photo/geometry and photo/illumination.
#include "mr/estimate.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <numbers>
#include <optional>
#include <vector>

#include "cv_bridge.h"
#include "mr/error.h"
#include "photo/airlight.h"
#include "photo/geometry.h"
#include "photo/horizon.h"
#include "photo/illumination.h"
#include "photo/lamps.h"
#include "photo/sky_mask.h"

namespace mr {

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

std::string fmt(const char* format, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

void check_camera(const Camera& camera) {
  if (camera.width <= 0 || camera.height <= 0 || !(camera.focal_px > 0) ||
      !std::isfinite(camera.focal_px) || !std::isfinite(camera.cx) || !std::isfinite(camera.cy))
    throw Error(ErrorCode::invalid_argument,
                "estimate: invalid camera (" + std::to_string(camera.width) + "x" +
                    std::to_string(camera.height) + ", focal " + fmt("%g", camera.focal_px) + " px)");
}

// Mean-free helper: the photo's RGB pixels inside a polygon (pixel centres, even-odd rule).
std::vector<std::array<float, 3>> pixels_in(const Image& photo, const std::vector<PixelPoint>& poly) {
  double x0 = 1e300, y0 = 1e300, x1 = -1e300, y1 = -1e300;
  for (const auto& p : poly) {
    x0 = std::min(x0, p[0]), x1 = std::max(x1, p[0]);
    y0 = std::min(y0, p[1]), y1 = std::max(y1, p[1]);
  }
  std::vector<std::array<float, 3>> out;
  const int xa = std::max(0, int(std::floor(x0))), xb = std::min(photo.width() - 1, int(std::ceil(x1)));
  const int ya = std::max(0, int(std::floor(y0))), yb = std::min(photo.height() - 1, int(std::ceil(y1)));
  for (int y = ya; y <= yb; ++y)
    for (int x = xa; x <= xb; ++x)
      if (photo::inside_polygon(poly, x, y))
        out.push_back({photo.at(x, y, 0), photo.at(x, y, 1), photo.at(x, y, 2)});
  return out;
}

// Overcast fall-back: the sky radiance is taken from the sky pixels only when the automatic
// sky mask found at least this many of them and this fraction of the image (fewer: a sliver
// whose colour is mostly edge, haze or a bright facade; mr fog then uses the dark channel prior).
constexpr std::size_t kMinOvercastSkyPixels = 64;
constexpr double kMinOvercastSkyFraction = 0.01;

// Per-channel median of the photo (scene-linear RGB) over the pixels where the distance map is
// +inf (the sky), over at most about a million of them (an even stride); non-finite values are
// skipped, negative medians clamped to 0. The median ignores birds, wires and a bright sun halo
// up to half the sky.
Rgb median_sky_radiance(const Image& photo, const Image& distance_m) {
  std::size_t count = 0;
  for (const float d : distance_m.pixels()) count += std::isinf(d) && d > 0;
  const std::size_t stride = std::max<std::size_t>(1, count / 1'000'000 + (count % 1'000'000 != 0));
  std::array<std::vector<float>, 3> values;
  for (auto& v : values) v.reserve(count / stride + 1);
  std::size_t k = 0;
  for (int y = 0; y < photo.height(); ++y)
    for (int x = 0; x < photo.width(); ++x) {
      const float d = distance_m.at(x, y, 0);
      if (!(std::isinf(d) && d > 0) || k++ % stride != 0) continue;
      for (int c = 0; c < 3; ++c)
        if (const float v = photo.at(x, y, c); std::isfinite(v)) values[c].push_back(v);
    }
  Rgb out{0, 0, 0};
  for (int c = 0; c < 3; ++c) {
    auto& v = values[c];
    if (v.empty()) continue;
    auto mid = v.begin() + std::ptrdiff_t(v.size() / 2);
    std::nth_element(v.begin(), mid, v.end());
    float m = *mid;
    if (v.size() % 2 == 0) m = 0.5f * (m + *std::max_element(v.begin(), mid));
    out[c] = std::max(0.0f, m);
  }
  return out;
}

}  // namespace

const char* to_string(EstimateSource source) noexcept {
  switch (source) {
    case EstimateSource::annotations:
      return "annotations";
    case EstimateSource::known_length:
      return "known_length";
    case EstimateSource::fallback:
      return "fallback";
    case EstimateSource::horizontal_vps:
      return "horizontal_vps";
    case EstimateSource::horizontal_vp_and_zenith:
      return "horizontal_vp_and_zenith";
    case EstimateSource::zenith:
      return "zenith";
    case EstimateSource::horizontal_vp_level:
      return "horizontal_vp_level";
  }
  return "?";
}

CameraPose pose_from_horizon(const Camera& camera, const std::array<PixelPoint, 2>& horizon,
                             double camera_height_m) {
  check_camera(camera);
  if (!(camera_height_m > 0) || !std::isfinite(camera_height_m))
    throw Error(ErrorCode::invalid_argument,
                "/camera_height_m: must be > 0, found " + fmt("%g", camera_height_m));
  const photo::PitchRoll pr = photo::pitch_roll_from_horizon(camera, horizon);
  CameraPose pose;
  pose.position_m = {0, camera_height_m, 0};
  pose.yaw_deg = 0;
  pose.pitch_deg = pr.pitch_deg;
  pose.roll_deg = pr.roll_deg;
  return pose;
}

namespace {

EstimateSource source_of(photo::HorizonCue cue) {
  switch (cue) {
    case photo::HorizonCue::horizontal_vps:
      return EstimateSource::horizontal_vps;
    case photo::HorizonCue::horizontal_vp_and_zenith:
      return EstimateSource::horizontal_vp_and_zenith;
    case photo::HorizonCue::zenith:
      return EstimateSource::zenith;
    case photo::HorizonCue::horizontal_vp_level:
      return EstimateSource::horizontal_vp_level;
    case photo::HorizonCue::none:
      break;
  }
  return EstimateSource::fallback;
}

GeometryEstimate geometry(const Image* photo, const Camera& camera, const Annotations& annotations,
                          const EstimateOptions& options) {
  check_camera(camera);
  validate_annotations(annotations, "");
  const bool automatic = photo && options.automatic;
  if (photo && (photo->width() != camera.width || photo->height() != camera.height))
    throw Error(ErrorCode::size_mismatch,
                "estimate: photo is " + std::to_string(photo->width()) + "x" +
                    std::to_string(photo->height()) + ", camera is " + std::to_string(camera.width) +
                    "x" + std::to_string(camera.height));
  GeometryEstimate g;
  g.pose.position_m = {0, 1, 0};
  std::optional<photo::AutoHorizon> auto_horizon;
  if (!annotations.horizon && automatic) {
    auto_horizon = photo::estimate_horizon(photo->view(), camera);
    if (auto_horizon->cue == photo::HorizonCue::none) auto_horizon.reset();
  }
  if (annotations.horizon) {
    g.pose = pose_from_horizon(camera, *annotations.horizon, 1.0);
    g.horizon_source = EstimateSource::annotations;
    g.confidence = 1;
  } else if (auto_horizon) {
    g.pose = pose_from_horizon(camera, auto_horizon->points, 1.0);
    g.horizon_source = source_of(auto_horizon->cue);
    g.confidence = auto_horizon->confidence;
  } else {
    g.pose.pitch_deg = g.pose.roll_deg = 0;  // level: the horizon through the principal point
    g.horizon_source = EstimateSource::fallback;
    g.confidence = 0.1;
  }
  double height = options.default_camera_height_m;
  g.height_source = EstimateSource::fallback;
  if (annotations.camera_height_m) {
    height = *annotations.camera_height_m;
    g.height_source = EstimateSource::annotations;
  } else if (annotations.known_length) {
    height = photo::camera_height_from_known_length(camera, g.pose, *annotations.known_length);
    g.height_source = EstimateSource::known_length;
  }
  if (!(height > 0) || !std::isfinite(height))
    throw Error(ErrorCode::invalid_argument,
                "default_camera_height_m: must be > 0, found " + fmt("%g", height));
  g.pose.position_m = {0, height, 0};
  g.horizon = photo::horizon_of_pose(camera, g.pose);
  photo::DistanceMap map = photo::distance_map(camera, g.pose, annotations);
  g.distance_m = std::move(map.distance_m);
  g.sky_pixels = map.counts[int(photo::Coverage::sky)];
  g.ground_pixels = map.counts[int(photo::Coverage::ground)];
  g.plane_pixels = map.counts[int(photo::Coverage::plane)];
  g.hint_pixels = map.counts[int(photo::Coverage::hint)];
  if (!automatic) return g;

  // The automatic sky: carve it out of the planes; what is above the horizon and not sky
  // becomes the far billboard, and so does the ground behind it.
  const photo::SkyMask mask = photo::estimate_sky_mask(photo->view(), g.horizon);
  g.sky_from_mask = true;
  const int w = camera.width, h = camera.height;
  const double depression = options.billboard_depression_deg;
  if (!(depression > 0 && depression < 90))
    throw Error(ErrorCode::invalid_argument,
                "billboard_depression_deg: must be in (0, 90), found " + fmt("%g", depression));
  const double forward = height / std::tan(depression * kDeg);
  const Vec3 f = g.pose.axes()[0];
  const double fl = std::hypot(f.x, f.z);
  const Vec3 fwd{f.x / fl, 0, f.z / fl};  // the camera's horizontal viewing direction
  auto billboard = [&](int x, int y) {
    const Vec3 d = g.pose.ray_direction(camera, x, y);
    const double along = d.x * fwd.x + d.z * fwd.z;
    return float(forward / std::max(along, 0.05));  // rays nearly sideways: 20 x forward at most
  };
  const double slope = (g.horizon[1][1] - g.horizon[0][1]) / std::max(1.0, g.horizon[1][0] - g.horizon[0][0]);
  std::vector<std::uint8_t> billboard_above(std::size_t(w), 0);  // the column's structure reaches the horizon
  std::size_t counts[5] = {0, 0, 0, 0, 0};  // sky, ground, plane, hint, billboard
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      float& d = g.distance_m.at(x, y, 0);
      int cov = int(map.coverage[i]);
      if (mask.sky[i] && map.coverage[i] == photo::Coverage::plane) {
        d = std::numeric_limits<float>::infinity(), cov = int(photo::Coverage::sky);
      } else if (!mask.sky[i] && map.coverage[i] == photo::Coverage::sky) {
        d = billboard(x, y), cov = 4;
      } else if (map.coverage[i] == photo::Coverage::ground && billboard_above[std::size_t(x)]) {
        const float b = billboard(x, y);
        if (b < d) d = b, cov = 4;
      }
      ++counts[cov];
      // The pixel just above the horizon in this column decides whether a billboard stands there.
      const double yh = g.horizon[0][1] + (x - g.horizon[0][0]) * slope;
      if (y < yh && y + 1 >= yh) billboard_above[std::size_t(x)] = cov == 4;
    }
  }
  g.sky_pixels = counts[0];
  g.ground_pixels = counts[1];
  g.plane_pixels = counts[2];
  g.hint_pixels = counts[3];
  g.billboard_pixels = counts[4];
  return g;
}

}  // namespace

GeometryEstimate estimate_geometry(const Camera& camera, const Annotations& annotations,
                                   const EstimateOptions& options) {
  return geometry(nullptr, camera, annotations, options);
}

GeometryEstimate estimate_geometry(const Image& photo, const Camera& camera,
                                   const Annotations& annotations, const EstimateOptions& options) {
  return geometry(&photo, camera, annotations, options);
}

SceneEstimate estimate_scene(const Image& photo, const Camera& camera,
                             const Annotations& annotations, const EstimateOptions& options) {
  check_camera(camera);
  if (photo.width() != camera.width || photo.height() != camera.height)
    throw Error(ErrorCode::size_mismatch,
                "estimate: photo is " + std::to_string(photo.width()) + "x" +
                    std::to_string(photo.height()) + ", camera is " + std::to_string(camera.width) +
                    "x" + std::to_string(camera.height));
  if (photo.channels() < 3)
    throw Error(ErrorCode::invalid_argument,
                "estimate: the photo has " + std::to_string(photo.channels()) +
                    " channel(s); RGB is needed");
  SceneEstimate est;
  est.geometry = estimate_geometry(photo, camera, annotations, options);
  const GeometryEstimate& g = est.geometry;
  est.scene.pose = g.pose;
  const char* horizon_how =
      g.horizon_source == EstimateSource::annotations      ? "annotated"
      : g.horizon_source == EstimateSource::horizontal_vps ? "automatic, through two horizontal vanishing points"
      : g.horizon_source == EstimateSource::horizontal_vp_and_zenith
          ? "automatic, from a horizontal and the vertical vanishing point"
      : g.horizon_source == EstimateSource::zenith ? "automatic, from the vertical vanishing point"
      : g.horizon_source == EstimateSource::horizontal_vp_level
          ? "automatic, level through a horizontal vanishing point"
      : options.automatic ? "not annotated, no usable lines; assumed level through the image centre"
                          : "not annotated; assumed level through the image centre";
  est.notes.push_back(std::string("horizon: ") + horizon_how + " (" + to_string(g.horizon_source) + ")" +
                      ", pitch " + fmt("%.2f", g.pose.pitch_deg) + " deg, roll " +
                      fmt("%.2f", g.pose.roll_deg) + " deg, confidence " + fmt("%.2f", g.confidence));
  est.notes.push_back(std::string("camera height: ") + fmt("%.3f", g.pose.position_m.y) + " m (" +
                      (g.height_source == EstimateSource::annotations
                           ? "annotated"
                           : g.height_source == EstimateSource::known_length ? "from the known length"
                                                                             : "default") +
                      ")");
  const double n = double(photo.width()) * photo.height();
  est.notes.push_back("depth: " + fmt("%.1f", 100.0 * g.ground_pixels / n) + " % ground, " +
                      fmt("%.1f", 100.0 * g.plane_pixels / n) + " % planes, " +
                      fmt("%.1f", 100.0 * g.hint_pixels / n) + " % hints, " +
                      fmt("%.1f", 100.0 * g.sky_pixels / n) + " % sky" +
                      (g.sky_from_mask ? " (automatic sky mask), " + fmt("%.1f", 100.0 * g.billboard_pixels / n) +
                                             " % far billboard at " +
                                             fmt("%.0f", g.pose.position_m.y /
                                                             std::tan(options.billboard_depression_deg * kDeg)) +
                                             " m"
                                       : std::string()));

  if (!annotations.shadow_pairs.empty()) {
    std::vector<photo::ShadowPair> pairs;
    for (const auto& p : annotations.shadow_pairs)
      pairs.push_back({p.caster_top, p.caster_foot, p.shadow_tip});
    photo::SunFit fit;
    try {
      fit = photo::fit_sun_direction(pairs, camera, g.pose);
    } catch (const Error& e) {
      throw Error(e.code(), std::string("/shadow_pairs: ") + e.what());
    }
    SunEstimate sun;
    sun.direction_to_sun = fit.direction_to_sun;
    sun.azimuth_deg = fit.azimuth_deg;
    sun.elevation_deg = fit.elevation_deg;
    sun.rms_residual_deg = fit.rms_residual_deg;
    sun.median_residual_px = fit.median_residual_px;
    est.sun = sun;
    Sun s;
    s.direction_to_sun = fit.direction_to_sun;
    est.notes.push_back("sun: from " + std::to_string(pairs.size()) + " shadow pair(s), azimuth " +
                        fmt("%.1f", fit.azimuth_deg) + " deg, elevation " +
                        fmt("%.1f", fit.elevation_deg) + " deg, residual " +
                        fmt("%.2f", fit.rms_residual_deg) + " deg RMS, " +
                        fmt("%.2f", fit.median_residual_px) + " px median");
    if (!annotations.sunlit_patch.empty()) {
      photo::SunSkyPatches patches;
      try {
        patches.lit = photo::PatchStats::from_pixels(pixels_in(photo, annotations.sunlit_patch));
      } catch (const Error& e) {
        throw Error(e.code(), std::string("/sunlit_patch: ") + e.what());
      }
      try {
        patches.shadowed = photo::PatchStats::from_pixels(pixels_in(photo, annotations.shadowed_patch));
      } catch (const Error& e) {
        throw Error(e.code(), std::string("/shadowed_patch: ") + e.what());
      }
      patches.direction_to_sun = fit.direction_to_sun;
      photo::SunSkyRatio ratio;
      try {
        ratio = photo::fit_sun_sky_ratio(patches);
      } catch (const Error& e) {
        throw Error(e.code(), std::string("/sunlit_patch, /shadowed_patch: ") + e.what());
      }
      const std::array<float, 3> sky = photo::estimate_airlight_dark_channel(photo.view());
      est.scene.lighting.sky_radiance = Rgb{sky[0], sky[1], sky[2]};
      for (int c = 0; c < 3; ++c)
        s.irradiance[c] = float(ratio.ratio_rgb[c] * std::numbers::pi * sky[c]);
      est.notes.push_back("sun/sky: E_sun / (pi L_sky) = " + fmt("%.2f", ratio.ratio) + " +- " +
                          fmt("%.2f", ratio.ratio_sigma) +
                          "; sky radiance from the photo (dark channel prior)");
    }
    est.scene.lighting.sun = s;
  } else {
    est.notes.push_back("sun: no shadow pairs; sky light only (overcast)");
    // Overcast fall-back (issue 4 item 5): the sky light is what the sky pixels show.
    const std::size_t min_sky = std::max<std::size_t>(
        kMinOvercastSkyPixels, std::size_t(std::ceil(kMinOvercastSkyFraction * n)));
    if (g.sky_from_mask && g.sky_pixels >= min_sky) {
      const Rgb sky = median_sky_radiance(photo, g.distance_m);
      est.scene.lighting.sky_radiance = sky;
      est.notes.push_back("sky: radiance from " + std::to_string(g.sky_pixels) +
                          " sky pixels (overcast), median " + fmt("%.4g", sky[0]) + " " +
                          fmt("%.4g", sky[1]) + " " + fmt("%.4g", sky[2]));
    } else {
      est.notes.push_back(
          std::string("sky: ") +
          (g.sky_from_mask ? "only " + std::to_string(g.sky_pixels) + " sky pixels (fewer than " +
                                 std::to_string(min_sky) + ")"
                           : std::string("no automatic sky mask")) +
          "; radiance left to mr fog (dark channel prior)");
    }
  }

  if (!annotations.lamps.empty()) {
    // Interior lamps (issue 4 item 5): lifted with the distance map, intensities fitted to the
    // shading of the lamp patches (photo/lamps.h states the model).
    std::vector<photo::LampMark> marks;
    for (const auto& l : annotations.lamps) marks.push_back({l.pixel, l.offset_m, l.color});
    std::vector<photo::LampPatch> patches;
    for (const auto& p : annotations.lamp_patches) {
      photo::LampPatch patch;
      patch.polygon = p.polygon;
      if (p.albedo) patch.albedo = *p.albedo;
      patches.push_back(std::move(patch));
    }
    photo::LampFit fit;
    try {
      fit = photo::fit_lamps(photo, g.distance_m, camera, g.pose, marks, patches);
    } catch (const Error& e) {
      throw Error(e.code(), std::string("/lamps, /lamp_patches: ") + e.what());
    }
    for (std::size_t i = 0; i < marks.size(); ++i) {
      Lamp lamp;
      lamp.position_m = fit.positions_m[i];
      const auto& I = fit.intensity_per_sr[i];
      lamp.intensity_per_sr = Rgb{float(I[0]), float(I[1]), float(I[2])};
      est.scene.lighting.lamps.push_back(lamp);
      const Vec3& q = fit.positions_m[i];
      est.notes.push_back("lamp " + std::to_string(i) + ": at (" + fmt("%.2f", q.x) + ", " +
                          fmt("%.2f", q.y) + ", " + fmt("%.2f", q.z) + ") m, intensity " +
                          fmt("%.4g", I[0]) + " " + fmt("%.4g", I[1]) + " " + fmt("%.4g", I[2]) +
                          " per sr");
    }
    est.notes.push_back("lamps: " + std::to_string(marks.size()) + " lamp(s) fitted to " +
                        std::to_string(fit.pixels_used) + " pixels of " +
                        std::to_string(patches.size()) + " patch(es), residual " +
                        fmt("%.1f", 100 * fit.rms_residual) + " % RMS, " +
                        fmt("%.1f", 100 * fit.median_abs_residual) +
                        " % median (of the median patch radiance)" +
                        (fit.converged ? "" : "; Ceres did not report convergence"));
  }
  return est;
}

Image render_estimate_overlay(const Image& photo, const SceneEstimate& estimate,
                              const Annotations& annotations) {
  const GeometryEstimate& g = estimate.geometry;
  const int w = photo.width(), h = photo.height();
  if (photo.channels() < 3)
    throw Error(ErrorCode::invalid_argument, "overlay: the photo needs RGB channels");
  if (g.distance_m.width() != w || g.distance_m.height() != h)
    throw Error(ErrorCode::size_mismatch, "overlay: the estimate's distance map is " +
                                              std::to_string(g.distance_m.width()) + "x" +
                                              std::to_string(g.distance_m.height()) +
                                              ", the photo " + std::to_string(w) + "x" +
                                              std::to_string(h));
  Image out(w, h, 3);
  // Log-distance colour map over the finite range.
  float dmin = std::numeric_limits<float>::infinity(), dmax = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float d = g.distance_m.at(x, y, 0);
      if (std::isfinite(d) && d > 0) dmin = std::min(dmin, d), dmax = std::max(dmax, d);
    }
  const double l0 = std::log(std::max(1e-3f, dmin)), l1 = std::log(std::max(dmax, dmin * 1.001f));
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const float d = g.distance_m.at(x, y, 0);
      float c[3];
      float mix;
      if (!std::isfinite(d)) {
        c[0] = c[1] = c[2] = 1.25f, mix = 0.6f;  // sky: washed out white, unlike far blue
      } else {
        const double t = std::clamp((std::log(std::max(d, 1e-3f)) - l0) / (l1 - l0), 0.0, 1.0);
        // red -> yellow -> green -> cyan -> blue
        const double hue = 4 * t;
        const int seg = std::min(3, int(hue));
        const float f = float(hue - seg);
        const float ramps[5][3] = {{1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0, 1, 1}, {0, 0, 1}};
        for (int k = 0; k < 3; ++k) c[k] = ramps[seg][k] * (1 - f) + ramps[seg + 1][k] * f;
        mix = 0.5f;
      }
      for (int k = 0; k < 3; ++k) {
        const float p = std::max(0.0f, photo.at(x, y, k));
        out.at(x, y, k) = (1 - mix) * p + mix * c[k] * 0.8f;
      }
    }
  }
  cv::Mat m = detail::as_mat(out.view());
  const int thick = std::max(1, std::min(w, h) / 300);
  constexpr int kShift = 4;  // sub-pixel drawing: coordinates in 1/16 px
  auto pt = [](const PixelPoint& p) {
    return cv::Point(int(std::lround(p[0] * (1 << kShift))), int(std::lround(p[1] * (1 << kShift))));
  };
  auto polygon = [&](const std::vector<PixelPoint>& poly, const cv::Scalar& colour) {
    std::vector<cv::Point> pts;
    for (const auto& p : poly) pts.push_back(pt(p));
    const cv::Point* data = pts.data();
    const int count = int(pts.size());
    cv::polylines(m, &data, &count, 1, true, colour, thick, cv::LINE_AA, kShift);
  };
  for (const auto& p : annotations.planes) polygon(p.polygon, cv::Scalar(1, 0.9, 0));
  for (const auto& p : annotations.distance_hints) polygon(p.polygon, cv::Scalar(0, 0.9, 1));
  if (!annotations.sunlit_patch.empty()) polygon(annotations.sunlit_patch, cv::Scalar(0.2, 1, 0.2));
  if (!annotations.shadowed_patch.empty())
    polygon(annotations.shadowed_patch, cv::Scalar(0, 0.35, 0));
  for (const auto& s : annotations.shadow_pairs) {
    cv::line(m, pt(s.caster_foot), pt(s.caster_top), cv::Scalar(1, 0, 1), thick, cv::LINE_AA, kShift);
    cv::line(m, pt(s.caster_top), pt(s.shadow_tip), cv::Scalar(1, 0, 1), thick, cv::LINE_AA, kShift);
  }
  for (const auto& p : annotations.lamp_patches) polygon(p.polygon, cv::Scalar(1, 0.5, 0));
  for (const auto& l : annotations.lamps) {
    const int r = std::max(3, std::min(w, h) / 80) << kShift;
    cv::circle(m, pt(l.pixel), r, cv::Scalar(1, 0.6, 0), thick + 1, cv::LINE_AA, kShift);
  }
  cv::line(m, pt(g.horizon[0]), pt(g.horizon[1]), cv::Scalar(1, 0, 0), thick + 1, cv::LINE_AA, kShift);
  if (estimate.sun) {
    // Compass at the top centre: up = the camera's horizontal forward, right = its right.
    const double az = (estimate.sun->azimuth_deg - g.pose.yaw_deg) * kDeg;
    const double len = std::min(w, h) / 10.0;
    const PixelPoint c{w / 2.0, len * 1.2};
    const PixelPoint tip{c[0] + len * std::sin(az), c[1] - len * std::cos(az)};
    cv::circle(m, pt(c), int(len * (1 << kShift)), cv::Scalar(1, 1, 1), thick, cv::LINE_AA, kShift);
    cv::arrowedLine(m, pt(c), pt(tip), cv::Scalar(1, 0.85, 0.2), thick + 1, cv::LINE_AA, kShift, 0.25);
  }
  return out;
}

}  // namespace mr
