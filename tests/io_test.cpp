#include <gtest/gtest.h>
#include <sys/resource.h>

#include <OpenImageIO/imageio.h>

#include <cmath>
#include <csignal>
#include <random>

#include "mr/error.h"
#include "mr/io.h"
#include "oiio_bridge.h"
#include "test_support.h"

namespace fs = std::filesystem;

namespace mr {
namespace {

double srgb_encode(double v) {
  return v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1 / 2.4) - 0.055;
}

// Values that the stored type represents exactly: k / (2^bits - 1) for integers, k / 256 for
// half, arbitrary for float.
Image make_exact_image(int w, int h, int channels, PixelType type) {
  Image im(w, h, channels);
  std::mt19937 rng(7);
  for (float& v : im.pixels()) {
    switch (type) {
      case PixelType::uint8: v = float(rng() % 256) / 255.0f; break;
      case PixelType::uint16: v = float(rng() % 65536) / 65535.0f; break;
      case PixelType::half: v = float(rng() % 257) / 256.0f; break;
      default: v = std::uniform_real_distribution<float>(0.0f, 4.0f)(rng); break;
    }
  }
  return im;
}

struct RoundTripCase {
  const char* extension;
  PixelType type;
  double tolerance;  // max |written - read| on raw (unconverted) values
  bool relative = false;  // tolerance relative to the pixel's largest channel (RGBE)
};

class RawRoundTrip : public ::testing::TestWithParam<RoundTripCase> {};

TEST_P(RawRoundTrip, ValuesSurvive) {
  const RoundTripCase& c = GetParam();
  test::ScratchDir dir;
  const fs::path path = dir / (std::string("im.") + c.extension);
  const Image im = make_exact_image(37, 23, 3, c.type);
  WriteOptions w;
  w.pixel_type = c.type;
  w.colorspace = colorspace::raw;
  write_image(path, im, w);
  EXPECT_EQ(probe_image(path).pixel_type, c.type == PixelType::half ? PixelType::half : c.type);
  ReadOptions r;
  r.to_scene_linear = false;
  const Image back = read_image(path, r);
  ASSERT_EQ(back.width(), 37);
  ASSERT_EQ(back.height(), 23);
  ASSERT_EQ(back.channels(), 3);
  double worst = 0;
  for (std::size_t p = 0; p < im.pixel_count(); ++p) {
    const float* a = im.data() + 3 * p;
    const float* b = back.data() + 3 * p;
    const double scale = c.relative ? std::max({a[0], a[1], a[2]}) : 1.0;
    for (int k = 0; k < 3; ++k) worst = std::max(worst, std::fabs(double(a[k]) - b[k]) / scale);
  }
  EXPECT_LE(worst, c.tolerance) << c.extension << " " << to_string(c.type);
  EXPECT_EQ(dir.list(), std::vector<std::string>{path.filename().string()});  // no temp files left
}

INSTANTIATE_TEST_SUITE_P(
    Formats, RawRoundTrip,
    ::testing::Values(RoundTripCase{"png", PixelType::uint8, 1e-7},
                      RoundTripCase{"png", PixelType::uint16, 1e-7},
                      RoundTripCase{"tif", PixelType::uint8, 1e-7},
                      RoundTripCase{"tif", PixelType::uint16, 1e-7},
                      RoundTripCase{"tif", PixelType::float32, 0.0},
                      RoundTripCase{"exr", PixelType::half, 0.0},
                      RoundTripCase{"exr", PixelType::float32, 0.0},
                      // RGBE: 8-bit mantissas sharing an exponent, so 2^-7 of the largest channel.
                      RoundTripCase{"hdr", PixelType::float32, 1.0 / 128, true}),
    [](const auto& info) {
      return std::string(info.param.extension) + "_" + to_string(info.param.type);
    });

TEST(Io, JpegOfASmoothPhotoIsCloseAtQuality95) {
  test::ScratchDir dir;
  const Image im = test::make_test_photo(128, 96);
  write_image(dir / "a.jpg", im);
  const Image back = read_image(dir / "a.jpg");
  double sum = 0;
  for (std::size_t i = 0; i < im.pixels().size(); ++i)
    sum += std::fabs(srgb_encode(im.pixels()[i]) - srgb_encode(std::max(0.0f, back.pixels()[i])));
  // JPEG is lossy (quality 95, 4:4:4 chroma): mean error in the encoded domain below one and a
  // half 8-bit code values, worst below 8 code values.
  EXPECT_LT(sum / im.pixels().size(), 1.5 / 255);
  double worst = 0;
  for (std::size_t i = 0; i < im.pixels().size(); ++i)
    worst = std::max(worst, std::fabs(srgb_encode(im.pixels()[i]) - srgb_encode(std::max(0.0f, back.pixels()[i]))));
  EXPECT_LT(worst, 8.0 / 255);
}

TEST(Io, IntegerFilesAreSrgbEncodedAndDecodedThroughOcio) {
  test::ScratchDir dir;
  const Image im = test::make_test_photo(64, 32);
  for (auto [type, ext, step] : {std::tuple{PixelType::uint8, "png", 255.0},
                                 std::tuple{PixelType::uint16, "png", 65535.0},
                                 std::tuple{PixelType::uint16, "tif", 65535.0}}) {
    const fs::path path = dir / (std::string("srgb") + to_string(type) + "." + ext);
    WriteOptions w;
    w.pixel_type = type;
    write_image(path, im, w);
    // Stored codes are the sRGB encoding of the linear values, rounded.
    ReadOptions raw;
    raw.to_scene_linear = false;
    const Image codes = read_image(path, raw);
    double worst_code = 0;
    for (std::size_t i = 0; i < im.pixels().size(); ++i)
      worst_code = std::max(worst_code, std::fabs(srgb_encode(im.pixels()[i]) * step - codes.pixels()[i] * step));
    EXPECT_LE(worst_code, 0.5 + 1e-3) << path;
    // Decoding gets back to linear within that half code step.
    const Image back = read_image(path);
    double worst = 0;
    for (std::size_t i = 0; i < im.pixels().size(); ++i)
      worst = std::max(worst, std::fabs(srgb_encode(im.pixels()[i]) - srgb_encode(back.pixels()[i])));
    EXPECT_LE(worst, 0.5 / step + 1e-5) << path;
  }
}

TEST(Io, FloatFilesAreTakenAsLinear) {
  test::ScratchDir dir;
  const Image im = make_exact_image(16, 16, 3, PixelType::float32);
  write_image(dir / "lin.exr", im);
  EXPECT_EQ(test::max_abs_diff(read_image(dir / "lin.exr"), im), 0.0);
}

TEST(Io, GreyImagesBecomeRgb) {
  test::ScratchDir dir;
  Image grey(8, 4, 1);
  for (float& v : grey.pixels()) v = 0.5f;
  WriteOptions w;
  w.colorspace = colorspace::raw;
  write_image(dir / "g.png", grey, w);
  const Image back = read_image(dir / "g.png");
  ASSERT_EQ(back.channels(), 3);
  EXPECT_NEAR(back.at(3, 2, 1), 0.2140, 2e-3);  // sRGB 128/255 decoded
}

TEST(Io, MetadataTravelsFromInputToOutput) {
  test::ScratchDir dir;
  Image im = test::make_test_photo(32, 24);
  auto& attrs = im.metadata();
  attrs.set("Make", std::string("libmr test camera"));
  attrs.set("Model", std::string("Mk II"));
  attrs.impl().attributes.attribute("Exif:FocalLengthIn35mmFilm", 28);
  attrs.impl().attributes.attribute("Exif:PhotographicSensitivity", OIIO::TypeUInt16, std::array<std::uint16_t, 1>{400}.data());
  write_image(dir / "first.jpg", im);
  const Image first = read_image(dir / "first.jpg");
  write_image(dir / "second.jpg", first);
  const Image second = read_image(dir / "second.jpg");
  EXPECT_EQ(second.metadata().get_string("Make"), "libmr test camera");
  EXPECT_EQ(second.metadata().get_string("Model"), "Mk II");
  EXPECT_EQ(second.metadata().get_number("Exif:FocalLengthIn35mmFilm"), 28.0);
  EXPECT_EQ(second.metadata().get_number("Exif:PhotographicSensitivity"), 400.0);
  write_image(dir / "third.exr", second);
  EXPECT_EQ(read_image(dir / "third.exr").metadata().get_string("Make"), "libmr test camera");
}

TEST(Io, LayeredExrHasStandardChannelNamesThatOiioReads) {
  test::ScratchDir dir;
  const Image rgb = test::make_test_photo(20, 10);
  Image t(20, 10, 3), r(20, 10, 3), z(20, 10, 1, {"Z"});
  for (std::size_t i = 0; i < t.pixels().size(); ++i) {
    t.pixels()[i] = 0.25f;
    r.pixels()[i] = 0.5f;
  }
  for (float& v : z.pixels()) v = 123.456f;
  const ExrLayer layers[] = {{"", &rgb}, {"transmittance", &t}, {"inscatter", &r}, {"depth", &z, true}};
  const fs::path path = dir / "layers.exr";
  write_exr_layers(path, layers, rgb.metadata(), PixelType::half);

  auto in = OIIO::ImageInput::open(path.string());
  ASSERT_TRUE(in);
  const OIIO::ImageSpec spec = in->spec();
  std::vector<std::string> names(spec.channelnames.begin(), spec.channelnames.end());
  for (const char* want : {"R", "G", "B", "transmittance.R", "transmittance.G", "transmittance.B",
                           "inscatter.R", "inscatter.G", "inscatter.B", "depth.Z"})
    EXPECT_NE(std::find(names.begin(), names.end(), want), names.end()) << want;
  EXPECT_EQ(names.size(), 10u);
  std::vector<float> px(std::size_t(spec.width) * spec.height * spec.nchannels);
  ASSERT_TRUE(in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeFloat, px.data()));
  auto channel = [&](const std::string& n) { return int(std::find(names.begin(), names.end(), n) - names.begin()); };
  const float* p = px.data() + (3 * spec.width + 7) * spec.nchannels;
  EXPECT_EQ(p[channel("transmittance.G")], 0.25f);
  EXPECT_EQ(p[channel("inscatter.B")], 0.5f);
  EXPECT_EQ(p[channel("depth.Z")], 123.456f);  // data layer kept in float, not rounded to half
  EXPECT_EQ(spec.channelformat(channel("depth.Z")), OIIO::TypeFloat);
  EXPECT_NEAR(p[channel("R")], rgb.at(7, 3, 0), 1e-3);
}

