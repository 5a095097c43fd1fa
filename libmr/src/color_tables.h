// Private to libmr and its tests: which way ColorConfig::convert_pixels converts.
//
// Conversions without channel crosstalk between 8/16-bit codes and floats go through tables
// built from OCIO's own results (the same values without OCIO's per-value arithmetic, e.g. a
// powf per value for the sRGB encoding) once enough pixels went through them; float-to-float
// conversions always run OCIO's processor (libmr/src/color.cpp).
#pragma once

namespace mr::detail {

enum class ConversionPath {
  automatic,  ///< as convert_pixels decides
  ocio,       ///< OCIO's processor on every pixel (the reference)
  tables,     ///< the tables from the first pixel, where they apply
};

/// While it lives, convert_pixels calls made on this thread take `path` (tests and benches).
class ScopedConversionPath {
 public:
  explicit ScopedConversionPath(ConversionPath path);
  ~ScopedConversionPath();
  ScopedConversionPath(const ScopedConversionPath&) = delete;
  ScopedConversionPath& operator=(const ScopedConversionPath&) = delete;

 private:
  ConversionPath previous_;
};

/// True if this thread's last convert_pixels call converted through the tables.
bool last_conversion_used_tables();

}  // namespace mr::detail
