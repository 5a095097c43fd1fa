// Issue 12, start-up: JPEG and OpenEXR read and written directly through libjpeg and OpenEXR
// (libmr/src/direct_codecs.h) give what OpenImageIO gives. Tolerance: none. Every sample and
// gallery photo and every JPEG / PNG / EXR under tests/data is opened the way libmr opens it
// (directly when the codecs take it, else through OIIO's module) and compared with OIIO's own
// decode: the same shape, types, attributes (names, types, values, order) and pixels, as
// stored and as float. Written JPEGs decode (by OIIO) to what OIIO's writer gives for the same
// pixels and header. Damaged files give mr::Error naming the file.
#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <random>
#include <vector>

#include "core/metadata_impl.h"
#include "core/oiio_attributes.h"
#include "core/oiio_module.h"
#include "libmr/src/direct_codecs.h"
#include "libmr/src/image_files.h"
#include "mr/mr.h"
#include "test_support.h"

namespace fs = std::filesystem;

namespace mr {
namespace {

std::vector<fs::path> sample_files() {
  std::vector<fs::path> out;
  const fs::path root(MR_SOURCE_DIR);
  for (const fs::path& folder :
       {root / "sample_photos", root / "gallery" / "tune", root / "tests" / "data"})
    for (const auto& e : fs::recursive_directory_iterator(folder)) {
      std::string ext = e.path().extension().string();
      for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
      if (ext == ".jpg" || ext == ".jpeg" || ext == ".png" || ext == ".exr")
        out.push_back(e.path());
    }
  std::sort(out.begin(), out.end());
  return out;
}

// The first APPn segment of a JPEG whose data starts with `prefix` (marker, length and data),
// or "" if none.
std::string jpeg_segment(const std::string& jpeg, int marker, const std::string& prefix) {
  std::size_t at = 2;
  while (at + 4 <= jpeg.size() && static_cast<unsigned char>(jpeg[at]) == 0xFF) {
    const int m = static_cast<unsigned char>(jpeg[at + 1]);
    if (m == 0xDA) break;
    const std::size_t len = std::size_t(static_cast<unsigned char>(jpeg[at + 2])) << 8 |
                            static_cast<unsigned char>(jpeg[at + 3]);
    if (m == marker && jpeg.compare(at + 4, prefix.size(), prefix) == 0)
      return jpeg.substr(at, 2 + len);
    at += 2 + len;
  }
  return "";
}

// `jpeg` with `segment` inserted right after its SOI marker.
std::string with_segment(const std::string& jpeg, const std::string& segment) {
  return jpeg.substr(0, 2) + segment + jpeg.substr(2);
}

// `jpeg` without the segment `segment` (one of its own).
std::string without_segment(std::string jpeg, const std::string& segment) {
  return jpeg.erase(jpeg.find(segment), segment.size());
}

void expect_same_attributes(const OIIO::ParamValueList& got, const OIIO::ParamValueList& want,
                            const std::string& what) {
  auto list = [](const OIIO::ParamValueList& l) {
    std::string text;
    for (const OIIO::ParamValue& p : l)
      text += "  " + p.name().string() + " = " + p.get_string(8) + "\n";
    return text;
  };
  ASSERT_EQ(got.size(), want.size()) << what << "\n" << list(got) << "against\n" << list(want);
  for (std::size_t i = 0; i < got.size(); ++i) {
    EXPECT_EQ(got[i].name(), want[i].name()) << what << " attribute " << i;
    EXPECT_EQ(got[i].type(), want[i].type()) << what << " " << want[i].name();
    EXPECT_EQ(got[i].get_string(1 << 20), want[i].get_string(1 << 20))
        << what << " " << want[i].name();
  }
}

void expect_same_attributes(const detail::AttributeList& got, const OIIO::ParamValueList& want,
                            const std::string& what) {
  expect_same_attributes(detail::to_oiio(got), want, what);
}

// The same list bit for bit: names, types, counts, interpolation, value bytes (strings as text).
void expect_identical(const OIIO::ParamValueList& got, const OIIO::ParamValueList& want,
                      const std::string& what) {
  ASSERT_EQ(got.size(), want.size()) << what;
  for (std::size_t i = 0; i < got.size(); ++i) {
    const OIIO::ParamValue &a = got[i], &b = want[i];
    EXPECT_EQ(a.name(), b.name()) << what;
    EXPECT_EQ(a.type(), b.type()) << what << " " << b.name();
    EXPECT_EQ(a.type().reserved, b.type().reserved) << what << " " << b.name();
    EXPECT_EQ(a.nvalues(), b.nvalues()) << what << " " << b.name();
    EXPECT_EQ(a.interp(), b.interp()) << what << " " << b.name();
    ASSERT_EQ(a.datasize(), b.datasize()) << what << " " << b.name();
    if (b.type().basetype == OIIO::TypeDesc::STRING) {
      for (std::size_t k = 0; k < std::size_t(b.nvalues()) * b.type().basevalues(); ++k)
        EXPECT_EQ(a.get<OIIO::ustring>(int(k)), b.get<OIIO::ustring>(int(k))) << what;
    } else {
      EXPECT_EQ(std::memcmp(a.data(), b.data(), std::size_t(b.datasize())), 0)
          << what << " " << b.name();
    }
  }
}

// OIIO's list converted to mr's and back is the same list, and mr's converted to OIIO's and
// back is equal too.
void expect_lossless(const OIIO::ParamValueList& list, const std::string& what) {
  const detail::AttributeList mine = detail::from_oiio(list);
  expect_identical(detail::to_oiio(mine), list, what);
  EXPECT_TRUE(detail::from_oiio(detail::to_oiio(mine)) == mine) << what;
}

// Every value of `type` read both ways, compared bit for bit.
void expect_same_pixels(detail::ImageReader& mine, OIIO::ImageInput& oiio, OIIO::TypeDesc type,
                        const std::string& what) {
  const OIIO::ImageSpec& s = oiio.spec();
  const std::size_t bytes = std::size_t(s.width) * s.height * s.nchannels * type.size();
  std::vector<unsigned char> a(bytes), b(bytes);
  mine.read_image(detail::from_oiio(type), a.data());
  ASSERT_TRUE(oiio.read_image(0, 0, 0, s.nchannels, type, b.data())) << oiio.geterror();
  std::size_t differ = 0;
  for (std::size_t i = 0; i < bytes; ++i) differ += a[i] != b[i];
  EXPECT_EQ(differ, 0u) << what << " as " << type;
}

TEST(DirectCodecs, DecodesEverySampleAsOiio) {
  // Also files libmr writes: a float depth map and a half colour EXR (OIIO's writer adds a
  // DateTime), JPEGs with and without alpha in the image (written as RGB).
  test::ScratchDir dir;
  std::vector<fs::path> files = sample_files();
  {
    Image depth(33, 17, 1, {"Z"});
    for (int y = 0; y < 17; ++y)
      for (int x = 0; x < 33; ++x) depth.at(x, y, 0) = y < 5 ? 1e30f : 1.5f * x + 0.25f * y;
    WriteOptions raw;
    raw.colorspace = colorspace::raw;
    raw.pixel_type = PixelType::float32;
    write_image(dir / "depth.exr", depth, raw);
    const Image photo = test::make_test_photo(33, 17);
    WriteOptions half;
    half.pixel_type = PixelType::half;
    write_image(dir / "half.exr", photo, half);
    write_image(dir / "photo.jpg", photo);
    files.insert(files.end(), {dir / "depth.exr", dir / "half.exr", dir / "photo.jpg"});
    // Camera EXIF: the EXIF block of every sample and gallery JPEG (phones, Canon, Olympus,
    // Minolta; both byte orders; GPS, maker notes) in a small JPEG of its own, in place of
    // the one libmr wrote.
    const std::string small = test::read_bytes(dir / "photo.jpg");
    const std::string own = jpeg_segment(small, 0xE1, std::string("Exif\0", 5));
    ASSERT_FALSE(own.empty());
    const std::string bare = without_segment(small, own);
    for (const fs::path& source : sample_files()) {
      if (source.extension() != ".jpg") continue;
      const std::string exif =
          jpeg_segment(test::read_bytes(source), 0xE1, std::string("Exif\0", 5));
      if (exif.empty()) continue;
      const fs::path spliced = dir / ("exif_of_" + source.stem().string() + ".jpg");
      test::write_bytes(spliced, with_segment(bare, exif));
      files.push_back(spliced);
    }
    // Blocks OIIO's reader ignores (a phone's MPF APP2, an XMP extension, an APP1 that is not
    // "Exif", makers' own APPn, an APP13 that is not "Photoshop 3.0") beside an iPhone's EXIF.
    auto segment = [](int marker, const std::string& data) {
      return std::string(1, '\xFF') + char(marker) + char((data.size() + 2) >> 8) +
             char((data.size() + 2) & 0xFF) + data;
    };
    const std::string iphone =
        jpeg_segment(test::read_bytes(fs::path(MR_SOURCE_DIR) / "sample_photos" / "leuven.jpg"),
                     0xE1, std::string("Exif\0", 5));
    test::write_bytes(
        dir / "other_blocks.jpg",
        with_segment(bare, iphone + segment(0xE2, std::string("MPF\0II*\0\x08\0\0\0", 12)) +
                               segment(0xE1, std::string("http://ns.adobe.com/xmp/extension/\0"
                                                         "0123456789ABCDEF0123456789ABCDEF",
                                                         67)) +
                               segment(0xE1, std::string("ExifX\0\0II*\0", 10)) +
                               segment(0xE3, "Meta data of a maker") +
                               segment(0xED, std::string("Adobe_CM\0\1\2", 11))));
    files.push_back(dir / "other_blocks.jpg");
    // PNGs as OIIO writes them: 8-bit RGB (sRGB), 16-bit grey (linear: gAMA 1), gamma 2.2,
    // 1-bit-free text chunks and a resolution (pHYs, tIME, tEXt), and with alpha (OIIO's).
    write_image(dir / "photo.png", photo);
    auto write_png = [&](const std::string& name, int channels, OIIO::TypeDesc format,
                         const std::vector<std::pair<std::string, std::string>>& texts,
                         float resolution) {
      OIIO::ImageSpec s(19, 13, channels, format);
      for (const auto& [key, value] : texts) s.attribute(key, value);
      if (resolution > 0) {
        s.attribute("XResolution", resolution);
        s.attribute("YResolution", resolution);
        s.attribute("ResolutionUnit", "in");
      }
      std::vector<std::uint16_t> values(std::size_t(19 * 13 * channels));
      for (std::size_t i = 0; i < values.size(); ++i)
        values[i] = std::uint16_t((i * 7919u) % 65536u);
      auto w = OIIO::ImageOutput::create("png");
      ASSERT_TRUE(w && w->open((dir / name).string(), s));
      ASSERT_TRUE(w->write_image(OIIO::TypeDesc::UINT16, values.data()));
      w->close();
      files.push_back(dir / name);
    };
    files.push_back(dir / "photo.png");
    write_png("grey16.png", 1, OIIO::TypeDesc::UINT16, {{"oiio:ColorSpace", "Linear"}}, 0);
    write_png("gamma.png", 3, OIIO::TypeDesc::UINT8, {{"oiio:ColorSpace", "Gamma2.2"}}, 0);
    write_png("texts.png", 3, OIIO::TypeDesc::UINT8,
              {{"ImageDescription", "A test; with text"},
               {"Artist", "Someone"},
               {"DocumentName", "Title"},
               {"Software", "mr test"},
               {"DateTime", "2026:12:03 16:00:00"},
               {"Comment", "free text"}},
              300);
    write_png("alpha.png", 4, OIIO::TypeDesc::UINT8, {}, 0);
    // A camera JPEG as OIIO writes one (bench/make_fog_inputs.py's): the iPhone photo's
    // attributes but its XMP (which OIIO's reader turns into attributes of its own).
    auto in =
        OIIO::ImageInput::open((fs::path(MR_SOURCE_DIR) / "sample_photos" / "leuven.jpg").string());
    ASSERT_TRUE(in);
    OIIO::ImageSpec spec(33, 17, 3, OIIO::TypeDesc::UINT8);
    spec.extra_attribs = in->spec().extra_attribs;
    std::vector<unsigned char> pixels(33 * 17 * 3);
    for (std::size_t i = 0; i < pixels.size(); ++i) pixels[i] = static_cast<unsigned char>(i * 7);
    auto out = OIIO::ImageOutput::create("jpg");
    ASSERT_TRUE(out && out->open((dir / "oiio_camera.jpg").string(), spec));
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, pixels.data()));
    out->close();
    files.push_back(dir / "oiio_camera.jpg");
  }
  int direct = 0, total = 0;
  for (const fs::path& path : files) {
    SCOPED_TRACE(path.string());
    ++total;
    const bool is_direct = detail::open_direct_reader(path) != nullptr;
    direct += is_direct;
    for (const OIIO::TypeDesc& type :
         {OIIO::TypeDesc(OIIO::TypeDesc::UNKNOWN), OIIO::TypeDesc(OIIO::TypeDesc::FLOAT)}) {
      auto mine = detail::open_image_reader(path);
      auto oiio = OIIO::ImageInput::open(path.string());
      ASSERT_TRUE(mine && oiio);
      const OIIO::ImageSpec& s = oiio->spec();
      const detail::ImageHeader& h = mine->spec();
      EXPECT_EQ(mine->format_name(), oiio->format_name());
      EXPECT_EQ(h.width, s.width);
      EXPECT_EQ(h.height, s.height);
      ASSERT_EQ(h.nchannels, s.nchannels);
      EXPECT_EQ(detail::to_oiio(h.format), s.format);
      EXPECT_EQ(h.channelnames, s.channelnames);
      EXPECT_EQ(h.tile_width, s.tile_width);
      EXPECT_EQ(h.channelformats.size(), s.channelformats.size());
      expect_same_attributes(h.extra_attribs, s.extra_attribs, path.filename().string());
      expect_lossless(s.extra_attribs, path.filename().string());
      expect_same_pixels(*mine, *oiio, type == OIIO::TypeDesc::UNKNOWN ? s.format : type,
                         path.filename().string());
    }
    std::printf("%-40s %s\n", path.filename().c_str(), is_direct ? "direct" : "OIIO module");
  }
  std::printf("%d of %d files decoded directly\n", direct, total);
  EXPECT_GT(direct, 0);
  // Camera EXIF is read directly: the iPhone's block (GPS, an Apple maker note), OIIO's, and
  // beside blocks OIIO ignores; so are PNGs without alpha.
  for (const char* name : {"exif_of_leuven.jpg", "oiio_camera.jpg", "other_blocks.jpg", "photo.png",
                           "grey16.png", "gamma.png", "texts.png"})
    EXPECT_TRUE(detail::open_direct_reader(dir / name)) << name;
}

