#include "photo/material/apply.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <string>

#include "core/cv_bridge.h"
#include "core/srgb_encode.h"
#include "mr/error.h"

namespace mr::photo {

namespace {

void require_size(const Image& image, const render::SurfaceGeometry& geometry, const char* what) {
  const Image& s = geometry.surface;
  if (image.width() != s.width() || image.height() != s.height())
    throw Error(ErrorCode::size_mismatch,
                std::string(what) + " is " + std::to_string(image.width()) + "x" +
                    std::to_string(image.height()) + ", the surface geometry " +
                    std::to_string(s.width()) + "x" + std::to_string(s.height()));
}

// Model shading below this share of its mean over the surfaces is not trusted: grazing or deep
// shadow in an estimated geometry, mostly wrong at depth edges, where the photo shows the
// surface lit. Dividing by it would make D explode (and clamp); with the floor, D times the
// floored shading still reproduces the photo's radiance, so its brightness there is kept.
constexpr double kShadingFloor = 0.05;

// Rec. 709 luminance of a linear RGB pixel.
float luminance(const float* rgb) {
  return 0.2126f * rgb[0] + 0.7152f * rgb[1] + 0.0722f * rgb[2];
}

// The 99th percentile of the photo's luminance over the surfaces (0 when none): the level of
// its bright surfaces, which sets the scale of the noise floor and of the snapping's colours.
float bright_surface_level(const Image& photo, const render::SurfaceGeometry& geometry) {
  std::vector<float> levels;
  for (int y = 0; y < photo.height(); ++y)
    for (int x = 0; x < photo.width(); ++x) {
      const float level = luminance(photo.pixel(x, y));
      if (geometry.surface.at(x, y, 0) > 0 && std::isfinite(level)) levels.push_back(level);
    }
  if (levels.empty()) return 0;
  const auto at = levels.begin() + std::ptrdiff_t(0.99 * double(levels.size() - 1));
  std::nth_element(levels.begin(), at, levels.end());
  return std::max(0.0f, *at);
}

// A pixel just outside a region (unlabelled or sky) on the object's edge is a mix of the
// object and what lies behind it (antialiasing, blur): kept as it is, the old object's colour in it
// shows as a dark or bright line along the new material (a dark outline between a re-coloured
// light shirt and the sand). Its share alpha of the object is estimated from the colour line
// between the object's old colour F (the mean of its region neighbours in the photo) and the
// background B (the mean of its outside neighbours): alpha = (P - B).(F - B) / |F - B|^2, clamped
// to [0, 1]; the pixel becomes P + alpha (F_new - F), F_new the neighbours' new colour. Where F
// and B differ by less than a third of the brighter (no edge to read a mix from: a texture's
// +-15 % is not one) the pixel stays as it is.
constexpr double kMinEdgeContrast = 1.0 / 3;
void decontaminate_outer_border(const Image& photo, const render::SurfaceGeometry& geometry,
                                const Image& region_labels, int regions, Image& out) {
  const int w = photo.width(), h = photo.height();
  auto region_at = [&](int x, int y) {
    const float v = region_labels.at(x, y, 0);
    return v >= 1 && v <= float(regions) && geometry.surface.at(x, y, 0) > 0;
  };
  tbb::parallel_for(0, h, [&](int y) {
    for (int x = 0; x < w; ++x) {
      if (region_at(x, y)) continue;
      double f_old[3] = {0, 0, 0}, f_new[3] = {0, 0, 0}, back[3] = {0, 0, 0};
      int in = 0, outside = 0;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int nx = x + dx, ny = y + dy;
          if ((dx == 0 && dy == 0) || nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
          if (region_at(nx, ny)) {
            for (int c = 0; c < 3; ++c)
              f_old[c] += photo.at(nx, ny, c), f_new[c] += out.at(nx, ny, c);
            ++in;
          } else {
            for (int c = 0; c < 3; ++c) back[c] += photo.at(nx, ny, c);
            ++outside;
          }
        }
      if (in == 0 || outside == 0) continue;
      double d[3], p[3], dd = 0, pd = 0, f2 = 0, b2 = 0;
      for (int c = 0; c < 3; ++c) {
        f_old[c] /= in, f_new[c] /= in, back[c] /= outside;
        d[c] = f_old[c] - back[c];
        p[c] = double(photo.at(x, y, c)) - back[c];
        dd += d[c] * d[c], pd += p[c] * d[c];
        f2 += f_old[c] * f_old[c], b2 += back[c] * back[c];
      }
      if (!(dd > kMinEdgeContrast * kMinEdgeContrast * std::max(f2, b2))) continue;
      const double alpha = std::clamp(pd / dd, 0.0, 1.0);
      for (int c = 0; c < 3; ++c)
        out.at(x, y, c) =
            float(std::max(0.0, double(photo.at(x, y, c)) + alpha * (f_new[c] - f_old[c])));
    }
  });
}

}  // namespace

Image diffuse_shading(const render::SurfaceGeometry& geometry, const Lighting& lighting) {
  const int w = geometry.surface.width(), h = geometry.surface.height();
  Image out(w, h, 3);
  tbb::parallel_for(0, h, [&](int y) {
    for (int x = 0; x < w; ++x) {
      const render::SurfacePoint point = render::surface_point(geometry, x, y);
      if (!point.surface) continue;
      // The diffuse term does not depend on the roughness.
      const render::ShadingTerms terms = render::shading_terms(point, lighting, 1.0f);
      for (int c = 0; c < 3; ++c) out.at(x, y, c) = std::max(0.0f, terms.diffuse[c]);
    }
  });
  return out;
}

namespace {

// Local mean of `values` (CV_32F, 1 or 3 channels, the full image) over the pixels whose group is
// g, for those pixels: normalised convolution with a tent (two box passes, support 4 r + 1; O(1)
// per pixel in r), so that nothing outside the group (another region, the sky) leaks in.
// Calls out(x, y, mean) for each pixel of the group.
// `weights` (CV_32F, optional) weights each pixel.
template <class Out>
void group_mean(const cv::Mat& values, const cv::Mat& group, int g, int radius, Out&& out,
                const cv::Mat* weights = nullptr) {
  const int w = values.cols, h = values.rows;
  int x0 = w, y0 = h, x1 = -1, y1 = -1;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (group.at<int>(y, x) == g)
        x0 = std::min(x0, x), x1 = std::max(x1, x), y0 = std::min(y0, y), y1 = std::max(y1, y);
  if (x1 < 0) return;
  const int reach = 2 * radius;
  const cv::Rect box(cv::Point(std::max(0, x0 - reach), std::max(0, y0 - reach)),
                     cv::Point(std::min(w, x1 + reach + 1), std::min(h, y1 + reach + 1)));
  cv::Mat weight(box.size(), CV_32F, cv::Scalar(0));
  cv::Mat weighted(box.size(), values.type(), cv::Scalar::all(0));
  const cv::Mat source = values(box);
  for (int y = 0; y < box.height; ++y)
    for (int x = 0; x < box.width; ++x)
      if (group.at<int>(y + box.y, x + box.x) == g) {
        const float wt = weights ? weights->at<float>(y + box.y, x + box.x) : 1.0f;
        weight.at<float>(y, x) = wt;
        if (values.channels() == 3)
          weighted.at<cv::Vec3f>(y, x) = wt * source.at<cv::Vec3f>(y, x);
        else
          weighted.at<float>(y, x) = wt * source.at<float>(y, x);
      }
  const cv::Size window(2 * radius + 1, 2 * radius + 1);
  for (int pass = 0; pass < 2; ++pass) {
    cv::boxFilter(weight, weight, -1, window, cv::Point(-1, -1), true, cv::BORDER_CONSTANT);
    cv::boxFilter(weighted, weighted, -1, window, cv::Point(-1, -1), true, cv::BORDER_CONSTANT);
  }
  tbb::parallel_for(0, box.height, [&](int y) {
    for (int x = 0; x < box.width; ++x) {
      if (group.at<int>(y + box.y, x + box.x) != g) continue;
      const float wsum = weight.at<float>(y, x);
      if (!(wsum > 1e-12f)) continue;
      float mean[3] = {0, 0, 0};
      for (int c = 0; c < values.channels(); ++c)
        mean[c] = (values.channels() == 3 ? weighted.at<cv::Vec3f>(y, x)[c]
                                          : weighted.at<float>(y, x)) / wsum;
      out(x + box.x, y + box.y, mean);
    }
  });
}

// True when the photo's values are 8-bit sRGB codes (at least 90 % of those sampled on a
// 7-pixel grid within a fiftieth of a code): a photo decoded from an 8-bit file. A 16-bit or float
// original, or a resampled one, lands on codes by chance (4 % of values), and has no 8-bit coding
// noise to calm.
bool eight_bit_coded(const Image& photo) {
  std::size_t sampled = 0, on_codes = 0;
  for (int y = 0; y < photo.height(); y += 7)
    for (int x = 0; x < photo.width(); x += 7)
      for (int c = 0; c < 3; ++c) {
        const float v = photo.at(x, y, c);
        if (!(v >= 0 && v <= 1)) continue;
        const float code = 255 * mr::detail::srgb_encode(v);
        on_codes += std::abs(code - std::round(code)) < 0.02f;
        ++sampled;
      }
  return sampled > 0 && on_codes >= 0.9 * double(sampled);
}

// The photo's luminance (scene-linear, CV_32F at its size; non-finite values as 0) and, in
// `calm`, the same with its coding noise filtered out (see DetailOptions::coding_noise_codes;
// a copy of it when that is 0).
cv::Mat photo_luminance(const Image& photo, float level, double coding_noise_codes, cv::Mat& calm) {
  const int w = photo.width(), h = photo.height();
  cv::Mat lum(h, w, CV_32F);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float l = luminance(photo.pixel(x, y));
      lum.at<float>(y, x) = std::isfinite(l) ? std::max(l, 0.0f) : 0.0f;
    }
  calm = lum.clone();
  if (!(coding_noise_codes > 0) || !(level > 0) || !eight_bit_coded(photo)) return lum;
  // Display codes (gamma 2.2, as photo/display.h encodes for OpenCV), the level at 255: the
  // coding noise is about even in them.
  constexpr float kGamma = 2.2f;
  cv::Mat code(h, w, CV_32F);
  tbb::parallel_for(0, h, [&](int y) {
    for (int x = 0; x < w; ++x)
      code.at<float>(y, x) =
          255 * std::pow(std::min(lum.at<float>(y, x) / level, 1.0f), 1 / kGamma);
  });
  // A range of 2.5 sigma takes in the blocks' steps of a few codes; the 7 x 7 window (spatial
  // sigma 2) spans the step between two 8 x 8 blocks.
  cv::Mat filtered;
  cv::bilateralFilter(code, filtered, 7, 2.5 * coding_noise_codes, 2.0);
  // Only where the coding noise, relative to the luminance (kGamma x noise / code), outweighs
  // the faintest texture worth keeping: a pixel keeps the share of its departure from the
  // filtered value that this texture would have against that noise. At mid-tones a few codes are
  // a real texture's (grass, plaster, weave); calming them cost the tuning half's texture bars.
  constexpr float kFaintTexture = 0.07f;  // relative
  const float full_code = kGamma * float(coding_noise_codes) / kFaintTexture;
  tbb::parallel_for(0, h, [&](int y) {
    for (int x = 0; x < w; ++x) {
      const float c = code.at<float>(y, x);
      if (!(c < full_code)) continue;
      const float raw = std::max(lum.at<float>(y, x), 1e-6f);
      const float filtered_lum =
          std::max(level * std::pow(filtered.at<float>(y, x) / 255, kGamma), 1e-6f);
      calm.at<float>(y, x) = filtered_lum * std::pow(raw / filtered_lum, c / full_code);
    }
  });
  return lum;
}

}  // namespace

