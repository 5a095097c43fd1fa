// libmr_opencv_contrib.so: libmr's calls into OpenCV's ximgproc, dnn and objdetect modules (the
// table in photo/opencv_contrib_module.h), a module of its own so that they and the libraries they
// pull in are mapped only by the runs that estimate geometry, sky or materials or run a depth
// network.
#include <opencv2/dnn.hpp>
#include <opencv2/objdetect.hpp>
#include <opencv2/ximgproc/edge_filter.hpp>
#include <opencv2/ximgproc/slic.hpp>

#include "photo/opencv_contrib_module.h"

namespace mr::photo::contrib {

namespace {

void guided_filter(cv::InputArray guide, cv::InputArray src, cv::OutputArray dst, int radius,
                   double eps, int d_depth) {
  cv::ximgproc::guidedFilter(guide, src, dst, radius, eps, d_depth);
}

void rolling_guidance_filter(cv::InputArray src, cv::OutputArray dst, int d, double sigma_color,
                             double sigma_space, int num_of_iter) {
  cv::ximgproc::rollingGuidanceFilter(src, dst, d, sigma_color, sigma_space, num_of_iter);
}

void fast_global_smoother_filter(cv::InputArray guide, cv::InputArray src, cv::OutputArray dst,
                                 double lambda, double sigma_color) {
  cv::ximgproc::fastGlobalSmootherFilter(guide, src, dst, lambda, sigma_color);
}

int slic_superpixels(cv::InputArray image, int algorithm, int region_size, float ruler,
                     int iterations, int min_element_size, cv::OutputArray labels) {
  cv::Ptr<cv::ximgproc::SuperpixelSLIC> slic =
      cv::ximgproc::createSuperpixelSLIC(image, algorithm, region_size, ruler);
  slic->iterate(iterations);
  slic->enforceLabelConnectivity(min_element_size);
  slic->getLabels(labels);
  return slic->getNumberOfSuperpixels();
}

void* read_onnx(const std::string& path) {
  auto net = std::make_unique<cv::dnn::Net>(cv::dnn::readNetFromONNX(path));
  if (!net->empty()) {
    net->setPreferableBackend(cv::dnn::DNN_BACKEND_OPENCV);
    net->setPreferableTarget(cv::dnn::DNN_TARGET_CPU);
  }
  return net.release();
}

void delete_net(void* net) {
  delete static_cast<cv::dnn::Net*>(net);
}

bool net_empty(const void* net) {
  return static_cast<const cv::dnn::Net*>(net)->empty();
}

cv::Mat forward(void* net, const cv::Mat& blob) {
  auto* n = static_cast<cv::dnn::Net*>(net);
  n->setInput(blob);
  return n->forward();
}

bool detect_faces(const cv::Mat& gray8, const std::string& cascade_path, double scale_factor,
                  int min_neighbors, int min_size, std::vector<cv::Rect>& faces) {
  faces.clear();
  // Read per call (~20 ms for the 0.7 MB XML): a classifier is not safe to share between the
  // threads of a batch.
  cv::CascadeClassifier cascade;
  if (cascade_path.empty() || !cascade.load(cascade_path)) return false;
  cascade.detectMultiScale(gray8, faces, scale_factor, min_neighbors, 0,
                           cv::Size(min_size, min_size));
  return true;
}

void detect_people(const cv::Mat& image8, double hit_threshold, double scale_factor,
                   std::vector<cv::Rect>& people, std::vector<double>& weights) {
  people.clear();
  weights.clear();
  // OpenCV 4.6's detectMultiScale crashes (SIGSEGV) on a picture smaller than the window.
  const cv::Size window = cv::HOGDescriptor().winSize;
  if (image8.cols < window.width || image8.rows < window.height) return;
  // Made per call, as the cascade above: cheap (the detector's weights are compiled in).
  cv::HOGDescriptor hog;
  hog.setSVMDetector(cv::HOGDescriptor::getDefaultPeopleDetector());
  hog.detectMultiScale(image8, people, weights, hit_threshold, cv::Size(8, 8), cv::Size(8, 8),
                       scale_factor);
}

const Module kModule{guided_filter,
                     rolling_guidance_filter,
                     fast_global_smoother_filter,
                     slic_superpixels,
                     read_onnx,
                     delete_net,
                     net_empty,
                     forward,
                     detect_faces,
                     detect_people};

}  // namespace

}  // namespace mr::photo::contrib

extern "C" __attribute__((visibility("default"))) const void* mr_opencv_contrib_module() {
  return &mr::photo::contrib::kModule;
}