// Randomly damaged camera EXIF blocks (bytes changed anywhere in the TIFF structure: counts,
// types, offsets, values; blocks cut short), each in a small JPEG: every one the direct reader
// takes decodes to OIIO's attributes exactly (the rest goes to OIIO's module). Seeded, so the
// same 400 files each run; the test fails if fewer than 40 are taken (it would test nothing).
TEST(DirectCodecs, DamagedExifDecodesAsOiioOrGoesToIt) {
  test::ScratchDir dir;
  write_image(dir / "small.jpg", test::make_test_photo(16, 12));
  const std::string small = test::read_bytes(dir / "small.jpg");
  const std::string bare =
      without_segment(small, jpeg_segment(small, 0xE1, std::string("Exif\0", 5)));
  std::vector<std::string> blocks;
  for (const fs::path& source : sample_files()) {
    if (source.extension() != ".jpg") continue;
    const std::string exif = jpeg_segment(test::read_bytes(source), 0xE1, std::string("Exif\0", 5));
    if (!exif.empty()) blocks.push_back(exif.substr(4));  // "Exif\0\0" and the TIFF block
  }
  ASSERT_GT(blocks.size(), 10u);
  std::mt19937 random(13);
  auto below = [&](std::size_t n) { return std::size_t(random() % std::max<std::size_t>(n, 1)); };
  int direct = 0;
  for (int k = 0; k < 400; ++k) {
    std::string b = blocks[below(blocks.size())];
    const int changes = 1 + int(below(8));
    for (int c = 0; c < changes; ++c) {
      // Mostly in the first 200 bytes, where the directories are.
      const std::size_t at = 6 + below(std::min<std::size_t>(b.size() - 6, k % 2 ? 200 : b.size()));
      b[at] = char(random() % 4 == 0 ? 0xFF : random() % 3 == 0 ? 0 : random() & 0xFF);
    }
    if (k % 10 == 0) b.resize(6 + below(b.size() - 6));
    const std::string segment =
        std::string("\xFF\xE1", 2) + char((b.size() + 2) >> 8) + char((b.size() + 2) & 0xFF) + b;
    const fs::path path = dir / ("damaged_" + std::to_string(k) + ".jpg");
    test::write_bytes(path, with_segment(bare, segment));
    SCOPED_TRACE(path.string());
    auto mine = detail::open_direct_reader(path);
    if (!mine) continue;  // OIIO's module reads it
    ++direct;
    auto oiio = OIIO::ImageInput::open(path.string());
    ASSERT_TRUE(oiio);
    expect_same_attributes(mine->spec().extra_attribs, oiio->spec().extra_attribs,
                           path.filename().string());
    expect_same_pixels(*mine, *oiio, OIIO::TypeDesc::UINT8, path.filename().string());
  }
  std::printf("%d of 400 damaged EXIF blocks decoded directly\n", direct);
  EXPECT_GE(direct, 40);
}

