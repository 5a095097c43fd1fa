// Integration tests: the `mr` command driven the way a user drives it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <regex>

#include "mr/io.h"
#include "test_support.h"

namespace fs = std::filesystem;

namespace mr {
namespace {

const std::string kMr = MR_CLI_PATH;

Image read_raw(const fs::path& path) {
  ReadOptions o;
  o.to_scene_linear = false;
  o.reject_non_finite = false;  // depth.Z holds +inf for the sky
  return read_image(path, o);
}

void write_raw(const fs::path& path, const Image& image, PixelType type) {
  WriteOptions o;
  o.pixel_type = type;
  o.colorspace = colorspace::raw;
  write_image(path, image, o);
}

void write_depth(const fs::path& path, int w, int h, float near_m = 5.0f, float far_m = 400.0f) {
  Image d(w, h, 1, {"Z"});
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      d.at(x, y, 0) = y < h / 4 ? 0.0f : far_m + (near_m - far_m) * float(y) / float(h - 1);  // sky at top
  write_raw(path, d, PixelType::float32);
}

void write_photo(const fs::path& path, int w, int h) { write_image(path, test::make_test_photo(w, h)); }

std::map<std::string, std::uint64_t> checksums(const fs::path& dir) {
  std::map<std::string, std::uint64_t> out;
  for (const auto& e : fs::directory_iterator(dir)) out[e.path().filename().string()] = test::file_checksum(e.path());
  return out;
}

int count(const std::string& text, const std::string& what) {
  int n = 0;
  for (std::size_t p = text.find(what); p != std::string::npos; p = text.find(what, p + 1)) ++n;
  return n;
}

bool has_temp_files(const fs::path& dir) {
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.path().filename().string().find(".mr-tmp-") != std::string::npos) return true;
  return false;
}

class CliBatch : public ::testing::Test {
 protected:
  void SetUp() override {
    in = dir / "in";
    out = dir / "out";
    fs::create_directories(in);
    write_photo(in / "good1.png", 96, 64);
    write_depth(in / "good1_depth.exr", 96, 64);
    write_photo(in / "good2.jpg", 80, 60);
    write_depth(in / "good2_depth.exr", 80, 60);
    write_photo(in / "truncated.jpg", 200, 150);
    const std::string bytes = test::read_bytes(in / "truncated.jpg");
    test::write_bytes(in / "truncated.jpg", bytes.substr(0, bytes.size() / 3));
    write_depth(in / "truncated_depth.exr", 200, 150);
    test::write_bytes(in / "notimage.jpg", "GIF89a? no, just text pretending to be a photo\n");
    write_depth(in / "notimage_depth.exr", 10, 10);
    write_photo(in / "wrongsize.png", 64, 48);
    write_depth(in / "wrongsize_depth.exr", 32, 24);
  }
  test::CommandResult mr_fog(const std::string& args) {
    return test::run(kMr + " fog " + args);
  }
  test::ScratchDir dir;
  fs::path in, out;
};

TEST_F(CliBatch, GoodPhotosAreWrittenBadOnesReportedAndNothingIsLost) {
  const auto inputs_before = checksums(in);
  const auto r = mr_fog(in.string() + " --out-dir " + out.string() + " --visibility 120m");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_EQ(count(r.output, "ERROR: "), 3) << r.output;
  for (const char* name : {"truncated.jpg", "notimage.jpg", "wrongsize"})
    EXPECT_NE(r.output.find(name), std::string::npos) << name << "\n" << r.output;
  EXPECT_NE(r.output.find("32x24"), std::string::npos) << r.output;  // both sizes named
  EXPECT_NE(r.output.find("64x48"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("2 done, 0 skipped (outputs exist), 3 failed"), std::string::npos) << r.output;

  std::vector<std::string> written;
  for (const auto& e : fs::directory_iterator(out)) written.push_back(e.path().filename().string());
  std::sort(written.begin(), written.end());
  EXPECT_EQ(written, (std::vector<std::string>{"good1_fog.png", "good2_fog.jpg"}));
  EXPECT_FALSE(has_temp_files(dir.path()));
  EXPECT_EQ(checksums(in), inputs_before);  // inputs unchanged

  const Image fogged = read_image(out / "good1_fog.png");
  EXPECT_EQ(fogged.width(), 96);
  EXPECT_EQ(fogged.height(), 64);
}

TEST_F(CliBatch, ResumeSkipsFinishedOutputsAndOverwriteRedoesThem) {
  fs::remove(in / "truncated.jpg");
  fs::remove(in / "notimage.jpg");
  fs::remove(in / "wrongsize.png");
  auto r = mr_fog(in.string() + " -o " + out.string() + " -q");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const auto first = checksums(out);
  const auto first_time = fs::last_write_time(out / "good1_fog.png");
  // Change the fog: a resumed batch must not touch finished outputs.
  r = mr_fog(in.string() + " -o " + out.string() + " --visibility 30m");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("0 done, 2 skipped"), std::string::npos) << r.output;
  EXPECT_EQ(checksums(out), first);
  EXPECT_EQ(fs::last_write_time(out / "good1_fog.png"), first_time);
  r = mr_fog(in.string() + " -o " + out.string() + " --visibility 30m --overwrite");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("2 done, 0 skipped"), std::string::npos) << r.output;
  const auto redone = checksums(out);
  EXPECT_NE(redone.at("good1_fog.png"), first.at("good1_fog.png"));
  EXPECT_NE(redone.at("good2_fog.jpg"), first.at("good2_fog.jpg"));
}