namespace {

// floored_shading's floor: kShadingFloor x the mean shading over the surfaces; -infinity (no
// floor: std::max(v, it) is v) where there is no surface or no light.
float shading_floor(const Image& shading, const render::SurfaceGeometry& geometry) {
  require_size(shading, geometry, "shading");
  const int w = shading.width(), h = shading.height();
  double mean_shading = 0;
  std::size_t n = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (geometry.surface.at(x, y, 0) > 0) {
        mean_shading += (shading.at(x, y, 0) + shading.at(x, y, 1) + shading.at(x, y, 2)) / 3.0;
        ++n;
      }
  if (n == 0 || !(mean_shading > 0)) return -std::numeric_limits<float>::infinity();
  return float(kShadingFloor * mean_shading / double(n));
}

}  // namespace

Image floored_shading(Image shading, const render::SurfaceGeometry& geometry) {
  const float floor_value = shading_floor(shading, geometry);
  if (floor_value == -std::numeric_limits<float>::infinity()) return shading;
  const int w = shading.width(), h = shading.height();
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (geometry.surface.at(x, y, 0) > 0)
        for (int c = 0; c < 3; ++c)
          shading.at(x, y, c) = std::max(shading.at(x, y, c), floor_value);
  return shading;
}

Image photo_detail(const Image& photo, const Image& shading_in,
                   const render::SurfaceGeometry& geometry, const DetailOptions& options) {
  require_size(photo, geometry, "photo");
  require_size(shading_in, geometry, "shading");
  if (options.region_labels) require_size(*options.region_labels, geometry, "region labels");
  if (photo.channels() < 3)
    throw Error(ErrorCode::invalid_argument, "photo_detail: the photo needs 3 channels");
  if (!(options.min_detail > 0 && options.max_detail >= options.min_detail))
    throw Error(ErrorCode::invalid_argument, "photo_detail: bad options (min/max detail)");
  if (!(options.noise_floor >= 0) || options.border_px < 0 || !(options.coding_noise_codes >= 0))
    throw Error(ErrorCode::invalid_argument,
                "photo_detail: bad options (noise floor, border, coding noise)");
  const int w = photo.width(), h = photo.height();
  // The floored shading's values are taken pixel by pixel, not held as an image.
  const float shading_floor_value = shading_floor(shading_in, geometry);
  constexpr float kFloorRadiance = 1e-5f;

  // The noise floor in the photo's units: a share of its bright surfaces' luminance (99th
  // percentile), so that it means the same for a display-referred JPEG and an EXR.
  const float level = bright_surface_level(photo, geometry);
  const float noise = float(options.noise_floor) * level;
  cv::Mat calm_luminance;
  cv::Mat photo_lum = photo_luminance(photo, level, options.coding_noise_codes, calm_luminance);

  // Groups whose base is smoothed separately: the regions (label > 0; label 0 is one more
  // group), or all surfaces as one. Smoothing across a region's border would bleed the
  // neighbour's albedo into the base and leave a band of wrong D (a halo, speckle on thin gaps).
  cv::Mat group(h, w, CV_32S, cv::Scalar(-1));
  int groups = 0;
  cv::Mat log_albedo(h, w, CV_32F, cv::Scalar(0)), calm_log_albedo(h, w, CV_32F, cv::Scalar(0));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      if (!(geometry.surface.at(x, y, 0) > 0)) continue;
      bool ok = true;
      float floored[3];
      for (int c = 0; c < 3; ++c) {
        floored[c] = std::max(shading_in.at(x, y, c), shading_floor_value);
        ok = ok && floored[c] > 0 && std::isfinite(photo.at(x, y, c));
      }
      if (!ok) continue;
      const int g = options.region_labels
                        ? std::max(0, int(options.region_labels->at(x, y, 0)))
                        : 0;
      group.at<int>(y, x) = g;
      groups = std::max(groups, g + 1);
      // Luminance only: a channel the photo barely records (green and blue of a red saucer)
      // holds mostly JPEG and sensor noise, which a new colour would show as coloured grain.
      const float s = luminance(floored);
      log_albedo.at<float>(y, x) =
          std::log((std::max(photo_lum.at<float>(y, x), kFloorRadiance) + noise) / s);
      calm_log_albedo.at<float>(y, x) =
          std::log((std::max(calm_luminance.at<float>(y, x), kFloorRadiance) + noise) / s);
    }
  // Each temporary is released once read for the last time: a large photo's peak is here.
  photo_lum.release();
  calm_luminance.release();
  const int radius = options.radius_px > 0
                         ? options.radius_px
                         : std::clamp(int(std::lround(0.08 * std::min(w, h))), 8, 256);
  const float lo = std::log(options.min_detail), hi = std::log(options.max_detail);
  // The base is a robust local mean: after a plain one, pixels far from it in log albedo (a
  // window in a wall, a dark gap in foliage) are down-weighted (Welsch, scale kRobustLog) and the
  // mean taken again. Otherwise a dark window pulls the wall's base down around it, and the
  // wall's D, hence the new material, glows in a halo the size of the filter.
  constexpr float kRobustLog = 0.5f;
  cv::Mat base(h, w, CV_32F, cv::Scalar(0));
  cv::Mat robust_weight(h, w, CV_32F, cv::Scalar(1));
  for (int pass = 0; pass < 3; ++pass) {
    for (int g = 0; g < groups; ++g)
      group_mean(
          log_albedo, group, g, radius,
          [&](int x, int y, const float* b) { base.at<float>(y, x) = b[0]; },
          pass == 0 ? nullptr : &robust_weight);
    if (pass == 2) break;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        if (group.at<int>(y, x) < 0) continue;
        const float r = log_albedo.at<float>(y, x) - base.at<float>(y, x);
        // A floor keeps every pixel in its own mean (no empty windows).
        robust_weight.at<float>(y, x) =
            std::max(1e-3f, std::exp(-r * r / (2 * kRobustLog * kRobustLog)));
      }
  }
  // A pixel on a region's border is mostly a mix of the region and what lies beyond it (an
  // antialiased ridge against the haze behind it): its D would be that mix's brightness over the
  // region's base, a bright or dark rim in the new material. D fades to 1 over the border's
  // pixels (distance to the nearest pixel of another group, the sky and unusable pixels
  // included), the feather in apply_materials blending them with the photo instead.
  robust_weight.release();
  cv::Mat inside(h, w, CV_8U, cv::Scalar(0)), border_distance;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int g = group.at<int>(y, x);
      if (g < 0) continue;
      bool same = true;
      for (int dy = -1; dy <= 1 && same; ++dy)
        for (int dx = -1; dx <= 1 && same; ++dx) {
          const int nx = std::clamp(x + dx, 0, w - 1), ny = std::clamp(y + dy, 0, h - 1);
          same = group.at<int>(ny, nx) == g;
        }
      inside.at<unsigned char>(y, x) = same ? 255 : 0;
    }
  cv::distanceTransform(inside, border_distance, cv::DIST_L2, 3);
  inside.release();
  Image detail(w, h, kDetailChannels);
  for (float& v : detail.pixels()) v = 1.0f;
  tbb::parallel_for(0, h, [&](int y) {
    for (int x = 0; x < w; ++x) {
      if (group.at<int>(y, x) < 0) continue;
      const float fade =
          std::min(1.0f, (border_distance.at<float>(y, x) + 1) / float(options.border_px + 1));
      const float b = base.at<float>(y, x);
      const float d = std::exp(fade * std::clamp(log_albedo.at<float>(y, x) - b, lo, hi));
      for (int c = 0; c < 3; ++c) detail.at(x, y, c) = d;
      detail.at(x, y, kCalmDetailChannel) =
          std::exp(fade * std::clamp(calm_log_albedo.at<float>(y, x) - b, lo, hi));
      detail.at(x, y, kBaseAlbedoChannel) = std::exp(b);
    }
  });
  return detail;
}

