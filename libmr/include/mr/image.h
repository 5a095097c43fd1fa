// mr::Image: float32 pixels, interleaved channels, with metadata; and cheap views onto them.
#pragma once

#include <cstddef>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "mr/export.h"
#include "mr/metadata.h"

namespace mr {

/// A rectangle of pixels: origin (x, y) and size.
struct MR_API Rect {
  int x = 0, y = 0, width = 0, height = 0;
};

/// Non-owning view onto float pixels: `height` rows of `width` pixels of `channels` floats,
/// consecutive pixels `channels` floats apart and rows `row_stride` floats apart. Cheap to copy.
/// The viewed memory must outlive the view.
template <class T>
struct MR_API BasicImageView {
  T* data = nullptr;
  int width = 0;
  int height = 0;
  int channels = 0;
  std::ptrdiff_t row_stride = 0;  ///< floats from one row to the next (>= width * channels)

  T* row(int y) const { return data + y * row_stride; }
  T* pixel(int x, int y) const { return row(y) + std::ptrdiff_t(x) * channels; }
  T& at(int x, int y, int c) const { return pixel(x, y)[c]; }
  bool contiguous() const { return row_stride == std::ptrdiff_t(width) * channels; }
  std::size_t pixel_count() const { return std::size_t(width) * std::size_t(height); }
  /// A sub-rectangle; throws mr::Error(invalid_argument) if it does not fit.
  BasicImageView sub(Rect r) const;
  operator BasicImageView<const T>() const { return {data, width, height, channels, row_stride}; }
};
using ImageView = BasicImageView<float>;
using ConstImageView = BasicImageView<const float>;

/// An owned image: width x height pixels of `channels` float32 values (interleaved, rows
/// contiguous, top row first), channel names and metadata. Colour images hold scene-linear
/// values unless their metadata says otherwise. Copying copies the pixels (use view() for a
/// cheap handle); moving is free.
class MR_API Image {
 public:
  Image() = default;
  /// Zero-filled image. Channel names default to R,G,B,A for 1..4 channels ("Y" for 1).
  /// Throws mr::Error(invalid_argument) for non-positive or absurd (> 2^31 pixel) sizes.
  Image(int width, int height, int channels, std::vector<std::string> channel_names = {});
  /// Like the constructor, but the pixels are left uninitialised (for outputs that every pixel
  /// of is about to be written; saves a pass over memory on large images).
  static Image uninitialized(int width, int height, int channels,
                             std::vector<std::string> channel_names = {});

  Image(const Image& other);
  Image& operator=(const Image& other);
  Image(Image&&) noexcept = default;
  Image& operator=(Image&&) noexcept = default;

  int width() const { return width_; }
  int height() const { return height_; }
  int channels() const { return channels_; }
  bool empty() const { return size_ == 0; }
  std::size_t pixel_count() const { return std::size_t(width_) * std::size_t(height_); }

  float* data() { return pixels_.get(); }
  const float* data() const { return pixels_.get(); }
  std::span<float> pixels() { return {pixels_.get(), size_}; }
  std::span<const float> pixels() const { return {pixels_.get(), size_}; }
  float* pixel(int x, int y) { return data() + (std::size_t(y) * width_ + x) * channels_; }
  const float* pixel(int x, int y) const {
    return data() + (std::size_t(y) * width_ + x) * channels_;
  }
  float& at(int x, int y, int c) { return pixel(x, y)[c]; }
  float at(int x, int y, int c) const { return pixel(x, y)[c]; }

  ImageView view() { return {data(), width_, height_, channels_, row_stride()}; }
  ConstImageView view() const { return {data(), width_, height_, channels_, row_stride()}; }
  std::ptrdiff_t row_stride() const { return std::ptrdiff_t(width_) * channels_; }

  const std::vector<std::string>& channel_names() const { return channel_names_; }
  void set_channel_names(std::vector<std::string> names);  ///< must have channels() entries
  /// Index of the named channel, or -1.
  int channel_index(const std::string& name) const;

  Metadata& metadata() { return metadata_; }
  const Metadata& metadata() const { return metadata_; }

  /// A new image holding the listed channels of this one (by index), metadata copied.
  Image select_channels(std::span<const int> channel_indices) const;

 private:
  int width_ = 0, height_ = 0, channels_ = 0;
  std::unique_ptr<float[]> pixels_;
  std::size_t size_ = 0;  ///< floats in pixels_
  std::vector<std::string> channel_names_;
  Metadata metadata_;
};

/// Copies a view into a new owned image (no metadata).
MR_API Image to_image(ConstImageView view);

}  // namespace mr
