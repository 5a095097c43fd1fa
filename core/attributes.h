// Private to libmr: typed, named attributes as OpenImageIO keeps them (ParamValueList), without
// OpenImageIO. Its Util library alone (a static ustring table) cost every run of `mr` 0.07 s of
// start-up (issue 12), so libmr keeps mr::Metadata and image headers in this list and converts
// to and from OIIO's only inside its OIIO module (core/oiio_attributes.h, exact both ways: the
// same names, type codes, counts, interpolation, values and order).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace mr::detail {

/// OIIO::TypeDesc's fields as plain integers, with OIIO's codes (core/oiio_attributes.h checks
/// them): the base type of the values, the aggregate (1 scalar, 2..4 vectors, 9 and 16
/// matrices), their semantics and the array length (0: not an array).
struct DataType {
  enum Base : std::uint8_t {
    kUnknown,
    kNone,
    kUInt8,
    kInt8,
    kUInt16,
    kInt16,
    kUInt32,
    kInt32,
    kUInt64,
    kInt64,
    kHalf,
    kFloat,
    kDouble,
    kString,
    kPtr
  };
  enum Aggregate : std::uint8_t { kScalar = 1, kVec2 = 2, kVec3 = 3, kVec4 = 4 };
  enum Semantics : std::uint8_t {
    kNoSemantics,
    kColor,
    kPoint,
    kVector,
    kNormal,
    kTimecode,
    kKeycode,
    kRational,
    kBox
  };

  std::uint8_t basetype = kUnknown;
  std::uint8_t aggregate = kScalar;
  std::uint8_t vecsemantics = kNoSemantics;
  std::uint8_t reserved = 0;
  int arraylen = 0;

  constexpr DataType() = default;
  constexpr DataType(Base base, std::uint8_t aggregate_ = kScalar,
                     std::uint8_t semantics = kNoSemantics, int arraylen_ = 0)
      : basetype(base), aggregate(aggregate_), vecsemantics(semantics), arraylen(arraylen_) {}

  /// Bytes of one base value (a string is stored as a pointer in OIIO: its size).
  std::size_t basesize() const {
    switch (basetype) {
      case kUInt8:
      case kInt8: return 1;
      case kUInt16:
      case kInt16:
      case kHalf: return 2;
      case kUInt32:
      case kInt32:
      case kFloat: return 4;
      case kUInt64:
      case kInt64:
      case kDouble: return 8;
      case kString: return sizeof(const char*);
      case kPtr: return sizeof(void*);
      default: return 0;
    }
  }
  /// Elements of an array (1 if not an array).
  std::size_t numelements() const { return arraylen >= 1 ? std::size_t(arraylen) : 1; }
  /// Base values in all: elements times the aggregate.
  std::size_t basevalues() const { return numelements() * aggregate; }
  std::size_t size() const { return basevalues() * basesize(); }
  bool is_array() const { return arraylen != 0; }
  /// A single value of base type `b` (OIIO's TypeDesc == BASETYPE: semantics not compared).
  bool is(Base b) const { return basetype == b && aggregate == kScalar && !is_array(); }
  /// As OIIO's c_str ("uint8", "float", ...) for the base types, for messages.
  const char* base_name() const;

  friend bool operator==(const DataType& a, const DataType& b) {
    return a.basetype == b.basetype && a.aggregate == b.aggregate &&
           a.vecsemantics == b.vecsemantics && a.arraylen == b.arraylen;
  }
  friend bool operator!=(const DataType& a, const DataType& b) { return !(a == b); }
};

inline constexpr DataType kTypeUnknown{DataType::kUnknown};
inline constexpr DataType kTypeUInt8{DataType::kUInt8};
inline constexpr DataType kTypeUInt16{DataType::kUInt16};
inline constexpr DataType kTypeInt{DataType::kInt32};
inline constexpr DataType kTypeHalf{DataType::kHalf};
inline constexpr DataType kTypeFloat{DataType::kFloat};
inline constexpr DataType kTypeString{DataType::kString};
inline constexpr DataType kTypeRational{DataType::kInt32, DataType::kVec2, DataType::kRational};

