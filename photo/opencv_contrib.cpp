#include "photo/opencv_contrib.h"

#include "core/modules.h"
#include "photo/opencv_contrib_module.h"

namespace mr::photo::contrib {

namespace {

const Module& module() {
  static const auto* m = static_cast<const Module*>(
      detail::load_module("libmr_opencv_contrib.so", "mr_opencv_contrib_module"));
  return *m;
}

}  // namespace

void guided_filter(cv::InputArray guide, cv::InputArray src, cv::OutputArray dst, int radius,
                   double eps, int d_depth) {
  module().guided_filter(guide, src, dst, radius, eps, d_depth);
}

void rolling_guidance_filter(cv::InputArray src, cv::OutputArray dst, int d, double sigma_color,
                             double sigma_space, int num_of_iter) {
  module().rolling_guidance_filter(src, dst, d, sigma_color, sigma_space, num_of_iter);
}

void fast_global_smoother_filter(cv::InputArray guide, cv::InputArray src, cv::OutputArray dst,
                                 double lambda, double sigma_color) {
  module().fast_global_smoother_filter(guide, src, dst, lambda, sigma_color);
}

int slic_superpixels(cv::InputArray image, int algorithm, int region_size, float ruler,
                     int iterations, int min_element_size, cv::OutputArray labels) {
  return module().slic_superpixels(image, algorithm, region_size, ruler, iterations,
                                   min_element_size, labels);
}

OnnxNet::OnnxNet(const std::string& path) : net_(module().read_onnx(path)) {}
OnnxNet::~OnnxNet() {
  if (net_) module().delete_net(net_);
}
OnnxNet::OnnxNet(OnnxNet&& other) noexcept : net_(other.net_) {
  other.net_ = nullptr;
}
OnnxNet& OnnxNet::operator=(OnnxNet&& other) noexcept {
  std::swap(net_, other.net_);
  return *this;
}
bool OnnxNet::empty() const {
  return !net_ || module().net_empty(net_);
}
cv::Mat OnnxNet::forward(const cv::Mat& blob) const {
  return module().forward(net_, blob);
}

bool detect_faces(const cv::Mat& gray8, const std::string& cascade_path, double scale_factor,
                  int min_neighbors, int min_size, std::vector<cv::Rect>& faces) {
  return module().detect_faces(gray8, cascade_path, scale_factor, min_neighbors, min_size, faces);
}

void detect_people(const cv::Mat& image8, double hit_threshold, double scale_factor,
                   std::vector<cv::Rect>& people, std::vector<double>& weights) {
  module().detect_people(image8, hit_threshold, scale_factor, people, weights);
}

}  // namespace mr::photo::contrib