namespace {

// render_with_detail's pixels; `output(i, x, y)` gives where the i-th listed pixel's RGB goes.
template <class Output>
void render_pixels_with_detail(const render::SurfaceGeometry& geometry, const Lighting& lighting,
                               const Image& shading, const Image* detail, const Material& material,
                               std::span<const std::int32_t> pixels, Output&& output) {
  require_size(shading, geometry, "shading");
  if (detail) require_size(*detail, geometry, "detail");
  if (detail && detail->channels() != 3 && detail->channels() != kDetailChannels)
    throw Error(ErrorCode::invalid_argument,
                "render_with_detail: the detail needs 3 or 5 channels");
  const int w = geometry.surface.width();
  // Display codes go as luminance^(1 / kDisplayGamma): a material k times the photo's albedo
  // amplifies their fluctuations (the coding noise) by k^(1 / kDisplayGamma).
  constexpr float kDisplayGamma = 2.2f;
  const float new_albedo = luminance(material.diffuse_albedo.data());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, pixels.size(), 1024),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      for (std::size_t i = range.begin(); i != range.end(); ++i) {
                        const int x = pixels[i] % w, y = pixels[i] / w;
                        const render::SurfacePoint point = render::surface_point(geometry, x, y);
                        if (!point.surface) continue;
                        const render::ShadingTerms terms =
                            render::shading_terms(point, lighting, material.roughness);
                        float* o = output(i, x, y);
                        // The photo's detail multiplies the specular lobe as it does the
                        // diffuse light: D is the photo's radiance over its local base, and the
                        // estimate cannot tell a brighter albedo from relief catching more light
                        // (a raised grain, a facet turned to the sun). A darker pixel is mostly a
                        // small shadow (a crevice, a leaf's shade), which shades the lobe too.
                        // Shading only the darker side left a dark glossy material's sheen,
                        // as bright as its diffuse light, flat over every bright grain: the
                        // texture half gone (tuning fig_plate, grand_canyon: correlation
                        // 0.86 / 0.83 -> 0.99 / 0.99).
                        float lobe_detail = detail ? luminance(detail->pixel(x, y)) : 1.0f;
                        // The share of the photo's coding noise kept: 1 / the amplification
                        // of display codes, so the new material shows no more of it than the
                        // old one did.
                        float calming = 1;
                        if (detail && detail->channels() == kDetailChannels) {
                          const float raw = detail->at(x, y, 0);
                          const float calm = detail->at(x, y, kCalmDetailChannel);
                          const float ratio =
                              new_albedo / std::max(detail->at(x, y, kBaseAlbedoChannel), 1e-6f);
                          if (ratio > 1 && raw > 0 && calm > 0) {
                            const float kept = std::pow(ratio, -1 / kDisplayGamma);
                            calming = calm * std::pow(raw / calm, kept) / raw;
                          }
                        }
                        lobe_detail *= calming;
                        for (int c = 0; c < 3; ++c) {
                          const float d = detail ? calming * detail->at(x, y, c) : 1.0f;
                          // `shading` is terms.diffuse; taking it from the argument keeps the
                          // caller's (possibly exposure-matched) shading authoritative.
                          o[c] = d * material.diffuse_albedo[c] * shading.at(x, y, c) +
                                 lobe_detail * (material.specular_albedo * terms.specular_f0[c] +
                                                terms.specular_bias[c]);
                        }
                      }
                    });
}

}  // namespace

void render_with_detail(const render::SurfaceGeometry& geometry, const Lighting& lighting,
                        const Image& shading, const Image* detail, const Material& material,
                        std::span<const std::int32_t> pixels, Image& out) {
  require_size(out, geometry, "output");
  render_pixels_with_detail(geometry, lighting, shading, detail, material, pixels,
                            [&](std::size_t, int x, int y) { return out.pixel(x, y); });
}

void render_with_detail(const render::SurfaceGeometry& geometry, const Lighting& lighting,
                        const Image& shading, const Image* detail, const Material& material,
                        std::span<const std::int32_t> pixels, std::span<float> rgb) {
  if (rgb.size() != 3 * pixels.size())
    throw Error(ErrorCode::invalid_argument,
                "render_with_detail: the output needs 3 floats per listed pixel");
  render_pixels_with_detail(geometry, lighting, shading, detail, material, pixels,
                            [&](std::size_t i, int, int) { return rgb.data() + 3 * i; });
}

int region_smoothing_radius(int width, int height) {
  return std::clamp(int(std::lround(0.03 * std::min(width, height))), 2, 24);
}

