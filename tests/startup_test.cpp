// Issue 12, start-up: `mr` maps OpenImageIO and OpenCV's ximgproc / dnn only when a run needs
// them. A streamed sky-only `mr fog` of a 16x12 JPEG (also one with a camera's EXIF, and a PNG)
// with its depth EXR loads none of them
// (the dynamic loader's own log, LD_DEBUG=files, lists every library a process maps); reading
// a TIFF loads OIIO's module, and estimating geometry loads OpenCV's contrib module, and both
// work. And libmr.so itself does not need them (readelf -d), nor libOpenImageIO_Util (its
// static ustring table was half of that run's time: mr::Metadata keeps its own list).
#include <gtest/gtest.h>

#include <string>
#include <utility>
#include <vector>

#include "mr/mr.h"
#include "test_support.h"

namespace fs = std::filesystem;

namespace mr {
namespace {

const std::string kHeavy[] = {"libOpenImageIO.so", "libopencv_ximgproc", "libopencv_dnn"};

bool maps(const std::string& log, const std::string& library) {
  return log.find("file=" + library) != std::string::npos;
}

// Writes a 16x12 photo (JPEG, directly) and its depth (OpenEXR, float).
void write_inputs(const fs::path& dir) {
  Image photo = test::make_test_photo(16, 12);
  write_image(dir / "tiny.jpg", photo);
  Image depth(16, 12, 1, {"Z"});
  for (int y = 0; y < 12; ++y)
    for (int x = 0; x < 16; ++x) depth.at(x, y, 0) = y < 4 ? 1e30f : 10.0f + 10.0f * y;
  WriteOptions raw;
  raw.colorspace = colorspace::raw;
  raw.pixel_type = PixelType::float32;
  write_image(dir / "tiny_depth.exr", depth, raw);
}

test::CommandResult run_mr(const std::string& args) {
  return test::run("LD_DEBUG=files " + std::string(MR_CLI_PATH) + " " + args + " 2>&1");
}

// `mr fog` of `photo` (in dir) with tiny_depth.exr, a sky-only fog, into dir/out.
test::CommandResult fog_tiny(const test::ScratchDir& dir, const std::string& photo,
                             const std::string& extra = "") {
  return run_mr("fog " + test::shell_quoted(dir / photo) + " --depth " +
                test::shell_quoted(dir / "tiny_depth.exr") + " --out-dir " +
                test::shell_quoted(dir / "out") + extra + " --visibility 150m --airlight 0.8 -q");
}

// Neither OIIO (its module or its libraries) nor OpenCV's contrib libraries were mapped.
void expect_no_heavy_library(const std::string& log) {
  for (const std::string& lib : kHeavy) EXPECT_FALSE(maps(log, lib)) << lib << " was loaded";
  EXPECT_FALSE(maps(log, "libmr_oiio.so"));
  EXPECT_FALSE(maps(log, "libOpenImageIO_Util")) << "OIIO's Util library was loaded";
}

TEST(Startup, LibmrDoesNotNeedTheHeavyLibraries) {
  const test::CommandResult r = test::run("readelf -d " + std::string(MR_LIBRARY_PATH));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(r.output.find("libOpenImageIO_Util"), std::string::npos) << r.output;
  for (const std::string& lib : kHeavy)
    EXPECT_EQ(r.output.find("[" + lib), std::string::npos) << lib << " in\n" << r.output;
}

TEST(Startup, SkyOnlyFogLoadsNoHeavyLibrary) {
  test::ScratchDir dir;
  write_inputs(dir.path());
  const test::CommandResult r = fog_tiny(dir, "tiny.jpg");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  ASSERT_TRUE(fs::exists(dir / "out" / "tiny_fog.jpg")) << r.output;
  expect_no_heavy_library(r.output);
  EXPECT_FALSE(maps(r.output, "libmr_opencv_contrib.so"));
  // `mr --version` neither.
  const test::CommandResult v = run_mr("--version");
  ASSERT_EQ(v.exit_code, 0) << v.output;
  for (const std::string& lib : kHeavy) EXPECT_FALSE(maps(v.output, lib)) << lib;
  EXPECT_FALSE(maps(v.output, "libOpenImageIO_Util"));
}

// The marker segments of a JPEG file before its scan: (offset, length with the marker).
std::vector<std::pair<std::size_t, std::size_t>> segments(const std::string& jpeg) {
  std::vector<std::pair<std::size_t, std::size_t>> out;
  std::size_t at = 2;
  while (at + 4 <= jpeg.size() && static_cast<unsigned char>(jpeg[at]) == 0xFF &&
         static_cast<unsigned char>(jpeg[at + 1]) != 0xDA) {
    const std::size_t len = std::size_t(static_cast<unsigned char>(jpeg[at + 2])) << 8 |
                            static_cast<unsigned char>(jpeg[at + 3]);
    out.emplace_back(at, 2 + len);
    at += 2 + len;
  }
  return out;
}

bool is_exif(const std::string& jpeg, std::size_t at) {
  return static_cast<unsigned char>(jpeg[at + 1]) == 0xE1 &&
         jpeg.compare(at + 4, 5, std::string("Exif\0", 5)) == 0;
}

// `jpeg` with its EXIF block (APP1 "Exif") replaced by `exif` (a whole segment).
std::string with_exif(const std::string& jpeg, const std::string& exif) {
  std::string out = jpeg.substr(0, 2) + exif;
  std::size_t end = 2;
  for (const auto& [at, len] : segments(jpeg)) {
    if (!is_exif(jpeg, at)) out += jpeg.substr(at, len);
    end = at + len;
  }
  return out + jpeg.substr(end);
}

// The first EXIF segment of a JPEG file.
std::string exif_segment(const std::string& jpeg) {
  for (const auto& [at, len] : segments(jpeg))
    if (is_exif(jpeg, at)) return jpeg.substr(at, len);
  return "";
}

TEST(Startup, CameraJpegLoadsNoHeavyLibrary) {
  // A phone photo's EXIF block (an iPhone's: Exif and GPS directories, a maker note) on the
  // 16x12 photo: read and written (its metadata copied into the output) without OIIO.
  test::ScratchDir dir;
  write_inputs(dir.path());
  const std::string iphone =
      exif_segment(test::read_bytes(fs::path(MR_SOURCE_DIR) / "sample_photos" / "leuven.jpg"));
  ASSERT_FALSE(iphone.empty());
  test::write_bytes(dir / "tiny.jpg", with_exif(test::read_bytes(dir / "tiny.jpg"), iphone));
  ASSERT_TRUE(read_image(dir / "tiny.jpg").metadata().contains("GPS:Latitude"));
  const test::CommandResult r = fog_tiny(dir, "tiny.jpg");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  ASSERT_TRUE(fs::exists(dir / "out" / "tiny_fog.jpg")) << r.output;
  expect_no_heavy_library(r.output);
  // The camera's metadata went into the output.
  const Metadata out = read_image(dir / "out" / "tiny_fog.jpg").metadata();
  EXPECT_EQ(out.get_string("Model").value_or(""), "iPhone 6");
  EXPECT_TRUE(out.contains("GPS:Latitude"));
}

TEST(Startup, PngInputLoadsNoHeavyLibrary) {
  // A PNG photo (written by OIIO's module, in this process) fogged into a JPEG: read through
  // libpng, no OIIO library in `mr`.
  test::ScratchDir dir;
  write_inputs(dir.path());
  write_image(dir / "tiny.png", read_image(dir / "tiny.jpg"));
  const test::CommandResult r = fog_tiny(dir, "tiny.png", " --format jpg");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  ASSERT_TRUE(fs::exists(dir / "out" / "tiny_fog.jpg")) << r.output;
  expect_no_heavy_library(r.output);
}

TEST(Startup, TiffAndEstimationLoadTheirModules) {
  test::ScratchDir dir;
  write_inputs(dir.path());
  write_image(dir / "tiny.tif", read_image(dir / "tiny.jpg"));  // through OIIO's module
  const test::CommandResult r = fog_tiny(dir, "tiny.tif");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(maps(r.output, "libOpenImageIO.so")) << "the TIFF was not read through OIIO";
  EXPECT_TRUE(fs::exists(dir / "out" / "tiny_fog.tif"));
  // No depth given: the geometry is estimated (sky mask, guided filter: ximgproc).
  Image photo = test::make_test_photo(96, 64);
  write_image(dir / "est.jpg", photo);
  const test::CommandResult e =
      run_mr("fog " + test::shell_quoted(dir / "est.jpg") + " --depth auto --out-dir " +
             test::shell_quoted(dir / "out2") + " --visibility 150m -q");
  ASSERT_EQ(e.exit_code, 0) << e.output;
  EXPECT_TRUE(maps(e.output, "libopencv_ximgproc")) << "estimation did not use ximgproc";
  EXPECT_TRUE(fs::exists(dir / "out2" / "est_fog.jpg"));
}

}  // namespace
}  // namespace mr