// What write_image stores for a photo with `metadata`: through the direct writer, and through
// OIIO's (the module's writer given the same header), compared by OIIO's decode.
// `colour` is the oiio:ColorSpace tag: write_image's (the config's sRGB) or OIIO's "sRGB".
// `direct`: whether libmr's writer must write it itself (1), through OIIO's module (0), or
// either (-1).
// `not_for_oiio`: attributes left out of OIIO's header (ones its writer aborts on).
void compare_writers(const Image& photo, const fs::path& dir, const std::string& name,
                     const std::string& colour = colorspace::srgb, int direct = -1,
                     const std::vector<std::string>& not_for_oiio = {}) {
  // The header write_image gives the writer: the photo's metadata with the encoding set.
  detail::ImageHeader h;
  h.width = photo.width(), h.height = photo.height(), h.nchannels = 3;
  h.format = detail::kTypeUInt8;
  h.channelnames = {"R", "G", "B"};
  h.extra_attribs = photo.metadata().impl().attributes;
  h.attribute("oiio:ColorSpace", colour);
  h.attribute("Compression", "jpeg:90");
  h.attribute("jpeg:subsampling", "4:4:4");
  if (direct >= 0) {
    EXPECT_EQ(detail::writes_jpeg_directly(h), direct == 1) << name;
  }
  // OCIO's sRGB codes of the photo, as write_image makes them.
  ColorConfig config = ColorConfig::builtin();
  std::vector<unsigned char> codes(photo.pixel_count() * 3);
  config.convert_pixels(photo.data(), 32, 12, 12 * photo.width(), codes.data(), 8, 3,
                        3 * photo.width(), photo.width(), photo.height(), colorspace::scene_linear,
                        colorspace::srgb);
  // The same header and codes through libmr's writer for .jpg and through OIIO's.
  const fs::path direct = dir / (name + "_direct.jpg"), theirs = dir / (name + "_oiio.jpg");
  for (const fs::path& path : {direct, theirs}) {
    std::unique_ptr<detail::ImageWriter> w =
        path == direct ? detail::create_image_writer(path)
                       : std::unique_ptr<detail::ImageWriter>(
                             detail::oiio_module().create_writer(path.string()));
    ASSERT_TRUE(w);
    detail::ImageHeader header = h;
    if (path == theirs)
      for (const std::string& n : not_for_oiio) header.extra_attribs.remove(n);
    w->open(path.string(), path.string(), header);
    w->write_image(detail::kTypeUInt8, codes.data());
    w->close();
  }
  auto a = OIIO::ImageInput::open(direct.string());
  auto b = OIIO::ImageInput::open(theirs.string());
  ASSERT_TRUE(a && b);
  expect_same_attributes(a->spec().extra_attribs, b->spec().extra_attribs, name);
  // And libmr reads both as OIIO does.
  for (const fs::path& path : {direct, theirs}) {
    auto mine = detail::open_image_reader(path);
    auto oiio = OIIO::ImageInput::open(path.string());
    ASSERT_TRUE(mine && oiio);
    expect_same_attributes(mine->spec().extra_attribs, oiio->spec().extra_attribs,
                           path.filename().string() + " read back");
    expect_same_pixels(*mine, *oiio, OIIO::TypeDesc::UINT8, path.filename().string());
    std::printf("%-28s read %s\n", path.filename().c_str(),
                detail::open_direct_reader(path) ? "directly" : "through OIIO");
  }
  std::vector<unsigned char> pa(codes.size()), pb(codes.size());
  ASSERT_TRUE(a->read_image(0, 0, 0, 3, OIIO::TypeDesc::UINT8, pa.data()));
  ASSERT_TRUE(b->read_image(0, 0, 0, 3, OIIO::TypeDesc::UINT8, pb.data()));
  EXPECT_TRUE(pa == pb) << name << ": the decoded pixels differ";
}

