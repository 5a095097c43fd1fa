// Batch robustness (issue 4 acceptance): `mr fog --depth auto` over copies of every sample photo
// (without their depth maps, so the geometry is estimated) plus adversarial images written here
// never crashes: each photo gets an output or a clear per-file "ERROR: <file>:" line, the exit code
// is 0 or 1 (a signal reads as 128 + n through the shell), and the inputs are unchanged.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <random>
#include <string>

#include "mr/io.h"
#include "mr/metadata.h"
#include "test_support.h"

namespace fs = std::filesystem;

namespace mr {
namespace {

const std::string kMr = MR_CLI_PATH;

std::map<std::string, std::uint64_t> checksums(const fs::path& dir) {
  std::map<std::string, std::uint64_t> out;
  for (const auto& e : fs::directory_iterator(dir)) out[e.path().filename().string()] = test::file_checksum(e.path());
  return out;
}

Image filled(int w, int h, int channels, float value) {
  Image im(w, h, channels);
  for (float& v : im.pixels()) v = value;
  return im;
}

TEST(CliRobustness, AutoDepthOverSamplesAndAdversarialImagesNeverCrashes) {
  test::ScratchDir dir;
  const fs::path in = dir / "in", out = dir / "out";
  fs::create_directories(in);
  std::vector<std::string> samples;
  for (const auto& e : fs::directory_iterator(fs::path(MR_SOURCE_DIR) / "sample_photos"))
    if (e.path().extension() == ".jpg") {
      fs::copy_file(e.path(), in / e.path().filename());
      samples.push_back(e.path().filename().string());
    }
  ASSERT_GE(samples.size(), 4u);

  write_image(in / "black.png", filled(64, 48, 3, 0.0f));
  write_image(in / "white.jpg", filled(64, 48, 3, 1.0f));
  Image noise(128, 96, 3);
  std::mt19937 rng(99);
  std::uniform_real_distribution<float> uniform(0.0f, 1.0f);
  for (float& v : noise.pixels()) v = uniform(rng);
  write_image(in / "noise.png", noise);
  write_image(in / "one_pixel.png", filled(1, 1, 3, 0.5f));
  write_image(in / "gray.png", filled(40, 30, 1, 0.3f));
  write_image(in / "panorama.jpg", test::make_test_photo(20000, 200));
  write_image(in / "no_exif.jpg", test::make_test_photo(96, 64));  // a fresh image: no metadata
  // EXIF Orientation = 6 (rotate 90 degrees clockwise to view). libmr's Metadata::set stores
  // numbers as float, which OIIO's JPEG writer does not encode as the (SHORT) EXIF tag, so the tag
  // is spliced in here as an APP1 segment right after the JPEG's SOI marker; read back to check.
  write_image(in / "rotated.jpg", test::make_test_photo(96, 64));
  {
    const std::string jpeg = test::read_bytes(in / "rotated.jpg");
    ASSERT_EQ(jpeg.substr(0, 2), "\xFF\xD8");
    const unsigned char app1[] = {0xFF, 0xE1, 0x00, 0x22, 'E', 'x', 'i', 'f', 0, 0,        // APP1, 34 bytes
                                  'I', 'I', 0x2A, 0x00, 0x08, 0x00, 0x00, 0x00,            // TIFF header
                                  0x01, 0x00,                                              // IFD0: 1 entry
                                  0x12, 0x01, 0x03, 0x00, 0x01, 0x00, 0x00, 0x00, 0x06, 0x00, 0x00, 0x00,
                                  0x00, 0x00, 0x00, 0x00};                                 // no next IFD
    test::write_bytes(in / "rotated.jpg",
                      jpeg.substr(0, 2) + std::string(reinterpret_cast<const char*>(app1), sizeof app1) +
                          jpeg.substr(2));
  }
  ReadOptions as_stored;
  as_stored.apply_orientation = false;
  EXPECT_EQ(read_image(in / "rotated.jpg", as_stored).metadata().get_number("Orientation").value_or(0), 6.0);
  EXPECT_EQ(probe_image(in / "rotated.jpg").orientation, 6);
  EXPECT_FALSE(read_image(in / "no_exif.jpg").metadata().contains("Exif:FocalLengthIn35mmFilm"));

  const auto before = checksums(in);
  const auto r = test::run(kMr + " fog " + in.string() + " --depth auto --quality draft -o " + out.string() +
                           " -j 2");
  std::printf("%s\n", r.output.c_str());
  EXPECT_TRUE(r.exit_code == 0 || r.exit_code == 1) << "exit code " << r.exit_code << "\n" << r.output;
  EXPECT_EQ(checksums(in), before) << "an input changed";

  int outputs = 0, errors = 0;
  for (const auto& [name, sum] : before) {
    const fs::path photo = in / name;
    const fs::path output = out / (photo.stem().string() + "_fog" + photo.extension().string());
    const bool has_error = r.output.find("ERROR: " + photo.string() + ":") != std::string::npos;
    if (fs::exists(output)) {
      ++outputs;
      EXPECT_FALSE(has_error) << name << ": both an output and an error";
      // The output is the photo as displayed: turned by its EXIF Orientation (5..8 swap the
      // sides) and tagged Orientation 1, so that viewers do not turn it again.
      const ImageFileInfo a = probe_image(photo), b = probe_image(output);
      const bool swapped = a.orientation >= 5;
      EXPECT_EQ(swapped ? a.height : a.width, b.width) << name;
      EXPECT_EQ(swapped ? a.width : a.height, b.height) << name;
      EXPECT_EQ(b.orientation, 1) << name;
    } else {
      ++errors;
      EXPECT_TRUE(has_error) << name << ": neither an output nor an ERROR line\n" << r.output;
    }
  }
  // The sample photos and the ordinary adversarial cases must all be fogged.
  for (const std::string& name : samples)
    EXPECT_TRUE(fs::exists(out / (fs::path(name).stem().string() + "_fog.jpg"))) << name;
  for (const char* name : {"black_fog.png", "white_fog.jpg", "noise_fog.png", "no_exif_fog.jpg", "rotated_fog.jpg",
                           "panorama_fog.jpg"})
    EXPECT_TRUE(fs::exists(out / name)) << name;
  // rotated.jpg (stored 96 x 64, Orientation 6) comes out upright: 64 wide, 96 high.
  const ImageFileInfo rotated = probe_image(out / "rotated_fog.jpg");
  EXPECT_EQ(rotated.width, 64);
  EXPECT_EQ(rotated.height, 96);
  EXPECT_EQ(r.exit_code, errors ? 1 : 0);
  std::printf("%d outputs, %d per-file errors\n", outputs, errors);
}

TEST(CliRobustness, AnnotationsNeedAutoDepthAndAreUsedPerPhoto) {
  test::ScratchDir dir;
  const fs::path in = dir / "in", out = dir / "out";
  fs::create_directories(in);
  fs::copy_file(fs::path(MR_SOURCE_DIR) / "sample_photos" / "leuven.jpg", in / "leuven.jpg");
  fs::copy_file(fs::path(MR_SOURCE_DIR) / "sample_photos" / "leuven_annotations.json", in / "leuven_annotations.json");
  write_image(in / "other.jpg", test::make_test_photo(96, 64));  // no annotations file: automatic
  const auto usage = test::run(kMr + " fog " + (in / "leuven.jpg").string() + " --annotations x.json -o " +
                               out.string());
  EXPECT_EQ(usage.exit_code, 2) << usage.output;
  EXPECT_NE(usage.output.find("--annotations needs --depth auto"), std::string::npos) << usage.output;

  const auto r = test::run(kMr + " fog " + (in / "*.jpg").string() +
                           " --depth auto --annotations '{dir}/{stem}_annotations.json' --quality draft --fov 60"
                           " --save-scene " + (dir / "plan.json").string() + " -o " + out.string());
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(fs::exists(out / "leuven_fog.jpg")) << r.output;
  EXPECT_TRUE(fs::exists(out / "other_fog.jpg")) << r.output;

  // A depth map that exists is used as it is (depth.Z of the AOVs equals it exactly).
  const fs::path in2 = dir / "in2";
  fs::create_directories(in2);
  for (const char* name : {"aerial.jpg", "aerial_depth.exr"})
    fs::copy_file(fs::path(MR_SOURCE_DIR) / "sample_photos" / name, in2 / name);
  const auto given = test::run(kMr + " fog " + in2.string() + " --depth auto --quality draft --format exr --aovs -o " +
                               (dir / "out2").string());
  ASSERT_EQ(given.exit_code, 0) << given.output;
  ReadOptions raw;
  raw.to_scene_linear = false;
  raw.reject_non_finite = false;
  const Image layers = read_image(dir / "out2" / "aerial_fog.exr", raw);
  const Image file_depth = read_image(in2 / "aerial_depth.exr", raw);
  const int z = layers.channel_index("depth.Z");
  ASSERT_GE(z, 0);
  double max_diff = 0;
  for (int y = 0; y < file_depth.height(); ++y)
    for (int x = 0; x < file_depth.width(); ++x)
      max_diff = std::max(max_diff, double(std::abs(layers.at(x, y, z) - file_depth.at(x, y, 0))));
  EXPECT_EQ(max_diff, 0.0);  // aerial has no sky (0) pixels; both are float32

  // A broken annotations file is that photo's error, not the batch's.
  test::write_bytes(in / "other_annotations.json", "{ not json");
  const auto bad = test::run(kMr + " fog " + (in / "*.jpg").string() +
                             " --depth auto --annotations '{dir}/{stem}_annotations.json' --quality draft"
                             " --overwrite -o " + out.string());
  EXPECT_EQ(bad.exit_code, 1) << bad.output;
  EXPECT_NE(bad.output.find("ERROR: " + (in / "other.jpg").string() + ": estimating the geometry"),
            std::string::npos)
      << bad.output;
}

}  // namespace
}  // namespace mr