render::SurfaceGeometry smooth_geometry_in_regions(render::SurfaceGeometry geometry,
                                                   const Image& region_labels, int radius_px) {
  require_size(region_labels, geometry, "region labels");
  const int w = region_labels.width(), h = region_labels.height();
  const int radius = radius_px > 0 ? radius_px : region_smoothing_radius(w, h);
  cv::Mat group(h, w, CV_32S, cv::Scalar(-1));
  int groups = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int k = int(region_labels.at(x, y, 0));
      if (k <= 0 || !(geometry.surface.at(x, y, 0) > 0)) continue;
      group.at<int>(y, x) = k;
      groups = std::max(groups, k + 1);
    }
  // Smoothed in place, one quantity at a time: each is read from its own copy of the input
  // values, so the geometry is held once (a large photo's peak memory is set here).
  const auto smooth = [&](Image& image, int channels, auto&& write) {
    cv::Mat values(h, w, channels == 3 ? CV_32FC3 : CV_32F, cv::Scalar::all(0));
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        if (group.at<int>(y, x) < 0) continue;
        float* v = values.ptr<float>(y) + std::size_t(x) * channels;
        for (int c = 0; c < channels; ++c) v[c] = image.at(x, y, c);
      }
    for (int g = 1; g < groups; ++g) group_mean(values, group, g, radius, write);
  };
  smooth(geometry.normal, 3, [&](int x, int y, const float* n) {
    const float length = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (!(length > 1e-3f)) return;
    for (int c = 0; c < 3; ++c) geometry.normal.at(x, y, c) = n[c] / length;
  });
  smooth(geometry.sun_visibility, 1,
         [&](int x, int y, const float* v) { geometry.sun_visibility.at(x, y, 0) = v[0]; });
  smooth(geometry.sky_visibility, 1,
         [&](int x, int y, const float* v) { geometry.sky_visibility.at(x, y, 0) = v[0]; });
  return geometry;
}

Image close_region_gaps(const Image& region_labels, const render::SurfaceGeometry& geometry,
                        int gap_px) {
  require_size(region_labels, geometry, "region labels");
  if (gap_px <= 0) return region_labels;
  const int w = region_labels.width(), h = region_labels.height();
  cv::Mat any(h, w, CV_8U, cv::Scalar(0));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) any.at<unsigned char>(y, x) = region_labels.at(x, y, 0) > 0 ? 255 : 0;
  // A closing fills gaps up to 2 * gap_px wide between or inside regions, never grows a region's
  // outline into open space (a straight or convex border is its own closing).
  cv::Mat closed;
  const cv::Mat kernel = cv::getStructuringElement(
      cv::MORPH_ELLIPSE, cv::Size(2 * gap_px + 1, 2 * gap_px + 1));
  cv::morphologyEx(any, closed, cv::MORPH_CLOSE, kernel, cv::Point(-1, -1), 1, cv::BORDER_REPLICATE);
  // Each filled pixel joins the nearest region (label of the nearest region pixel).
  cv::Mat not_region = 255 - any, distance, nearest;
  cv::distanceTransform(not_region, distance, nearest, cv::DIST_L2, 3, cv::DIST_LABEL_PIXEL);
  std::vector<float> label_of_index(1, 0.0f);  // DIST_LABEL_PIXEL numbers zero pixels row by row
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (any.at<unsigned char>(y, x)) label_of_index.push_back(region_labels.at(x, y, 0));
  Image out = region_labels;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      if (any.at<unsigned char>(y, x) || !closed.at<unsigned char>(y, x)) continue;
      if (!(geometry.surface.at(x, y, 0) > 0)) continue;  // sky seen through a gap stays sky
      const int index = nearest.at<int>(y, x);
      if (index > 0 && std::size_t(index) < label_of_index.size())
        out.at(x, y, 0) = label_of_index[std::size_t(index)];
    }
  return out;
}

