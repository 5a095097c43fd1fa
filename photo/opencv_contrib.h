// Private to libmr: the calls into OpenCV's contrib (ximgproc), dnn and objdetect modules,
// implemented in the module libmr_opencv_contrib.so (photo/opencv_contrib_module.cpp) and loaded on
// first use (core/modules.h): libopencv_ximgproc alone pulls in some 150 libraries (GDAL, DCMTK,
// ... through imgcodecs), which a run that estimates nothing never needs. Same signatures and
// parameters as the OpenCV functions they stand for; OpenCV's exceptions pass through.
#pragma once

#include <opencv2/core.hpp>

#include <memory>
#include <string>
#include <vector>

namespace mr::photo::contrib {

/// cv::ximgproc::guidedFilter.
void guided_filter(cv::InputArray guide, cv::InputArray src, cv::OutputArray dst, int radius,
                   double eps, int d_depth = -1);
/// cv::ximgproc::rollingGuidanceFilter.
void rolling_guidance_filter(cv::InputArray src, cv::OutputArray dst, int d = -1,
                             double sigma_color = 25, double sigma_space = 3, int num_of_iter = 4);
/// cv::ximgproc::fastGlobalSmootherFilter.
void fast_global_smoother_filter(cv::InputArray guide, cv::InputArray src, cv::OutputArray dst,
                                 double lambda, double sigma_color);
/// cv::ximgproc::createSuperpixelSLIC(image, algorithm, region_size, ruler), then
/// iterate(iterations), enforceLabelConnectivity(min_element_size), getLabels(labels).
/// Returns getNumberOfSuperpixels().
int slic_superpixels(cv::InputArray image, int algorithm, int region_size, float ruler,
                     int iterations, int min_element_size, cv::OutputArray labels);
/// cv::ximgproc::SLICO.
inline constexpr int kSlico = 101;

/// A cv::dnn::Net read from an ONNX file (cv::dnn::readNetFromONNX), run on the CPU with
/// OpenCV's own backend (DNN_BACKEND_OPENCV, DNN_TARGET_CPU).
class OnnxNet {
 public:
  explicit OnnxNet(const std::string& path);  ///< throws cv::Exception as readNetFromONNX
  ~OnnxNet();
  OnnxNet(OnnxNet&&) noexcept;
  OnnxNet& operator=(OnnxNet&&) noexcept;
  bool empty() const;
  /// setInput(blob); forward().
  cv::Mat forward(const cv::Mat& blob) const;

 private:
  void* net_;  // the module's cv::dnn::Net
};

/// cv::CascadeClassifier(cascade_path).detectMultiScale(gray8, faces, scale_factor,
/// min_neighbors, 0, {min_size, min_size}) on a CV_8UC1 picture. False (faces empty) when the
/// cascade file cannot be read.
bool detect_faces(const cv::Mat& gray8, const std::string& cascade_path, double scale_factor,
                  int min_neighbors, int min_size, std::vector<cv::Rect>& faces);

/// cv::HOGDescriptor with getDefaultPeopleDetector() (Dalal and Triggs 2005: upright people, 64 x
/// 128 windows), detectMultiScale(image8, people, weights, hit_threshold, {8, 8}, {8, 8},
/// scale_factor) on a CV_8UC1 or CV_8UC3 picture; none on a picture smaller than the window.
void detect_people(const cv::Mat& image8, double hit_threshold, double scale_factor,
                   std::vector<cv::Rect>& people, std::vector<double>& weights);

}  // namespace mr::photo::contrib
