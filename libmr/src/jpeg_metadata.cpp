#include "jpeg_metadata.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <map>
#include <set>
#include <string>

namespace mr::detail {

namespace {

constexpr std::uint16_t kAscii = 2, kShort = 3, kLong = 4, kRational = 5, kUndefined = 7;
constexpr std::uint16_t kExifDirectory = 34665, kExifVersion = 36864, kComponents = 37121,
                        kFlashPixVersion = 40960, kColorSpace = 40961;

}  // namespace

namespace {

// OIIO 2.4's EXIF tag tables (libOpenImageIO/exif.cpp): the attribute each tag of IFD0, the Exif
// and interoperability directories (one table for all three) and the GPS directory is read as.
// `skip`: OIIO knows the tag and reads nothing from it. `handler`: OIIO reads it its own way.
enum class Handler { none, skip, version_text, version_ints, maker_note };
struct ExifTag {
  std::uint16_t tag;
  const char* name;
  Handler handler;
};

// clang-format off
constexpr ExifTag kExifTags[] = {
    {256, "Exif:ImageWidth", Handler::skip}, {257, "Exif:ImageLength", Handler::skip},
    {258, "Exif:BitsPerSample", Handler::skip}, {259, "Exif:Compression", Handler::skip},
    {262, "Exif:Photometric", Handler::skip}, {277, "Exif:SamplesPerPixel", Handler::skip},
    {284, "Exif:PlanarConfig", Handler::skip},
    {530, "Exif:YCbCrSubsampling", Handler::none}, {531, "Exif:YCbCrPositioning", Handler::none},
    {274, "Orientation", Handler::none}, {282, "XResolution", Handler::none},
    {283, "YResolution", Handler::none}, {296, "ResolutionUnit", Handler::none},
    {270, "ImageDescription", Handler::none}, {271, "Make", Handler::none},
    {272, "Model", Handler::none}, {305, "Software", Handler::none},
    {315, "Artist", Handler::none}, {33432, "Copyright", Handler::none},
    {306, "DateTime", Handler::none},
    {33434, "ExposureTime", Handler::none}, {33437, "FNumber", Handler::none},
    {34850, "Exif:ExposureProgram", Handler::none},
    {34852, "Exif:SpectralSensitivity", Handler::none},
    // 34855 is listed twice (ISOSpeedRatings, then PhotographicSensitivity): the later wins.
    {34856, "Exif:OECF", Handler::skip},
    {36864, "Exif:ExifVersion", Handler::version_text},
    {36867, "Exif:DateTimeOriginal", Handler::none}, {36868, "Exif:DateTimeDigitized", Handler::none},
    {36880, "Exif:OffsetTime", Handler::none}, {36881, "Exif:OffsetTimeOriginal", Handler::none},
    {36882, "Exif:OffsetTimeDigitized", Handler::none},
    {37121, "Exif:ComponentsConfiguration", Handler::none},
    {37122, "Exif:CompressedBitsPerPixel", Handler::none},
    {37377, "Exif:ShutterSpeedValue", Handler::none}, {37378, "Exif:ApertureValue", Handler::none},
    {37379, "Exif:BrightnessValue", Handler::none}, {37380, "Exif:ExposureBiasValue", Handler::none},
    {37381, "Exif:MaxApertureValue", Handler::none}, {37382, "Exif:SubjectDistance", Handler::none},
    {37383, "Exif:MeteringMode", Handler::none}, {37384, "Exif:LightSource", Handler::none},
    {37385, "Exif:Flash", Handler::none}, {37386, "Exif:FocalLength", Handler::none},
    {37394, "Exif:SecurityClassification", Handler::none},
    {37395, "Exif:ImageHistory", Handler::none}, {37396, "Exif:SubjectArea", Handler::skip},
    {37500, "Exif:MakerNote", Handler::maker_note}, {37510, "Exif:UserComment", Handler::none},
    {37520, "Exif:SubsecTime", Handler::none}, {37521, "Exif:SubsecTimeOriginal", Handler::none},
    {37522, "Exif:SubsecTimeDigitized", Handler::none},
    {40960, "Exif:FlashPixVersion", Handler::version_text},
    {40961, "Exif:ColorSpace", Handler::none}, {40962, "Exif:PixelXDimension", Handler::none},
    {40963, "Exif:PixelYDimension", Handler::none}, {40964, "Exif:RelatedSoundFile", Handler::none},
    {41483, "Exif:FlashEnergy", Handler::none},
    {41484, "Exif:SpatialFrequencyResponse", Handler::skip},
    {41486, "Exif:FocalPlaneXResolution", Handler::none},
    {41487, "Exif:FocalPlaneYResolution", Handler::none},
    {41488, "Exif:FocalPlaneResolutionUnit", Handler::none},
    {41492, "Exif:SubjectLocation", Handler::none}, {41493, "Exif:ExposureIndex", Handler::none},
    {41495, "Exif:SensingMethod", Handler::none}, {41728, "Exif:FileSource", Handler::none},
    {41729, "Exif:SceneType", Handler::none}, {41730, "Exif:CFAPattern", Handler::skip},
    {41985, "Exif:CustomRendered", Handler::none}, {41986, "Exif:ExposureMode", Handler::none},
    {41987, "Exif:WhiteBalance", Handler::none}, {41988, "Exif:DigitalZoomRatio", Handler::none},
    {41989, "Exif:FocalLengthIn35mmFilm", Handler::none},
    {41990, "Exif:SceneCaptureType", Handler::none}, {41991, "Exif:GainControl", Handler::none},
    {41992, "Exif:Contrast", Handler::none}, {41993, "Exif:Saturation", Handler::none},
    {41994, "Exif:Sharpness", Handler::none},
    {41995, "Exif:DeviceSettingDescription", Handler::skip},
    {41996, "Exif:SubjectDistanceRange", Handler::none},
    {42016, "Exif:ImageUniqueID", Handler::none},
    {34855, "Exif:PhotographicSensitivity", Handler::none},
    {34864, "Exif:SensitivityType", Handler::none},
    {34865, "Exif:StandardOutputSensitivity", Handler::none},
    {34866, "Exif:RecommendedExposureIndex", Handler::none},
    {34867, "Exif:ISOSpeed", Handler::none}, {34868, "Exif:ISOSpeedLatitudeyyy", Handler::none},
    {34869, "Exif:ISOSpeedLatitudezzz", Handler::none},
    {37888, "Exif:Temperature", Handler::none}, {37889, "Exif:Humidity", Handler::none},
    {37890, "Exif:Pressure", Handler::none}, {37891, "Exif:WaterDepth", Handler::none},
    {37892, "Exif:Acceleration", Handler::none}, {37893, "Exif:CameraElevationAngle", Handler::none},
    {42032, "Exif:CameraOwnerName", Handler::none}, {42033, "Exif:BodySerialNumber", Handler::none},
    {42034, "Exif:LensSpecification", Handler::none}, {42035, "Exif:LensMake", Handler::none},
    {42036, "Exif:LensModel", Handler::none}, {42037, "Exif:LensSerialNumber", Handler::none},
    {42240, "Exif:Gamma", Handler::none}};

constexpr ExifTag kGpsTags[] = {
    {0, "GPS:VersionID", Handler::version_ints}, {1, "GPS:LatitudeRef", Handler::none},
    {2, "GPS:Latitude", Handler::none}, {3, "GPS:LongitudeRef", Handler::none},
    {4, "GPS:Longitude", Handler::none}, {5, "GPS:AltitudeRef", Handler::none},
    {6, "GPS:Altitude", Handler::none}, {7, "GPS:TimeStamp", Handler::none},
    {8, "GPS:Satellites", Handler::none}, {9, "GPS:Status", Handler::none},
    {10, "GPS:MeasureMode", Handler::none}, {11, "GPS:DOP", Handler::none},
    {12, "GPS:SpeedRef", Handler::none}, {13, "GPS:Speed", Handler::none},
    {14, "GPS:TrackRef", Handler::none}, {15, "GPS:Track", Handler::none},
    {16, "GPS:ImgDirectionRef", Handler::none}, {17, "GPS:ImgDirection", Handler::none},
    {18, "GPS:MapDatum", Handler::none}, {19, "GPS:DestLatitudeRef", Handler::none},
    {20, "GPS:DestLatitude", Handler::none}, {21, "GPS:DestLongitudeRef", Handler::none},
    {22, "GPS:DestLongitude", Handler::none}, {23, "GPS:DestBearingRef", Handler::none},
    {24, "GPS:DestBearing", Handler::none}, {25, "GPS:DestDistanceRef", Handler::none},
    {26, "GPS:DestDistance", Handler::none}, {27, "GPS:ProcessingMethod", Handler::none},
    {28, "GPS:AreaInformation", Handler::none}, {29, "GPS:DateStamp", Handler::none},
    {30, "GPS:Differential", Handler::none}, {31, "GPS:HPositioningError", Handler::none}};
// clang-format on

constexpr std::uint16_t kGpsDirectory = 34853, kInteropDirectory = 40965;
constexpr std::uint16_t kByte = 1, kSRational = 10;

const ExifTag* find_tag(bool gps, std::uint16_t tag) {
  if (gps) {
    for (const ExifTag& t : kGpsTags)
      if (t.tag == tag) return &t;
    return nullptr;
  }
  for (const ExifTag& t : kExifTags)
    if (t.tag == tag) return &t;
  return nullptr;
}

// Bytes of one value of a TIFF type (0: not a type OIIO knows).
std::size_t type_size(std::uint16_t type) {
  static constexpr std::size_t sizes[] = {0, 1, 1, 2, 4, 8, 1, 1, 2, 4, 8, 4, 8, 4};
  return type < 14 ? sizes[type] : 0;
}

// One EXIF block's TIFF structure, read as OIIO 2.4's decode_exif reads it. Every step that OIIO
// takes in a way this does not reproduce (or that depends on its reading out of bounds) makes
// the whole block fail, and the file goes to OIIO.
class ExifDecoder {
 public:
  ExifDecoder(const unsigned char* data, std::size_t size, AttributeList& out)
      : data_(data), size_(size), out_(out) {}