TEST(DirectCodecs, WritesJpegAsOiio) {
  test::ScratchDir dir;
  Image photo = test::make_test_photo(37, 21);  // not a whole number of MCUs
  compare_writers(photo, dir.path(), "plain");
  compare_writers(photo, dir.path(), "plain_srgb", "sRGB");
  photo.metadata().set("Software", "mr test");
  photo.metadata().set("Make", "Maker");
  photo.metadata().impl().attributes.attribute("Orientation", 1);
  photo.metadata().impl().attributes.attribute("XResolution", 300.0f);
  photo.metadata().impl().attributes.attribute("YResolution", 300.0f);
  photo.metadata().impl().attributes.attribute("ResolutionUnit", "in");
  compare_writers(photo, dir.path(), "tagged");
  compare_writers(photo, dir.path(), "tagged_srgb", "sRGB");
  compare_writers(photo, dir.path(), "tagged_rolloff", "srgb_rolloff");
  photo.metadata().set("Artist", "Someone");
  photo.metadata().set("Copyright", "CC BY 4.0");
  photo.metadata().set("DateTime", "2026:12:03 12:00:00");
  photo.metadata().impl().attributes.attribute("XResolution", 72.0f);
  photo.metadata().impl().attributes.attribute("YResolution", 72.0f);
  photo.metadata().impl().attributes.attribute("ResolutionUnit", "cm");
  compare_writers(photo, dir.path(), "more_tags");
  // A resolution with a pixel aspect: written by OIIO's writer (the module).
  photo.metadata().impl().attributes.attribute("XResolution", 72.5f);
  compare_writers(photo, dir.path(), "aspect");
  // Attributes the direct writer leaves to OIIO's (EXIF sub-directory): the same file anyway.
  photo.metadata().impl().attributes.attribute("Exif:FocalLengthIn35mmFilm", 28);
  compare_writers(photo, dir.path(), "exif");
}

