// Private to libmr: the table of libmr_opencv_contrib.so (photo/opencv_contrib_module.cpp), as
// photo/opencv_contrib.cpp calls it. C ABI: the module exports `mr_opencv_contrib_module`.
#pragma once

#include <opencv2/core.hpp>

#include <string>
#include <vector>

namespace mr::photo::contrib {

struct Module {
  void (*guided_filter)(cv::InputArray, cv::InputArray, cv::OutputArray, int, double, int);
  void (*rolling_guidance_filter)(cv::InputArray, cv::OutputArray, int, double, double, int);
  void (*fast_global_smoother_filter)(cv::InputArray, cv::InputArray, cv::OutputArray, double,
                                      double);
  int (*slic_superpixels)(cv::InputArray, int, int, float, int, int, cv::OutputArray);
  void* (*read_onnx)(const std::string& path);  // a new cv::dnn::Net
  void (*delete_net)(void* net);
  bool (*net_empty)(const void* net);
  cv::Mat (*forward)(void* net, const cv::Mat& blob);
  bool (*detect_faces)(const cv::Mat& gray8, const std::string& cascade_path, double scale_factor,
                       int min_neighbors, int min_size, std::vector<cv::Rect>& faces);
  void (*detect_people)(const cv::Mat& image8, double hit_threshold, double scale_factor,
                        std::vector<cv::Rect>& people, std::vector<double>& weights);
};

}  // namespace mr::photo::contrib