  bool decode() {
    if (size_ < 8) return false;
    little_ = data_[0] == 'I' && data_[1] == 'I';
    if (!little_ && !(data_[0] == 'M' && data_[1] == 'M')) return false;
    if (u16(2) != 42) return false;
    if (!directory(u32(4), false)) return false;
    // OIIO reads a maker note only for Canon (into Canon:* attributes): those go to OIIO.
    const auto make = out_.find("Make", kTypeString);
    if (maker_note_ && make != out_.end() && iequals(make->string_value(), "Canon")) return false;
    return true;
  }

 private:
  std::uint16_t u16(std::size_t at) const {
    return std::uint16_t(little_ ? data_[at] | data_[at + 1] << 8 : data_[at] << 8 | data_[at + 1]);
  }
  std::uint32_t u32(std::size_t at) const {
    const std::uint32_t b0 = data_[at], b1 = data_[at + 1], b2 = data_[at + 2], b3 = data_[at + 3];
    return little_ ? b0 | b1 << 8 | b2 << 16 | b3 << 24 : b0 << 24 | b1 << 16 | b2 << 8 | b3;
  }

  bool directory(std::size_t at, bool gps) {
    if (at >= size_ || at + 2 > size_ || !seen_.insert(at).second) return false;
    const std::size_t n = u16(at);
    // OIIO skips a GPS directory of more than 32 entries (a count in the wrong byte order).
    if (gps && n > 32) return true;
    // OIIO ignores an entry that reaches the block's last byte (a check of its own); such a
    // block goes to OIIO.
    if (at + 2 + n * 12 >= size_) return false;
    for (std::size_t i = 0; i < n; ++i)
      if (!entry(at + 2 + i * 12, gps)) return false;
    return true;
  }

