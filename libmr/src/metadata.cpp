#include "mr/metadata.h"

#include "oiio_bridge.h"

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
  return it->get_float_indexed(0);
}

void Metadata::set(const std::string& name, const std::string& value) {
  impl_->attributes.attribute(name, value);
}

void Metadata::set(const std::string& name, double value) {
  impl_->attributes.attribute(name, float(value));
}

void Metadata::erase(const std::string& name) { impl_->attributes.remove(name); }

}  // namespace mr