TEST_F(CliBatch, NeverOverwritesAnInputEvenWhenTheOutputPointsAtIt) {
  const auto before = checksums(in);
  const auto r = mr_fog((in / "good1.png").string() + " -o " + in.string() + " --suffix '' --overwrite");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("refusing to overwrite"), std::string::npos) << r.output;
  EXPECT_EQ(checksums(in), before);
}

TEST_F(CliBatch, AovsGoIntoTheExrOrBesideTheOutput) {
  auto r = mr_fog((in / "good1.png").string() + " -o " + out.string() + " --aovs --format exr -q");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const Image layered = read_raw(out / "good1_fog.exr");
  for (const char* name : {"R", "G", "B", "transmittance.R", "transmittance.B", "inscatter.G", "depth.Z"})
    EXPECT_GE(layered.channel_index(name), 0) << name;
  r = mr_fog((in / "good2.jpg").string() + " -o " + out.string() + " --aovs -q");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(fs::exists(out / "good2_fog.jpg"));
  const Image aovs = read_raw(out / "good2_fog_aovs.exr");
  EXPECT_GE(aovs.channel_index("depth.Z"), 0);
  // T = exp(-sigma d) with the default 150 m visibility, at a pixel with known depth.
  const int z = aovs.channel_index("depth.Z"), t = aovs.channel_index("transmittance.G");
  const float d = aovs.at(40, 50, z);
  EXPECT_NEAR(aovs.at(40, 50, t), std::exp(-3.912 / 150.0 * d), 1e-3);  // half precision
}

TEST_F(CliBatch, DepthPatternSingleFileAndDisparity) {
  fs::create_directories(dir / "depths");
  write_depth(dir / "depths" / "good1.exr", 96, 64);
  auto r = mr_fog((in / "good1.png").string() + " -o " + out.string() + " --depth '" +
                  (dir / "depths").string() + "/{stem}.exr' -q");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  // Disparity: a constant disparity map gives a constant depth; with a 0 baseline it is refused.
  Image disp(96, 64, 1);
  for (float& v : disp.pixels()) v = 20.0f / 255.0f;
  write_raw(dir / "disp.png", disp, PixelType::uint8);
  r = mr_fog((in / "good1.png").string() + " -o " + (dir / "o2").string() + " --depth " +
             (dir / "disp.png").string() + " --depth-kind disparity --baseline 0.16 --focal-px 500 -q");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  r = mr_fog((in / "good1.png").string() + " -o " + (dir / "o3").string() + " --depth " +
             (dir / "disp.png").string() + " --depth-kind disparity");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--baseline"), std::string::npos) << r.output;
}

TEST_F(CliBatch, UsageErrorsExitTwo) {
  for (const std::string args : {"", "--no-such-option x.jpg", "x.jpg --visibility fog",
                                 "x.jpg --visibility -3m", "x.jpg --airlight 1,2",
                                 "x.jpg --bit-depth 12", "x.jpg --format xyz",
                                 "x.jpg --visibility 100m --density 0.1"}) {
    const auto r = mr_fog(args);
    EXPECT_EQ(r.exit_code, 2) << args << "\n" << r.output;
  }
  EXPECT_EQ(test::run(kMr + " --version").exit_code, 0);
  EXPECT_EQ(test::run(kMr).exit_code, 2);
  // A missing photo is a failed job, not a usage error.
  const auto r = mr_fog((dir / "missing.jpg").string() + " -o " + out.string());
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("missing.jpg: no such file"), std::string::npos) << r.output;
}

TEST_F(CliBatch, InterruptLeavesNoPartialFiles) {
  fs::path many = dir / "many";
  fs::create_directories(many);
  for (int i = 0; i < 24; ++i) {
    write_photo(many / ("p" + std::to_string(i) + ".png"), 900, 700);
    write_depth(many / ("p" + std::to_string(i) + "_depth.exr"), 900, 700);
  }
  const auto before = checksums(many);
  const auto r = test::run("timeout --preserve-status -s INT 1 " + kMr + " fog " + many.string() +
                           " -o " + out.string() + " -j 2");
  const std::string info = r.output;
  // Either the batch finished within a second (exit 0) or it stopped cleanly on Ctrl-C (130).
  EXPECT_TRUE(r.exit_code == 130 || r.exit_code == 0) << r.exit_code << "\n" << info;
  EXPECT_FALSE(has_temp_files(dir.path())) << info;
  for (const auto& e : fs::directory_iterator(out)) EXPECT_NO_THROW(read_image(e.path())) << e.path();
  EXPECT_EQ(checksums(many), before);
}

}  // namespace
}  // namespace mr
