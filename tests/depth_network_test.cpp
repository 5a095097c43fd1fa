// mr::DepthNetwork (mr/depth_network.h) on tiny ONNX models generated here with Debian's
// python3-onnx (/usr/bin/python3, DESIGN.md section 8): a 1x1 convolution with known weights, so
// the network's output has a closed form, and the metric fit end to end on a synthetic
// ground-plane photo.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "mr/depth_network.h"
#include "mr/error.h"
#include "mr/estimate.h"

namespace fs = std::filesystem;

namespace {

// Writes a model: input "x" [1, in_channels, H, W] -> Conv 1x1 (weights [out, in], bias [out]) ->
// output "y" [1, out, H, W]. Opset 11, IR version 7 (what OpenCV 4.6's importer reads).
const char* kMakeModel = R"PY(
import sys, onnx
from onnx import helper, TensorProto
path, cin, cout = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
vals = [float(v) for v in sys.argv[4:]]
w, b = vals[:cin * cout], vals[cin * cout:]
assert len(b) == cout
graph = helper.make_graph(
    [helper.make_node("Conv", ["x", "w", "b"], ["y"], kernel_shape=[1, 1])],
    "tiny_depth",
    [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, cin, "H", "W"])],
    [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, cout, "H", "W"])],
    [helper.make_tensor("w", TensorProto.FLOAT, [cout, cin, 1, 1], w),
     helper.make_tensor("b", TensorProto.FLOAT, [cout], b)])
model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 11)])
model.ir_version = 7
onnx.checker.check_model(model)
onnx.save(model, path)
)PY";

class DepthNetworkTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (std::system("/usr/bin/python3 -c 'import onnx' >/dev/null 2>&1") != 0)
      GTEST_SKIP() << "/usr/bin/python3 has no onnx module (Debian package python3-onnx; "
                      "scripts/setup installs it)";
    dir_ = fs::temp_directory_path() /
           ("mr_depth_network_test_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
    std::ofstream(dir_ / "make_model.py") << kMakeModel;
  }
  void TearDown() override {
    std::error_code ec;
    if (!dir_.empty()) fs::remove_all(dir_, ec);
  }

  fs::path make_model(const std::string& name, int cin, int cout, const std::vector<double>& weights,
                      const std::vector<double>& bias) {
    const fs::path path = dir_ / name;
    std::ostringstream cmd;
    cmd.precision(17);
    cmd << "/usr/bin/python3 '" << (dir_ / "make_model.py").string() << "' '" << path.string()
        << "' " << cin << " " << cout;
    for (double v : weights) cmd << " " << v;
    for (double v : bias) cmd << " " << v;
    EXPECT_EQ(std::system(cmd.str().c_str()), 0) << cmd.str();
    return path;
  }

  fs::path dir_;
};

double srgb_encode(double v) {
  v = std::clamp(v, 0.0, 1.0);
  return v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1 / 2.4) - 0.055;
}
double srgb_decode(double v) { return v <= 0.04045 ? v / 12.92 : std::pow((v + 0.055) / 1.055, 2.4); }

const std::vector<double> kWeights{0.7, -0.2, 0.45};
const double kBias = 0.125;

// The closed form of the 1x1 convolution on the default (ImageNet, RGB) input convention.
double expected(const mr::DepthNetworkOptions& o, const float* rgb) {
  double sum = kBias;
  for (int c = 0; c < 3; ++c) {
    const int src = o.rgb ? c : 2 - c;
    sum += kWeights[c] * (srgb_encode(rgb[src]) - o.mean[c]) / o.std[c];
  }
  return sum;
}

mr::Image random_photo(int w, int h, unsigned seed) {
  mr::Image photo(w, h, 3);
  unsigned s = seed;
  for (float& v : photo.pixels()) {
    s = s * 1664525u + 1013904223u;
    v = float((s >> 8) & 0xffff) / 65535.0f * 1.2f - 0.05f;  // some values outside [0, 1]: clamped
  }
  return photo;
}