// A camera's metadata (as libmr reads it from a photo with an iPhone's EXIF block: Exif and
// GPS directories, IPTC) written by libmr's writer itself, and OIIO's quirks with it: a float
// whose inverse is whole written as 1/(int)f (0.5 reads back as infinity), a tag named twice,
// integers for rationals and floats for integers (not written), empty texts (not written),
// versions (OIIO's own), arrays for single values (their first), IPTC datasets from both names.
TEST(DirectCodecs, WritesCameraJpegAsOiio) {
  test::ScratchDir dir;
  const Image small = test::make_test_photo(37, 21);
  write_image(dir / "small.jpg", small);
  const std::string bytes = test::read_bytes(dir / "small.jpg");
  const std::string own = jpeg_segment(bytes, 0xE1, std::string("Exif\0", 5));
  const std::string iphone =
      jpeg_segment(test::read_bytes(fs::path(MR_SOURCE_DIR) / "sample_photos" / "leuven.jpg"), 0xE1,
                   std::string("Exif\0", 5));
  ASSERT_FALSE(own.empty() || iphone.empty());
  test::write_bytes(dir / "iphone.jpg", with_segment(without_segment(bytes, own), iphone));
  Image photo = read_image(dir / "iphone.jpg");
  ASSERT_TRUE(photo.metadata().impl().attributes.contains("GPS:Latitude"));
  compare_writers(photo, dir.path(), "iphone", colorspace::srgb, 1);
  compare_writers(photo, dir.path(), "iphone_srgb", "sRGB", 1);
  auto& a = photo.metadata().impl().attributes;
  using detail::DataType;
  a.attribute("ExposureTime", 0.5f);
  a.attribute("Exif:ShutterSpeedValue", -3.3f);
  const std::uint16_t iso[] = {200, 400};
  a.attribute("Exif:ISOSpeedRatings", detail::kTypeUInt16, iso);
  a.attribute("Exif:PhotographicSensitivity", detail::kTypeUInt16, iso + 1);
  a.attribute("Orientation", 3.0f);
  a.attribute("Exif:MaxApertureValue", 2);
  a.attribute("Exif:PixelXDimension", 4000);
  a.attribute("Exif:ExifVersion", "0221");
  a.attribute("Exif:CameraOwnerName", "");
  a.attribute("Exif:YCbCrSubsampling", DataType(DataType::kUInt16, 1, 0, 2), iso);
  a.attribute("GPS:AltitudeRef", 1);
  const int version[] = {2, 3, 0, 0};
  a.attribute("GPS:VersionID", DataType(DataType::kInt32, 1, 0, 4), version);
  a.attribute("GPS:Speed", 3);
  a.attribute("Artist", "Someone");
  a.attribute("IPTC:Creator", "Someone Else");
  a.attribute("IPTC:OriginatingProgram", "Program");
  a.attribute("Copyright", "CC BY 4.0");
  a.attribute("ImageDescription", "Fog; a test");  // a COM marker, EXIF and IPTC Caption
  compare_writers(photo, dir.path(), "quirks", colorspace::srgb, 1);
  compare_writers(photo, dir.path(), "quirks_srgb", "sRGB", 1);
  // Empty texts of the IPTC fields (a camera's blank Copyright): OIIO 2.4's writer aborts on
  // them (an assertion in its IPTC encoder); libmr's leaves them out, and the file decodes as
  // OIIO's writes it without them.
  a.attribute("Copyright", "");
  a.attribute("ImageDescription", "");
  compare_writers(photo, dir.path(), "empty_texts", colorspace::srgb, 1,
                  {"Copyright", "ImageDescription"});
  // The same through OIIO's writer (a pixel aspect it writes itself): no abort either.
  a.attribute("XResolution", 300.0f);
  a.attribute("YResolution", 200.0f);
  compare_writers(photo, dir.path(), "empty_texts_oiio", colorspace::srgb, 0,
                  {"Copyright", "ImageDescription"});
  a.attribute("XResolution", 72.0f);
  a.attribute("YResolution", 72.0f);
  a.attribute("Copyright", "CC BY 4.0");
  a.remove("ImageDescription");
  // Left to OIIO's writer (the same file anyway): a Canon (OIIO writes a maker note from its
  // Canon:* attributes), a Creator OIIO splits at ";".
  a.attribute("Artist", "One; Two");
  compare_writers(photo, dir.path(), "split", colorspace::srgb, 0);
  a.attribute("Artist", "Someone");
  a.attribute("Make", "Canon");
  compare_writers(photo, dir.path(), "canon", colorspace::srgb, 0);
}