namespace {

// A class's trusted pixels summed over a square window around each pixel (box filters with a
// constant zero border): their count, colour sum and sum of squares; mean and spread (the
// channels' mean variance, at least 0) where count is n.
struct WindowSums {
  cv::Mat count, sum, sum_squares;
  WindowSums(const cv::Mat& weight, const cv::Mat& colour, const cv::Mat& colour_squared,
             int half_width) {
    const cv::Size window(2 * half_width + 1, 2 * half_width + 1);
    cv::boxFilter(weight, count, -1, window, cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
    cv::boxFilter(colour, sum, -1, window, cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
    cv::boxFilter(colour_squared, sum_squares, -1, window, cv::Point(-1, -1), false,
                  cv::BORDER_CONSTANT);
  }
  cv::Vec3f mean(int j, int i, float n) const { return sum.at<cv::Vec3f>(j, i) / n; }
  float spread(int j, int i, float n, const cv::Vec3f& m) const {
    const cv::Vec3f v = sum_squares.at<cv::Vec3f>(j, i) / n - m.mul(m);
    return std::max(0.0f, (v[0] + v[1] + v[2]) / 3);
  }
};

}  // namespace

Image snap_regions_to_edges(const Image& region_labels, const Image& photo,
                            const render::SurfaceGeometry& geometry, int radius_px,
                            int strip_rows) {
  require_size(region_labels, geometry, "region labels");
  require_size(photo, geometry, "photo");
  if (region_labels.channels() != 1)
    throw Error(ErrorCode::invalid_argument, "region labels must have 1 channel");
  if (photo.channels() < 3)
    throw Error(ErrorCode::invalid_argument, "snap_regions_to_edges: the photo needs 3 channels");
  if (strip_rows < 1)
    throw Error(
        ErrorCode::invalid_argument,
        "snap_regions_to_edges: strip_rows must be >= 1, got " + std::to_string(strip_rows));
  if (radius_px <= 0) return region_labels;
  const int w = photo.width(), h = photo.height();
  // Colours compared display-encoded (gamma 1/2.2 of the value over the bright surfaces'
  // level), closer to how different they look than linear values, for a JPEG or an EXR alike.
  const float exposure = bright_surface_level(photo, geometry);
  if (!(exposure > 0)) return region_labels;
  cv::Mat guide(h, w, CV_32FC3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) {
        const float v = photo.at(x, y, c) / exposure;
        guide.at<cv::Vec3f>(y, x)[c] =
            std::pow(std::clamp(std::isfinite(v) ? v : 0.0f, 0.0f, 1.0f), 1 / 2.2f);
      }
  // Classes: the unlabelled surface (0) and each region; the sky is none (it stays sky).
  int regions = 0;
  for (float v : region_labels.pixels())
    if (std::isfinite(v)) regions = std::max(regions, int(v));
  const int classes = regions + 1;
  cv::Mat label(h, w, CV_32S, cv::Scalar(-1));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (geometry.surface.at(x, y, 0) > 0) {
        const float v = region_labels.at(x, y, 0);
        label.at<int>(y, x) = std::isfinite(v) ? std::clamp(int(v), 0, regions) : 0;
      }
  // Trusted pixels: their whole (2 r + 1)^2 window is of their class (the sky counting as
  // another). Each class's local colour: the mean and variance of its trusted pixels within 3 r.
  // Classes are taken one at a time, each over its bounding box grown by the windows' reach (a
  // mask may hold thousands of small regions), keeping per pixel the nearest class so far and
  // its own class's distance.
  //
  // An untrusted pixel (near a border) takes the class whose local colour it is clearly closer
  // to: squared distance to the class's mean over the class's variance (plus the noise of an
  // 8-bit photo), under a quarter of its own class's. A sliver of the neighbour inside a region
  // goes to the neighbour; where both sides look alike (no edge in the photo, or a texture
  // whose spread covers both) the mask's own border stays.
  const int r = radius_px, reach = 3 * radius_px;
  const cv::Mat square = cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * r + 1, 2 * r + 1));
  constexpr float kClearlyCloser = 0.25f;
  constexpr float kNoiseVariance = 0.02f * 0.02f;
  // At least a full trusted window's worth of the search window (its part inside the image): a
  // class seen in only a corner of the window has no reliable colour (a few pixels of one
  // texture phase would look like an exact match).
  const float min_share =
      float((2 * r + 1) * (2 * r + 1)) / float((2 * reach + 1) * (2 * reach + 1));
  std::vector<cv::Rect> box(classes);
  {
    std::vector<int> x0(classes, w), y0(classes, h), x1(classes, -1), y1(classes, -1);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        if (const int k = label.at<int>(y, x); k >= 0) {
          x0[k] = std::min(x0[k], x), x1[k] = std::max(x1[k], x);
          y0[k] = std::min(y0[k], y), y1[k] = std::max(y1[k], y);
        }
    const int grow = reach + r;
    for (int k = 0; k < classes; ++k)
      if (x1[k] >= 0)
        box[k] = cv::Rect(cv::Point(std::max(0, x0[k] - grow), std::max(0, y0[k] - grow)),
                          cv::Point(std::min(w, x1[k] + grow + 1), std::min(h, y1[k] + grow + 1)));
  }
  cv::Mat trusted_own(h, w, CV_8U, cv::Scalar(0));
  cv::Mat best_distance(h, w, CV_32F, cv::Scalar(INFINITY)), own_distance = best_distance.clone();
  cv::Mat best_class(h, w, CV_32S, cv::Scalar(-1));
  // Gaps: unlabelled surface pixels that a closing of the regions' union (gaps up to 2 r_gap
  // wide) would fill. A gap is no surface of its own (the unlabelled class's colour is measured
  // outside the gaps), so the rule below cannot move its pixels; each keeps the two regions
  // with the most trusted pixels around it, for the gap test after it.
  const int gap_radius = 2 * r;
  cv::Mat gap;
  {
    cv::Mat any = (label > 0) / 255, closed;
    cv::morphologyEx(any, closed, cv::MORPH_CLOSE,
                     cv::getStructuringElement(cv::MORPH_ELLIPSE,
                                               cv::Size(2 * gap_radius + 1, 2 * gap_radius + 1)),
                     cv::Point(-1, -1), 1, cv::BORDER_REPLICATE);
    gap = closed & (label == 0) / 255;
  }
  cv::Mat gap_index(h, w, CV_32S, cv::Scalar(-1));
  int gap_pixels = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (gap.at<unsigned char>(y, x)) gap_index.at<int>(y, x) = gap_pixels++;
  struct Neighbour {
    int k = -1;
    float count = 0, spread = 0;
    cv::Vec3f mean;
  };
  std::vector<std::array<Neighbour, 2>> gap_neighbours(static_cast<std::size_t>(gap_pixels));
  // Each class's window sums are made in strips of its box's rows, each strip with the rows its
  // windows and the trusted-pixel erosion read beyond it (so its sums are the whole box's: a
  // strip's cut edge lies farther than any window reaches): the temporaries are 7 floats a
  // pixel of a strip, not of the whole box (the frame, for the unlabelled class).
  for (int k = 0; k < classes; ++k) {
    if (box[k].empty()) continue;
    const cv::Rect roi = box[k];
    const bool gap_test = k > 0 && gap_pixels > 0 && cv::countNonZero(gap(roi)) > 0;
    const int far_reach = reach + gap_radius;
    const int sums_reach = gap_test ? far_reach : reach;
    for (int s0 = 0; s0 < roi.height; s0 += strip_rows) {
      const int s1 = s0 + std::min(strip_rows, roi.height - s0);  // (no overflow)
      // Rows of the trusted weight the sums read, and of the class mask its erosion reads.
      const int t0 = std::max(0, s0 - sums_reach), t1 = std::min(roi.height, s1 + sums_reach);
      const int m0 = std::max(0, t0 - r), m1 = std::min(roi.height, t1 + r);
      const cv::Rect mask_rows(roi.x, roi.y + m0, roi.width, m1 - m0);
      const cv::Rect rows(roi.x, roi.y + t0, roi.width, t1 - t0);
      // The unlabelled surface's colour only from outside the gaps: a gap between regions is
      // not a surface of its own, however wide its middle.
      const cv::Mat mask = k == 0 ? ((label(mask_rows) == 0) & (gap(mask_rows) == 0)) / 255
                                  : (label(mask_rows) == k) / 255;
      cv::Mat eroded, weight, colour, colour_squared;
      cv::erode(mask, eroded, square, cv::Point(-1, -1), 1, cv::BORDER_REPLICATE);
      const cv::Mat trusted = eroded.rowRange(t0 - m0, t1 - m0);
      trusted.convertTo(weight, CV_32F);
      {
        cv::Mat weight3;
        cv::cvtColor(weight, weight3, cv::COLOR_GRAY2BGR);
        cv::multiply(weight3, guide(rows), colour);
      }
      cv::multiply(colour, guide(rows), colour_squared);
      // The gap test's colours from farther: the middle of a gap 2 r_gap wide is r_gap from
      // either side, whose trusted pixels start r further in. Made and used first, then
      // released, so the two sums are never held together.
      if (gap_test) {
        const WindowSums far(weight, colour, colour_squared, far_reach);
        tbb::parallel_for(s0, s1, [&](int j) {
          const int y = roi.y + j;
          for (int i = 0; i < roi.width; ++i) {
            const int x = roi.x + i, g = gap_index.at<int>(y, x);
            if (g < 0) continue;
            // At least a full trusted window's worth of the region around the gap pixel.
            const float n = far.count.at<float>(j - t0, i);
            if (n >= float((2 * r + 1) * (2 * r + 1))) {
              const cv::Vec3f mean = far.mean(j - t0, i, n);
              auto& two = gap_neighbours[std::size_t(g)];
              const Neighbour here{k, n, far.spread(j - t0, i, n, mean), mean};
              if (n > two[0].count)
                two[1] = two[0], two[0] = here;
              else if (n > two[1].count)
                two[1] = here;
            }
          }
        });
      }
      const WindowSums near(weight, colour, colour_squared, reach);
      colour.release();
      colour_squared.release();
      tbb::parallel_for(s0, s1, [&](int j) {
        const int y = roi.y + j;
        for (int i = 0; i < roi.width; ++i) {
          const int x = roi.x + i, own = label.at<int>(y, x);
          if (own < 0) continue;
          if (own == k && trusted.at<unsigned char>(j - t0, i))
            trusted_own.at<unsigned char>(y, x) = 1;
          const float n = near.count.at<float>(j - t0, i);
          const float min_count =
              min_share * float((std::min(x + reach, w - 1) - std::max(x - reach, 0) + 1) *
                                (std::min(y + reach, h - 1) - std::max(y - reach, 0) + 1));
          if (!(n >= min_count)) continue;
          const cv::Vec3f mean = near.mean(j - t0, i, n);
          const cv::Vec3f d = guide.at<cv::Vec3f>(y, x) - mean;
          const float distance = d.dot(d) / (near.spread(j - t0, i, n, mean) + kNoiseVariance);
          if (own == k) own_distance.at<float>(y, x) = distance;
          if (distance < best_distance.at<float>(y, x)) {
            best_distance.at<float>(y, x) = distance;
            best_class.at<int>(y, x) = k;
          }
        }
      });
    }
  }
  Image out = region_labels;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int own = label.at<int>(y, x), best = best_class.at<int>(y, x);
      if (own < 0 || trusted_own.at<unsigned char>(y, x) || best < 0 || best == own) continue;
      // (Without enough trusted pixels of its own class nearby there is nothing to compare.)
      const float own_d = own_distance.at<float>(y, x);
      if (std::isfinite(own_d) && best_distance.at<float>(y, x) < kClearlyCloser * own_d)
        out.at(x, y, 0) = float(best);
    }
  // A gap pixel joins a region when the regions around it explain its colour: it is within the
  // colour spread of one of them (a strip the mask missed), or a mix of the two (a soft border
  // between them, e.g. a shadow's penumbra, painted as two regions with the blend left out: kept
  // as the photo, it would be a line of the old material between the new ones). A thin object
  // of its own colour (a pole, a seam) is neither, and stays.
  constexpr float kWithinSpread = 9.0f;  // squared distance over the variance (3 channels: ~3)
  tbb::parallel_for(0, h, [&](int y) {
    for (int x = 0; x < w; ++x) {
      const int g = gap_index.at<int>(y, x);
      // (A gap pixel beside unlabelled surface outside the gaps, wide enough for a colour of its
      // own, was judged by the rule above.)
      if (g < 0 || std::isfinite(own_distance.at<float>(y, x))) continue;
      const auto& two = gap_neighbours[std::size_t(g)];
      const cv::Vec3f p = guide.at<cv::Vec3f>(y, x);
      int join = -1;
      float nearest = kWithinSpread;
      for (const Neighbour& c : two)
        if (c.k > 0) {
          const cv::Vec3f d = p - c.mean;
          const float distance = d.dot(d) / (c.spread + kNoiseVariance);
          if (distance <= nearest) nearest = distance, join = c.k;
        }
      if (join < 0 && two[1].k > 0) {
        const cv::Vec3f e = two[1].mean - two[0].mean, d = p - two[0].mean;
        const float length_squared = e.dot(e);
        const float t = length_squared > 0 ? d.dot(e) / length_squared : -1;
        const cv::Vec3f off = d - t * e;
        const float variance = (two[0].spread + two[1].spread) / 2 + kNoiseVariance;
        if (t >= 0 && t <= 1 && off.dot(off) / variance <= kWithinSpread)
          join = t < 0.5f ? two[0].k : two[1].k;
        // Off the mix but nearer to one region than half the step between them: a darker or
        // lighter part of that surface (a shaded fold), not an object of its own.
        const cv::Vec3f to_second = p - two[1].mean;
        const float d0 = d.dot(d), d1 = to_second.dot(to_second);
        if (join < 0 && std::min(d0, d1) <= 0.25f * length_squared)
          join = d0 <= d1 ? two[0].k : two[1].k;
      }
      if (join > 0) out.at(x, y, 0) = float(join);
    }
  });
  // A moved pixel with fewer than 3 of its 8 neighbours in its new class is a lone flip (noise,
  // a speck of clutter near the border): it would leave a speck of the other material. Back.
  Image snapped = out;
  tbb::parallel_for(0, h, [&](int y) {
    for (int x = 0; x < w; ++x) {
      const float now = snapped.at(x, y, 0);
      if (now == region_labels.at(x, y, 0)) continue;
      int same = 0;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int nx = x + dx, ny = y + dy;
          if ((dx || dy) && nx >= 0 && ny >= 0 && nx < w && ny < h && snapped.at(nx, ny, 0) == now)
            ++same;
        }
      if (same < 3) out.at(x, y, 0) = region_labels.at(x, y, 0);
    }
  });
  // A gap pixel left alone among joined ones (a highlight, a dark grain of the penumbra, or one
  // that joined the other region and went back above) would be a speck of the old material
  // inside the new one: with at least 6 of its 8 neighbours in one region, it joins that region.
  if (gap_pixels > 0) {
    const Image joined = out;
    tbb::parallel_for(0, h, [&](int y) {
      for (int x = 0; x < w; ++x) {
        if (gap_index.at<int>(y, x) < 0 || joined.at(x, y, 0) != 0.0f) continue;
        int count[8] = {}, labels[8] = {}, kinds = 0;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int nx = x + dx, ny = y + dy;
            if (!(dx || dy) || nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
            const int k = label.at<int>(ny, nx) < 0 ? 0 : int(joined.at(nx, ny, 0));
            if (k <= 0) continue;
            int i = 0;
            while (i < kinds && labels[i] != k) ++i;
            if (i == kinds) labels[kinds++] = k;
            ++count[i];
          }
        for (int i = 0; i < kinds; ++i)
          if (count[i] >= 6) out.at(x, y, 0) = float(labels[i]);
      }
    });
  }
  return out;
}

