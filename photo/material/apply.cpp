#include "photo/material/apply.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <opencv2/ximgproc/edge_filter.hpp>
#include <string>

#include "cv_bridge.h"
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

Image photo_detail(const Image& photo, const Image& shading,
                   const render::SurfaceGeometry& geometry, const DetailOptions& options) {
  require_size(photo, geometry, "photo");
  require_size(shading, geometry, "shading");
  if (photo.channels() < 3)
    throw Error(ErrorCode::invalid_argument, "photo_detail: the photo needs 3 channels");
  if (!(options.min_detail > 0 && options.max_detail >= options.min_detail && options.eps_log > 0))
    throw Error(ErrorCode::invalid_argument, "photo_detail: bad options (min/max detail, eps)");
  const int w = photo.width(), h = photo.height();
  // Shading below 1e-3 of the image's mean is too dark to divide by (deep shadow, grazing).
  double mean_shading = 0;
  std::size_t n = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (geometry.surface.at(x, y, 0) > 0) {
        mean_shading += (shading.at(x, y, 0) + shading.at(x, y, 1) + shading.at(x, y, 2)) / 3.0;
        ++n;
      }
  Image detail(w, h, 3);
  for (float& v : detail.pixels()) v = 1.0f;
  if (n == 0) return detail;
  mean_shading /= double(n);
  const float floor_shading = float(1e-3 * mean_shading);
  constexpr float kFloorRadiance = 1e-5f;

  cv::Mat log_albedo(h, w, CV_32FC3);
  cv::Mat usable(h, w, CV_8U, cv::Scalar(0));
  double log_sum[3] = {0, 0, 0};
  std::size_t usable_count = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      bool ok = geometry.surface.at(x, y, 0) > 0;
      for (int c = 0; c < 3 && ok; ++c) ok = shading.at(x, y, c) > floor_shading;
      auto* la = log_albedo.ptr<cv::Vec3f>(y) + x;
      if (!ok) continue;
      usable.at<unsigned char>(y, x) = 1;
      ++usable_count;
      for (int c = 0; c < 3; ++c) {
        (*la)[c] = std::log(std::max(photo.at(x, y, c), kFloorRadiance) / shading.at(x, y, c));
        log_sum[c] += (*la)[c];
      }
    }
  if (usable_count == 0) return detail;
  // Unusable pixels (sky, unlit) take the mean so that they neither pull edges nor halos.
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (!usable.at<unsigned char>(y, x)) {
        auto* la = log_albedo.ptr<cv::Vec3f>(y) + x;
        for (int c = 0; c < 3; ++c) (*la)[c] = float(log_sum[c] / double(usable_count));
      }
  const int radius = options.radius_px > 0
                         ? options.radius_px
                         : std::clamp(int(std::lround(0.02 * std::min(w, h))), 4, 48);
  cv::Mat smooth;
  cv::ximgproc::guidedFilter(log_albedo, log_albedo, smooth, radius, options.eps_log);
  const float lo = std::log(options.min_detail), hi = std::log(options.max_detail);
  tbb::parallel_for(0, h, [&](int y) {
    for (int x = 0; x < w; ++x) {
      if (!usable.at<unsigned char>(y, x)) continue;
      const auto& la = log_albedo.ptr<cv::Vec3f>(y)[x];
      const auto& ls = smooth.ptr<cv::Vec3f>(y)[x];
      for (int c = 0; c < 3; ++c) detail.at(x, y, c) = std::exp(std::clamp(la[c] - ls[c], lo, hi));
    }
  });
  return detail;
}

