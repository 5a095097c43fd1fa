#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/stat.h>

#include <OpenImageIO/imageio.h>

#include <array>
#include <cmath>
#include <csignal>
#include <random>

#include "mr/camera.h"
#include "mr/depth.h"
#include "mr/error.h"
#include "mr/io.h"
#include "core/oiio_bridge.h"
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
  attrs.impl().attributes.attribute("Exif:PhotographicSensitivity", detail::kTypeUInt16, std::array<std::uint16_t, 1>{400}.data());
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

// EXIF Orientation. A 5x3 stored image whose 8-bit codes name their stored position:
// R = 16 y + x + 1, G = x, B = y. Written with OIIO directly so that the (SHORT) tag is stored.
constexpr int kOrientW = 5, kOrientH = 3;

std::array<int, 3> orient_codes(int x, int y) { return {16 * y + x + 1, x, y}; }

void write_oriented(const fs::path& path, int orientation, int channels = 3) {
  std::vector<unsigned char> codes;
  for (int y = 0; y < kOrientH; ++y)
    for (int x = 0; x < kOrientW; ++x)
      for (int c = 0; c < channels; ++c) codes.push_back((unsigned char)orient_codes(x, y)[c]);
  OIIO::ImageSpec spec(kOrientW, kOrientH, channels, OIIO::TypeDesc::UINT8);
  spec.attribute("Orientation", orientation);
  if (path.extension() == ".jpg") {
    spec.attribute("Compression", "jpeg:100");
    spec.attribute("jpeg:subsampling", "4:4:4");
  }
  auto out = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(out);
  ASSERT_TRUE(out->open(path.string(), spec)) << out->geterror();
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, codes.data()));
  ASSERT_TRUE(out->close());
}

// The stored pixel shown at displayed (dx, dy), straight from the EXIF 2.3 table (where row 0
// and column 0 of the stored image end up): 2 row 0 top / col 0 right, 3 bottom / right,
// 4 bottom / left, 5 left / top, 6 right / top, 7 right / bottom, 8 left / bottom.
std::array<int, 2> stored_position(int orientation, int dx, int dy) {
  const int w = kOrientW, h = kOrientH;
  switch (orientation) {
    case 2: return {w - 1 - dx, dy};
    case 3: return {w - 1 - dx, h - 1 - dy};
    case 4: return {dx, h - 1 - dy};
    case 5: return {dy, dx};
    case 6: return {dy, h - 1 - dx};
    case 7: return {w - 1 - dy, h - 1 - dx};
    case 8: return {w - 1 - dy, dx};
    default: return {dx, dy};
  }
}

float code_value(int code) { return float(code) / 255.0f; }

TEST(IoOrientation, Orientation6And3TurnThePixelsAsExifSays) {
  test::ScratchDir dir;
  ReadOptions raw;
  raw.to_scene_linear = false;
  constexpr float kExact = 1e-6f;  // lossless TIFF, 8-bit codes / 255: exact
  {
    write_oriented(dir / "o6.tif", 6);
    EXPECT_EQ(probe_image(dir / "o6.tif").orientation, 6);
    const Image im = read_image(dir / "o6.tif", raw);
    ASSERT_EQ(im.width(), kOrientH);   // turned 90 degrees clockwise: 3 wide,
    ASSERT_EQ(im.height(), kOrientW);  // 5 high
    // Stored row 0 becomes the right-hand column, stored column 0 the top row.
    EXPECT_NEAR(im.at(2, 0, 0), code_value(orient_codes(0, 0)[0]), kExact);  // top-right = stored (0,0)
    EXPECT_NEAR(im.at(0, 0, 0), code_value(orient_codes(0, 2)[0]), kExact);  // top-left = stored (0,2)
    EXPECT_NEAR(im.at(2, 4, 0), code_value(orient_codes(4, 0)[0]), kExact);  // bottom-right = stored (4,0)
    EXPECT_NEAR(im.at(0, 4, 0), code_value(orient_codes(4, 2)[0]), kExact);  // bottom-left = stored (4,2)
    EXPECT_NEAR(im.at(1, 3, 0), code_value(orient_codes(3, 1)[0]), kExact);
    EXPECT_EQ(im.metadata().get_number("Orientation"), 1.0);
  }
  {
    write_oriented(dir / "o3.tif", 3);
    const Image im = read_image(dir / "o3.tif", raw);
    ASSERT_EQ(im.width(), kOrientW);
    ASSERT_EQ(im.height(), kOrientH);
    EXPECT_NEAR(im.at(0, 0, 0), code_value(orient_codes(4, 2)[0]), kExact);
    EXPECT_NEAR(im.at(4, 2, 0), code_value(orient_codes(0, 0)[0]), kExact);
    EXPECT_NEAR(im.at(1, 0, 0), code_value(orient_codes(3, 2)[0]), kExact);
    EXPECT_NEAR(im.at(4, 0, 0), code_value(orient_codes(0, 2)[0]), kExact);
    EXPECT_EQ(im.metadata().get_number("Orientation"), 1.0);
  }
}

