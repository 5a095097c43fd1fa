// Private to libmr: what libmr asks of OpenImageIO, implemented in the module libmr_oiio.so
// (core/oiio_module.cpp) and loaded on first use (core/modules.h). Every format but the batch
// ones (JPEG, PNG, OpenEXR: core/direct_codecs.cpp) is read and written through it, and the
// resampling and texture decoding libmr borrows from OIIO.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/image_codec.h"

namespace mr::detail {

/// The module's table (C ABI: the module exports `mr_oiio_module`, returning it). The functions
/// throw mr::Error naming the file.
struct OiioModule {
  /// OIIO::ImageInput::open on `path`; mr::Error(io) "<path>: not a readable image (...)".
  ImageReader* (*open_reader)(const std::string& path);
  /// OIIO::ImageOutput::create for `path`'s extension; nullptr if no writer takes it.
  ImageWriter* (*create_writer)(const std::string& path);
  /// OIIO's "extension_list": "tiff:tif,tiff;jpeg:jpg,jpeg;...".
  std::string (*extension_list)();
  /// ImageBufAlgo::resize of packed float pixels (`filter` "": OIIO's default for the direction).
  void (*resize)(const float* src, int src_width, int src_height, int channels, float* dst,
                 int width, int height, const char* filter);
  /// A model's texture (a file, or `size` bytes at `memory` named `filename` for its format):
  /// at most 4 channels as float, unassociated alpha. false with `why` on failure, as for a
  /// texture that is too large (`max_side` pixels a side, `max_pixels` in all).
  bool (*decode_texture)(const std::string& filename, const void* memory, std::size_t size,
                         int max_side, std::uint64_t max_pixels, std::vector<float>& pixels,
                         int& width, int& height, int& channels, std::string& why);
};

/// The loaded module (loads it on the first call; throws mr::Error(io) if it is missing).
const OiioModule& oiio_module();

}  // namespace mr::detail