namespace {

// Per pixel in [0, 1]: 1 where the photo shows no edge within 2 px (the largest step of log
// luminance between neighbours, after a blur of 1 px, at most kPlainStep), falling to 0 at a
// step of kEdgeStep (a region's border on the photo's own edge).
cv::Mat photo_plainness(const Image& photo) {
  constexpr float kPlainStep = 0.05f, kEdgeStep = 0.2f;
  const int w = photo.width(), h = photo.height();
  cv::Mat log_y(h, w, CV_32F);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      log_y.at<float>(y, x) = std::log(luminance(photo.pixel(x, y)) + 0.003f);
  cv::GaussianBlur(log_y, log_y, cv::Size(0, 0), 1.0);
  cv::Mat step(h, w, CV_32F, cv::Scalar(0));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float v = log_y.at<float>(y, x);
      float s = 0;
      if (x + 1 < w) s = std::max(s, std::abs(log_y.at<float>(y, x + 1) - v));
      if (x > 0) s = std::max(s, std::abs(log_y.at<float>(y, x - 1) - v));
      if (y + 1 < h) s = std::max(s, std::abs(log_y.at<float>(y + 1, x) - v));
      if (y > 0) s = std::max(s, std::abs(log_y.at<float>(y - 1, x) - v));
      step.at<float>(y, x) = s;
    }
  cv::dilate(step, step, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(5, 5)));
  cv::Mat plain(h, w, CV_32F);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      plain.at<float>(y, x) =
          std::clamp((kEdgeStep - step.at<float>(y, x)) / (kEdgeStep - kPlainStep), 0.0f, 1.0f);
  return plain;
}

}  // namespace

namespace {

// At most this many values (an even subsample of more) give the photo's white and a region's
// percentile: 4 MB, not 4 bytes a pixel of a camera-size photo or region.
constexpr std::size_t kPercentileSamples = std::size_t(1) << 20;

std::size_t sample_stride(std::size_t count) {
  return std::max<std::size_t>(1, (count + kPercentileSamples - 1) / kPercentileSamples);
}

// The value at index floor(fraction x (n - 1)) of `values` in order (reordered); values non-empty.
float percentile_of(std::span<float> values, double fraction) {
  const auto nth = values.begin() + std::ptrdiff_t(fraction * double(values.size() - 1));
  std::nth_element(values.begin(), nth, values.end());
  return *nth;
}

// The largest of a rendered pixel's three channels (NaN when one is).
float brightest_channel(const float* rgb) {
  return std::max({rgb[0], rgb[1], rgb[2]});
}

}  // namespace

float photo_white_level(const Image& photo) {
  const std::size_t stride = sample_stride(photo.pixel_count());
  std::vector<float> brightest;
  brightest.reserve(photo.pixel_count() / stride + 1);
  const int channels = std::min(photo.channels(), 3);
  for (std::size_t i = 0; i < photo.pixel_count(); i += stride) {
    const float* p = photo.data() + i * std::size_t(photo.channels());
    // A photo's pixel may have one channel NaN: its other channels still count.
    float m = -std::numeric_limits<float>::infinity();
    for (int c = 0; c < channels; ++c)
      if (std::isfinite(p[c])) m = std::max(m, p[c]);
    if (std::isfinite(m)) brightest.push_back(m);
  }
  if (brightest.empty()) return 1.0f;
  return std::max(1.0f, percentile_of(brightest, 0.999));
}

float region_range_fit(std::span<float> brightest, float white_level) {
  if (brightest.empty() || !(white_level > 0)) return 1.0f;
  const float level = percentile_of(brightest, kRangeFitPercentile / 100);
  return level > white_level ? white_level / level : 1.0f;
}

float region_range_fit(const Image& rendered, std::span<const std::int32_t> pixels,
                       float white_level) {
  if (!(white_level > 0)) return 1.0f;
  const int w = rendered.width();
  std::vector<float> brightest;
  for (const std::int32_t p : pixels) {
    const float m = brightest_channel(rendered.pixel(p % w, p / w));
    if (std::isfinite(m)) brightest.push_back(m);
  }
  return region_range_fit(brightest, white_level);
}

namespace {

// Scales `rgb` (3 floats a pixel, pixel i at index i) by the region_range_fit of the pixels
// for which in_region(i) holds (`region_pixels` of them; every stride-th one taken where they
// are more than kPercentileSamples); returns the factor.
template <class InRegion>
float fit_to_range(std::span<float> rgb, float white_level, std::size_t region_pixels,
                   InRegion&& in_region, std::vector<float>& brightest) {
  if (!(white_level > 0)) return 1.0f;
  const std::size_t stride = sample_stride(region_pixels);
  brightest.clear();
  std::size_t seen = 0;
  for (std::size_t i = 0; 3 * i < rgb.size(); ++i)
    if (in_region(i) && seen++ % stride == 0) {
      const float m = brightest_channel(&rgb[3 * i]);
      if (std::isfinite(m)) brightest.push_back(m);
    }
  const float s = region_range_fit(brightest, white_level);
  if (s < 1)
    for (float& v : rgb) v *= s;
  return s;
}

}  // namespace