TEST_F(DepthNetworkTest, OutputMatchesClosedFormAtTheInputSize) {
  const fs::path model = make_model("conv.onnx", 3, 1, kWeights, {kBias});
  for (bool rgb : {true, false}) {
    mr::DepthNetworkOptions o;
    o.input_width = 40, o.input_height = 24;
    o.rgb = rgb;
    const mr::DepthNetwork net(model, o);
    const mr::Image photo = random_photo(40, 24, 7);  // no resize either way
    const mr::Image out = net.run(photo);
    ASSERT_EQ(out.width(), 40);
    ASSERT_EQ(out.height(), 24);
    ASSERT_EQ(out.channels(), 1);
    double max_err = 0;
    for (int y = 0; y < 24; ++y)
      for (int x = 0; x < 40; ++x)
        max_err = std::max(max_err, std::abs(out.at(x, y, 0) - expected(o, photo.pixel(x, y))));
    // Float32 arithmetic on values of magnitude ~5: 1e-5 absolute.
    EXPECT_LT(max_err, 1e-5) << (rgb ? "RGB" : "BGR");
  }
}

TEST_F(DepthNetworkTest, ResizesToTheNetworkAndBack) {
  const fs::path model = make_model("conv.onnx", 3, 1, kWeights, {kBias});
  mr::DepthNetworkOptions o;
  o.input_width = 32, o.input_height = 16;
  const mr::DepthNetwork net(model, o);
  // A constant photo survives both resizes exactly (the filters are normalised).
  mr::Image photo(100, 70, 3);
  const float colour[3] = {0.18f, 0.5f, 0.03f};
  for (int y = 0; y < 70; ++y)
    for (int x = 0; x < 100; ++x) std::copy_n(colour, 3, photo.pixel(x, y));
  const mr::Image out = net.run(photo);
  ASSERT_EQ(out.width(), 100);
  ASSERT_EQ(out.height(), 70);
  const double want = expected(o, colour);
  double max_err = 0;
  for (float v : out.pixels()) max_err = std::max(max_err, std::abs(v - want));
  EXPECT_LT(max_err, 1e-5);
  // A grey (one channel) photo feeds its value to all three inputs.
  mr::Image grey(50, 30, 1);
  for (float& v : grey.pixels()) v = 0.25f;
  const float g3[3] = {0.25f, 0.25f, 0.25f};
  const mr::Image out_grey = net.run(grey);
  for (float v : out_grey.pixels()) ASSERT_NEAR(v, expected(o, g3), 1e-5);
}

// A ground-plane photo whose red channel encodes (after the sRGB encoding the network sees)
// k / z, z the planar depth of the ground; the network picks red and undoes the normalisation,
// so its output is inverse depth with scale 1/k and shift 0, and the fit must find them.
struct GroundScene {
  mr::Camera camera;
  mr::GeometryEstimate geometry;
  mr::Image photo;
};
GroundScene ground_scene(int w, int h, double k) {
  GroundScene s;
  s.camera = mr::Camera::from_horizontal_fov(w, h, 70.0);
  mr::Annotations a;
  a.horizon = std::array<mr::PixelPoint, 2>{mr::PixelPoint{0.0, 0.42 * h}, mr::PixelPoint{w - 1.0, 0.38 * h}};
  a.camera_height_m = 1.7;
  s.geometry = mr::estimate_geometry(s.camera, a);
  s.photo = mr::Image(w, h, 3);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const double d = s.geometry.distance_m.at(x, y, 0);
      float* p = s.photo.pixel(x, y);
      p[0] = std::isfinite(d) ? float(srgb_decode(k / (d / s.camera.z_to_distance(x, y)))) : 0.0f;
      p[1] = 0.3f, p[2] = 0.6f;  // ignored by the network
    }
  }
  return s;
}

