// `mr material` driven like a user drives it, on the sample photos (reduced to a third of their
// size so that each run takes a few seconds): the depth map found by the {stem}_depth.exr
// convention, a mask PNG or an annotations JSON as regions, outputs written and inputs untouched,
// fog in the same run, and bad input answered with a message and exit code.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <nlohmann/json.hpp>

#include "mr/annotations.h"
#include "mr/camera.h"
#include "mr/color.h"
#include "mr/io.h"
#include "test_support.h"

namespace fs = std::filesystem;

namespace mr {
namespace {

const std::string kMr = MR_CLI_PATH;
const fs::path kSamples = fs::path(MR_SOURCE_DIR) / "sample_photos";

using test::shell_quoted;

// A sample photo and its depth map at a third of their size.
void write_reduced(const std::string& stem, const fs::path& dir) {
  test::write_reduced_sample(kSamples, stem, dir);
}

class MaterialCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new test::ScratchDir;
    write_reduced("leuven", dir_->path());
    write_reduced("building", dir_->path());
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  void SetUp() override {
    work = dir_->path() / ::testing::UnitTest::GetInstance()->current_test_info()->name();
    fs::create_directories(work);
  }
  // Regions on the reduced leuven (250 x 187): the street (1) and the left house's wall (2).
  fs::path write_mask(int w = 250, int h = 187) {
    Image m(w, h, 1);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        if (y > 140 && y < 180 && x > 40 && x < 200) m.at(x, y, 0) = 1.0f / 255;
        if (y > 30 && y < 120 && x > 2 && x < 35) m.at(x, y, 0) = 2.0f / 255;
      }
    WriteOptions o;
    o.colorspace = colorspace::raw;
    o.pixel_type = PixelType::uint8;
    const fs::path path = work / ("mask_" + std::to_string(w) + ".png");
    write_image(path, m, o);
    return path;
  }
  std::string base() const {
    return kMr + " material --sample " + shell_quoted(dir_->path() / "building.png") +
           " --sample-fov 50 --target " + shell_quoted(dir_->path() / "leuven.png") + " --fov 60";
  }
  static test::ScratchDir* dir_;
  fs::path work;
};
test::ScratchDir* MaterialCli::dir_ = nullptr;

std::map<std::string, std::uint64_t> checksums(const fs::path& dir) {
  std::map<std::string, std::uint64_t> out;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.is_regular_file()) out[e.path().filename().string()] = test::file_checksum(e.path());
  return out;
}

TEST_F(MaterialCli, MaskRegionsWriteImageAndJsonInputsUntouched) {
  const fs::path mask = write_mask();
  const auto before = checksums(dir_->path());
  const auto r = test::run(base() + " --regions " + shell_quoted(mask) + " -o " +
                           shell_quoted(work / "out.png") + " --materials-json " +
                           shell_quoted(work / "chosen.json") + " --seed 3");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("leuven_depth.exr"), std::string::npos)
      << r.output;  // found by convention
  EXPECT_NE(r.output.find("default light"), std::string::npos) << r.output;
  const Image out = read_image(work / "out.png");
  EXPECT_EQ(out.width(), 250);
  EXPECT_EQ(out.height(), 187);
  const auto doc = nlohmann::json::parse(test::read_bytes(work / "chosen.json"));
  EXPECT_EQ(doc["format"], "mr-materials");
  EXPECT_EQ(doc["regions"].size(), 2u);
  EXPECT_GE(doc["candidates"].size(), 1u);
  EXPECT_EQ(before, checksums(dir_->path()));  // inputs never modified
  // Pixels outside the regions are the photo's (8-bit round trip: exact).
  const Image photo = read_image(dir_->path() / "leuven.png");
  EXPECT_EQ(out.at(120, 10, 0), photo.at(120, 10, 0));
  EXPECT_EQ(out.at(240, 100, 1), photo.at(240, 100, 1));
  // The street changed.
  double changed = 0;
  for (int y = 145; y < 175; ++y)
    for (int x = 50; x < 190; ++x) changed += std::abs(out.at(x, y, 1) - photo.at(x, y, 1));
  EXPECT_GT(changed / (30 * 140), 0.005);
  // An existing output is not replaced without --overwrite.
  const auto again = test::run(base() + " --regions " + shell_quoted(mask) + " -o " +
                               shell_quoted(work / "out.png"));
  EXPECT_EQ(again.exit_code, 2) << again.output;
  EXPECT_NE(again.output.find("--overwrite"), std::string::npos) << again.output;
}