TEST(IoErrors, MissingNotAnImageTruncatedAndNaN) {
  test::ScratchDir dir;
  auto expect_error = [](const fs::path& p, ErrorCode code) {
    try {
      read_image(p);
      ADD_FAILURE() << p << ": expected an error";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), code) << e.what();
      EXPECT_NE(std::string(e.what()).find(p.filename().string()), std::string::npos) << e.what();
    }
  };
  expect_error(dir / "missing.png", ErrorCode::io);
  test::write_bytes(dir / "text.jpg", "this is not a JPEG file at all\n");
  expect_error(dir / "text.jpg", ErrorCode::io);
  test::write_bytes(dir / "empty.png", "");
  expect_error(dir / "empty.png", ErrorCode::io);

  const Image im = test::make_test_photo(256, 256);
  for (const char* name : {"trunc.jpg", "trunc.png", "trunc.exr", "trunc.tif"}) {
    write_image(dir / name, im);
    std::string bytes = test::read_bytes(dir / name);
    test::write_bytes(dir / name, bytes.substr(0, bytes.size() / 2));
    try {
      read_image(dir / name);
      ADD_FAILURE() << name << ": truncated file read without error";
    } catch (const Error& e) {
      EXPECT_TRUE(e.code() == ErrorCode::corrupt_input || e.code() == ErrorCode::io) << e.what();
      EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
    }
  }

  Image nan = test::make_test_photo(8, 8);
  nan.at(3, 3, 1) = std::nanf("");
  nan.at(4, 3, 1) = INFINITY;
  write_image(dir / "nan.exr", nan);
  expect_error(dir / "nan.exr", ErrorCode::corrupt_input);
}