TEST(IoOrientation, EveryOrientationMatchesTheExifTableAndCanBeSwitchedOff) {
  test::ScratchDir dir;
  ReadOptions raw;
  raw.to_scene_linear = false;
  for (int orientation = 1; orientation <= 8; ++orientation) {
    SCOPED_TRACE("Orientation " + std::to_string(orientation));
    const fs::path path = dir / ("o" + std::to_string(orientation) + ".tif");
    write_oriented(path, orientation);
    const Image im = read_image(path, raw);
    const bool swapped = orientation >= 5;
    ASSERT_EQ(im.width(), swapped ? kOrientH : kOrientW);
    ASSERT_EQ(im.height(), swapped ? kOrientW : kOrientH);
    for (int dy = 0; dy < im.height(); ++dy)
      for (int dx = 0; dx < im.width(); ++dx) {
        const auto [sx, sy] = stored_position(orientation, dx, dy);
        for (int c = 0; c < 3; ++c)
          ASSERT_NEAR(im.at(dx, dy, c), code_value(orient_codes(sx, sy)[c]), 1e-6f)
              << "displayed (" << dx << ", " << dy << ") channel " << c;
      }
    EXPECT_EQ(im.metadata().get_number("Orientation").value_or(1), 1.0);

    ReadOptions stored = raw;
    stored.apply_orientation = false;
    const Image as_stored = read_image(path, stored);
    ASSERT_EQ(as_stored.width(), kOrientW);
    ASSERT_EQ(as_stored.height(), kOrientH);
    for (int y = 0; y < kOrientH; ++y)
      for (int x = 0; x < kOrientW; ++x)
        ASSERT_NEAR(as_stored.at(x, y, 0), code_value(orient_codes(x, y)[0]), 1e-6f);
    EXPECT_EQ(as_stored.metadata().get_number("Orientation").value_or(1), double(orientation));
  }
}

TEST(IoOrientation, PhoneJpegIsReadUprightAndWrittenWithOrientation1) {
  test::ScratchDir dir;
  write_oriented(dir / "phone.jpg", 6);
  ReadOptions stored;
  stored.apply_orientation = false;
  ASSERT_EQ(read_image(dir / "phone.jpg", stored).metadata().get_number("Orientation"), 6.0);
  const Image upright = read_image(dir / "phone.jpg");  // scene-linear, turned
  ASSERT_EQ(upright.width(), kOrientH);
  ASSERT_EQ(upright.height(), kOrientW);
  EXPECT_EQ(upright.metadata().get_number("Orientation"), 1.0);
  // Written and read again: not turned a second time (the copy says Orientation 1).
  write_image(dir / "copy.png", upright);
  write_image(dir / "copy.jpg", upright);
  for (const char* name : {"copy.png", "copy.jpg"}) {
    SCOPED_TRACE(name);
    const Image again = read_image(dir / name);
    ASSERT_EQ(again.width(), kOrientH);
    ASSERT_EQ(again.height(), kOrientW);
    EXPECT_EQ(again.metadata().get_number("Orientation").value_or(1), 1.0);
    // Same pixels as first read: 8-bit sRGB re-encoding plus JPEG q95 on tiny code values;
    // scene-linear of codes <= 37 is below 0.02, so 0.01 absolute is a loose bound.
    for (int y = 0; y < again.height(); ++y)
      for (int x = 0; x < again.width(); ++x)
        EXPECT_NEAR(again.at(x, y, 0), upright.at(x, y, 0), 0.01f) << x << "," << y;
  }
}

