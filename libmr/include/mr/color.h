// mr::ColorConfig: colour-space conversions through OpenColorIO.
#pragma once

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "mr/export.h"
#include "mr/image.h"

namespace mr {

/// Colour-space names libmr asks for. Each is an OCIO role or alias that the shipped config
/// defines; a user config ($OCIO / --ocio-config) should define the roles at least.
namespace colorspace {
inline constexpr const char* scene_linear = "scene_linear";  ///< role: working space
inline constexpr const char* srgb = "srgb_texture";          ///< sRGB-encoded (8/16-bit files)
inline constexpr const char* acescg = "ACEScg";
inline constexpr const char* raw = "raw";  ///< data: never converted
/// sRGB-encoded after a highlight roll-off (highlight_rolloff below): the default for
/// display-referred (8/16-bit) outputs of `mr fog`. Built into libmr's config (a user config
/// may define it too; where it does not, display outputs fall back to srgb).
inline constexpr const char* srgb_rolloff = "srgb_rolloff";
}  // namespace colorspace

/// The highlight roll-off of the srgb_rolloff colour space, applied per channel to scene-linear
/// values before the sRGB encoding (issue 11 item 5): the identity up to the knee, then a
/// shoulder that approaches 1 without reaching it,
///   f(x) = x                                   for x <= knee,
///   f(x) = knee + (1 - knee) u / (1 + u),  u = (x - knee) / (1 - knee)   above,
/// continuous with a continuous slope (1 at the knee), strictly increasing, below 1 for every
/// finite x, so fog brighter than the photo's white keeps its gradations instead of clipping: an
/// 8-bit code reaches 255 only above x = 9.7 (knee 0.8). The knee keeps the photo's mid-tones
/// exactly as they were: every value <= 0.8 (sRGB code 231 of 255) passes unchanged; the
/// photo's own highlights above it are compressed, white (1.0) to 0.9 (code 243).
inline constexpr double kHighlightRolloffKnee = 0.8;
MR_API double highlight_rolloff(double x, double knee = kHighlightRolloffKnee);
/// Its inverse (for x < 1): x above the knee from f = knee + (1 - knee) u / (1 + u).
MR_API double highlight_rolloff_inverse(double y, double knee = kHighlightRolloffKnee);

/// An OpenColorIO config. Cheap to copy (shared, immutable). Thread-safe.
class MR_API ColorConfig {
 public:
  /// libmr's shipped config (libmr/data/config.ocio, embedded in the library).
  static ColorConfig builtin();
  /// A config file. Throws mr::Error(color) naming the file if OCIO cannot load it.
  static ColorConfig from_file(const std::filesystem::path& path);
  /// `explicit_path` if not empty, else $OCIO if set, else builtin().
  static ColorConfig from_environment(const std::filesystem::path& explicit_path = {});

  /// Where the config came from: a file path, or "<builtin>".
  const std::string& source() const;
  /// Names of all colour spaces.
  std::vector<std::string> colorspace_names() const;
  /// True if `name` is a colour space, alias or role of this config.
  bool has_colorspace(const std::string& name) const;
  /// True if `name` is a data (never converted) space.
  bool is_data(const std::string& name) const;
  /// The colour space for display-referred (integer) outputs: colorspace::srgb_rolloff when
  /// this config has it, else colorspace::srgb.
  const char* display_colorspace() const;

  /// Converts the first three channels of every pixel in place, from `from` to `to`
  /// (names, aliases or roles). Extra channels (alpha, ...) are left alone. Runs in parallel.
  /// Throws mr::Error(color) if either space is unknown or the image has fewer than 3 channels.
  void convert(ImageView rgb, const std::string& from, const std::string& to) const;

  /// Private to libmr: converts the first three channels of `width` x `height` pixels between
  /// buffers of different types (uint8 / uint16 / float32, as OCIO bit depths 8, 16, 32), e.g.
  /// 8-bit sRGB codes straight to linear floats through OCIO's lookup-table path. Strides in
  /// bytes. Integer outputs are clamped and rounded by OCIO.
  void convert_pixels(const void* src, int src_bits, std::ptrdiff_t src_pixel_bytes,
                      std::ptrdiff_t src_row_bytes, void* dst, int dst_bits,
                      std::ptrdiff_t dst_pixel_bytes, std::ptrdiff_t dst_row_bytes, int width,
                      int height, const std::string& from, const std::string& to) const;

  struct Impl;

 private:
  explicit ColorConfig(std::shared_ptr<const Impl> impl);
  std::shared_ptr<const Impl> impl_;
};

}  // namespace mr
