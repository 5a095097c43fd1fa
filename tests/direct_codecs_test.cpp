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
#include <vector>

#include "core/metadata_impl.h"
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

// Every value of `type` read both ways, compared bit for bit.
void expect_same_pixels(detail::ImageReader& mine, OIIO::ImageInput& oiio, OIIO::TypeDesc type,
                        const std::string& what) {
  const OIIO::ImageSpec& s = oiio.spec();
  const std::size_t bytes = std::size_t(s.width) * s.height * s.nchannels * type.size();
  std::vector<unsigned char> a(bytes), b(bytes);
  mine.read_image(type, a.data());
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
      EXPECT_EQ(h.format, s.format);
      EXPECT_EQ(h.channelnames, s.channelnames);
      EXPECT_EQ(h.tile_width, s.tile_width);
      EXPECT_EQ(h.channelformats.size(), s.channelformats.size());
      expect_same_attributes(h.extra_attribs, s.extra_attribs, path.filename().string());
      expect_same_pixels(*mine, *oiio, type == OIIO::TypeDesc::UNKNOWN ? s.format : type,
                         path.filename().string());
    }
    std::printf("%-40s %s\n", path.filename().c_str(), is_direct ? "direct" : "OIIO module");
  }
  std::printf("%d of %d files decoded directly\n", direct, total);
  EXPECT_GT(direct, 0);
}

// What write_image stores for a photo with `metadata`: through the direct writer, and through
// OIIO's (the module's writer given the same header), compared by OIIO's decode.
// `colour` is the oiio:ColorSpace tag: write_image's (the config's sRGB) or OIIO's "sRGB".
void compare_writers(const Image& photo, const fs::path& dir, const std::string& name,
                     const std::string& colour = colorspace::srgb) {
  // The header write_image gives the writer: the photo's metadata with the encoding set.
  detail::ImageHeader h;
  h.width = photo.width(), h.height = photo.height(), h.nchannels = 3;
  h.format = OIIO::TypeDesc::UINT8;
  h.channelnames = {"R", "G", "B"};
  h.extra_attribs = photo.metadata().impl().attributes;
  h.attribute("oiio:ColorSpace", colour);
  h.attribute("Compression", "jpeg:90");
  h.attribute("jpeg:subsampling", "4:4:4");
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
    w->open(path.string(), path.string(), h);
    w->write_image(OIIO::TypeDesc::UINT8, codes.data());
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