/// One attribute: OIIO::ParamValue's contents. `nvalues` values of `type`; non-string values
/// as their bytes (native endianness), strings one per base value.
struct Attribute {
  std::string name;
  DataType type;
  int nvalues = 1;
  int interp = 0;                    ///< OIIO's ParamValue::Interp (0: constant)
  std::vector<unsigned char> bytes;  ///< nvalues * type.size() bytes, unless a string type
  std::vector<std::string> strings;  ///< nvalues * type.basevalues() strings, if a string type

  Attribute() = default;
  Attribute(std::string_view name, int value);
  Attribute(std::string_view name, float value);
  Attribute(std::string_view name, std::string_view value);
  /// `nvalues` values of `type` at `data` (for a string type: an array of `const char*`).
  Attribute(std::string_view name, DataType type, int nvalues, const void* data);

  /// As OIIO 2.4's ParamValue::get_int: the first value if single (not a vector) and an
  /// integer, a string only if it is entirely an integer; else `fallback`.
  int get_int(int fallback = 0) const;
  /// As OIIO 2.4's ParamValue::get_float: the first value if single and a number but a 32-bit
  /// int (OIIO 2.4 does not convert those), a rational divided (0 for a zero denominator), a
  /// string only if entirely a number; else `fallback`.
  float get_float(float fallback = 0) const;
  /// As ParamValue::get_string(maxsize): a single string itself, else the values as OIIO
  /// formats them (", " between values, rationals "n/d", strings quoted and escaped, at most
  /// `maxsize` values and then ", ... [N x type]").
  std::string get_string(int maxsize = 64) const;
  /// The first string (a string type), else "".
  const std::string& string_value() const;

  friend bool operator==(const Attribute& a, const Attribute& b) {
    return a.name == b.name && a.type == b.type && a.nvalues == b.nvalues && a.interp == b.interp &&
           a.bytes == b.bytes && a.strings == b.strings;
  }
};

/// OIIO::ParamValueList's behaviour, over Attribute: a vector in insertion order; lookups by
/// name case-sensitive unless said otherwise, as OIIO's defaults.
class AttributeList : public std::vector<Attribute> {
 public:
  /// The first attribute named `name` (and of `type`, unless kTypeUnknown).
  iterator find(std::string_view name, DataType type = kTypeUnknown, bool casesensitive = true);
  const_iterator find(std::string_view name, DataType type = kTypeUnknown,
                      bool casesensitive = true) const;
  bool contains(std::string_view name, DataType type = kTypeUnknown,
                bool casesensitive = true) const {
    return find(name, type, casesensitive) != cend();
  }
  void remove(std::string_view name, DataType type = kTypeUnknown, bool casesensitive = true);
  /// Replaces the first attribute of the same name in place, else appends.
  void add_or_replace(Attribute attribute, bool casesensitive = true);
  /// As ParamValueList::attribute: add_or_replace, nothing for an empty name.
  void attribute(std::string_view name, int value) { set(name, Attribute(name, value)); }
  void attribute(std::string_view name, float value) { set(name, Attribute(name, value)); }
  void attribute(std::string_view name, std::string_view value) {
    set(name, Attribute(name, value));
  }
  void attribute(std::string_view name, const char* value) {
    set(name, Attribute(name, std::string_view(value)));
  }
  void attribute(std::string_view name, const std::string& value) {
    set(name, Attribute(name, std::string_view(value)));
  }
  void attribute(std::string_view name, DataType type, const void* data) {
    set(name, Attribute(name, type, 1, data));
  }
  /// As ParamValueList::get_int / get_float (case-insensitive, converting).
  int get_int(std::string_view name, int fallback = 0) const;
  float get_float(std::string_view name, float fallback = 0) const;

 private:
  void set(std::string_view name, Attribute attribute) {
    if (!name.empty()) add_or_replace(std::move(attribute));
  }
};

/// Case-insensitive ASCII comparison (OIIO's Strutil::iequals for names).
bool iequals(std::string_view a, std::string_view b);

}  // namespace mr::detail
