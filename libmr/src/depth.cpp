#include "mr/depth.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <cmath>
#include <limits>

#include "depth_convert.h"
#include "mr/error.h"
#include "mr/io.h"

namespace mr {

namespace {

std::string size_text(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

int depth_channel(const Image& stored) {
  for (const char* name : {"Z", "depth.Z", "Y", "depth.Y", "R"})
    if (int c = stored.channel_index(name); c >= 0) return c;
  return 0;
}

}  // namespace

DepthMap depth_to_distance(Image stored, const Camera& camera, const DepthOptions& options) {
  if (!(options.scale > 0) || !std::isfinite(options.scale))
    throw Error(ErrorCode::invalid_argument,
                "depth scale " + std::to_string(options.scale) + " must be positive and finite");
  if (options.kind == DepthKind::disparity &&
      (!(options.baseline_m > 0) || !std::isfinite(options.baseline_m)))
    throw Error(ErrorCode::invalid_argument,
                "disparity depth needs a positive stereo baseline (got " +
                    std::to_string(options.baseline_m) + " m)");
  if (!std::isfinite(options.doffs_px))
    throw Error(ErrorCode::invalid_argument, "disparity doffs must be finite");
  if (stored.width() != camera.width || stored.height() != camera.height)
    throw Error(ErrorCode::size_mismatch, "depth map is " + size_text(stored.width(), stored.height()) +
                                              ", photo is " + size_text(camera.width, camera.height));
  if (stored.channels() != 1) {
    const int c = depth_channel(stored);
    stored = stored.select_channels(std::span<const int>(&c, 1));
  }
  stored.set_channel_names({"Z"});

  if (!(options.sky_depth_m > 0))  // NaN or <= 0; +inf is allowed (no threshold)
    throw Error(ErrorCode::invalid_argument,
                "sky depth " + std::to_string(options.sky_depth_m) + " must be positive");

  const int width = stored.width();
  const double f_b = camera.focal_px * options.baseline_m;
  // Counts: no surface at all; of those the values that are not a sky encoding (NaN, -inf,
  // negative: a broken file rather than sky) and the finite values at or above the sky
  // threshold; and surfaces clamped to the far limit.
  using Counts = detail::DepthCounts;
  const Counts counts = tbb::parallel_reduce(
      tbb::blocked_range<int>(0, stored.height()), Counts{},
      [&](const tbb::blocked_range<int>& rows, Counts count) {
        for (int y = rows.begin(); y < rows.end(); ++y) {
          float* row = stored.pixel(0, y);
          for (int x = 0; x < width; ++x)
            row[x] = detail::stored_depth_to_distance(double(row[x]) * options.scale, options,
                                                      camera, f_b, x, y, count);
        }
        return count;
      },
      [](const Counts& a, const Counts& b) { return a + b; });
  DepthMap out{std::move(stored), counts.no_surface, counts.invalid};
  out.sky_threshold_pixels = counts.sky_threshold;
  out.clamped_pixels = counts.clamped;
  return out;
}

DepthMap read_depth(const std::filesystem::path& path, const Camera& camera,
                    const DepthOptions& options) {
  const ImageFileInfo info = probe_image(path);
  // The size from the header, before decoding: a wrong map is noticed at once, not after
  // decoding gigabytes of it.
  const bool turned = info.orientation >= 5;  // read_image swaps width and height
  const int shown_w = turned ? info.height : info.width, shown_h = turned ? info.width : info.height;
  if (shown_w != camera.width || shown_h != camera.height)
    throw Error(ErrorCode::size_mismatch, path.string() + ": depth map is " +
                                              size_text(shown_w, shown_h) + ", photo is " +
                                              size_text(camera.width, camera.height));
  ReadOptions raw;
  raw.to_scene_linear = false;
  raw.reject_non_finite = false;  // non-finite depth means "no surface"
  Image stored = read_image(path, raw);
  // Integer files: undo OIIO's normalisation to get the stored integers back.
  const double max_code = info.pixel_type == PixelType::uint8    ? 255.0
                          : info.pixel_type == PixelType::uint16 ? 65535.0
                                                                 : 0.0;
  if (max_code > 0)
    for (float& v : stored.pixels()) v = float(std::round(double(v) * max_code));
  try {
    return depth_to_distance(std::move(stored), camera, options);
  } catch (const Error& e) {
    throw Error(e.code(), path.string() + ": " + e.what());
  }
}

}  // namespace mr
