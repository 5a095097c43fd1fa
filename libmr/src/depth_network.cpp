// ONNX depth network through OpenCV's dnn module (mr/depth_network.h). All image resizing is
// OpenImageIO's (ImageBufAlgo::resize); OpenCV only runs the graph.
#include "mr/depth_network.h"


#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <optional>
#include <opencv2/core.hpp>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include "core/oiio_module.h"
#include "core/srgb_encode.h"
#include "mr/error.h"
#include "photo/opencv_contrib.h"

namespace mr {

namespace {

using detail::srgb_encode;

std::string shape_text(const cv::Mat& m) {
  std::string s = "[";
  for (int i = 0; i < m.dims; ++i) s += (i ? ", " : "") + std::to_string(m.size[i]);
  return s + "]";
}

// `src` resized to w x h with OIIO (a copy when the size already matches). `filter` empty: OIIO's
// default for the direction of the resize.
Image resize_image(const Image& src, int w, int h, const char* filter) {
  if (src.width() == w && src.height() == h) return src;
  Image out = Image::uninitialized(w, h, src.channels(), src.channel_names());
  detail::oiio_module().resize(src.data(), src.width(), src.height(), src.channels(), out.data(),
                               w, h, filter);
  return out;
}

}  // namespace

struct DepthNetwork::Impl {
  std::filesystem::path path;
  DepthNetworkOptions options;
  mutable std::optional<photo::contrib::OnnxNet> net;

