// Monocular depth network (issue 4, item 4): an ONNX model given by path, run through OpenCV's
// dnn module, whose relative map mr::fit_relative_depth makes metric against the ground plane
// of an mr::GeometryEstimate.
//
//   mr::DepthNetwork net("midas_v21_small_256.onnx");         // MiDaS v2.1 small: the defaults
//   mr::GeometryEstimate g = mr::estimate_geometry(photo, camera, annotations);
//   mr::NetworkDepth d = mr::estimate_network_depth(net, photo, camera, g);
//   mr::fog(photo, d.fit.distance_m, camera, scene);
//
// Which models load: single-input, single-output ONNX graphs made of operators OpenCV 4.6's ONNX
// importer supports, with a fixed-size float input [1, 3, H, W] (NCHW) and one output map
// [1, 1, h, w], [1, h, w] or [h, w] (any h, w: it is resized to the photo). Known to fit:
// MiDaS v2.1 small (model-small.onnx, 256x256, ImageNet mean/std, RGB, inverse depth) with
// the default options; DPT / MiDaS v3 hybrid exports (384x384, mean = std = 0.5) and
// Depth Anything exports (518x518, ImageNet mean/std) with input size and normalisation set
// accordingly -- provided their operators load in OpenCV 4.6 (graphs needing newer operators,
// dynamic shapes or opsets OpenCV 4.6 lacks are rejected at load time with OpenCV's message).
#pragma once

#include <array>
#include <filesystem>
#include <memory>

#include "mr/camera.h"
#include "mr/depth_fit.h"
#include "mr/estimate.h"
#include "mr/export.h"
#include "mr/image.h"

namespace mr {

struct MR_API DepthNetworkOptions {
  /// The network's input size in pixels (the photo is resized to it, aspect ratio not kept, as
  /// MiDaS' and DPT's reference ONNX runners do).
  int input_width = 256, input_height = 256;
  /// Per-channel normalisation of the sRGB-encoded input in [0, 1], in the network's channel
  /// order: (v - mean) / std. Defaults: ImageNet (MiDaS v2.1, Depth Anything).
  std::array<float, 3> mean{0.485f, 0.456f, 0.406f};
  std::array<float, 3> std{0.229f, 0.224f, 0.225f};
  /// Channel order of the input tensor: RGB (MiDaS, DPT, Depth Anything), else BGR.
  bool rgb = true;
  /// What the output is (mr/depth_fit.h): inverse depth (MiDaS, DPT, Depth Anything: larger is
  /// nearer) or affine depth (larger is farther).
  RelativeDepthKind output = RelativeDepthKind::inverse_depth;
};

/// An ONNX depth network loaded with cv::dnn::readNetFromONNX and checked by a forward pass on
/// a zero input of the configured size. Input convention: the scene-linear photo (RGB, at least
/// 3 channels; 1 channel: grey) is resized with OpenImageIO to input_width x input_height in
/// linear light, clamped to [0, 1], encoded with the sRGB transfer function (the 8-bit-like
/// display values such networks were trained on, as floats in [0, 1]), normalised with
/// mean / std, and laid out as NCHW float [1, 3, H, W]. The output map is resized back to the
/// photo's size with OpenImageIO (no cv::dnn::blobFromImage: all resizing is OIIO's).
/// Runs on OpenCV's CPU backend. Not thread-safe: one run() at a time per object.
class MR_API DepthNetwork {
 public:
  /// Throws mr::Error naming the file: io (missing, not a regular file, unreadable),
  /// corrupt_input (not an ONNX model OpenCV can load; it does not accept a [1, 3, H, W] input
  /// of the configured size; its output is not one map, or not finite), invalid_argument
  /// (options out of range: sizes in [8, 4096], std > 0, all finite).
  explicit DepthNetwork(const std::filesystem::path& model, const DepthNetworkOptions& options = {});
  ~DepthNetwork();
  DepthNetwork(DepthNetwork&&) noexcept;
  DepthNetwork& operator=(DepthNetwork&&) noexcept;

  const std::filesystem::path& path() const;
  const DepthNetworkOptions& options() const;

  /// The relative map (one channel "Z", the photo's size, in the network's units: output
  /// says whether larger is nearer). Throws mr::Error: invalid_argument for an empty photo or
  /// one with 2 channels; corrupt_input (naming the model) when the output is not finite or
  /// OpenCV fails.
  Image run(const Image& photo) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

struct MR_API NetworkDepthOptions {
  /// The fit's options; its kind is taken from the network's options and its camera is the
  /// photo's (the network's map is planar, z-like).
  DepthFitOptions fit;
  /// Ground pixels farther than this are not references (near the horizon the ground plane's
  /// distance is very sensitive to the estimated pitch).
  double max_reference_distance_m = 150.0;
};

struct MR_API NetworkDepth {
  Image relative;               ///< the network's map at the photo's size
  Image reference_distance_m;   ///< the ground-plane references used (+inf elsewhere)
  DepthFit fit;                 ///< fit.distance_m: the metric map (metres along the ray)
};

/// The network's relative map made metric in one call: run(photo), then fit_relative_depth
/// against the ground plane of `geometry` (the pixels estimate_geometry put on the ground,
/// i.e. whose distance is the ray's intersection with y = 0 at the pose's camera height, up to
/// max_reference_distance_m). Throws what run() and fit_relative_depth throw (too few ground
/// pixels, a fit with scale <= 0, ...); size_mismatch when photo, camera and geometry differ in size.
MR_API NetworkDepth estimate_network_depth(const DepthNetwork& network, const Image& photo,
                                    const Camera& camera, const GeometryEstimate& geometry,
                                    const NetworkDepthOptions& options = {});

}  // namespace mr
