#include "mr/working_size.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <string>

#include "mr/error.h"
#include "photo/fog_upsample.h"

namespace mr {

namespace {

void check_size(int width, int height, const char* what) {
  if (width <= 0 || height <= 0)
    throw Error(ErrorCode::invalid_argument, std::string(what) + ": size " + std::to_string(width) +
                                                 "x" + std::to_string(height) + " is not positive");
}

Image resized(const Image& image, int width, int height, int interpolation, const char* what) {
  if (image.empty()) throw Error(ErrorCode::invalid_argument, std::string(what) + ": empty image");
  check_size(width, height, what);
  Image out = Image::uninitialized(width, height, image.channels(), image.channel_names());
  out.metadata() = image.metadata();
  const cv::Mat in(image.height(), image.width(), CV_32FC(image.channels()),
                   const_cast<float*>(image.data()));
  cv::Mat dst(height, width, CV_32FC(image.channels()), out.data());
  cv::resize(in, dst, dst.size(), 0, 0, interpolation);
  return out;
}

}  // namespace

std::optional<WorkingSize> working_size(int width, int height, int long_side_px) {
  check_size(width, height, "working_size");
  const int longer = std::max(width, height);
  if (long_side_px <= 0 || longer <= long_side_px) return std::nullopt;
  const double s = double(long_side_px) / longer;
  return WorkingSize{std::max(1, int(std::lround(width * s))),
                     std::max(1, int(std::lround(height * s)))};
}

Image working_copy(const Image& photo, int width, int height) {
  if (photo.empty()) throw Error(ErrorCode::invalid_argument, "working_copy: empty image");
  check_size(width, height, "working_copy");
  // sRGB's curve, odd-symmetric and continued as a power beyond 1 (invertible everywhere).
  auto encode = [](float v) {
    const float a = std::abs(v);
    const float e = a <= 0.0031308f ? 12.92f * a : 1.055f * std::pow(a, 1.0f / 2.4f) - 0.055f;
    return std::copysign(e, v);
  };
  auto decode = [](float e) {
    const float a = std::abs(e);
    const float v = a <= 0.04045f ? a / 12.92f : std::pow((a + 0.055f) / 1.055f, 2.4f);
    return std::copysign(v, e);
  };
  const int colour = std::min(photo.channels(), 3);
  // Each colour value through `f`, rows in parallel (a 24 MP photo: 72 M powers).
  auto each_colour = [&](Image& image, auto f) {
    tbb::parallel_for(tbb::blocked_range<int>(0, image.height()),
                      [&](const tbb::blocked_range<int>& rows) {
                        for (int y = rows.begin(); y < rows.end(); ++y)
                          for (int x = 0; x < image.width(); ++x)
                            for (int c = 0; c < colour; ++c)
                              image.pixel(x, y)[c] = f(image.pixel(x, y)[c]);
                      });
  };
  Image encoded = photo;
  each_colour(encoded, [&](float v) { return std::isfinite(v) ? encode(v) : 0.0f; });
  Image out = resized(encoded, width, height, cv::INTER_AREA, "working_copy");
  each_colour(out, decode);
  return out;
}

Image resize_nearest(const Image& image, int width, int height) {
  return resized(image, width, height, cv::INTER_NEAREST_EXACT, "resize_nearest");
}

Camera scale_camera(const Camera& camera, int width, int height) {
  check_size(width, height, "scale_camera");
  check_size(camera.width, camera.height, "scale_camera (the camera)");
  const double sx = double(width) / camera.width, sy = double(height) / camera.height;
  Camera out = camera;
  out.width = width;
  out.height = height;
  // One focal length for both axes (square pixels): the mean of the sides' scales, which differ
  // only by the rounding of a side.
  out.focal_px = camera.focal_px * 0.5 * (sx + sy);
  out.cx = camera.cx * sx;
  out.cy = camera.cy * sy;
  return out;
}

FogLayers upsample_fog_layers(const Image& photo, const Image& working_photo,
                              const FogLayers& working, bool keep_layers) {
  FogLayers out;
  out.airlight = working.airlight;
  out.composite =
      Image::uninitialized(photo.width(), photo.height(), photo.channels(), photo.channel_names());
  out.composite.metadata() = photo.metadata();
  if (keep_layers) {
    out.transmittance = Image::uninitialized(photo.width(), photo.height(), 3);
    out.inscatter = Image::uninitialized(photo.width(), photo.height(), 3);
  }
  const ImageView none{};
  photo::upsample_fog(working_photo.view(), working.transmittance.view(), working.inscatter.view(),
                      photo.view(), out.composite.view(),
                      keep_layers ? out.transmittance.view() : none,
                      keep_layers ? out.inscatter.view() : none);
  return out;
}

}  // namespace mr