  bool entry(std::size_t e, bool gps) {
    const std::uint16_t tag = u16(e), type = u16(e + 2);
    const std::uint32_t count = u32(e + 4);
    if (tag == kExifDirectory || tag == kGpsDirectory || tag == kInteropDirectory)
      return directory(u32(e + 8), tag == kGpsDirectory);
    const ExifTag* t = find_tag(gps, tag);
    if (!t || t->handler == Handler::skip) return true;  // OIIO ignores it
    const std::size_t size = type_size(type);
    if (size == 0 || count == 0) return false;
    const std::uint64_t len = std::uint64_t(size) * count;
    std::size_t at = e + 8;
    if (len > 4) {
      at = u32(e + 8);
      if (at + len > size_) return false;  // OIIO would drop it; left to OIIO
    }
    const std::string name = t->name;
    if (out_.contains(name)) return false;  // a tag twice: which wins is OIIO's business
    switch (t->handler) {
      case Handler::version_text:
        if (len != 4) return true;
        for (int k = 0; k < 4; ++k)
          if (data_[at + k] == 0) return false;
        out_.push_back(
            Attribute(name, std::string_view(reinterpret_cast<const char*>(data_ + at), 4)));
        return true;
      case Handler::version_ints: {
        if (len != 4) return true;
        const int v[4] = {data_[at], data_[at + 1], data_[at + 2], data_[at + 3]};
        out_.push_back(Attribute(
            name, DataType(DataType::kInt32, DataType::kScalar, DataType::kNoSemantics, 4), 1, v));
        return true;
      }
      case Handler::maker_note:
        // OIIO keeps the note's offset for after the block (read only for Canon) and drops it;
        // an offset of 0 stays behind as an attribute: OIIO's.
        if (len <= 4) return true;
        if (u32(e + 8) == 0 || maker_note_) return false;
        maker_note_ = true;
        return true;
      default:
        break;
    }
    const int n = int(count);
    auto typed = [&](DataType::Base b) {
      return DataType(b, DataType::kScalar, DataType::kNoSemantics, n == 1 ? 0 : n);
    };
    if (type == kShort) {
      std::vector<std::uint16_t> v(count);
      for (std::size_t k = 0; k < count; ++k) v[k] = u16(at + 2 * k);
      if (name == "ResolutionUnit") {  // OIIO names the unit
        if (count != 1 || v[0] < 1 || v[0] > 3) return false;
        out_.push_back(Attribute(name, std::string_view(v[0] == 1   ? "none"
                                                        : v[0] == 2 ? "in"
                                                                    : "cm")));
        return true;
      }
      out_.push_back(Attribute(name, typed(DataType::kUInt16), 1, v.data()));
    } else if (type == kLong) {
      std::vector<std::uint32_t> v(count);
      for (std::size_t k = 0; k < count; ++k) v[k] = u32(at + 4 * k);
      out_.push_back(Attribute(name, typed(DataType::kUInt32), 1, v.data()));
    } else if (type == kRational || type == kSRational) {
      std::vector<float> v(count);
      for (std::size_t k = 0; k < count; ++k) {
        const std::uint32_t num = u32(at + 8 * k), den = u32(at + 8 * k + 4);
        v[k] = type == kRational ? float(double(num) / double(den))
                                 : float(double(std::int32_t(num)) / double(std::int32_t(den)));
      }
      if (count == 1)
        out_.push_back(Attribute(name, v[0]));
      else
        out_.push_back(Attribute(name, typed(DataType::kFloat), 1, v.data()));
    } else if (type == kAscii) {
      std::size_t length = count;
      const char* text = reinterpret_cast<const char*>(data_ + at);
      while (length && text[length - 1] == 0) --length;  // the terminating NULs
      const std::size_t nul = std::string_view(text, length).find('\0');
      if (nul != std::string_view::npos) length = nul;  // a stray NUL ends it
      out_.push_back(Attribute(name, std::string_view(text, length)));
    } else if (type == kByte && count == 1) {
      out_.push_back(Attribute(name, int(data_[at])));
    }
    // Other types (UNDEFINED, SBYTE, SSHORT, SLONG, FLOAT, DOUBLE, several BYTEs): OIIO reads
    // nothing from them.
    return true;
  }

