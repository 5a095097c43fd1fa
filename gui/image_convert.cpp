#include "image_convert.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace mrstudio {

QImage to_display(const mr::Image& linear, const mr::ColorConfig& color, float exposure) {
  if (linear.empty()) return {};
  const int w = linear.width(), h = linear.height(), c = linear.channels();
  mr::Image rgb(w, h, 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float* p = linear.pixel(x, y);
      float* q = rgb.pixel(x, y);
      for (int k = 0; k < 3; ++k) q[k] = std::max(0.0f, p[c >= 3 ? k : 0] * exposure);
    }
  color.convert(rgb.view(), mr::colorspace::scene_linear, mr::colorspace::srgb);
  QImage out(w, h, QImage::Format_RGB888);
  for (int y = 0; y < h; ++y) {
    uchar* line = out.scanLine(y);
    const float* p = rgb.pixel(0, y);
    for (int i = 0; i < w * 3; ++i) {
      const float v = std::isfinite(p[i]) ? std::clamp(p[i], 0.0f, 1.0f) : 0.0f;
      line[i] = uchar(std::lround(v * 255.0f));
    }
  }
  return out;
}

QSize fit_pixels(int width, int height, double max_pixels) {
  const double n = double(width) * double(height);
  if (n <= max_pixels || width <= 0 || height <= 0) return {width, height};
  const double s = std::sqrt(max_pixels / n);
  return {std::max(1, int(std::floor(width * s))), std::max(1, int(std::floor(height * s)))};
}

mr::Image downscale_area(const mr::Image& image, int width, int height) {
  if (width == image.width() && height == image.height()) return image;
  const int c = image.channels();
  mr::Image out(width, height, c, image.channel_names());
  out.metadata() = image.metadata();
  const double sx = double(image.width()) / width, sy = double(image.height()) / height;
  for (int y = 0; y < height; ++y) {
    const int y0 = int(std::floor(y * sy)), y1 = std::max(y0 + 1, int(std::floor((y + 1) * sy)));
    for (int x = 0; x < width; ++x) {
      const int x0 = int(std::floor(x * sx)), x1 = std::max(x0 + 1, int(std::floor((x + 1) * sx)));
      float* q = out.pixel(x, y);
      for (int yy = y0; yy < std::min(y1, image.height()); ++yy)
        for (int xx = x0; xx < std::min(x1, image.width()); ++xx) {
          const float* p = image.pixel(xx, yy);
          for (int k = 0; k < c; ++k) q[k] += p[k];
        }
      const float n =
          float((std::min(y1, image.height()) - y0) * (std::min(x1, image.width()) - x0));
      for (int k = 0; k < c; ++k) q[k] /= n;
    }
  }
  return out;
}

QImage depth_colormap(const mr::Image& distance_m) {
  const int w = distance_m.width(), h = distance_m.height();
  QImage out(w, h, QImage::Format_RGB888);
  if (distance_m.empty()) return out;
  float lo = std::numeric_limits<float>::infinity(), hi = 0;
  for (float d : distance_m.pixels())
    if (std::isfinite(d) && d > 0) lo = std::min(lo, d), hi = std::max(hi, d);
  const double l0 = std::log(std::max(1e-3f, lo)), l1 = std::log(std::max(hi, lo * 1.001f));
  for (int y = 0; y < h; ++y) {
    uchar* line = out.scanLine(y);
    for (int x = 0; x < w; ++x) {
      const float d = distance_m.at(x, y, 0);
      std::array<double, 3> rgb{0.85, 0.85, 0.88};  // sky / no surface
      if (std::isfinite(d) && d > 0) {
        const double t = std::clamp((std::log(double(d)) - l0) / std::max(1e-9, l1 - l0), 0.0, 1.0);
        // red -> yellow -> green -> cyan -> blue
        const double hue = t * 240.0 / 60.0;
        const double f = hue - std::floor(hue);
        switch (int(std::floor(hue))) {
          case 0:
            rgb = {1, f, 0};
            break;
          case 1:
            rgb = {1 - f, 1, 0};
            break;
          case 2:
            rgb = {0, 1, f};
            break;
          case 3:
            rgb = {0, 1 - f, 1};
            break;
          default:
            rgb = {0, 0, 1};
            break;
        }
      }
      for (int k = 0; k < 3; ++k) line[3 * x + k] = uchar(std::lround(rgb[k] * 255));
    }
  }
  return out;
}

}  // namespace mrstudio
