// Private to libmr: reproducible runs of OpenCV's randomised steps (GrabCut seeds its colour
// models by k-means from OpenCV's per-thread random generator).
#pragma once

#include <opencv2/core.hpp>

#include <cstdint>

namespace mr::photo {

/// While it lives, OpenCV's per-thread random generator (cv::theRNG()) starts from the state a
/// thread starts with (cv::RNG()); the caller's state is given back after. Every earlier call
/// moved that state on, so without it the same photo estimated twice in one process gave people
/// of different outlines (photo/people.cpp, photo/subject.cpp).
class ReproducibleRandom {
 public:
  ReproducibleRandom() : caller_state_(cv::theRNG().state) { cv::theRNG().state = cv::RNG().state; }
  ~ReproducibleRandom() { cv::theRNG().state = caller_state_; }
  ReproducibleRandom(const ReproducibleRandom&) = delete;
  ReproducibleRandom& operator=(const ReproducibleRandom&) = delete;

 private:
  std::uint64_t caller_state_;
};

}  // namespace mr::photo
