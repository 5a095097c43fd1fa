#include <gtest/gtest.h>

#include <cmath>

#include "mr/camera.h"
#include "mr/depth.h"
#include "mr/error.h"
#include "mr/io.h"
#include "test_support.h"

namespace fs = std::filesystem;

namespace mr {
namespace {

void write_raw(const fs::path& path, const Image& im, PixelType type) {
  WriteOptions w;
  w.pixel_type = type;
  w.colorspace = colorspace::raw;
  write_image(path, im, w);
}

// Portable float map, written by hand: "Pf", size, negative scale = little endian, rows bottom up.
void write_pfm(const fs::path& path, const Image& grey) {
  std::string bytes = "Pf\n" + std::to_string(grey.width()) + " " + std::to_string(grey.height()) + "\n-1.0\n";
  for (int y = grey.height() - 1; y >= 0; --y)
    bytes.append(reinterpret_cast<const char*>(grey.pixel(0, y)), sizeof(float) * grey.width());
  test::write_bytes(path, bytes);
}

TEST(Camera, FovFocalAndExif) {
  const Camera c = Camera::from_horizontal_fov(1000, 500, 90.0);
  EXPECT_NEAR(c.focal_px, 500.0, 1e-9);
  EXPECT_NEAR(c.horizontal_fov_deg(), 90.0, 1e-9);
  EXPECT_DOUBLE_EQ(c.cx, 500.0);
  EXPECT_DOUBLE_EQ(c.z_to_distance(499, 249), std::sqrt(1 + 2 * std::pow(0.5 / 500, 2)));
  EXPECT_NEAR(c.z_to_distance(0, 249), std::sqrt(std::pow(499.5 / 500, 2) + std::pow(0.5 / 500, 2) + 1), 1e-12);
  Metadata m;
  EXPECT_NEAR(Camera::from_metadata(1000, 500, m).horizontal_fov_deg(), 60.0, 1e-9);
  m.set("Exif:FocalLengthIn35mmFilm", 36.0);  // 36 mm on a 36 mm frame: f = width
  EXPECT_NEAR(Camera::from_metadata(1000, 500, m).focal_px, 1000.0, 1e-9);
  EXPECT_THROW(Camera::from_horizontal_fov(10, 10, 180.0), Error);
  EXPECT_THROW(Camera::from_focal_px(10, 10, -1.0), Error);
}

TEST(Depth, DistanceFromFloatFilesInEachFormat) {
  test::ScratchDir dir;
  const Camera cam = Camera::from_horizontal_fov(40, 30, 60.0);
  Image z(40, 30, 1, {"Z"});
  for (int y = 0; y < 30; ++y)
    for (int x = 0; x < 40; ++x) z.at(x, y, 0) = 1.0f + x + 100.0f * y;
  write_pfm(dir / "d.pfm", z);  // OIIO 2.4 reads PFM but cannot write it
  write_raw(dir / "d.exr", z, PixelType::float32);
  write_raw(dir / "d.tif", z, PixelType::float32);
  for (const char* name : {"d.exr", "d.tif", "d.pfm"}) {
    const DepthMap d = read_depth(dir / name, cam);
    EXPECT_EQ(d.no_surface_pixels, 0u);
    EXPECT_EQ(d.distance_m.channels(), 1);
    EXPECT_EQ(d.distance_m.at(7, 5, 0), 508.0f) << name;
    EXPECT_EQ(d.distance_m.at(39, 29, 0), 2940.0f) << name;
  }
}

TEST(Depth, PlanarZIsConvertedAlongTheRay) {
  const Camera cam = Camera::from_horizontal_fov(64, 48, 75.0);
  Image z(64, 48, 1);
  for (float& v : z.pixels()) v = 10.0f;
  const DepthMap d = depth_to_distance(z, cam, {DepthKind::planar_z});
  for (int y : {0, 20, 47})
    for (int x : {0, 31, 63}) {
      const auto dir = cam.ray_direction(x, y);
      EXPECT_NEAR(d.distance_m.at(x, y, 0), 10.0 / dir[2], 1e-4);
    }
  EXPECT_GT(d.distance_m.at(0, 0, 0), d.distance_m.at(32, 24, 0));
}

TEST(Depth, SixteenBitPngWithScale) {
  test::ScratchDir dir;
  const Camera cam = Camera::from_horizontal_fov(8, 4, 60.0);
  Image mm(8, 4, 1);
  for (int x = 0; x < 8; ++x)
    for (int y = 0; y < 4; ++y) mm.at(x, y, 0) = float(1000 * (x + 1) + y) / 65535.0f;  // codes
  write_raw(dir / "mm.png", mm, PixelType::uint16);
  DepthOptions o;
  o.scale = 0.001;  // millimetres
  const DepthMap d = read_depth(dir / "mm.png", cam, o);
  EXPECT_NEAR(d.distance_m.at(2, 3, 0), 3.003, 1e-6);
  EXPECT_NEAR(d.distance_m.at(7, 0, 0), 8.000, 1e-6);
}

TEST(Depth, DisparityFollowsTheMiddleburyConvention) {
  test::ScratchDir dir;
  // Middlebury: Z = baseline * f / (d + doffs).
  const double f = 1247.0, baseline = 0.16, doffs = 3.5;
  const Camera cam = Camera::from_focal_px(10, 6, f);
  Image disp(10, 6, 1);
  for (int y = 0; y < 6; ++y)
    for (int x = 0; x < 10; ++x) disp.at(x, y, 0) = float(10 + 7 * x + y) / 255.0f;
  disp.at(4, 4, 0) = 0;  // unknown disparity
  write_raw(dir / "disp.png", disp, PixelType::uint8);
  DepthOptions o;
  o.kind = DepthKind::disparity;
  o.baseline_m = baseline;
  o.doffs_px = doffs;
  o.scale = 0.5;  // stored value = 2 x disparity
  const DepthMap d = read_depth(dir / "disp.png", cam, o);
  for (int y = 0; y < 6; ++y)
    for (int x = 0; x < 10; ++x) {
      if (x == 4 && y == 4) continue;
      const double z = baseline * f / ((10 + 7 * x + y) * 0.5 + doffs);
      EXPECT_NEAR(d.distance_m.at(x, y, 0), z * cam.z_to_distance(x, y), 1e-5 * z);
    }
  EXPECT_TRUE(std::isinf(d.distance_m.at(4, 4, 0)));
  EXPECT_EQ(d.no_surface_pixels, 1u);
  o.baseline_m = 0;
  EXPECT_THROW(read_depth(dir / "disp.png", cam, o), Error);
}

TEST(Depth, NonFiniteZeroAndNegativeAreNoSurface) {
  const Camera cam = Camera::from_horizontal_fov(4, 1, 60.0);
  Image z(4, 1, 1);
  z.at(0, 0, 0) = std::nanf("");
  z.at(1, 0, 0) = 0.0f;
  z.at(2, 0, 0) = -3.0f;
  z.at(3, 0, 0) = 5.0f;
  const DepthMap d = depth_to_distance(z, cam, {});
  EXPECT_EQ(d.no_surface_pixels, 3u);
  EXPECT_EQ(d.invalid_pixels, 2u);  // NaN and -3; 0 is the sky encoding
  for (int x = 0; x < 3; ++x) EXPECT_TRUE(std::isinf(d.distance_m.at(x, 0, 0)) && d.distance_m.at(x, 0, 0) > 0);
  EXPECT_EQ(d.distance_m.at(3, 0, 0), 5.0f);
}

TEST(Depth, SizeMismatchNamesBothSizesAndTheFile) {
  test::ScratchDir dir;
  write_raw(dir / "small.exr", Image(32, 16, 1), PixelType::float32);
  try {
    read_depth(dir / "small.exr", Camera::from_horizontal_fov(64, 48, 60.0));
    FAIL() << "expected a size mismatch";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::size_mismatch);
    const std::string msg = e.what();
    EXPECT_NE(msg.find("small.exr"), std::string::npos) << msg;
    EXPECT_NE(msg.find("32x16"), std::string::npos) << msg;
    EXPECT_NE(msg.find("64x48"), std::string::npos) << msg;
  }
  DepthOptions bad;
  bad.scale = -1;
  EXPECT_THROW(depth_to_distance(Image(2, 2, 1), Camera::from_horizontal_fov(2, 2, 60.0), bad), Error);
}

TEST(Depth, PicksTheZChannelOfALayeredFile) {
  const Camera cam = Camera::from_horizontal_fov(2, 2, 60.0);
  Image layered(2, 2, 4, {"R", "G", "B", "depth.Z"});
  for (std::size_t i = 0; i < 4; ++i) {
    layered.pixels()[i * 4] = 1.0f;
    layered.pixels()[i * 4 + 3] = 42.0f;
  }
  EXPECT_EQ(depth_to_distance(layered, cam, {}).distance_m.at(1, 1, 0), 42.0f);
}

}  // namespace
}  // namespace mr