void render_with_detail(const render::SurfaceGeometry& geometry, const Lighting& lighting,
                        const Image& shading, const Image* detail, const Material& material,
                        std::span<const std::int32_t> pixels, Image& out) {
  require_size(out, geometry, "output");
  require_size(shading, geometry, "shading");
  if (detail) require_size(*detail, geometry, "detail");
  const int w = geometry.surface.width();
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, pixels.size(), 1024),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      for (std::size_t i = range.begin(); i != range.end(); ++i) {
                        const int x = pixels[i] % w, y = pixels[i] / w;
                        const render::SurfacePoint point = render::surface_point(geometry, x, y);
                        if (!point.surface) continue;
                        const render::ShadingTerms terms =
                            render::shading_terms(point, lighting, material.roughness);
                        float* o = out.pixel(x, y);
                        for (int c = 0; c < 3; ++c) {
                          const float d = detail ? detail->at(x, y, c) : 1.0f;
                          // `shading` is terms.diffuse; taking it from the argument keeps the
                          // caller's (possibly exposure-matched) shading authoritative.
                          o[c] = d * material.diffuse_albedo[c] * shading.at(x, y, c) +
                                 material.specular_albedo * terms.specular_f0[c] +
                                 terms.specular_bias[c];
                        }
                      }
                    });
}

Image apply_materials(const Image& photo, const render::SurfaceGeometry& geometry,
                      const Lighting& lighting, const Image& shading, const Image& region_labels,
                      std::span<const Material> materials, const Image* detail, double feather_px) {
  require_size(photo, geometry, "photo");
  require_size(region_labels, geometry, "region labels");
  if (region_labels.channels() != 1)
    throw Error(ErrorCode::invalid_argument, "region labels must have 1 channel");
  if (!(feather_px >= 0)) throw Error(ErrorCode::invalid_argument, "feather_px must be >= 0");
  const int w = photo.width(), h = photo.height();
  const int regions = int(materials.size());
  // Per region: its pixels (surface only) and, for feathering, the distance to its border.
  std::vector<std::vector<std::int32_t>> pixels(regions);
  cv::Mat inside(h, w, CV_8U, cv::Scalar(0));
  cv::Mat label_mat(h, w, CV_32S, cv::Scalar(0));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float v = region_labels.at(x, y, 0);
      const int k = v >= 1 && v <= float(regions) ? int(v) : 0;
      label_mat.at<int>(y, x) = k;
      if (k == 0 || !(geometry.surface.at(x, y, 0) > 0)) continue;
      pixels[k - 1].push_back(y * w + x);
    }
  Image rendered = photo;
  for (int k = 0; k < regions; ++k)
    render_with_detail(geometry, lighting, shading, detail, materials[k], pixels[k], rendered);
  // Distance (px) from each region pixel to the nearest pixel not of its own region: a pixel is
  // "inside" when its 4-neighbours share its label (image borders count as inside).
  cv::Mat same(h, w, CV_8U, cv::Scalar(0));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int k = label_mat.at<int>(y, x);
      same.at<unsigned char>(y, x) = k > 0 ? 255 : 0;
      if (k == 0) continue;
      const int nx[4] = {x - 1, x + 1, x, x}, ny[4] = {y, y, y - 1, y + 1};
      for (int i = 0; i < 4; ++i) {
        if (nx[i] < 0 || ny[i] < 0 || nx[i] >= w || ny[i] >= h) continue;
        if (label_mat.at<int>(ny[i], nx[i]) != k) same.at<unsigned char>(y, x) = 0;
      }
    }
  cv::Mat distance;
  cv::distanceTransform(same, distance, cv::DIST_L2, 3);
  Image out = photo;
  for (int k = 0; k < regions; ++k)
    for (std::int32_t index : pixels[k]) {
      const int x = index % w, y = index / w;
      // Border pixels (distance 0) get half weight, full weight from feather_px inwards.
      const float alpha =
          feather_px > 0
              ? std::min(1.0f, (distance.at<float>(y, x) + 0.5f) / float(feather_px + 0.5))
              : 1.0f;
      for (int c = 0; c < 3; ++c)
        out.at(x, y, c) = alpha * rendered.at(x, y, c) + (1 - alpha) * photo.at(x, y, c);
    }
  return out;
}

}  // namespace mr::photo
