#include "jpeg_metadata.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <map>
#include <string>

namespace mr::detail {

namespace {

enum class Kind { text, integer, resolution, unit };
constexpr std::uint16_t kAscii = 2, kShort = 3, kLong = 4, kRational = 5, kUndefined = 7;
constexpr std::uint16_t kExifDirectory = 34665, kExifVersion = 36864, kComponents = 37121,
                        kFlashPixVersion = 40960, kColorSpace = 40961;

struct Field {
  const char* name;
  Kind kind;
};

const std::map<std::uint16_t, Field>& fields() {
  static const std::map<std::uint16_t, Field> table = {{270, {"ImageDescription", Kind::text}},
                                                       {271, {"Make", Kind::text}},
                                                       {272, {"Model", Kind::text}},
                                                       {274, {"Orientation", Kind::integer}},
                                                       {282, {"XResolution", Kind::resolution}},
                                                       {283, {"YResolution", Kind::resolution}},
                                                       {296, {"ResolutionUnit", Kind::unit}},
                                                       {305, {"Software", Kind::text}},
                                                       {306, {"DateTime", Kind::text}},
                                                       {315, {"Artist", Kind::text}},
                                                       {33432, {"Copyright", Kind::text}}};
  return table;
}

const std::pair<const std::uint16_t, Field>* field_named(const std::string& name) {
  for (const auto& entry : fields())
    if (name == entry.second.name) return &entry;
  return nullptr;
}

// A float as a TIFF rational that gives it back exactly (num / den in float), or false.
bool as_rational(float value, std::uint32_t& num, std::uint32_t& den) {
  if (!(value >= 0) || !std::isfinite(value)) return false;
  for (std::uint32_t d = 1; d <= (1u << 20); d *= 2) {
    const double n = double(value) * d;
    if (n > 4294967295.0) return false;
    if (n == std::floor(n) && float(double(std::uint32_t(n)) / d) == value) {
      num = std::uint32_t(n), den = d;
      return true;
    }
  }
  return false;
}

}  // namespace

bool decode_tiff_fields(const unsigned char* data, std::size_t size, AttributeList& out) {
  if (size < 8) return false;
  const bool little = data[0] == 'I' && data[1] == 'I';
  if (!little && !(data[0] == 'M' && data[1] == 'M')) return false;
  auto u16 = [&](std::size_t at) {
    return std::uint16_t(little ? data[at] | data[at + 1] << 8 : data[at] << 8 | data[at + 1]);
  };
  auto u32 = [&](std::size_t at) {
    return little ? std::uint32_t(data[at]) | std::uint32_t(data[at + 1]) << 8 |
                        std::uint32_t(data[at + 2]) << 16 | std::uint32_t(data[at + 3]) << 24
                  : std::uint32_t(data[at]) << 24 | std::uint32_t(data[at + 1]) << 16 |
                        std::uint32_t(data[at + 2]) << 8 | std::uint32_t(data[at + 3]);
  };
  if (u16(2) != 42) return false;
  // The Exif sub-directory OIIO writes for an sRGB image: versions 0230 and 0100, colour
  // space 1 (sRGB), decoded where IFD0 points to it.
  auto exif_directory = [&](std::size_t at) {
    if (at + 2 > size) return false;
    const std::size_t n = u16(at);
    if (at + 2 + n * 12 > size) return false;
    for (std::size_t i = 0; i < n; ++i) {
      const std::size_t e = at + 2 + i * 12;
      const std::uint16_t tag = u16(e), type = u16(e + 2);
      const std::uint32_t count = u32(e + 4);
      if ((tag == kExifVersion || tag == kFlashPixVersion) && type == kUndefined && count == 4) {
        const std::string_view v(reinterpret_cast<const char*>(data + e + 8), 4);
        out.push_back(
            Attribute(tag == kExifVersion ? "Exif:ExifVersion" : "Exif:FlashPixVersion", v));
      } else if (tag == kComponents && type == kUndefined && count == 4) {
        // ComponentsConfiguration: OIIO writes it (Y, Cb, Cr) and reads nothing from it.
      } else if (tag == kColorSpace && type == kShort && count == 1 && u16(e + 8) == 1) {
        const std::uint16_t srgb = 1;
        out.push_back(Attribute("Exif:ColorSpace", kTypeUInt16, 1, &srgb));
      } else {
        return false;
      }
    }
    return true;
  };
  const std::size_t ifd = u32(4);
  if (ifd + 2 > size) return false;
  const std::size_t count = u16(ifd);
  if (ifd + 2 + count * 12 > size) return false;
  for (std::size_t i = 0; i < count; ++i) {
    const std::size_t e = ifd + 2 + i * 12;
    const std::uint16_t tag = u16(e), type = u16(e + 2);
    const std::uint32_t n = u32(e + 4);
    if (tag == kExifDirectory) {
      if (type != kLong || n != 1 || !exif_directory(u32(e + 8))) return false;
      continue;
    }
    const auto it = fields().find(tag);
    if (it == fields().end()) return false;
    const Field& f = it->second;
    if (f.kind == Kind::text) {
      if (type != kAscii) return false;
      const std::size_t at = n <= 4 ? e + 8 : u32(e + 8);
      if (at + n > size) return false;
      std::size_t len = n;
      while (len && data[at + len - 1] == 0) --len;  // the terminating NULs
      out.push_back(
          Attribute(f.name, std::string_view(reinterpret_cast<const char*>(data + at), len)));
    } else if (f.kind == Kind::integer || f.kind == Kind::unit) {
      if (type != kShort || n != 1) return false;
      const int v = u16(e + 8);
      if (f.kind == Kind::integer) {
        const std::uint16_t stored = std::uint16_t(v);  // SHORT: OIIO keeps it uint16
        out.push_back(Attribute(f.name, kTypeUInt16, 1, &stored));
      } else {
        if (v < 1 || v > 3) return false;
        out.push_back(Attribute(f.name, std::string_view(v == 1 ? "none" : v == 2 ? "in" : "cm")));
      }
    } else {
      if (type != kRational || n != 1) return false;
      const std::size_t at = u32(e + 8);
      if (at + 8 > size) return false;
      const std::uint32_t num = u32(at), den = u32(at + 4);
      if (den == 0) return false;
      out.push_back(Attribute(f.name, float(double(num) / double(den))));
    }
  }
  return true;
}

bool is_tiff_field(const Attribute& p) {
  const auto* entry = field_named(p.name);
  if (!entry) return false;
  const DataType t = p.type;
  switch (entry->second.kind) {
    case Kind::text:
      return t.is(DataType::kString);
    case Kind::integer:
      return (t.is(DataType::kInt32) || t.is(DataType::kUInt16)) && p.get_int() >= 0 &&
             p.get_int() <= 65535;
    case Kind::unit: {  // not written to EXIF (as OIIO): the JFIF density unit holds it
      if (!t.is(DataType::kString)) return false;
      const std::string& v = p.string_value();
      return v == "none" || v == "in" || v == "cm";
    }
    case Kind::resolution: {
      std::uint32_t num = 0, den = 0;
      return t.is(DataType::kFloat) && as_rational(p.get_float(), num, den);
    }
  }
  return false;
}

std::vector<char> encode_tiff_fields(const AttributeList& attributes) {
  // In the attributes' order, as OIIO writes them (and reads them back).
  std::vector<std::pair<std::uint16_t, const Attribute*>> present;
  for (const Attribute& p : attributes)
    if (is_tiff_field(p) && p.name != "ResolutionUnit")
      present.emplace_back(field_named(p.name)->first, &p);
  const auto colour = attributes.find("oiio:ColorSpace", kTypeString, false);
  const bool exif_directory = colour != attributes.cend() && colour->string_value() == "sRGB";
  std::size_t pointer_entry = 0;
  std::vector<char> out;
  out.reserve(256);
  for (char c : {'E', 'x', 'i', 'f', '\0', '\0', 'I', 'I', '*', '\0'}) out.push_back(c);
  auto put16 = [&](std::uint16_t v) { out.push_back(char(v & 0xFF)), out.push_back(char(v >> 8)); };
  auto put32 = [&](std::uint32_t v) {
    for (int k = 0; k < 4; ++k) out.push_back(char((v >> (8 * k)) & 0xFF));
  };
  put32(8);
  const std::size_t entries = present.size() + (exif_directory ? 1 : 0);
  put16(std::uint16_t(entries));
  std::vector<char> extra;  // values longer than 4 bytes, after the directory
  const std::uint32_t extra_at = std::uint32_t(8 + 2 + entries * 12 + 4);
  for (const auto& [tag, p] : present) {
    const Field& f = fields().at(tag);
    put16(tag);
    if (f.kind == Kind::text) {
      std::string v = p->string_value();
      v.push_back('\0');
      put16(kAscii);
      put32(std::uint32_t(v.size()));
      if (v.size() <= 4) {
        v.resize(4, '\0');
        out.insert(out.end(), v.begin(), v.end());
      } else {
        put32(extra_at + std::uint32_t(extra.size()));
        extra.insert(extra.end(), v.begin(), v.end());
        if (extra.size() % 2) extra.push_back(0);  // word alignment
      }
    } else if (f.kind == Kind::integer || f.kind == Kind::unit) {
      const std::string unit = f.kind == Kind::unit ? p->get_string() : "";
      const int v = f.kind == Kind::integer ? p->get_int()
                    : unit == "none"        ? 1
                    : unit == "in"          ? 2
                                            : 3;
      put16(kShort);
      put32(1);
      put16(std::uint16_t(v));
      put16(0);
    } else {
      std::uint32_t num = 0, den = 1;
      as_rational(p->get_float(), num, den);
      put16(kRational);
      put32(1);
      put32(extra_at + std::uint32_t(extra.size()));
      for (std::uint32_t v : {num, den})
        for (int k = 0; k < 4; ++k) extra.push_back(char((v >> (8 * k)) & 0xFF));
    }
  }
  if (exif_directory) {  // the pointer to the Exif directory: the last tag of IFD0
    pointer_entry = out.size();
    put16(kExifDirectory);
    put16(kLong);
    put32(1);
    put32(0);  // set below
  }
  put32(0);              // no next directory
  if (exif_directory) {  // "0230", Y Cb Cr, "0100", sRGB (values of 4 bytes sit in the entries)
    out.insert(out.end(), extra.begin(), extra.end());
    extra.clear();
    if ((out.size() - 6) % 2) out.push_back(0);
    const std::uint32_t at = std::uint32_t(out.size() - 6);
    const std::size_t pointer_value = pointer_entry + 8;
    for (int k = 0; k < 4; ++k) out[pointer_value + k] = char((at >> (8 * k)) & 0xFF);
    put16(4);
    for (const auto& [tag, value] : {std::pair<std::uint16_t, const char*>{kExifVersion, "0230"},
                                     {kComponents, "\1\2\3\0"},
                                     {kFlashPixVersion, "0100"}}) {
      put16(tag);
      put16(kUndefined);
      put32(4);
      out.insert(out.end(), value, value + 4);
    }
    put16(kColorSpace);
    put16(kShort);
    put32(1);
    put16(1);
    put16(0);
    put32(0);
  }
  out.insert(out.end(), extra.begin(), extra.end());
  return out;
}

namespace {

struct Dataset {
  int number;
  const char* field;  // the attribute OIIO writes it from
  const char* name;   // the attribute OIIO reads it as
};
constexpr Dataset kDatasets[] = {{65, "Software", "IPTC:OriginatingProgram"},
                                 {80, "Artist", "IPTC:Creator"},
                                 {116, "Copyright", "IPTC:CopyrightNotice"}};

}  // namespace

bool decode_iptc(const unsigned char* data, std::size_t size, AttributeList& out) {
  std::size_t at = 0;
  while (at < size) {
    // An image resource: "8BIM", id, a padded Pascal name, a size, padded data.
    if (at + 12 > size || std::memcmp(data + at, "8BIM", 4) != 0) return false;
    const int id = data[at + 4] << 8 | data[at + 5];
    std::size_t p = at + 6;
    const std::size_t name_len = data[p];
    p += (name_len + 2) & ~std::size_t(1);
    if (p + 4 > size) return false;
    const std::size_t len = std::size_t(data[p]) << 24 | std::size_t(data[p + 1]) << 16 |
                            std::size_t(data[p + 2]) << 8 | data[p + 3];
    p += 4;
    if (id != 0x0404 || p + len > size) return false;
    for (std::size_t q = p; q < p + len;) {
      if (q + 5 > p + len || data[q] != 0x1C || data[q + 1] != 2) return false;
      const int number = data[q + 2];
      const std::size_t n = std::size_t(data[q + 3]) << 8 | data[q + 4];
      if ((n & 0x8000) || q + 5 + n > p + len) return false;
      const Dataset* d = nullptr;
      for (const Dataset& k : kDatasets)
        if (k.number == number) d = &k;
      if (!d) return false;
      out.push_back(
          Attribute(d->name, std::string_view(reinterpret_cast<const char*>(data + q + 5), n)));
      q += 5 + n;
    }
    at = p + len + (len & 1);
  }
  return true;
}

std::vector<char> encode_iptc(const AttributeList& attributes) {
  std::vector<char> iim;
  for (const Dataset& d : kDatasets) {
    const auto it = attributes.find(d.field, kTypeString, false);
    if (it == attributes.cend()) continue;
    const std::string& v = it->string_value();
    const std::size_t n = std::min<std::size_t>(v.size(), 0x7FFF);
    for (int c : {0x1C, 2, d.number, int(n >> 8), int(n & 0xFF)}) iim.push_back(char(c));
    iim.insert(iim.end(), v.begin(), v.begin() + std::ptrdiff_t(n));
  }
  if (iim.empty()) return {};
  std::vector<char> out;
  for (char c : std::string("Photoshop 3.0") + '\0' + "8BIM") out.push_back(c);
  for (int c : {0x04, 0x04, 0, 0}) out.push_back(char(c));
  for (int shift : {24, 16, 8, 0}) out.push_back(char((iim.size() >> shift) & 0xFF));
  out.insert(out.end(), iim.begin(), iim.end());
  return out;
}

}  // namespace mr::detail