TEST_F(DepthNetworkTest, MetricFitEndToEndOnAGroundPlane) {
  mr::DepthNetworkOptions o;  // ImageNet mean / std, RGB
  const fs::path model = make_model("red.onnx", 3, 1, {o.std[0], 0, 0}, {o.mean[0]});
  const double k = 3.0;  // z >= 3.7 m at the bottom row: k / z <= 0.82
  {
    // At the network's size: exact up to float rounding.
    o.input_width = 96, o.input_height = 64;
    const mr::DepthNetwork net(model, o);
    const GroundScene s = ground_scene(96, 64, k);
    const mr::NetworkDepth nd = mr::estimate_network_depth(net, s.photo, s.camera, s.geometry);
    EXPECT_NEAR(nd.fit.scale, 1 / k, 1e-5 / k);
    EXPECT_NEAR(nd.fit.shift, 0.0, 1e-5);
    EXPECT_EQ(nd.fit.inliers, nd.fit.reference_pixels);
    EXPECT_GT(nd.fit.reference_pixels, 96u * 30u);
    EXPECT_LT(nd.fit.rms_inlier_residual, 1e-5);
    double max_rel = 0;
    std::size_t compared = 0;
    for (int y = 0; y < 64; ++y)
      for (int x = 0; x < 96; ++x) {
        const double want = s.geometry.distance_m.at(x, y, 0);
        if (!std::isfinite(want) || want > 150) continue;
        max_rel = std::max(max_rel, std::abs(nd.fit.distance_m.at(x, y, 0) / want - 1));
        ++compared;
      }
    EXPECT_GT(compared, 96u * 30u);
    EXPECT_LT(max_rel, 1e-4);  // float32 photo and network: 1e-4 relative on the distance
  }
  {
    // A photo 3x the network's size: resized down (in linear light) and the output back up;
    // the ground's inverse depth is affine in the image, so only the horizon's kink, the
    // borders and the sRGB curve's non-linearity under the resize filter perturb it.
    o.input_width = 64, o.input_height = 48;
    const mr::DepthNetwork net(model, o);
    const GroundScene s = ground_scene(192, 144, k);
    const mr::NetworkDepth nd = mr::estimate_network_depth(net, s.photo, s.camera, s.geometry);
    EXPECT_NEAR(nd.fit.scale * k, 1.0, 0.03);
    EXPECT_GT(double(nd.fit.inliers), 0.9 * double(nd.fit.reference_pixels));
    EXPECT_LT(nd.fit.median_abs_residual, 0.02);
    std::vector<double> rel;
    for (int y = 0; y < 144; ++y)
      for (int x = 0; x < 192; ++x) {
        const double want = s.geometry.distance_m.at(x, y, 0);
        if (std::isfinite(want) && want <= 50)
          rel.push_back(std::abs(nd.fit.distance_m.at(x, y, 0) / want - 1));
      }
    ASSERT_FALSE(rel.empty());
    std::nth_element(rel.begin(), rel.begin() + rel.size() / 2, rel.end());
    EXPECT_LT(rel[rel.size() / 2], 0.02);  // median relative error of the ground within 50 m
    std::printf("resized: scale*k %.5f, inliers %zu/%zu, median residual %.4f, rms %.4f, "
                "median |rel err| within 50 m %.4f\n",
                nd.fit.scale * k, nd.fit.inliers, nd.fit.reference_pixels,
                nd.fit.median_abs_residual, nd.fit.rms_inlier_residual, rel[rel.size() / 2]);
  }
}

void expect_error(const fs::path& model, mr::ErrorCode code, const std::string& words,
                  const mr::DepthNetworkOptions& o = {}) {
  try {
    mr::DepthNetwork net(model, o);
    ADD_FAILURE() << model << " loaded";
  } catch (const mr::Error& e) {
    EXPECT_EQ(e.code(), code) << e.what();
    const std::string what = e.what();
    EXPECT_NE(what.find(model.string()), std::string::npos) << what;
    EXPECT_NE(what.find(words), std::string::npos) << what;
  }
}

TEST_F(DepthNetworkTest, BadModelsAreClearErrors) {
  expect_error(dir_ / "missing.onnx", mr::ErrorCode::io, "no such depth network file");
  expect_error(dir_, mr::ErrorCode::io, "not a regular file");
  std::ofstream(dir_ / "empty.onnx").close();
  expect_error(dir_ / "empty.onnx", mr::ErrorCode::io, "cannot read");
  std::ofstream(dir_ / "garbage.onnx") << "this is not a protobuf\x01\x02\xff";
  expect_error(dir_ / "garbage.onnx", mr::ErrorCode::corrupt_input, "not an ONNX model");
  // Expects 4 input channels: does not run on [1, 3, H, W].
  expect_error(make_model("four.onnx", 4, 1, std::vector<double>(4, 0.25), {0}),
               mr::ErrorCode::corrupt_input, "does not run on a [1, 3, 256, 256] input");
  // Two output maps.
  expect_error(make_model("two.onnx", 3, 2, std::vector<double>(6, 0.25), {0, 0}),
               mr::ErrorCode::corrupt_input, "is not one float depth map");
  // Options out of range.
  mr::DepthNetworkOptions o;
  o.std[1] = 0;
  expect_error(make_model("ok.onnx", 3, 1, kWeights, {kBias}), mr::ErrorCode::invalid_argument,
               "positive finite std", o);
}

}  // namespace
