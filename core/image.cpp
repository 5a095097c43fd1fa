#include "mr/image.h"

#include <algorithm>
#include <cstring>

#include "mr/error.h"

namespace mr {

namespace {

std::vector<std::string> default_channel_names(int channels) {
  switch (channels) {
    case 1: return {"Y"};
    case 2: return {"Y", "A"};
    case 3: return {"R", "G", "B"};
    case 4: return {"R", "G", "B", "A"};
    default: {
      std::vector<std::string> names;
      for (int c = 0; c < channels; ++c) names.push_back("channel" + std::to_string(c));
      return names;
    }
  }
}

}  // namespace

template <class T>
BasicImageView<T> BasicImageView<T>::sub(Rect r) const {
  if (r.x < 0 || r.y < 0 || r.width < 0 || r.height < 0 || r.x + r.width > width ||
      r.y + r.height > height)
    throw Error(ErrorCode::invalid_argument,
                "sub-rectangle " + std::to_string(r.width) + "x" + std::to_string(r.height) +
                    "+" + std::to_string(r.x) + "+" + std::to_string(r.y) +
                    " does not fit in a " + std::to_string(width) + "x" +
                    std::to_string(height) + " view");
  return {pixel(r.x, r.y), r.width, r.height, channels, row_stride};
}
template struct BasicImageView<float>;
template struct BasicImageView<const float>;

Image::Image(int width, int height, int channels, std::vector<std::string> channel_names)
    : Image(uninitialized(width, height, channels, std::move(channel_names))) {
  std::fill_n(pixels_.get(), size_, 0.0f);
}

Image::Image(const Image& other)
    : width_(other.width_), height_(other.height_), channels_(other.channels_),
      pixels_(other.size_ ? new float[other.size_] : nullptr), size_(other.size_),
      channel_names_(other.channel_names_), metadata_(other.metadata_) {
  std::copy_n(other.pixels_.get(), size_, pixels_.get());
}

Image& Image::operator=(const Image& other) {
  if (this != &other) *this = Image(other);
  return *this;
}

Image Image::uninitialized(int width, int height, int channels,
                           std::vector<std::string> channel_names) {
  Image im;
  im.width_ = width;
  im.height_ = height;
  im.channels_ = channels;
  constexpr std::size_t kMaxPixels = std::size_t(1) << 31;
  if (width <= 0 || height <= 0 || channels <= 0 || channels > 64 ||
      std::size_t(width) * std::size_t(height) > kMaxPixels)
    throw Error(ErrorCode::invalid_argument,
                "image size " + std::to_string(width) + "x" + std::to_string(height) + "x" +
                    std::to_string(channels) +
                    " is out of range (positive, at most 2^31 pixels and 64 channels)");
  im.size_ = im.pixel_count() * std::size_t(channels);
  im.pixels_.reset(new float[im.size_]);  // default-initialised: no zeroing pass
  if (channel_names.empty()) channel_names = default_channel_names(channels);
  im.set_channel_names(std::move(channel_names));
  return im;
}

void Image::set_channel_names(std::vector<std::string> names) {
  if (int(names.size()) != channels_)
    throw Error(ErrorCode::invalid_argument,
                "channel names: got " + std::to_string(names.size()) + " names for " +
                    std::to_string(channels_) + " channels");
  channel_names_ = std::move(names);
}

int Image::channel_index(const std::string& name) const {
  auto it = std::find(channel_names_.begin(), channel_names_.end(), name);
  return it == channel_names_.end() ? -1 : int(it - channel_names_.begin());
}

Image Image::select_channels(std::span<const int> channel_indices) const {
  std::vector<std::string> names;
  for (int c : channel_indices) {
    if (c < 0 || c >= channels_)
      throw Error(ErrorCode::invalid_argument, "select_channels: channel index " +
                                                   std::to_string(c) + " out of range [0, " +
                                                   std::to_string(channels_) + ")");
    names.push_back(channel_names_[c]);
  }
  Image out = uninitialized(width_, height_, int(channel_indices.size()), std::move(names));
  const int n = out.channels();
  for (std::size_t i = 0; i < pixel_count(); ++i)
    for (int k = 0; k < n; ++k) out.pixels_[i * n + k] = pixels_[i * channels_ + channel_indices[k]];
  out.metadata_ = metadata_;
  return out;
}

Image to_image(ConstImageView view) {
  Image out = Image::uninitialized(view.width, view.height, view.channels);
  const std::size_t row_floats = std::size_t(view.width) * view.channels;
  for (int y = 0; y < view.height; ++y)
    std::memcpy(out.data() + y * row_floats, view.row(y), row_floats * sizeof(float));
  return out;
}

}  // namespace mr
