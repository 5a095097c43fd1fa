#include "mr/metadata.h"

#include <algorithm>
#include <cstdint>
#include <cstring>

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
  for (const auto& p : impl_->attributes) out.push_back(p.name);
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
  using detail::DataType;
  auto it = impl_->attributes.find(name);
  if (it == impl_->attributes.end()) return std::nullopt;
  const DataType t = it->type;
  if (t.basetype == DataType::kString || t.basetype == DataType::kUnknown ||
      t.basetype == DataType::kPtr)
    return std::nullopt;
  if (it->bytes.size() < std::max<std::size_t>(t.basesize() * t.aggregate, 1))
    return double(it->get_float());  // no value (NONE): 0, as OIIO's get_float_indexed
  const unsigned char* d = it->bytes.data();
  auto read = [d](auto value, std::size_t index) {
    std::memcpy(&value, d + index * sizeof value, sizeof value);
    return value;
  };
  if (t.vecsemantics == DataType::kRational) {  // two ints: numerator, denominator
    const std::int32_t num = read(std::int32_t(), 0), den = read(std::int32_t(), 1);
    return den == 0 ? std::nullopt : std::optional<double>(double(num) / den);
  }
  // The first element, read by type: OIIO 2.4's get_float_indexed returns 0 for INT values.
  switch (t.basetype) {
    case DataType::kInt8: return double(read(std::int8_t(), 0));
    case DataType::kUInt8: return double(read(std::uint8_t(), 0));
    case DataType::kInt16: return double(read(std::int16_t(), 0));
    case DataType::kUInt16: return double(read(std::uint16_t(), 0));
    case DataType::kInt32: return double(read(std::int32_t(), 0));
    case DataType::kUInt32: return double(read(std::uint32_t(), 0));
    case DataType::kInt64: return double(read(std::int64_t(), 0));
    case DataType::kUInt64: return double(read(std::uint64_t(), 0));
    case DataType::kFloat: return double(read(float(), 0));
    case DataType::kDouble: return read(double(), 0);
    default: return double(it->get_float());  // HALF
  }
}

void Metadata::set(const std::string& name, const std::string& value) {
  impl_->attributes.attribute(name, std::string_view(value));
}

void Metadata::set(const std::string& name, double value) {
  impl_->attributes.attribute(name, float(value));
}

void Metadata::erase(const std::string& name) {
  impl_->attributes.remove(name);
}

}  // namespace mr