// Design rule (DESIGN.md section 7): display-referred outputs go through the highlight roll-off,
// never a hard clip. `mr material` wrote 8-bit outputs with plain sRGB, so a light material on a
// surface the photo shows dark with sunlit patches clipped flat to white (gallery/tune
// dragonfly: 7.5 % of its regions' pixels at 255 where the photo is not). Here a dark wall
// with bright patches (left half, the region) takes a light sample's material; the same transfer
// is written to EXR (scene-linear, unclipped) and to PNG at the photo's own exposure
// (--physical-exposure): every pixel the transfer changed is the EXR's value through the roll-off
// (within one 8-bit code, so none at 255), every other pixel is the photo's exactly. By default
// the region is exposed down as a whole instead (mr::MaterialTransferOptions::fit_photo_range):
// its interior is one factor times the physical rendering and at most 1 % of it beyond white.
TEST_F(MaterialCli, ChangedPixelsRollOffAndTheRestIsThePhoto) {
  constexpr int kW = 120, kH = 90;
  Image target(kW, kH, 3), sample(kW, kH, 3), depth(kW, kH, 1), mask(kW, kH, 1);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      // A fixed ripple of +-5 % stands in for texture (no random numbers in a test).
      const float ripple = 1 + 0.05f * std::sin(0.9f * float(x) + 1.7f * float(y));
      const bool patch = x < 55 && (x - 5) % 12 < 4 && (y - 5) % 12 < 4 && x >= 5 && y >= 5;
      const float t = x < 60 ? (patch ? 0.6f : 0.02f) : 0.25f;
      for (int c = 0; c < 3; ++c) {
        target.at(x, y, c) = t * ripple;
        sample.at(x, y, c) = 0.6f * ripple;
      }
      depth.at(x, y, 0) = 5.0f;
      mask.at(x, y, 0) = x < 60 ? 1.0f / 255 : 0.0f;
    }
  WriteOptions png8;
  png8.pixel_type = PixelType::uint8;
  write_image(work / "target.png", target, png8);
  write_image(work / "sample.png", sample, png8);
  write_image(work / "target_depth.exr", depth);
  write_image(work / "sample_depth.exr", depth);
  WriteOptions raw = png8;
  raw.colorspace = colorspace::raw;
  write_image(work / "mask.png", mask, raw);
  const std::string transfer = kMr + " material --sample " + shell_quoted(work / "sample.png") +
                               " --sample-fov 50 --target " + shell_quoted(work / "target.png") +
                               " --fov 50 --regions " + shell_quoted(work / "mask.png") +
                               " --seed 3";
  const std::string common = transfer + " -q --physical-exposure";
  const auto r_exr = test::run(common + " -o " + shell_quoted(work / "linear.exr"));
  ASSERT_EQ(r_exr.exit_code, 0) << r_exr.output;
  const auto r_png = test::run(common + " -o " + shell_quoted(work / "display.png"));
  ASSERT_EQ(r_png.exit_code, 0) << r_png.output;
  const Image linear = read_image(work / "linear.exr");
  const Image display = read_image(work / "display.png");
  const Image photo = read_image(work / "target.png");
  ASSERT_EQ(display.width(), linear.width());
  auto encode = [](double v) {  // sRGB code of a linear value, clamped as the encoder does
    v = std::clamp(v, 0.0, 1.0);
    const double e = v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1 / 2.4) - 0.055;
    return 255 * e;
  };
  int changed = 0, above_white = 0, at_255 = 0, unchanged_differ = 0, off = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      bool differs = false;
      for (int c = 0; c < 3; ++c)
        differs = differs || std::abs(linear.at(x, y, c) - photo.at(x, y, c)) > 1e-6f;
      changed += differs;
      for (int c = 0; c < 3; ++c) {
        if (!differs) {
          unchanged_differ += display.at(x, y, c) != photo.at(x, y, c);
          continue;
        }
        const double v = linear.at(x, y, c);
        above_white += v >= 1;
        at_255 += display.at(x, y, c) >= 1.0f;
        off += std::abs(encode(display.at(x, y, c)) - encode(highlight_rolloff(v))) > 1.01;
      }
    }
  std::printf("changed pixels %d: channel values at or above white %d, at code 255 %d\n", changed,
              above_white, at_255);
  EXPECT_GT(changed, 40 * kH);      // the region changed
  EXPECT_GT(above_white, 3 * 100);  // the patches came out above white (the case tested)
  EXPECT_EQ(at_255, 0);
  EXPECT_EQ(off, 0);
  EXPECT_EQ(unchanged_differ, 0);
  // The default: exposed down to the photo's white, and the notes (not quiet) say by how much.
  const auto r_fit = test::run(transfer + " -o " + shell_quoted(work / "fitted.exr") +
                               " --materials-json " + shell_quoted(work / "fitted.json"));
  ASSERT_EQ(r_fit.exit_code, 0) << r_fit.output;
  EXPECT_NE(r_fit.output.find("stops to stay within the photo's white"), std::string::npos)
      << r_fit.output;
  const Image fitted = read_image(work / "fitted.exr");
  // The factor over the region's interior (beyond the feather's reach); the share beyond white
  // over all its pixels (what the percentile counts; a feathered border pixel mixes the rendering
  // with the photo, below white, so it is beyond only where the rendering is).
  std::vector<double> ratios;
  int region = 0, fitted_beyond = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < 60; ++x) {
      ++region;
      fitted_beyond += std::max({fitted.at(x, y, 0), fitted.at(x, y, 1), fitted.at(x, y, 2)}) > 1;
      if (x >= 4 && x < 56 && y >= 4 && y < kH - 4)
        for (int c = 0; c < 3; ++c)
          ratios.push_back(double(fitted.at(x, y, c)) / linear.at(x, y, c));
    }
  std::sort(ratios.begin(), ratios.end());
  const double factor = ratios[ratios.size() / 2];
  std::printf(
      "default: exposed down by %.4f (ratios %.6f to %.6f), %d of %d region pixels "
      "beyond white\n",
      factor, ratios.front(), ratios.back(), fitted_beyond, region);
  EXPECT_LT(factor, 0.5);
  EXPECT_NEAR(ratios.front(), factor, 1e-5 * factor);
  EXPECT_NEAR(ratios.back(), factor, 1e-5 * factor);
  EXPECT_LE(fitted_beyond, region / 100);
  // The JSON gives the factor the image shows (float rendering: a relative 1e-5).
  const auto doc = nlohmann::json::parse(test::read_bytes(work / "fitted.json"));
  EXPECT_NEAR(doc["regions"][0]["exposure"].get<double>(), factor, 1e-5 * factor);
  // A 16-bit target stays 16-bit in a PNG output (as `mr fog` keeps it); an 8-bit one 8-bit.
  WriteOptions png16;
  png16.pixel_type = PixelType::uint16;
  write_image(work / "target16.png", target, png16);
  write_image(work / "target16_depth.exr", depth);
  const auto r16 = test::run(kMr + " material --sample " + shell_quoted(work / "sample.png") +
                             " --sample-fov 50 --target " + shell_quoted(work / "target16.png") +
                             " --fov 50 --regions " + shell_quoted(work / "mask.png") +
                             " --seed 3 -q -o " + shell_quoted(work / "display16.png"));
  ASSERT_EQ(r16.exit_code, 0) << r16.output;
  EXPECT_EQ(probe_image(work / "display16.png").pixel_type, PixelType::uint16);
  EXPECT_EQ(probe_image(work / "display.png").pixel_type, PixelType::uint8);
}

