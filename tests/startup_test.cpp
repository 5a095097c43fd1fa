// Issue 12, start-up: `mr` maps OpenImageIO and OpenCV's ximgproc / dnn only when a run needs
// them. A streamed sky-only `mr fog` of a 16x12 JPEG (also one with a camera's EXIF, and a PNG)
// with its depth EXR loads none of them
// (the dynamic loader's own log, LD_DEBUG=files, lists every library a process maps); reading
// a TIFF loads OIIO's module, and estimating geometry loads OpenCV's contrib module, and both
// work. And libmr.so itself does not need them (readelf -d), nor libOpenImageIO_Util (its
// static ustring table was half of that run's time: mr::Metadata keeps its own list).
#include <gtest/gtest.h>

#include <string>

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
  const test::CommandResult r =
      run_mr("fog " + test::shell_quoted(dir / "tiny.jpg") + " --depth " +
             test::shell_quoted(dir / "tiny_depth.exr") + " --out-dir " +
             test::shell_quoted(dir / "out") + " --visibility 150m --airlight 0.8 -q");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  ASSERT_TRUE(fs::exists(dir / "out" / "tiny_fog.jpg")) << r.output;
  for (const std::string& lib : kHeavy) EXPECT_FALSE(maps(r.output, lib)) << lib << " was loaded";
  EXPECT_FALSE(maps(r.output, "libmr_oiio.so"));
  EXPECT_FALSE(maps(r.output, "libmr_opencv_contrib.so"));
  EXPECT_FALSE(maps(r.output, "libOpenImageIO_Util")) << "OIIO's Util library was loaded";
  // `mr --version` neither.
  const test::CommandResult v = run_mr("--version");
  ASSERT_EQ(v.exit_code, 0) << v.output;
  for (const std::string& lib : kHeavy) EXPECT_FALSE(maps(v.output, lib)) << lib;
  EXPECT_FALSE(maps(v.output, "libOpenImageIO_Util"));
}

// `jpeg` with its EXIF block (APP1 "Exif") replaced by `exif` (a whole segment).
std::string with_exif(const std::string& jpeg, const std::string& exif) {
  std::string out = jpeg.substr(0, 2) + exif;
  std::size_t at = 2;
  while (at + 4 <= jpeg.size() && static_cast<unsigned char>(jpeg[at]) == 0xFF) {
    const std::size_t len = std::size_t(static_cast<unsigned char>(jpeg[at + 2])) << 8 |
                            static_cast<unsigned char>(jpeg[at + 3]);
    if (static_cast<unsigned char>(jpeg[at + 1]) == 0xDA) break;
    if (!(static_cast<unsigned char>(jpeg[at + 1]) == 0xE1 &&
          jpeg.compare(at + 4, 5, std::string("Exif\0", 5)) == 0))
      out += jpeg.substr(at, 2 + len);
    at += 2 + len;
  }
  return out + jpeg.substr(at);
}

// The first EXIF segment of a JPEG file.
std::string exif_segment(const std::string& jpeg) {
  std::size_t at = 2;
  while (at + 4 <= jpeg.size() && static_cast<unsigned char>(jpeg[at]) == 0xFF) {
    const std::size_t len = std::size_t(static_cast<unsigned char>(jpeg[at + 2])) << 8 |
                            static_cast<unsigned char>(jpeg[at + 3]);
    if (static_cast<unsigned char>(jpeg[at + 1]) == 0xE1 &&
        jpeg.compare(at + 4, 5, std::string("Exif\0", 5)) == 0)
      return jpeg.substr(at, 2 + len);
    at += 2 + len;
  }
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
  const test::CommandResult r =
      run_mr("fog " + test::shell_quoted(dir / "tiny.jpg") + " --depth " +
             test::shell_quoted(dir / "tiny_depth.exr") + " --out-dir " +
             test::shell_quoted(dir / "out") + " --visibility 150m --airlight 0.8 -q");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  ASSERT_TRUE(fs::exists(dir / "out" / "tiny_fog.jpg")) << r.output;
  for (const std::string& lib : kHeavy) EXPECT_FALSE(maps(r.output, lib)) << lib << " was loaded";
  EXPECT_FALSE(maps(r.output, "libmr_oiio.so"));
  EXPECT_FALSE(maps(r.output, "libOpenImageIO_Util"));
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
  const test::CommandResult r =
      run_mr("fog " + test::shell_quoted(dir / "tiny.png") + " --depth " +
             test::shell_quoted(dir / "tiny_depth.exr") + " --out-dir " +
             test::shell_quoted(dir / "out") + " --format jpg --visibility 150m --airlight 0.8 -q");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  ASSERT_TRUE(fs::exists(dir / "out" / "tiny_fog.jpg")) << r.output;
  for (const std::string& lib : kHeavy) EXPECT_FALSE(maps(r.output, lib)) << lib << " was loaded";
  EXPECT_FALSE(maps(r.output, "libmr_oiio.so"));
  EXPECT_FALSE(maps(r.output, "libOpenImageIO_Util"));
}

TEST(Startup, TiffAndEstimationLoadTheirModules) {
  test::ScratchDir dir;
  write_inputs(dir.path());
  write_image(dir / "tiny.tif", read_image(dir / "tiny.jpg"));  // through OIIO's module
  const test::CommandResult r =
      run_mr("fog " + test::shell_quoted(dir / "tiny.tif") + " --depth " +
             test::shell_quoted(dir / "tiny_depth.exr") + " --out-dir " +
             test::shell_quoted(dir / "out") + " --visibility 150m --airlight 0.8 -q");
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