  // Forward pass on an NCHW blob; the output as an h x w CV_32F map. Errors name the model.
  cv::Mat forward(const cv::Mat& blob) const {
    cv::Mat out;
    try {
      out = net->forward(blob);
    } catch (const cv::Exception& e) {
      throw Error(ErrorCode::corrupt_input,
                  path.string() + ": does not run on a [1, 3, " + std::to_string(options.input_height) +
                      ", " + std::to_string(options.input_width) + "] input: " + e.err);
    }
    int h = 0, w = 0;
    if (out.dims == 4 && out.size[0] == 1 && out.size[1] == 1) {
      h = out.size[2], w = out.size[3];
    } else if (out.dims == 3 && out.size[0] == 1) {
      h = out.size[1], w = out.size[2];
    } else if (out.dims == 2) {
      h = out.size[0], w = out.size[1];
    }
    if (h <= 0 || w <= 0 || out.type() != CV_32F)
      throw Error(ErrorCode::corrupt_input,
                  path.string() + ": output " + shape_text(out) +
                      " is not one float depth map ([1, 1, h, w], [1, h, w] or [h, w])");
    cv::Mat map(h, w, CV_32F);
    std::copy_n(out.ptr<float>(), std::size_t(h) * std::size_t(w), map.ptr<float>());
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        if (!std::isfinite(map.at<float>(y, x)))
          throw Error(ErrorCode::corrupt_input, path.string() + ": output is not finite at (" +
                                                    std::to_string(x) + ", " + std::to_string(y) + ")");
    return map;
  }
};

DepthNetwork::DepthNetwork(const std::filesystem::path& model, const DepthNetworkOptions& options)
    : impl_(std::make_unique<Impl>()) {
  impl_->path = model;
  impl_->options = options;
  const std::string name = model.string();
  const auto& o = options;
  if (o.input_width < 8 || o.input_width > 4096 || o.input_height < 8 || o.input_height > 4096)
    throw Error(ErrorCode::invalid_argument, name + ": network input size " +
                                                 std::to_string(o.input_width) + "x" +
                                                 std::to_string(o.input_height) + " is not in [8, 4096]");
  for (int c = 0; c < 3; ++c)
    if (!std::isfinite(o.mean[c]) || !std::isfinite(o.std[c]) || !(o.std[c] > 0))
      throw Error(ErrorCode::invalid_argument,
                  name + ": network normalisation needs finite means and positive finite std");

  std::error_code ec;
  if (!std::filesystem::exists(model, ec))
    throw Error(ErrorCode::io, name + ": no such depth network file");
  if (!std::filesystem::is_regular_file(model, ec))
    throw Error(ErrorCode::io, name + ": depth network is not a regular file");
  std::ifstream probe(model, std::ios::binary);
  char first = 0;
  if (!probe || !probe.get(first))
    throw Error(ErrorCode::io, name + ": cannot read the depth network (empty or unreadable)");
  probe.close();

  try {
    impl_->net.emplace(name);
  } catch (const cv::Exception& e) {
    throw Error(ErrorCode::corrupt_input, name + ": not an ONNX model OpenCV can load: " + e.err);
  }
  if (impl_->net->empty())
    throw Error(ErrorCode::corrupt_input, name + ": not an ONNX model OpenCV can load (empty network)");
  // Check the input and output shapes now, so a wrong model fails at load time.
  const int shape[4] = {1, 3, o.input_height, o.input_width};
  impl_->forward(cv::Mat(4, shape, CV_32F, cv::Scalar(0)));
}

DepthNetwork::~DepthNetwork() = default;
DepthNetwork::DepthNetwork(DepthNetwork&&) noexcept = default;
DepthNetwork& DepthNetwork::operator=(DepthNetwork&&) noexcept = default;

const std::filesystem::path& DepthNetwork::path() const { return impl_->path; }
const DepthNetworkOptions& DepthNetwork::options() const { return impl_->options; }

Image DepthNetwork::run(const Image& photo) const {
  const auto& o = impl_->options;
  if (photo.empty()) throw Error(ErrorCode::invalid_argument, "depth network: empty photo");
  if (photo.channels() == 2)
    throw Error(ErrorCode::invalid_argument, "depth network: the photo has 2 channels (need grey or RGB)");
  const int W = o.input_width, H = o.input_height;
  // Resize in linear light (OIIO's default filter for the direction), then encode.
  const Image small = resize_image(photo, W, H, "");
  const int shape[4] = {1, 3, H, W};
  cv::Mat blob(4, shape, CV_32F);
  float* planes = blob.ptr<float>();
  const std::size_t plane = std::size_t(W) * std::size_t(H);
  const bool grey = small.channels() == 1;
  for (int y = 0; y < H; ++y) {
    for (int x = 0; x < W; ++x) {
      const float* p = small.pixel(x, y);
      for (int c = 0; c < 3; ++c) {
        const int src = grey ? 0 : (o.rgb ? c : 2 - c);
        const float v = srgb_encode(p[src]);
        planes[std::size_t(c) * plane + std::size_t(y) * W + x] = (v - o.mean[c]) / o.std[c];
      }
    }
  }
  cv::Mat map = impl_->forward(blob);
  Image relative(map.cols, map.rows, 1, {"Z"});
  for (int y = 0; y < map.rows; ++y)
    std::copy_n(map.ptr<float>(y), map.cols, relative.pixel(0, y));
  // Back to the photo's size; a triangle (bilinear) filter does not overshoot at depth edges.
  Image full = resize_image(relative, photo.width(), photo.height(), "triangle");
  full.set_channel_names({"Z"});
  return full;
}

NetworkDepth estimate_network_depth(const DepthNetwork& network, const Image& photo,
                                    const Camera& camera, const GeometryEstimate& geometry,
                                    const NetworkDepthOptions& options) {
  const Image& g = geometry.distance_m;
  if (photo.width() != camera.width || photo.height() != camera.height || g.width() != camera.width ||
      g.height() != camera.height)
    throw Error(ErrorCode::size_mismatch,
                "depth network: photo " + std::to_string(photo.width()) + "x" +
                    std::to_string(photo.height()) + ", camera " + std::to_string(camera.width) +
                    "x" + std::to_string(camera.height) + ", geometry " + std::to_string(g.width()) +
                    "x" + std::to_string(g.height()) + " differ");
  if (!(options.max_reference_distance_m > 0))
    throw Error(ErrorCode::invalid_argument, "depth network: max_reference_distance_m must be > 0");
  NetworkDepth result;
  result.relative = network.run(photo);

  // Ground references: pixels whose estimated distance is the ray's hit on y = 0.
  const double h = geometry.pose.position_m.y;
  const float inf = std::numeric_limits<float>::infinity();
  result.reference_distance_m = Image(camera.width, camera.height, 1, {"Z"});
  for (int y = 0; y < camera.height; ++y) {
    for (int x = 0; x < camera.width; ++x) {
      float& ref = result.reference_distance_m.at(x, y, 0);
      ref = inf;
      const double d = g.at(x, y, 0);
      if (!std::isfinite(d) || d <= 0 || d > options.max_reference_distance_m) continue;
      const Vec3 dir = geometry.pose.ray_direction(camera, x, y);
      if (!(dir.y < 0) || !(h > 0)) continue;
      const double ground = h / -dir.y;
      if (std::abs(d - ground) <= 1e-4 * ground) ref = float(d);
    }
  }
  DepthFitOptions fit = options.fit;
  fit.kind = network.options().output;
  fit.camera = camera;
  result.fit = fit_relative_depth(result.relative, result.reference_distance_m, fit);
  return result;
}

}  // namespace mr