TEST_F(MaterialCli, AnnotationRegionsAndFogInOneRun) {
  Annotations a;
  a.planes.push_back({{{40, 145}, {200, 145}, {200, 180}, {40, 180}}, std::nullopt});
  save_annotations(work / "regions.json", a);
  const auto r = test::run(base() + " --regions " + shell_quoted(work / "regions.json") + " -o " +
                           shell_quoted(work / "fog.png") + " --visibility 40m -q");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  // Fog lifts the far street: the top of the frame (sky and far houses) grows brighter/greyer.
  const Image out = read_image(work / "fog.png");
  const Image photo = read_image(dir_->path() / "leuven.png");
  double diff = 0;
  for (int x = 0; x < 250; ++x) diff += std::abs(out.at(x, 100, 1) - photo.at(x, 100, 1));
  EXPECT_GT(diff / 250, 0.005);
}

TEST_F(MaterialCli, SceneTargetFromADistanceMapAlone) {
  // A 3D scene given by its distance map: a flat wall 4 m away filling a 90 x 60 frame, one
  // region in its middle. No --target photo: the region is rendered over black.
  Image depth(90, 60, 1, {"Z"});
  const Camera camera = Camera::from_horizontal_fov(90, 60, 60);
  for (int y = 0; y < 60; ++y)
    for (int x = 0; x < 90; ++x) depth.at(x, y, 0) = float(4 * camera.z_to_distance(x, y));
  WriteOptions wd;
  wd.pixel_type = PixelType::float32;
  wd.colorspace = colorspace::raw;
  write_image(work / "wall_depth.exr", depth, wd);
  Image mask(90, 60, 1);
  for (int y = 15; y < 45; ++y)
    for (int x = 20; x < 70; ++x) mask.at(x, y, 0) = 1.0f / 255;
  WriteOptions o;
  o.colorspace = colorspace::raw;
  o.pixel_type = PixelType::uint8;
  write_image(work / "wall_mask.png", mask, o);
  const std::string cmd =
      kMr + " material --sample " + shell_quoted(dir_->path() / "building.png") +
      " --sample-fov 50 --target-depth " + shell_quoted(work / "wall_depth.exr") +
      " --fov 60 --regions " + shell_quoted(work / "wall_mask.png");
  auto r = test::run(cmd + " -o " + shell_quoted(work / "wall.exr"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("3D scene"), std::string::npos) << r.output;
  const Image out = read_image(work / "wall.exr");
  ASSERT_EQ(out.width(), 90);
  EXPECT_EQ(out.at(5, 5, 1), 0.0f);     // outside the region: black
  EXPECT_GT(out.at(45, 30, 1), 0.01f);  // the region: lit by the default light
  // Neither a photo nor a distance map: a usage error.
  r = test::run(kMr + " material --sample " + shell_quoted(dir_->path() / "building.png") +
                " --regions " + shell_quoted(work / "wall_mask.png") + " -o " +
                shell_quoted(work / "none.exr"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--target-depth"), std::string::npos) << r.output;
}

TEST_F(MaterialCli, BadInputsGiveMessages) {
  // Wrong-size mask.
  auto r = test::run(base() + " --regions " + shell_quoted(write_mask(100, 80)) + " -o " +
                     shell_quoted(work / "a.png"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("region mask is 100x80, the photo is 250x187"), std::string::npos)
      << r.output;
  // Empty mask.
  WriteOptions o;
  o.colorspace = colorspace::raw;
  o.pixel_type = PixelType::uint8;
  write_image(work / "empty.png", Image(250, 187, 1), o);
  r = test::run(base() + " --regions " + shell_quoted(work / "empty.png") + " -o " +
                shell_quoted(work / "a.png"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("no region"), std::string::npos) << r.output;
  // A sample with no usable segment (all black).
  Image black(120, 90, 3);
  write_image(work / "black.png", black);
  Image depth(120, 90, 1, {"Z"});
  for (float& v : depth.pixels()) v = 5;
  WriteOptions wd;
  wd.pixel_type = PixelType::float32;
  wd.colorspace = colorspace::raw;
  write_image(work / "black_depth.exr", depth, wd);
  r = test::run(kMr + " material --sample " + shell_quoted(work / "black.png") + " --target " +
                shell_quoted(dir_->path() / "leuven.png") + " --regions " +
                shell_quoted(write_mask()) + " -o " + shell_quoted(work / "a.png"));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("no usable segment"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("black.png"), std::string::npos) << r.output;
  // Missing sample; output onto an input; unwritable format.
  r = test::run(kMr + " material --sample " + shell_quoted(work / "missing.jpg") + " --target " +
                shell_quoted(dir_->path() / "leuven.png") + " --regions " +
                shell_quoted(write_mask()) + " -o " + shell_quoted(work / "a.png"));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("missing.jpg"), std::string::npos) << r.output;
  r = test::run(base() + " --regions " + shell_quoted(write_mask()) + " -o " +
                shell_quoted(dir_->path() / "leuven.png") + " --overwrite");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("is an input file"), std::string::npos) << r.output;
  r = test::run(base() + " --regions " + shell_quoted(write_mask()) + " -o " +
                shell_quoted(work / "a.notaformat"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_FALSE(fs::exists(work / "a.png"));  // nothing written by any failed run
  // Missing required option.
  r = test::run(kMr + " material --sample " + shell_quoted(work / "black.png"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
}

}  // namespace
}  // namespace mr
