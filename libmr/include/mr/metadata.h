// mr::Metadata: the attributes that travel with an image (EXIF, colour space, ...).
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "mr/export.h"

namespace mr {

/// Named attributes of an image, carried from input to output files. Names follow
/// OpenImageIO's conventions ("Exif:FocalLengthIn35mmFormat", "Make", "oiio:ColorSpace").
/// Values keep their type internally (so EXIF rationals round-trip); this interface reads them
/// as text or numbers. A value type: copies are independent.
class MR_API Metadata {
 public:
  Metadata();
  ~Metadata();
  Metadata(const Metadata&);
  Metadata& operator=(const Metadata&);
  Metadata(Metadata&&) noexcept;
  Metadata& operator=(Metadata&&) noexcept;

  /// Attribute names, in insertion order.
  std::vector<std::string> names() const;
  bool contains(const std::string& name) const;
  /// The value as text (numbers formatted), or nullopt if absent.
  std::optional<std::string> get_string(const std::string& name) const;
  /// The value as a number (first element of arrays/rationals), or nullopt if absent or textual.
  std::optional<double> get_number(const std::string& name) const;

  void set(const std::string& name, const std::string& value);
  void set(const std::string& name, double value);
  void erase(const std::string& name);

  /// Private to libmr: the typed attribute list behind this object (core/metadata_impl.h).
  struct Impl;
  Impl& impl() { return *impl_; }
  const Impl& impl() const { return *impl_; }

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace mr