// mr's attribute list (core/attributes.h) against OIIO's ParamValueList on values of every
// type OIIO's TypeDesc describes in files (scalars, vectors, matrices, arrays, rationals, time
// codes, several values, strings with quotes, control characters and NULs): the conversion is
// exact both ways, and the values read as text (get_string, also cut at 1 and 8 values), int
// and float exactly as OIIO reads them. Tolerance: none.
TEST(DirectCodecs, AttributeListsAreOiiosExactly) {
  using T = OIIO::TypeDesc;
  const int ints[] = {1, 250, -3, 4, 7, 0, 2147483647, -2147483647, 5, 6, 9, 12, 13, 14, 15, 16};
  const unsigned uints[] = {3, 5, 0x01020304u, 4000000000u, 9, 10};
  const float floats[] = {1.5f, 2, 3e-7f, -0.1f, 1e30f, 0.25f, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16};
  const double doubles[] = {0.1, -2.5e100, 3};
  const std::uint16_t u16[] = {400, 7, 0x3c00, 0x7bff};
  const std::int16_t i16[] = {-3, 300};
  const std::uint8_t u8[] = {48, 50, 51, 48};
  const std::int8_t i8[] = {-5, 100};
  const std::uint64_t u64[] = {1234567890123ull, 18446744073709551615ull};
  const std::int64_t i64[] = {-1234567890123ll, 5};
  std::vector<int> many(100);
  for (int k = 0; k < 100; ++k) many[std::size_t(k)] = k * k - 50;
  const OIIO::ustring strings[] = {OIIO::ustring("plain"), OIIO::ustring("a\"b\n\t\\c"),
                                   OIIO::ustring(std::string("nul\0inside", 10)),
                                   OIIO::ustring("")};
  OIIO::ParamValueList list;
  auto add = [&](const char* name, T type, int n, const void* data) {
    list.push_back(OIIO::ParamValue(name, type, n, data));
  };
  add("int", T::INT, 1, ints);
  add("ints", T::INT, 3, ints);
  add("int[3]", T(T::INT, 3), 1, ints);
  add("many", T::INT, 100, many.data());
  add("many[100]", T(T::INT, 100), 1, many.data());
  add("rational", OIIO::TypeRational, 1, ints);
  add("rationals", OIIO::TypeRational, 2, ints);
  add("rational[2]", T(T::INT, T::VEC2, T::RATIONAL, 2), 1, ints);
  add("rational0", OIIO::TypeRational, 1, ints + 4);
  add("urational", T(T::UINT, T::VEC2, T::RATIONAL), 1, uints);
  add("uint", T::UINT, 2, uints + 2);
  add("timecode", OIIO::TypeTimeCode, 1, uints + 2);
  add("keycode", OIIO::TypeKeyCode, 1, ints);
  add("box2i", OIIO::TypeBox2i, 1, ints);
  add("float", T::FLOAT, 1, floats);
  add("floats", T::FLOAT, 5, floats);
  add("vec3", OIIO::TypeVector, 1, floats);
  add("color", OIIO::TypeColor, 1, floats + 3);
  add("vec2 x2", T(T::FLOAT, T::VEC2), 2, floats);
  add("matrix", OIIO::TypeMatrix44, 1, floats);
  add("matrix33", OIIO::TypeMatrix33, 1, floats);
  add("double", T::DOUBLE, 3, doubles);
  add("half", T::HALF, 4, u16);
  add("uint16", T::UINT16, 1, u16);
  add("uint16[2]", T(T::UINT16, 2), 1, u16);
  add("int16", T::INT16, 2, i16);
  add("uint8[4]", T(T::UINT8, 4), 1, u8);
  add("int8", T::INT8, 2, i8);
  add("uint64", T::UINT64, 2, u64);
  add("int64", T::INT64, 2, i64);
  list.push_back(OIIO::ParamValue("string", strings[1]));
  list.push_back(OIIO::ParamValue("nul string", strings[2]));
  list.push_back(OIIO::ParamValue("empty string", strings[3]));
  add("strings", T::STRING, 3, strings);
  add("string[2]", T(T::STRING, 2), 1, strings);
  list.push_back(OIIO::ParamValue("int text", T::STRING, "  42"));
  list.push_back(OIIO::ParamValue("float text", T::STRING, "2.5"));
  list.push_back(OIIO::ParamValue("not a number", T::STRING, "2.5 m"));
  list.push_back(OIIO::ParamValue("vertex", T::FLOAT, 2, OIIO::ParamValue::INTERP_VERTEX, floats));
  expect_lossless(list, "synthetic");
  const detail::AttributeList mine = detail::from_oiio(list);
  ASSERT_EQ(mine.size(), list.size());
  for (std::size_t i = 0; i < list.size(); ++i) {
    const OIIO::ParamValue& p = list[i];
    const detail::Attribute& a = mine[i];
    for (int maxsize : {64, 1, 8, 1 << 20})
      EXPECT_EQ(a.get_string(maxsize), p.get_string(maxsize)) << a.name << " cut at " << maxsize;
    EXPECT_EQ(a.get_int(-77), p.get_int(-77)) << a.name;
    const float fa = a.get_float(-77), fb = p.get_float(-77);
    EXPECT_TRUE(std::memcmp(&fa, &fb, sizeof fa) == 0) << a.name << ": " << fa << " vs " << fb;
    EXPECT_EQ(mine.get_int(a.name), list.get_int(p.name().string())) << a.name;
  }
  // List edits as OIIO's: replace in place, case-insensitive lookups, removal.
  OIIO::ParamValueList theirs = list;
  detail::AttributeList ours = mine;
  theirs.attribute("Float", 3.0f);  // another name (case-sensitive): appended
  theirs.attribute("float", 4.0f);  // replaced in place, then by an int
  theirs.attribute("float", 5);
  theirs.attribute("", 6);  // ignored
  theirs.attribute("rational", "text");
  theirs.remove("ints");
  theirs.remove("INT16");  // case-sensitive: stays
  ours.attribute("Float", 3.0f);
  ours.attribute("float", 4.0f);
  ours.attribute("float", 5);
  ours.attribute("", 6);
  ours.attribute("rational", "text");
  ours.remove("ints");
  ours.remove("INT16");
  expect_identical(detail::to_oiio(ours), theirs, "edited");
  EXPECT_EQ(ours.get_float("FLOAT"), theirs.get_float("FLOAT"));
  EXPECT_EQ(ours.contains("FLOAT"), theirs.contains("FLOAT"));
  EXPECT_EQ(ours.contains("Float"), theirs.contains("Float"));
}

TEST(DirectCodecs, DamagedFilesNameTheFile) {
  test::ScratchDir dir;
  const Image photo = test::make_test_photo(64, 48);
  write_image(dir.path() / "whole.jpg", photo);
  Image depth(64, 48, 1, {"Z"});
  WriteOptions raw;
  raw.colorspace = colorspace::raw;
  raw.pixel_type = PixelType::float32;
  write_image(dir.path() / "whole.exr", depth, raw);
  write_image(dir.path() / "whole.png", photo);
  for (const char* name : {"whole.jpg", "whole.exr", "whole.png"}) {
    const std::string bytes = test::read_bytes(dir.path() / name);
    const fs::path cut = dir.path() / (std::string("cut_") + name);
    test::write_bytes(cut, bytes.substr(0, bytes.size() * 2 / 3));
    try {
      read_image(cut);
      ADD_FAILURE() << name << ": a truncated file was read";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(cut.string()), std::string::npos) << e.what();
    }
  }
  const fs::path text = dir.path() / "notes.jpg";
  test::write_bytes(text, "not an image at all\n");
  try {
    read_image(text);
    ADD_FAILURE() << "a text file was read";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(text.string()), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace mr
