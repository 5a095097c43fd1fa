#include "mr/metadata.h"

#include <cstdint>

#include "core/metadata_impl.h"

namespace mr {

Metadata::Metadata() : impl_(std::make_unique<Impl>()) {}
Metadata::~Metadata() = default;
Metadata::Metadata(const Metadata& other) : impl_(std::make_unique<Impl>(*other.impl_)) {}
Metadata& Metadata::operator=(const Metadata& other) {
  if (this != &other) *impl_ = *other.impl_;
  return *this;
}
Metadata::Metadata(Metadata&& other) noexcept : impl_(std::make_unique<Impl>()) {
  std::swap(impl_, other.impl_);
}
Metadata& Metadata::operator=(Metadata&& other) noexcept {
  std::swap(impl_, other.impl_);
  return *this;
}

std::vector<std::string> Metadata::names() const {
  std::vector<std::string> out;
  for (const auto& p : impl_->attributes) out.push_back(p.name().string());
  return out;
}

bool Metadata::contains(const std::string& name) const {
  return impl_->attributes.contains(name);
}

std::optional<std::string> Metadata::get_string(const std::string& name) const {
  auto it = impl_->attributes.find(name);
  if (it == impl_->attributes.end()) return std::nullopt;
  return it->get_string();
}

std::optional<double> Metadata::get_number(const std::string& name) const {
  auto it = impl_->attributes.find(name);
  if (it == impl_->attributes.end()) return std::nullopt;
  const OIIO::TypeDesc t = it->type();
  if (t.basetype == OIIO::TypeDesc::STRING || t.basetype == OIIO::TypeDesc::UNKNOWN ||
      t.basetype == OIIO::TypeDesc::PTR)
    return std::nullopt;
  if (t.vecsemantics == OIIO::TypeDesc::RATIONAL) {  // two ints: numerator, denominator
    const int* v = static_cast<const int*>(it->data());
    return v[1] == 0 ? std::nullopt : std::optional<double>(double(v[0]) / v[1]);
  }
  // The first element, read by type: OIIO 2.4's get_float_indexed returns 0 for INT values.
  const void* d = it->data();
  switch (t.basetype) {
    case OIIO::TypeDesc::INT8: return double(*static_cast<const std::int8_t*>(d));
    case OIIO::TypeDesc::UINT8: return double(*static_cast<const std::uint8_t*>(d));
    case OIIO::TypeDesc::INT16: return double(*static_cast<const std::int16_t*>(d));
    case OIIO::TypeDesc::UINT16: return double(*static_cast<const std::uint16_t*>(d));
    case OIIO::TypeDesc::INT32: return double(*static_cast<const std::int32_t*>(d));
    case OIIO::TypeDesc::UINT32: return double(*static_cast<const std::uint32_t*>(d));
    case OIIO::TypeDesc::INT64: return double(*static_cast<const std::int64_t*>(d));
    case OIIO::TypeDesc::UINT64: return double(*static_cast<const std::uint64_t*>(d));
    case OIIO::TypeDesc::FLOAT: return double(*static_cast<const float*>(d));
    case OIIO::TypeDesc::DOUBLE: return *static_cast<const double*>(d);
    default: return it->get_float_indexed(0);  // HALF
  }
}

void Metadata::set(const std::string& name, const std::string& value) {
  impl_->attributes.attribute(name, value);
}

void Metadata::set(const std::string& name, double value) {
  impl_->attributes.attribute(name, float(value));
}

void Metadata::erase(const std::string& name) { impl_->attributes.remove(name); }

}  // namespace mr