  const unsigned char* data_;
  std::size_t size_;
  AttributeList& out_;
  bool little_ = true;
  bool maker_note_ = false;
  std::set<std::size_t> seen_;
};

}  // namespace

bool decode_exif(const unsigned char* data, std::size_t size, AttributeList& out) {
  AttributeList decoded;
  if (!ExifDecoder(data, size, decoded).decode()) return false;
  for (Attribute& p : decoded) out.push_back(std::move(p));
  return true;
}

namespace {

// OIIO 2.4's encode_exif: each attribute whose name (any case) is in its tables is written with
// the table's TIFF type and count, whatever the attribute's own type. `count` 0: as long as the
// text.
struct WriteTag {
  std::uint16_t tag;
  std::uint16_t type;  // 0: OIIO writes nothing for it
  int count;
};

bool write_tag(std::string_view name, WriteTag& out) {
  // clang-format off
  static const std::map<std::string, WriteTag> table = [] {
    std::map<std::string, WriteTag> t;
    auto lower = [](std::string s) {
      for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
      return s;
    };
    // The types of OIIO's tables (kExifTags and kGpsTags name the same tags).
    const std::map<std::uint16_t, std::pair<std::uint16_t, int>> exif_types = {
        {530, {kShort, 1}}, {531, {kShort, 1}}, {274, {kShort, 1}}, {282, {kRational, 1}},
        {283, {kRational, 1}}, {296, {kShort, 1}}, {270, {kAscii, 0}}, {271, {kAscii, 0}},
        {272, {kAscii, 0}}, {305, {kAscii, 0}}, {315, {kAscii, 0}}, {33432, {kAscii, 0}},
        {306, {kAscii, 0}}, {33434, {kRational, 1}}, {33437, {kRational, 1}},
        {34850, {kShort, 1}}, {34852, {kAscii, 0}}, {34855, {kShort, 1}},
        {36867, {kAscii, 0}}, {36868, {kAscii, 0}}, {36880, {kAscii, 0}}, {36881, {kAscii, 0}},
        {36882, {kAscii, 0}}, {37122, {kRational, 1}}, {37377, {10, 1}}, {37378, {kRational, 1}},
        {37379, {10, 1}}, {37380, {10, 1}}, {37381, {kRational, 1}}, {37382, {kRational, 1}},
        {37383, {kShort, 1}}, {37384, {kShort, 1}}, {37385, {kShort, 1}},
        {37386, {kRational, 1}}, {37394, {kAscii, 1}}, {37395, {kAscii, 1}},
        {37520, {kAscii, 0}}, {37521, {kAscii, 0}}, {37522, {kAscii, 0}}, {40961, {kShort, 1}},
        {40962, {kLong, 1}}, {40963, {kLong, 1}}, {40964, {kAscii, 0}}, {41483, {kRational, 1}},
        {41486, {kRational, 1}}, {41487, {kRational, 1}}, {41488, {kShort, 1}},
        {41492, {kShort, 2}}, {41493, {kRational, 1}}, {41495, {kShort, 1}},
        {41985, {kShort, 1}}, {41986, {kShort, 1}}, {41987, {kShort, 1}},
        {41988, {kRational, 1}}, {41989, {kShort, 1}}, {41990, {kShort, 1}},
        {41991, {kRational, 1}}, {41992, {kShort, 1}}, {41993, {kShort, 1}},
        {41994, {kShort, 1}}, {41996, {kShort, 1}}, {42016, {kAscii, 0}}, {34864, {kShort, 1}},
        {34865, {kLong, 1}}, {34866, {kLong, 1}}, {34867, {kLong, 1}}, {34868, {kLong, 1}},
        {34869, {kLong, 1}}, {37888, {10, 1}}, {37889, {kRational, 1}},
        {37890, {kRational, 1}}, {37891, {10, 1}}, {37892, {kRational, 1}}, {37893, {10, 1}},
        {42032, {kAscii, 0}}, {42033, {kAscii, 0}}, {42034, {kRational, 4}},
        {42035, {kAscii, 0}}, {42036, {kAscii, 0}}, {42037, {kAscii, 0}},
        {42240, {kRational, 0}}, {37510, {1, 0}}, {37500, {1, 0}}};
    const std::map<std::uint16_t, std::pair<std::uint16_t, int>> gps_types = {
        {0, {1, 4}}, {1, {kAscii, 2}}, {2, {kRational, 3}}, {3, {kAscii, 2}},
        {4, {kRational, 3}}, {5, {1, 1}}, {6, {kRational, 1}}, {7, {kRational, 3}},
        {8, {kAscii, 0}}, {9, {kAscii, 2}}, {10, {kAscii, 2}}, {11, {kRational, 1}},
        {12, {kAscii, 2}}, {13, {kRational, 1}}, {14, {kAscii, 2}}, {15, {kRational, 1}},
        {16, {kAscii, 2}}, {17, {kRational, 1}}, {18, {kAscii, 0}}, {19, {kAscii, 2}},
        {20, {kRational, 3}}, {21, {kAscii, 2}}, {22, {kRational, 3}}, {23, {kAscii, 2}},
        {24, {kRational, 1}}, {25, {kAscii, 2}}, {26, {kRational, 1}}, {29, {kAscii, 0}},
        {30, {kShort, 1}}, {31, {kRational, 1}}};
    for (const ExifTag& e : kExifTags) {
      const auto it = exif_types.find(e.tag);
      t[lower(e.name)] = it == exif_types.end() ? WriteTag{e.tag, 0, 0}
                                                : WriteTag{e.tag, it->second.first, it->second.second};
    }
    t[lower("Exif:ISOSpeedRatings")] = {34855, kShort, 1};
    for (const ExifTag& e : kGpsTags) {
      const auto it = gps_types.find(e.tag);
      t[lower(e.name)] = it == gps_types.end() ? WriteTag{e.tag, 0, 0}
                                               : WriteTag{e.tag, it->second.first, it->second.second};
    }
    return t;
  }();
  // clang-format on
  std::string key(name);
  for (char& c : key) c = char(std::tolower(static_cast<unsigned char>(c)));
  const auto it = table.find(key);
  if (it == table.end()) return false;
  out = it->second;
  return true;
}

bool is_gps_name(std::string_view name) {
  return name.substr(0, 4) == "GPS:";
}

// OIIO's float_to_rational (fmath.h), quirks included: a float whose inverse is whole gets the
// denominator (int)f, 0 below 1 (0.5 is written 1/0 and reads back as infinity).
void float_to_rational(float f, std::uint32_t& num, std::uint32_t& den) {
  if (f <= 0) {
    num = 0, den = 1;
  } else if (double(int(1.0 / f)) == 1.0 / f) {
    num = 1, den = std::uint32_t(int(f));
  } else {
    num = std::uint32_t(int(f)), den = 1;
    while (std::fabs(f - static_cast<float>(num)) > 0.00001f && den < 1000000) {
      den *= 10, f *= 10, num = std::uint32_t(int(f));
    }
  }
}

void float_to_rational(float f, std::int32_t& num, std::int32_t& den) {
  std::uint32_t n = 0, d = 0;
  float_to_rational(std::fabs(f), n, d);
  num = f >= 0 ? std::int32_t(n) : -std::int32_t(n);
  den = std::int32_t(d);
}

// The values OIIO's writer reads from an attribute for a tag (a value of `type` for
// count one, else as said below), or false where OIIO's result is not reproduced here.
struct Entry {
  std::uint16_t tag = 0, type = 0;
  std::uint32_t count = 0;
  std::vector<unsigned char> bytes;  // little-endian
};

// Whether OIIO writes `p` (into `entry`); false in `ok` where this cannot say what OIIO does.
bool exif_entry(const Attribute& p, const WriteTag& t, Entry& entry, bool& ok) {
  ok = true;
  entry.tag = t.tag, entry.type = t.type;
  auto put = [&](std::uint32_t v, int bytes) {
    for (int k = 0; k < bytes; ++k) entry.bytes.push_back((unsigned char)((v >> (8 * k)) & 0xFF));
  };
  const DataType& type = p.type;
  const std::size_t values = std::size_t(p.nvalues) * type.numelements();
  switch (t.type) {
    case kAscii: {
      if (!type.is(DataType::kString)) return false;  // OIIO writes nothing
      const std::string& v = p.string_value();
      if (v.empty()) return false;  // nor for an empty text
      if (v.find('\0') != std::string::npos) return ok = false;
      entry.count = std::uint32_t(v.size() + 1);
      entry.bytes.assign(v.begin(), v.end());
      entry.bytes.push_back(0);
      return true;
    }
    case kRational:
    case 10: {
      if (type.basetype != DataType::kFloat) return false;  // OIIO writes nothing
      if (type.aggregate != DataType::kScalar || type.vecsemantics) return ok = false;
      if (t.count < 1 || values < std::size_t(t.count)) return ok = false;  // OIIO overreads
      const float* f = reinterpret_cast<const float*>(p.bytes.data());
      for (int k = 0; k < t.count; ++k) {
        if (t.type == kRational) {
          std::uint32_t num = 0, den = 0;
          float_to_rational(f[k], num, den);
          put(num, 4), put(den, 4);
        } else {
          std::int32_t num = 0, den = 0;
          float_to_rational(f[k], num, den);
          put(std::uint32_t(num), 4), put(std::uint32_t(den), 4);
        }
      }
      entry.count = std::uint32_t(t.count);
      return true;
    }
    case kShort:
    case kLong:
    case 1: {
      if (type.basetype == DataType::kString) {
        // OIIO 2.4 writes nothing for text; later versions parse whole numbers.
        for (const std::string& v : p.strings)
          if (v.find_first_of("0123456789") != std::string::npos) return ok = false;
        return false;
      }
      if (type.aggregate != DataType::kScalar || p.bytes.empty()) return ok = false;
      std::int64_t v = 0;
      switch (type.basetype) {
        case DataType::kUInt32:
          v = *reinterpret_cast<const std::uint32_t*>(p.bytes.data());
          break;
        case DataType::kInt32:
          v = *reinterpret_cast<const std::int32_t*>(p.bytes.data());
          break;
        case DataType::kUInt16:
          v = *reinterpret_cast<const std::uint16_t*>(p.bytes.data());
          break;
        case DataType::kInt16:
          v = *reinterpret_cast<const std::int16_t*>(p.bytes.data());
          break;
        case DataType::kFloat:
        case DataType::kDouble:
        case DataType::kHalf:
          return false;  // OIIO writes nothing

        default:
          return ok = false;  // bytes, 64-bit, text: OIIO's versions differ
      }
      entry.count = 1;
      put(std::uint32_t(v), t.type == kShort ? 2 : t.type == kLong ? 4 : 1);
      return true;
    }
    default:
      return false;  // UNDEFINED and the skipped tags: OIIO writes nothing
  }
}

struct Directories {
  std::vector<Entry> ifd0, exif, gps;
};

// Adds or replaces (in place, as OIIO's append_tiff_dir_entry) the entry for its tag.
void add(std::vector<Entry>& dir, Entry e) {
  for (Entry& d : dir)
    if (d.tag == e.tag) {
      d = std::move(e);
      return;
    }
  dir.push_back(std::move(e));
}

bool build_directories(const AttributeList& attributes, Directories& dirs) {
  for (const Attribute& p : attributes) {
    WriteTag t;
    if (!write_tag(p.name, t)) continue;
    // OIIO looks "GPS:" up (case-sensitively) in its GPS table, other names in its Exif table.
    if (iequals(p.name.substr(0, 4), "gps:") && !is_gps_name(p.name)) return false;
    Entry e;
    bool ok = true;
    if (!exif_entry(p, t, e, ok)) {
      if (!ok) return false;
      continue;
    }
    if (is_gps_name(p.name))
      add(dirs.gps, std::move(e));
    else if (t.tag < 33434 || t.tag > 42016)  // OIIO's range of the Exif directory
      add(dirs.ifd0, std::move(e));
    else
      add(dirs.exif, std::move(e));
  }
  // The sRGB colour space (OIIO's "sRGB" tag): an Exif ColorSpace of 1.
  const auto colour = attributes.find("oiio:ColorSpace", kTypeString, false);
  if (colour != attributes.cend() && colour->string_value() == "sRGB") {
    Entry e;
    e.tag = kColorSpace, e.type = kShort, e.count = 1, e.bytes = {1, 0};
    add(dirs.exif, std::move(e));
  }
  if (!dirs.exif.empty()) {
    for (const auto& [tag, value] : {std::pair<std::uint16_t, const char*>{kExifVersion, "0230"},
                                     {kFlashPixVersion, "0100"},
                                     {kComponents, "\1\2\3\0"}}) {
      Entry e;
      e.tag = tag, e.type = kUndefined, e.count = 4;
      e.bytes.assign(value, value + 4);
      add(dirs.exif, std::move(e));
    }
  }
  if (!dirs.gps.empty()) {
    Entry e;
    e.tag = 0, e.type = 1, e.count = 4, e.bytes = {2, 2, 0, 0};
    add(dirs.gps, std::move(e));
  }
  auto by_tag = [](const Entry& a, const Entry& b) { return a.tag < b.tag; };
  std::stable_sort(dirs.exif.begin(), dirs.exif.end(), by_tag);
  std::stable_sort(dirs.gps.begin(), dirs.gps.end(), by_tag);
  return true;
}

}  // namespace

bool is_exif_attribute(const Attribute& p) {
  WriteTag t;
  if (!write_tag(p.name, t)) return false;
  Entry e;
  bool ok = true;
  exif_entry(p, t, e, ok);
  return ok;
}

std::vector<char> encode_exif(const AttributeList& attributes) {
  Directories dirs;
  if (!build_directories(attributes, dirs)) return {};
  // Little-endian: the directories one after the other (IFD0 with the pointers to the Exif and
  // GPS directories last, as OIIO puts them), each followed by its values longer than 4 bytes.
  std::vector<char> out;
  for (char c : {'E', 'x', 'i', 'f', '\0', '\0', 'I', 'I', '*', '\0', '\x08', '\0', '\0', '\0'})
    out.push_back(c);
  const std::size_t base = 6;  // offsets count from the TIFF header
  auto put16 = [&](std::uint16_t v) { out.push_back(char(v & 0xFF)), out.push_back(char(v >> 8)); };
  auto put32 = [&](std::uint32_t v) {
    for (int k = 0; k < 4; ++k) out.push_back(char((v >> (8 * k)) & 0xFF));
  };
  auto set32 = [&](std::size_t at, std::uint32_t v) {
    for (int k = 0; k < 4; ++k) out[at + k] = char((v >> (8 * k)) & 0xFF);
  };
  // Writes a directory with `pointers` extra LONG entries (their value slots returned).
  auto directory = [&](const std::vector<Entry>& dir, const std::vector<std::uint16_t>& pointers) {
    std::vector<std::size_t> slots;
    std::vector<std::pair<std::size_t, const Entry*>> long_values;
    put16(std::uint16_t(dir.size() + pointers.size()));
    for (const Entry& e : dir) {
      put16(e.tag), put16(e.type), put32(e.count);
      if (e.bytes.size() <= 4) {
        std::vector<unsigned char> v = e.bytes;
        v.resize(4, 0);
        out.insert(out.end(), v.begin(), v.end());
      } else {
        long_values.emplace_back(out.size(), &e);
        put32(0);
      }
    }
    for (std::uint16_t tag : pointers) {
      put16(tag), put16(kLong), put32(1);
      slots.push_back(out.size());
      put32(0);
    }
    put32(0);  // no next directory
    for (const auto& [slot, e] : long_values) {
      if ((out.size() - base) % 2) out.push_back(0);  // word alignment
      set32(slot, std::uint32_t(out.size() - base));
      out.insert(out.end(), e->bytes.begin(), e->bytes.end());
    }
    if ((out.size() - base) % 2) out.push_back(0);
    return slots;
  };
  std::vector<std::uint16_t> pointers;
  if (!dirs.exif.empty()) pointers.push_back(kExifDirectory);
  if (!dirs.gps.empty()) pointers.push_back(34853);
  const std::vector<std::size_t> slots = directory(dirs.ifd0, pointers);
  std::size_t next = 0;
  if (!dirs.exif.empty()) {
    set32(slots[next++], std::uint32_t(out.size() - base));
    directory(dirs.exif, {});
  }
  if (!dirs.gps.empty()) {
    set32(slots[next++], std::uint32_t(out.size() - base));
    directory(dirs.gps, {});
  }
  return out;
}

bool can_encode_exif(const AttributeList& attributes) {
  Directories dirs;
  return build_directories(attributes, dirs);
}

namespace {

// OIIO's IPTC datasets for the three TIFF fields: each written from the IPTC attribute, then
// from the TIFF field (OIIO's iptc.cpp, in its table's order); read back as the IPTC attribute,
// a repeated dataset replacing the value, or for a repeatable one (Creator) joined with "; ".
struct Dataset {
  int number;
  const char* field;  // the TIFF field OIIO also writes it from
  const char* name;   // the attribute OIIO reads it as (and writes it from)
  bool repeatable;
};
constexpr Dataset kDatasets[] = {{65, "Software", "IPTC:OriginatingProgram", false},
                                 {80, "Artist", "IPTC:Creator", true},
                                 {116, "Copyright", "IPTC:CopyrightNotice", false},
                                 {120, "ImageDescription", "IPTC:Caption", false}};

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
      if (!d || n == 0) return false;  // empty values: OIIO's own handling
      const std::string_view value(reinterpret_cast<const char*>(data + q + 5), n);
      if (value.find('\0') != std::string_view::npos) return false;
      // A repeatable dataset's value OIIO trims (31 spaces read as ""): left to OIIO.
      if (d->repeatable && (std::isspace(static_cast<unsigned char>(value.front())) ||
                            std::isspace(static_cast<unsigned char>(value.back()))))
        return false;
      const auto it = out.find(d->name);
      if (it != out.end() && d->repeatable)
        *it = Attribute(d->name, it->string_value() + "; " + std::string(value));
      else
        out.add_or_replace(Attribute(d->name, value));
      q += 5 + n;
    }
    at = p + len + (len & 1);
  }
  return true;
}