Image apply_materials(const Image& photo, const render::SurfaceGeometry& geometry,
                      const Lighting& lighting, const Image& shading, const Image& region_labels,
                      std::span<const Material> materials, const Image* detail,
                      const CompositeOptions& options, DespeckleStats* despeckled,
                      std::vector<float>* exposures) {
  const double feather_px = options.feather_px, smooth_feather_px = options.smooth_feather_px;
  require_size(photo, geometry, "photo");
  require_size(region_labels, geometry, "region labels");
  if (region_labels.channels() != 1)
    throw Error(ErrorCode::invalid_argument, "region labels must have 1 channel");
  if (!(feather_px >= 0) || !(smooth_feather_px >= 0))
    throw Error(ErrorCode::invalid_argument, "feather_px and smooth_feather_px must be >= 0");
  const int w = photo.width(), h = photo.height();
  const int regions = int(materials.size());
  // Per region: its pixels (surface only).
  std::vector<std::vector<std::int32_t>> pixels(regions);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float v = region_labels.at(x, y, 0);
      const int k = v >= 1 && v <= float(regions) ? int(v) : 0;
      if (k == 0 || !(geometry.surface.at(x, y, 0) > 0)) continue;
      pixels[k - 1].push_back(y * w + x);
    }
  if (exposures) exposures->assign(std::size_t(regions), 1.0f);
  std::vector<float> rendered;  // a region's rendering (its band's), 3 floats a pixel
  std::vector<float> brightest;
  Image out = photo;
  if (!(feather_px > 0)) {
    for (int k = 0; k < regions; ++k) {
      rendered.resize(3 * pixels[k].size());
      render_with_detail(geometry, lighting, shading, detail, materials[k], pixels[k], rendered);
      const float s = fit_to_range(
          rendered, options.white_level, pixels[k].size(), [](std::size_t) { return true; },
          brightest);
      if (exposures) (*exposures)[std::size_t(k)] = s;
      for (std::size_t i = 0; i < pixels[k].size(); ++i)
        std::copy_n(&rendered[3 * i], 3, out.pixel(pixels[k][i] % w, pixels[k][i] / w));
    }
    return out;
  }
  // Soft edges: each region's weight is its indicator blurred by a Gaussian of sigma feather_px,
  // the photo's the blurred indicator of everything else (unlabelled surfaces and the sky), so the
  // weights sum to 1 at every pixel: between two regions the border blends their two renderings
  // (a ramp into the photo on each side would leave a line of the old material between them),
  // and a ragged border's 1-pixel teeth take their neighbourhood's majority instead of staying
  // specks. Each material is rendered where its weight reaches into the other regions; outside
  // the regions nothing changes.
  // Where the photo shows no edge across a region's border with the unlabelled surface (a
  // brush's border through a plain saucer or a smooth blur), a border ragged by a pixel or two
  // against a strong change of colour left 1-pixel teeth and notches, the ramp lying inside the
  // region only: there the feather goes on outside it, a blur of sigma smooth_feather_px
  // weighted by how plain the photo is (photo_plainness); on the photo's edges nothing outside
  // changes, so the new material stops at the edge.
  // The wide feather reaches 2 sigma outside a region, and only where the photo is plain over
  // as far around (plainness eroded by that reach): it never crosses the photo's edge onto
  // another surface as a glow.
  const double wide_px = std::max(feather_px, smooth_feather_px);
  const int wide_reach = int(std::ceil(2 * wide_px));
  cv::Mat plain;
  if (wide_px > feather_px)
    cv::erode(photo_plainness(photo), plain,
              cv::getStructuringElement(cv::MORPH_RECT,
                                        cv::Size(2 * wide_reach + 1, 2 * wide_reach + 1)));
  const int narrow_reach = std::max(1, int(std::ceil(3 * feather_px)));
  const int reach = std::max(narrow_reach, wide_reach);
  const cv::Size kernel(2 * narrow_reach + 1, 2 * narrow_reach + 1),
      wide_kernel(2 * wide_reach + 1, 2 * wide_reach + 1);
  cv::Mat indicator(h, w, CV_32F), weight, wide_weight;
  auto is_surface = [&](int x, int y) { return geometry.surface.at(x, y, 0) > 0; };
  auto is_region = [&](int x, int y) {
    const float v = region_labels.at(x, y, 0);
    return v >= 1 && v <= float(regions) && is_surface(x, y);
  };
  // The regions' weighted renderings are summed into `out` itself (a pixel's photo value
  // replaced by 0 at its first weight), the photo blended back in at the end.
  cv::Mat region_weight(h, w, CV_32F, cv::Scalar(0));
  std::vector<std::int32_t> band;
  indicator.setTo(0);
  for (int k = 1; k <= regions; ++k) {
    if (pixels[k - 1].empty()) continue;
    // Over the region's bounding box grown by the blur's reach only (a mask may hold thousands
    // of small regions); the blur of a sub-matrix reads its parent beyond it, as a whole-frame
    // blur would.
    int x0 = w, y0 = h, x1 = -1, y1 = -1;
    for (std::int32_t index : pixels[k - 1]) {
      const int x = index % w, y = index / w;
      indicator.at<float>(y, x) = 1.0f;
      x0 = std::min(x0, x), x1 = std::max(x1, x), y0 = std::min(y0, y), y1 = std::max(y1, y);
    }
    const cv::Rect roi(cv::Point(std::max(0, x0 - reach), std::max(0, y0 - reach)),
                       cv::Point(std::min(w, x1 + reach + 1), std::min(h, y1 + reach + 1)));
    cv::GaussianBlur(indicator(roi), weight, kernel, feather_px, feather_px, cv::BORDER_REPLICATE);
    // Outside the regions, over the unlabelled surface, the wide feather by how plain the photo
    // is there; inside them (and between two regions) the narrow one, so a region a few pixels
    // across keeps its own colour.
    if (!plain.empty()) {
      cv::GaussianBlur(indicator(roi), wide_weight, wide_kernel, wide_px, wide_px,
                       cv::BORDER_REPLICATE);
      for (int y = 0; y < roi.height; ++y)
        for (int x = 0; x < roi.width; ++x)
          if (!is_region(x + roi.x, y + roi.y))
            weight.at<float>(y, x) =
                plain.at<float>(y + roi.y, x + roi.x) * wide_weight.at<float>(y, x);
    }
    for (std::int32_t index : pixels[k - 1]) indicator.at<float>(index / w, index % w) = 0.0f;
    band.clear();  // the region's pixels and its neighbours' within the blur's reach
    for (int y = roi.y; y < roi.y + roi.height; ++y)
      for (int x = roi.x; x < roi.x + roi.width; ++x)
        if (weight.at<float>(y - roi.y, x - roi.x) > 1e-4f && is_surface(x, y) &&
            (is_region(x, y) || !plain.empty()))
          band.push_back(y * w + x);
    rendered.resize(3 * band.size());
    render_with_detail(geometry, lighting, shading, detail, materials[k - 1], band, rendered);
    // The exposure is the region's own pixels', not its feather's.
    const float s = fit_to_range(
        rendered, options.white_level, pixels[k - 1].size(),
        [&](std::size_t i) {
          const int x = band[i] % w, y = band[i] / w;
          return is_region(x, y) && int(region_labels.at(x, y, 0)) == k;
        },
        brightest);
    if (exposures) (*exposures)[std::size_t(k - 1)] = s;
    for (std::size_t i = 0; i < band.size(); ++i) {
      const int x = band[i] % w, y = band[i] / w;
      const float wk = weight.at<float>(y - roi.y, x - roi.x);
      float* sum = out.pixel(x, y);
      if (region_weight.at<float>(y, x) == 0)
        for (int c = 0; c < 3; ++c) sum[c] = 0;
      region_weight.at<float>(y, x) += wk;
      for (int c = 0; c < 3; ++c) sum[c] += wk * rendered[3 * i + c];
    }
  }
  // Sky pixels stay the photo's, and so do those outside the regions but where the wide feather
  // reaches over a plain photo; the photo fills what the regions' weights leave (a ramp inside a
  // region's border with the photo, and on across it where the photo is plain).
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float total = region_weight.at<float>(y, x);
      if (!(total > 0) || !is_surface(x, y)) continue;
      const float wr = std::min(1.0f, total);
      for (int c = 0; c < 3; ++c)
        out.at(x, y, c) = wr / total * out.at(x, y, c) + (1 - wr) * photo.at(x, y, c);
    }
  decontaminate_outer_border(photo, geometry, region_labels, regions, out);
  if (options.despeckle_borders) {
    const DespeckleStats stats =
        despeckle_region_borders(photo, geometry, region_labels, regions, out);
    if (despeckled) *despeckled = stats;
  }
  return out;
}

