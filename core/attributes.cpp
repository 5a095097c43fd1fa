#include "core/attributes.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <type_traits>

namespace mr::detail {

namespace {

// IEEE half to float (normals, subnormals, infinities, NaN).
float half_to_float(std::uint16_t h) {
  const std::uint32_t sign = std::uint32_t(h >> 15) << 31;
  const int exponent = (h >> 10) & 0x1F;
  const std::uint32_t mantissa = h & 0x3FF;
  float magnitude;
  if (exponent == 0)
    magnitude = std::ldexp(float(mantissa), -24);
  else if (exponent == 31)
    magnitude = mantissa ? std::nanf("") : INFINITY;
  else
    magnitude = std::ldexp(float(mantissa | 0x400), exponent - 25);
  std::uint32_t bits;
  std::memcpy(&bits, &magnitude, 4);
  bits = (bits & 0x7FFFFFFF) | sign;
  float out;
  std::memcpy(&out, &bits, 4);
  return out;
}

template <typename T>
T load(const unsigned char* bytes, std::size_t index) {
  T v;
  std::memcpy(&v, bytes + index * sizeof(T), sizeof(T));
  return v;
}

// Value `i` (a base value) of a numeric type as double, for get_float and formatting.
double number_at(const Attribute& a, std::size_t i) {
  const unsigned char* b = a.bytes.data();
  switch (a.type.basetype) {
    case DataType::kUInt8:
      return load<std::uint8_t>(b, i);
    case DataType::kInt8:
      return load<std::int8_t>(b, i);
    case DataType::kUInt16:
      return load<std::uint16_t>(b, i);
    case DataType::kInt16:
      return load<std::int16_t>(b, i);
    case DataType::kUInt32:
      return load<std::uint32_t>(b, i);
    case DataType::kInt32:
      return load<std::int32_t>(b, i);
    case DataType::kUInt64:
      return double(load<std::uint64_t>(b, i));
    case DataType::kInt64:
      return double(load<std::int64_t>(b, i));
    case DataType::kHalf:
      return half_to_float(load<std::uint16_t>(b, i));
    case DataType::kFloat:
      return load<float>(b, i);
    case DataType::kDouble:
      return load<double>(b, i);
    default:
      return 0;
  }
}

// OIIO's "%g" of a float value (floats and halves as float, as OIIO passes them).
std::string format_g(double v) {
  char text[64];
  std::snprintf(text, sizeof text, "%g", v);
  return text;
}

// Base value `i` as OIIO's tostring formats it ("%d", "%u", "%g", "%p").
std::string format_value(const Attribute& a, std::size_t i) {
  const unsigned char* b = a.bytes.data();
  switch (a.type.basetype) {
    case DataType::kUInt8:
      return std::to_string(load<std::uint8_t>(b, i));
    case DataType::kInt8:
      return std::to_string(load<std::int8_t>(b, i));
    case DataType::kUInt16:
      return std::to_string(load<std::uint16_t>(b, i));
    case DataType::kInt16:
      return std::to_string(load<std::int16_t>(b, i));
    case DataType::kUInt32:
      return std::to_string(load<std::uint32_t>(b, i));
    case DataType::kInt32:
      return std::to_string(load<std::int32_t>(b, i));
    case DataType::kUInt64:
      return std::to_string(load<std::uint64_t>(b, i));
    case DataType::kInt64:
      return std::to_string(load<std::int64_t>(b, i));
    case DataType::kHalf:
    case DataType::kFloat:
    case DataType::kDouble:
      return format_g(number_at(a, i));
    case DataType::kPtr: {
      char text[32];
      std::snprintf(text, sizeof text, "%p", load<void*>(b, i));
      return text;
    }
    default:
      return "";
  }
}

// OIIO's Strutil::escape_chars: C escapes for quotes, backslashes and control characters.
std::string escape(const std::string& s) {
  std::string out;
  for (char c : s) {
    const char* e = c == '\n'   ? "\\n"
                    : c == '\t' ? "\\t"
                    : c == '\v' ? "\\v"
                    : c == '\b' ? "\\b"
                    : c == '\r' ? "\\r"
                    : c == '\f' ? "\\f"
                    : c == '\a' ? "\\a"
                    : c == '\\' ? "\\\\"
                    : c == '"'  ? "\\\""
                                : nullptr;
    if (e)
      out += e;
    else
      out += c;
  }
  return out;
}

// From OpenEXR's time code: the BCD fields of the first word.
int bcd_field(std::uint32_t value, int min_bit, int max_bit) {
  const std::uint32_t mask = ~(~0u << (max_bit - min_bit + 1)) << min_bit;
  const std::uint32_t bcd = (value & mask) >> min_bit;
  return int((bcd & 0x0F) + 10 * ((bcd >> 4) & 0x0F));
}

// The whole text (after leading white space) as a number, as OIIO's Strutil::parse_* and an
// empty rest.
template <typename T>
bool parse_whole(const std::string& s, T& value) {
  const char* p = s.c_str();
  while (std::isspace(static_cast<unsigned char>(*p))) ++p;
  if (!*p) return false;
  char* end = nullptr;
  if constexpr (std::is_same_v<T, int>) {
    const long v = std::strtol(p, &end, 10);
    value = int(v);
  } else {
    value = std::strtof(p, &end);
  }
  return end != p && end == s.c_str() + s.size();  // all of it, NULs too
}

}  // namespace

const char* DataType::base_name() const {
  static const char* const kNames[] = {"unknown", "void",  "uint8",  "int8",   "uint16",
                                       "int16",   "uint",  "int",    "uint64", "int64",
                                       "half",    "float", "double", "string", "pointer"};
  return basetype < sizeof kNames / sizeof kNames[0] ? kNames[basetype] : "unknown";
}

Attribute::Attribute(std::string_view name_, int value) : Attribute(name_, kTypeInt, 1, &value) {}
Attribute::Attribute(std::string_view name_, float value)
    : Attribute(name_, kTypeFloat, 1, &value) {}
Attribute::Attribute(std::string_view name_, std::string_view value)
    : name(name_), type(kTypeString), strings{std::string(value)} {}

Attribute::Attribute(std::string_view name_, DataType type_, int nvalues_, const void* data)
    : name(name_), type(type_), nvalues(nvalues_) {
  const std::size_t n = std::size_t(std::max(nvalues, 0));
  if (type.basetype == DataType::kString) {
    const auto* text = static_cast<const char* const*>(data);
    for (std::size_t i = 0; i < n * type.basevalues(); ++i)
      strings.emplace_back(text && text[i] ? text[i] : "");
  } else {
    bytes.assign(n * type.size(), 0);
    if (data && !bytes.empty()) std::memcpy(bytes.data(), data, bytes.size());
  }
}

// OIIO 2.4 converts the first element (the type without its array length) with convert_type:
// only single values convert, rationals to float only, and 32-bit ints never to float (as
// measured against OIIO 2.4.7: tests/direct_codecs_test.cpp).
int Attribute::get_int(int fallback) const {
  if (type.basetype == DataType::kString) {
    int v = fallback;
    return !strings.empty() && parse_whole(strings[0], v) ? v : fallback;
  }
  if (type.aggregate != DataType::kScalar || bytes.size() < type.basesize()) return fallback;
  switch (type.basetype) {
    case DataType::kUInt8: return load<std::uint8_t>(bytes.data(), 0);
    case DataType::kInt8: return load<std::int8_t>(bytes.data(), 0);
    case DataType::kUInt16: return load<std::uint16_t>(bytes.data(), 0);
    case DataType::kInt16: return load<std::int16_t>(bytes.data(), 0);
    case DataType::kUInt32: return int(load<std::uint32_t>(bytes.data(), 0));
    case DataType::kInt32: return load<std::int32_t>(bytes.data(), 0);
    case DataType::kUInt64: return int(load<std::uint64_t>(bytes.data(), 0));
    case DataType::kInt64: return int(load<std::int64_t>(bytes.data(), 0));
    default: return fallback;
  }
}

float Attribute::get_float(float fallback) const {
  if (type.basetype == DataType::kString) {
    float v = fallback;
    return !strings.empty() && parse_whole(strings[0], v) ? v : fallback;
  }
  if (type.basetype == DataType::kInt32 && type.aggregate == DataType::kVec2 &&
      type.vecsemantics == DataType::kRational && bytes.size() >= 8) {
    const int num = load<std::int32_t>(bytes.data(), 0);
    const int den = load<std::int32_t>(bytes.data(), 1);
    return den ? float(num) / float(den) : 0.0f;
  }
  if (type.aggregate != DataType::kScalar || bytes.size() < type.basesize()) return fallback;
  switch (type.basetype) {
    case DataType::kUInt8:
    case DataType::kInt8:
    case DataType::kUInt16:
    case DataType::kInt16:
    case DataType::kUInt32:
    case DataType::kUInt64:
    case DataType::kInt64:
    case DataType::kHalf:
    case DataType::kFloat:
    case DataType::kDouble: return float(number_at(*this, 0));
    default: return fallback;  // also INT32
  }
}

std::string Attribute::get_string(int maxsize) const {
  const std::size_t nfull = type.basevalues() * std::size_t(std::max(nvalues, 0));
  const std::size_t n = maxsize > 0 ? std::min(nfull, std::size_t(maxsize)) : nfull;
  // Several values, or fewer than all: OIIO formats them as one flat array of base values.
  const bool flat = nvalues > 1 || n < nfull;
  std::string out;
  if (type.basetype == DataType::kString) {
    if (!flat && !type.is_array() && type.aggregate == DataType::kScalar) return string_value();
    for (std::size_t i = 0; i < n; ++i)
      out += (i ? ", \"" : "\"") + escape(i < strings.size() ? strings[i] : "") + "\"";
  } else if (bytes.size() < nfull * type.basesize()) {
    return out;
  } else if (!flat && type.vecsemantics == DataType::kTimecode &&
             type.basetype == DataType::kUInt32 && type.aggregate == DataType::kScalar &&
             type.arraylen == 2) {
    const std::uint32_t t = load<std::uint32_t>(bytes.data(), 0);
    char text[32];
    std::snprintf(text, sizeof text, "%02d:%02d:%02d:%02d", bcd_field(t, 24, 29),
                  bcd_field(t, 16, 22), bcd_field(t, 8, 14), bcd_field(t, 0, 5));
    out = text;
  } else if (!flat && type.vecsemantics == DataType::kRational &&
             type.aggregate == DataType::kVec2 &&
             (type.basetype == DataType::kInt32 || type.basetype == DataType::kUInt32)) {
    for (std::size_t i = 0; i < n; i += 2)
      out += (i ? ", " : "") + format_value(*this, i) + "/" + format_value(*this, i + 1);
  } else {
    for (std::size_t i = 0; i < n; ++i) out += (i ? ", " : "") + format_value(*this, i);
  }
  if (n < nfull) out += ", ... [" + std::to_string(nfull) + " x " + type.base_name() + "]";
  return out;
}

const std::string& Attribute::string_value() const {
  static const std::string kEmpty;
  return type.basetype == DataType::kString && !strings.empty() ? strings[0] : kEmpty;
}

bool iequals(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (std::tolower(static_cast<unsigned char>(a[i])) !=
        std::tolower(static_cast<unsigned char>(b[i])))
      return false;
  return true;
}

AttributeList::iterator AttributeList::find(std::string_view name, DataType type,
                                            bool casesensitive) {
  for (auto it = begin(); it != end(); ++it)
    if ((casesensitive ? it->name == name : iequals(it->name, name)) &&
        (type == kTypeUnknown || type == it->type))
      return it;
  return end();
}

AttributeList::const_iterator AttributeList::find(std::string_view name, DataType type,
                                                  bool casesensitive) const {
  return const_cast<AttributeList*>(this)->find(name, type, casesensitive);
}

void AttributeList::remove(std::string_view name, DataType type, bool casesensitive) {
  const auto it = find(name, type, casesensitive);
  if (it != end()) erase(it);
}

void AttributeList::add_or_replace(Attribute attribute, bool casesensitive) {
  const auto it = find(attribute.name, kTypeUnknown, casesensitive);
  if (it != end())
    *it = std::move(attribute);
  else
    push_back(std::move(attribute));
}

int AttributeList::get_int(std::string_view name, int fallback) const {
  const auto it = find(name, kTypeUnknown, false);
  return it == cend() ? fallback : it->get_int(fallback);
}

float AttributeList::get_float(std::string_view name, float fallback) const {
  const auto it = find(name, kTypeUnknown, false);
  return it == cend() ? fallback : it->get_float(fallback);
}

}  // namespace mr::detail