bool is_iptc_attribute(const Attribute& p) {
  for (const Dataset& d : kDatasets)
    if (iequals(p.name, d.field) || iequals(p.name, d.name)) return true;
  return false;
}

bool can_encode_iptc(const AttributeList& attributes) {
  for (const Dataset& d : kDatasets) {
    int seen = 0;
    for (const Attribute& p : attributes) {
      if (!iequals(p.name, d.field) && !iequals(p.name, d.name)) continue;
      ++seen;
      // A name twice (in two cases), a value OIIO would split at ";", or not text: OIIO's.
      // An empty text OIIO's writer asserts on (it aborts): written without the dataset.
      if (!p.type.is(DataType::kString)) return false;
      const std::string& v = p.string_value();
      if (v.size() > 0x7FFF || v.find('\0') != std::string::npos) return false;
      if (d.repeatable && (v.find(';') != std::string::npos ||
                           (!v.empty() && (std::isspace(static_cast<unsigned char>(v.front())) ||
                                           std::isspace(static_cast<unsigned char>(v.back()))))))
        return false;
    }
    if (seen > 2) return false;
    const auto a = attributes.find(d.field, kTypeUnknown, false);
    const auto b = attributes.find(d.name, kTypeUnknown, false);
    if ((a != attributes.cend() && a->name != d.field) ||
        (b != attributes.cend() && b->name != d.name))
      return false;
  }
  return true;
}

std::vector<char> encode_iptc(const AttributeList& attributes) {
  std::vector<char> iim;
  for (const Dataset& d : kDatasets) {
    for (const char* source : {d.name, d.field}) {
      const auto it = attributes.find(source, kTypeString, false);
      if (it == attributes.cend()) continue;
      const std::string& v = it->string_value();
      if (v.empty()) continue;  // OIIO's writer aborts on it
      const std::size_t n = std::min<std::size_t>(v.size(), 0x7FFF);
      for (int c : {0x1C, 2, d.number, int(n >> 8), int(n & 0xFF)}) iim.push_back(char(c));
      iim.insert(iim.end(), v.begin(), v.begin() + std::ptrdiff_t(n));
    }
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