TEST(IoErrors, WritesAreAtomicAndNeverLeaveTemporaryFiles) {
  test::ScratchDir dir;
  const Image im = test::make_test_photo(512, 512);
  // Missing output folder.
  EXPECT_THROW(write_image(dir / "no/such/folder/x.png", im), Error);
  // Unknown extension and impossible bit depths are refused before anything is written.
  EXPECT_THROW(write_image(dir / "x.unknownext", im), Error);
  WriteOptions sixteen;
  sixteen.pixel_type = PixelType::uint16;
  EXPECT_THROW(write_image(dir / "x.jpg", im, sixteen), Error);
  // overwrite = false keeps an existing file.
  write_image(dir / "keep.png", im);
  const auto before = test::file_checksum(dir / "keep.png");
  WriteOptions keep;
  keep.overwrite = false;
  EXPECT_THROW(write_image(dir / "keep.png", test::make_test_photo(4, 4), keep), Error);
  EXPECT_EQ(test::file_checksum(dir / "keep.png"), before);

  // A full disk, simulated with a file size limit: the write fails cleanly and the old file
  // at the path survives.
  write_image(dir / "full.exr", test::make_test_photo(4, 4));
  const auto old_sum = test::file_checksum(dir / "full.exr");
  rlimit old_limit{};
  getrlimit(RLIMIT_FSIZE, &old_limit);
  auto old_handler = std::signal(SIGXFSZ, SIG_IGN);
  rlimit small = old_limit;
  small.rlim_cur = 4096;
  setrlimit(RLIMIT_FSIZE, &small);
  WriteOptions f;
  f.pixel_type = PixelType::float32;
  bool threw = false;
  try {
    write_image(dir / "full.exr", make_exact_image(512, 512, 3, PixelType::float32), f);
  } catch (const Error& e) {
    threw = true;
    EXPECT_EQ(e.code(), ErrorCode::io) << e.what();
  }
  setrlimit(RLIMIT_FSIZE, &old_limit);
  std::signal(SIGXFSZ, old_handler);
  EXPECT_TRUE(threw);
  EXPECT_EQ(test::file_checksum(dir / "full.exr"), old_sum);
  EXPECT_EQ(dir.list(), (std::vector<std::string>{"full.exr", "keep.png"}));
}

TEST(Io, ParsesPixelTypes) {
  EXPECT_EQ(parse_pixel_type("8"), PixelType::uint8);
  EXPECT_EQ(parse_pixel_type("16"), PixelType::uint16);
  EXPECT_EQ(parse_pixel_type("half"), PixelType::half);
  EXPECT_EQ(parse_pixel_type("float"), PixelType::float32);
  EXPECT_THROW(parse_pixel_type("12"), Error);
  EXPECT_TRUE(is_readable_image_extension("a.JPG"));
  EXPECT_TRUE(is_writable_image_extension("a.exr"));
  EXPECT_FALSE(is_readable_image_extension("a.txt"));
  EXPECT_TRUE(is_readable_image_extension("a.pfm"));
  EXPECT_FALSE(is_writable_image_extension("a.pfm"));  // OIIO 2.4 has no PFM writer
}

}  // namespace
}  // namespace mr