TEST(IoOrientation, DepthMapsAreNotTurnedByThePhotosOrientation) {
  test::ScratchDir dir;
  // A phone photo (Orientation 6) is displayed 3 x 5; its depth map is stored as displayed,
  // without an Orientation tag, and read_depth takes it as it is.
  write_oriented(dir / "phone.jpg", 6);
  const Image photo = read_image(dir / "phone.jpg");
  const Camera camera = Camera::from_focal_px(photo.width(), photo.height(), 10.0);
  Image depth(kOrientH, kOrientW, 1);
  for (int y = 0; y < kOrientW; ++y)
    for (int x = 0; x < kOrientH; ++x) depth.at(x, y, 0) = float(1 + x + 10 * y);
  WriteOptions w;
  w.pixel_type = PixelType::float32;
  write_image(dir / "depth.exr", depth, w);
  DepthOptions as_distance;
  as_distance.kind = DepthKind::distance;
  const DepthMap read = read_depth(dir / "depth.exr", camera, as_distance);
  ASSERT_EQ(read.distance_m.width(), kOrientH);
  ASSERT_EQ(read.distance_m.height(), kOrientW);
  for (int y = 0; y < kOrientW; ++y)
    for (int x = 0; x < kOrientH; ++x) EXPECT_EQ(read.distance_m.at(x, y, 0), depth.at(x, y, 0));
  // A depth file with its own Orientation tag is turned by it (stored 5 x 3, displayed 3 x 5).
  write_oriented(dir / "depth_o6.tif", 6, 1);
  const DepthMap turned = read_depth(dir / "depth_o6.tif", camera, as_distance);
  ASSERT_EQ(turned.distance_m.width(), kOrientH);
  ASSERT_EQ(turned.distance_m.height(), kOrientW);
  for (int dy = 0; dy < kOrientW; ++dy)
    for (int dx = 0; dx < kOrientH; ++dx) {
      const auto [sx, sy] = stored_position(6, dx, dy);
      EXPECT_EQ(turned.distance_m.at(dx, dy, 0), float(orient_codes(sx, sy)[0]));  // 8-bit codes
    }
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


TEST(IoErrors, TextFilesAreWrittenAtomicallyAndOnlyAsRegularFiles) {
  test::ScratchDir dir;
  write_text_file(dir / "a.json", "{\"x\": 1}\n");
  EXPECT_EQ(test::read_bytes(dir / "a.json"), "{\"x\": 1}\n");
  write_text_file(dir / "a.json", "{}");  // replaced
  EXPECT_EQ(test::read_bytes(dir / "a.json"), "{}");
  EXPECT_THROW(write_text_file(dir / "a.json", "new", /*overwrite=*/false), Error);
  EXPECT_EQ(test::read_bytes(dir / "a.json"), "{}");
  try {
    write_text_file(dir / "no/such/folder/b.json", "{}");
    ADD_FAILURE() << "a missing folder must be an error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::io);
    EXPECT_NE(std::string(e.what()).find("b.json"), std::string::npos) << e.what();
  }
  // A FIFO or a symbolic link at the target is refused, not replaced by a regular file.
  ASSERT_EQ(::mkfifo((dir / "pipe.json").c_str(), 0600), 0);
  EXPECT_THROW(write_text_file(dir / "pipe.json", "{}"), Error);
  std::filesystem::create_symlink(dir / "a.json", dir / "link.json");
  EXPECT_THROW(write_text_file(dir / "link.json", "{}"), Error);
  EXPECT_TRUE(std::filesystem::is_fifo(dir / "pipe.json"));
  EXPECT_TRUE(std::filesystem::is_symlink(dir / "link.json"));
  std::size_t entries = 0;  // no temporary left behind
  for (const auto& entry : std::filesystem::directory_iterator(dir.path())) {
    ++entries;
    EXPECT_EQ(entry.path().filename().string().find(".mr-tmp-"), std::string::npos);
  }
  EXPECT_EQ(entries, 3u);
}

}  // namespace
}  // namespace mr