namespace mr {
namespace {

// The bundled Middlebury "Aloe" ground truth: the disparity PNG through the C++ loader must give
// the distance map that sample_photos/make_depth.py computed independently (float64, Python).
TEST(Depth, MiddleburyAloeDisparityMatchesTheSampleDepthMap) {
  const fs::path samples = fs::path(MR_SOURCE_DIR) / "sample_photos";
  const Camera cam = Camera::from_focal_px(1282, 1110, 3740.0);
  DepthOptions o;
  o.kind = DepthKind::disparity;
  o.baseline_m = 0.160;
  o.doffs_px = 270.0;
  const DepthMap from_disparity = read_depth(samples / "aloe_disparity.png", cam, o);
  const DepthMap reference = read_depth(samples / "aloe_depth.exr", cam);
  // Unknown disparities (occlusions, 3.45 %) are no surface for the loader; the sample map
  // fills them with the farther neighbour in the row, so it has none.
  EXPECT_GT(from_disparity.no_surface_pixels, 40000u);
  EXPECT_EQ(reference.no_surface_pixels, 0u);
  double worst = 0;
  for (std::size_t i = 0; i < reference.distance_m.pixel_count(); ++i) {
    const float a = from_disparity.distance_m.data()[i], b = reference.distance_m.data()[i];
    if (std::isinf(a)) continue;
    worst = std::max(worst, std::fabs(double(a) - b) / b);
  }
  EXPECT_LT(worst, 1e-6);  // float32 rounding of the same formula
  EXPECT_GT(reference.distance_m.at(640, 900, 0), 1.0f);
  EXPECT_LT(reference.distance_m.at(640, 900, 0), 2.0f);
}

}  // namespace
}  // namespace mr