namespace {

// log(v + floor): steps of a code or two near black (the 8-bit coding's, invisible) are not
// specks, in the photo or in the composite (kSpeckNoiseFloor).
float log_value(float v, float floor) {
  return std::log(std::max(std::max(v, 0.0f) + floor, 1e-6f));
}

// How far, at most over the channels, the log value at (x, y) lies beyond both its neighbours
// along the axis (dx, dy) (0 when between them); edges replicated.
float axis_extremum(const Image& image, int x, int y, int dx, int dy, float floor) {
  const int w = image.width(), h = image.height();
  const int ax = std::clamp(x + dx, 0, w - 1), ay = std::clamp(y + dy, 0, h - 1);
  const int bx = std::clamp(x - dx, 0, w - 1), by = std::clamp(y - dy, 0, h - 1);
  float worst = 0;
  for (int c = 0; c < 3; ++c) {
    const float v = log_value(image.at(x, y, c), floor), a = log_value(image.at(ax, ay, c), floor),
                b = log_value(image.at(bx, by, c), floor);
    worst = std::max({worst, std::min(v - a, v - b), std::min(a - v, b - v)});
  }
  return worst;
}

// The largest over the channels of |log value - the median of the 3 x 3 log values| at (x, y)
// (edges replicated); `median` gets the medians (linear: the log is monotonic).
float median_deviation(const Image& image, int x, int y, float floor, float median[3]) {
  const int w = image.width(), h = image.height();
  float worst = 0;
  for (int c = 0; c < 3; ++c) {
    float values[9];
    int n = 0;
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx)
        values[n++] = image.at(std::clamp(x + dx, 0, w - 1), std::clamp(y + dy, 0, h - 1), c);
    std::nth_element(values, values + 4, values + 9);
    median[c] = values[4];
    worst = std::max(worst,
                     std::abs(log_value(image.at(x, y, c), floor) - log_value(values[4], floor)));
  }
  return worst;
}

}  // namespace

DespeckleStats despeckle_region_borders(const Image& photo, const render::SurfaceGeometry& geometry,
                                        const Image& region_labels, int regions, Image& out) {
  require_size(photo, geometry, "photo");
  require_size(region_labels, geometry, "region labels");
  require_size(out, geometry, "output");
  if (photo.channels() < 3 || out.channels() < 3)
    throw Error(ErrorCode::invalid_argument, "despeckle_region_borders: images need 3 channels");
  const int w = photo.width(), h = photo.height();
  cv::Mat label(h, w, CV_32S);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float v = region_labels.at(x, y, 0);
      label.at<int>(y, x) =
          v >= 1 && v <= float(regions) && geometry.surface.at(x, y, 0) > 0 ? int(v) : 0;
    }
  cv::Mat border(h, w, CV_8U, cv::Scalar(0)), region(h, w, CV_8U, cv::Scalar(0));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int k = label.at<int>(y, x);
      region.at<unsigned char>(y, x) = k > 0 ? 255 : 0;
      if ((x + 1 < w && label.at<int>(y, x + 1) != k) ||
          (y + 1 < h && label.at<int>(y + 1, x) != k))
        border.at<unsigned char>(y, x) = 255;
    }
  // A border between (x, y) and its right or lower neighbour: the kDespeckleBandPx pixels on
  // each side of it (x - band + 1 .. x + band).
  const cv::Mat square = cv::getStructuringElement(
      cv::MORPH_RECT, cv::Size(2 * kDespeckleBandPx, 2 * kDespeckleBandPx),
      cv::Point(kDespeckleBandPx, kDespeckleBandPx));
  const cv::Mat window = cv::getStructuringElement(
      cv::MORPH_RECT, cv::Size(2 * kDespeckleBandPx + 1, 2 * kDespeckleBandPx + 1));
  cv::dilate(border, border, square);
  cv::dilate(region, region, window);
  std::vector<std::int32_t> band;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (border.at<unsigned char>(y, x) && region.at<unsigned char>(y, x))
        band.push_back(y * w + x);
  DespeckleStats stats;
  stats.band_pixels = band.size();
  if (band.empty()) return stats;
  const float floor = kSpeckNoiseFloor * bright_surface_level(photo, geometry);
  // The photo's own shape at each band pixel: specks it shows are detail, never touched.
  std::vector<float> photo_axis(band.size()), photo_median(band.size());
  tbb::parallel_for(std::size_t(0), band.size(), [&](std::size_t i) {
    const int x = band[i] % w, y = band[i] / w;
    float unused[3];
    photo_axis[i] =
        std::max(axis_extremum(photo, x, y, 1, 0, floor), axis_extremum(photo, x, y, 0, 1, floor));
    photo_median[i] = median_deviation(photo, x, y, floor, unused);
  });
  constexpr int kMaxPasses = 10;
  std::vector<std::array<float, 3>> replacement(band.size());
  std::vector<unsigned char> replace(band.size());
  enum : unsigned char { kKeep, kMixed, kMedian };
  for (int pass = 0; pass < kMaxPasses; ++pass) {
    // Each step reads `out` as the step before left it and writes afterwards, so the order of
    // the pixels does not matter.
    tbb::parallel_for(std::size_t(0), band.size(), [&](std::size_t i) {
      replace[i] = kKeep;
      const int x = band[i] % w, y = band[i] / w;
      const float horizontal = axis_extremum(out, x, y, 1, 0, floor),
                  vertical = axis_extremum(out, x, y, 0, 1, floor);
      float* value = replacement[i].data();
      if (std::max(horizontal, vertical) > kSpeckJump && photo_axis[i] < kPhotoCalm) {
        const int dx = horizontal >= vertical ? 1 : 0, dy = 1 - dx;
        const int ax = std::clamp(x + dx, 0, w - 1), ay = std::clamp(y + dy, 0, h - 1);
        const int bx = std::clamp(x - dx, 0, w - 1), by = std::clamp(y - dy, 0, h - 1);
        double dd = 0, pd = 0;
        for (int c = 0; c < 3; ++c) {
          const double d = double(photo.at(bx, by, c)) - photo.at(ax, ay, c);
          dd += d * d, pd += (double(photo.at(x, y, c)) - photo.at(ax, ay, c)) * d;
        }
        const float t = dd > 1e-12 ? float(std::clamp(pd / dd, 0.0, 1.0)) : 0.5f;
        for (int c = 0; c < 3; ++c) value[c] = (1 - t) * out.at(ax, ay, c) + t * out.at(bx, by, c);
        replace[i] = kMixed;
      } else if (photo_median[i] < kPhotoCalm &&
                 median_deviation(out, x, y, floor, value) > kSpeckJump) {
        replace[i] = kMedian;
      }
    });
    std::size_t changed = 0;
    for (std::size_t i = 0; i < band.size(); ++i)
      if (replace[i] != kKeep) {
        const int x = band[i] % w, y = band[i] / w;
        for (int c = 0; c < 3; ++c) out.at(x, y, c) = replacement[i][c];
        ++changed;
      }
    if (changed == 0) break;
    // A mixed pixel into both axes' ranges of its neighbours as they now are (widened by
    // kPhotoCalm): one that was a speck along the other axis too is not left one there. (Against
    // the neighbours before the step, a 1-pixel line would be held at its old value by its own
    // pixels along it.)
    const float widen = std::exp(kPhotoCalm);
    tbb::parallel_for(std::size_t(0), band.size(), [&](std::size_t i) {
      if (replace[i] != kMixed) return;
      const int x = band[i] % w, y = band[i] / w;
      float* value = replacement[i].data();
      for (const auto& [sx, sy] : {std::pair{1, 0}, std::pair{0, 1}}) {
        const int px = std::clamp(x + sx, 0, w - 1), py = std::clamp(y + sy, 0, h - 1);
        const int qx = std::clamp(x - sx, 0, w - 1), qy = std::clamp(y - sy, 0, h - 1);
        for (int c = 0; c < 3; ++c) {
          const float a = out.at(px, py, c), b = out.at(qx, qy, c);
          value[c] = std::clamp(value[c], std::min(a, b) / widen, std::max(a, b) * widen);
        }
      }
    });
    for (std::size_t i = 0; i < band.size(); ++i)
      if (replace[i] == kMixed) {
        const int x = band[i] % w, y = band[i] / w;
        for (int c = 0; c < 3; ++c) out.at(x, y, c) = replacement[i][c];
      }
    stats.changed += changed;
    stats.passes = pass + 1;
  }
  return stats;
}

}  // namespace mr::photo
