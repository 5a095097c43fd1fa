// Private to libmr: mr's attribute lists (core/attributes.h) as OpenImageIO's ParamValueList and
// back, for code that links OIIO itself (the OIIO module, tests). Header-only, so libmr.so does
// not need libOpenImageIO_Util. Exact both ways: names, type codes, value counts,
// interpolation, values (bytes; strings as ustrings, embedded NULs too) and order.
#pragma once

#include <OpenImageIO/paramlist.h>
#include <OpenImageIO/typedesc.h>
#include <OpenImageIO/ustring.h>

#include <cstring>
#include <vector>

#include "core/attributes.h"

namespace mr::detail {

// DataType's codes are OIIO's.
static_assert(int(DataType::kUnknown) == int(OIIO::TypeDesc::UNKNOWN) &&
              int(DataType::kNone) == int(OIIO::TypeDesc::NONE) &&
              int(DataType::kUInt8) == int(OIIO::TypeDesc::UINT8) &&
              int(DataType::kInt8) == int(OIIO::TypeDesc::INT8) &&
              int(DataType::kUInt16) == int(OIIO::TypeDesc::UINT16) &&
              int(DataType::kInt16) == int(OIIO::TypeDesc::INT16) &&
              int(DataType::kUInt32) == int(OIIO::TypeDesc::UINT32) &&
              int(DataType::kInt32) == int(OIIO::TypeDesc::INT32) &&
              int(DataType::kUInt64) == int(OIIO::TypeDesc::UINT64) &&
              int(DataType::kInt64) == int(OIIO::TypeDesc::INT64) &&
              int(DataType::kHalf) == int(OIIO::TypeDesc::HALF) &&
              int(DataType::kFloat) == int(OIIO::TypeDesc::FLOAT) &&
              int(DataType::kDouble) == int(OIIO::TypeDesc::DOUBLE) &&
              int(DataType::kString) == int(OIIO::TypeDesc::STRING) &&
              int(DataType::kPtr) == int(OIIO::TypeDesc::PTR));
static_assert(int(DataType::kScalar) == int(OIIO::TypeDesc::SCALAR) &&
              int(DataType::kVec2) == int(OIIO::TypeDesc::VEC2) &&
              int(DataType::kVec3) == int(OIIO::TypeDesc::VEC3) &&
              int(DataType::kVec4) == int(OIIO::TypeDesc::VEC4));
static_assert(int(DataType::kNoSemantics) == int(OIIO::TypeDesc::NOSEMANTICS) &&
              int(DataType::kColor) == int(OIIO::TypeDesc::COLOR) &&
              int(DataType::kPoint) == int(OIIO::TypeDesc::POINT) &&
              int(DataType::kVector) == int(OIIO::TypeDesc::VECTOR) &&
              int(DataType::kNormal) == int(OIIO::TypeDesc::NORMAL) &&
              int(DataType::kTimecode) == int(OIIO::TypeDesc::TIMECODE) &&
              int(DataType::kKeycode) == int(OIIO::TypeDesc::KEYCODE) &&
              int(DataType::kRational) == int(OIIO::TypeDesc::RATIONAL) &&
              int(DataType::kBox) == int(OIIO::TypeDesc::BOX));

inline OIIO::TypeDesc to_oiio(DataType t) {
  OIIO::TypeDesc out(OIIO::TypeDesc::BASETYPE(t.basetype), OIIO::TypeDesc::AGGREGATE(t.aggregate),
                     OIIO::TypeDesc::VECSEMANTICS(t.vecsemantics), t.arraylen);
  out.reserved = t.reserved;
  return out;
}

inline DataType from_oiio(OIIO::TypeDesc t) {
  DataType out(DataType::Base(t.basetype), t.aggregate, t.vecsemantics, t.arraylen);
  out.reserved = t.reserved;
  return out;
}

inline OIIO::ParamValue to_oiio(const Attribute& a) {
  const OIIO::TypeDesc type = to_oiio(a.type);
  if (a.type.basetype != DataType::kString)
    return OIIO::ParamValue(a.name, type, a.nvalues, OIIO::ParamValue::Interp(a.interp),
                            a.bytes.empty() ? nullptr : a.bytes.data());
  // Zeroed storage (null ustrings), then each string interned whole (NULs included).
  OIIO::ParamValue p(a.name, type, a.nvalues, OIIO::ParamValue::Interp(a.interp), nullptr);
  auto* u = static_cast<OIIO::ustring*>(const_cast<void*>(p.data()));
  for (std::size_t i = 0; i < a.strings.size(); ++i) u[i] = OIIO::ustring(a.strings[i]);
  return p;
}

inline Attribute from_oiio(const OIIO::ParamValue& p) {
  Attribute a;
  a.name = p.name().string();
  a.type = from_oiio(p.type());
  a.nvalues = p.nvalues();
  a.interp = int(p.interp());
  const std::size_t n = std::size_t(std::max(p.nvalues(), 0));
  if (a.type.basetype == DataType::kString) {
    const auto* u = static_cast<const OIIO::ustring*>(p.data());
    for (std::size_t i = 0; i < n * a.type.basevalues(); ++i) a.strings.push_back(u[i].string());
  } else {
    const auto* b = static_cast<const unsigned char*>(p.data());
    a.bytes.assign(b, b + n * a.type.size());
  }
  return a;
}

inline OIIO::ParamValueList to_oiio(const AttributeList& list) {
  OIIO::ParamValueList out;
  out.reserve(list.size());
  for (const Attribute& a : list) out.push_back(to_oiio(a));
  return out;
}

inline AttributeList from_oiio(const OIIO::ParamValueList& list) {
  AttributeList out;
  out.reserve(list.size());
  for (const OIIO::ParamValue& p : list) out.push_back(from_oiio(p));
  return out;
}

}  // namespace mr::detail
