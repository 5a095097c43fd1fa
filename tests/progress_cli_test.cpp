// Progress on the command line (cli/progress.h): with stderr a pipe, `mr fog`, `mr estimate`
// and `mr material` print no progress bytes (no carriage return, no escape sequence, no
// progress note); with -v they print progress as note lines (a stage's start); with stderr a
// terminal (util-linux `script` gives one; skipped without it) the bar shows the photo's
// stage and fraction. No timing assertions.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

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

class ProgressCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new test::ScratchDir;
    write_reduced("leuven", dir_->path());
    write_reduced("building", dir_->path());
    // Regions on the reduced leuven (250 x 187): the street and a wall.
    Image m(250, 187, 1);
    for (int y = 0; y < 187; ++y)
      for (int x = 0; x < 250; ++x) {
        if (y > 140 && y < 180 && x > 40 && x < 200) m.at(x, y, 0) = 1.0f / 255;
        if (y > 30 && y < 120 && x > 2 && x < 35) m.at(x, y, 0) = 2.0f / 255;
      }
    WriteOptions o;
    o.colorspace = colorspace::raw;
    o.pixel_type = PixelType::uint8;
    write_image(dir_->path() / "mask.png", m, o);
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  static fs::path dir() { return dir_->path(); }
  // Output folder of this test.
  fs::path out(const std::string& name) const {
    return dir() / (std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) +
                    "_" + name);
  }
  static std::string fog_sun() {
    return kMr + " fog " + shell_quoted(dir() / "leuven.png") + " --fov 60 --sun-elevation 30 " +
           "--sun-azimuth 120 --layer 0,40 --overwrite";
  }
  static std::string fog_sky() {  // sky light only: the streamed path
    return kMr + " fog " + shell_quoted(dir() / "leuven.png") +
           " --fov 60 --airlight 0.7 --overwrite";
  }
  static std::string estimate(const fs::path& scene) {
    return kMr + " estimate " + shell_quoted(dir() / "leuven.png") + " -o " + shell_quoted(scene);
  }
  static std::string material(const fs::path& output) {
    return kMr + " material --sample " + shell_quoted(dir() / "building.png") +
           " --sample-fov 50 --target " + shell_quoted(dir() / "leuven.png") +
           " --fov 60 --regions " + shell_quoted(dir() / "mask.png") + " -o " +
           shell_quoted(output);
  }

 private:
  static test::ScratchDir* dir_;
};
test::ScratchDir* ProgressCli::dir_ = nullptr;

// What a bar or a progress note would leave in the output.
void expect_no_progress(const test::CommandResult& r, const std::string& what) {
  EXPECT_EQ(r.exit_code, 0) << what << "\n" << r.output;
  EXPECT_EQ(r.output.find('\r'), std::string::npos) << what << "\n" << r.output;
  EXPECT_EQ(r.output.find('\033'), std::string::npos) << what << "\n" << r.output;
  EXPECT_EQ(r.output.find("note:"), std::string::npos) << what << "\n" << r.output;
}

TEST_F(ProgressCli, PipesGetNoProgressBytes) {
  // stderr into the pipe too (2>&1): exactly what a log file would get.
  expect_no_progress(test::run(fog_sun() + " -o " + shell_quoted(out("sun")) + " 2>&1"),
                     "fog, sun");
  expect_no_progress(test::run(fog_sky() + " -o " + shell_quoted(out("sky")) + " 2>&1"),
                     "fog, sky only");
  expect_no_progress(test::run(estimate(out("scene.json")) + " 2>&1"), "estimate");
  expect_no_progress(test::run(material(out("material.png")) + " 2>&1"), "material");
}

TEST_F(ProgressCli, VerboseInAPipePrintsStagesAsLines) {
  const std::string leuven = (dir() / "leuven.png").string();
  auto r = test::run(fog_sun() + " -o " + shell_quoted(out("sun")) + " -v 2>&1");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("note: " + leuven + ": occluders\n"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("note: " + leuven + ": render\n"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find('\r'), std::string::npos) << r.output;
  r = test::run(fog_sky() + " -o " + shell_quoted(out("sky")) + " -v 2>&1");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("note: " + leuven + ": render\n"), std::string::npos) << r.output;
  r = test::run(estimate(out("scene.json")) + " -v 2>&1");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  std::size_t at = 0;
  for (const char* step : {"horizon", "sky mask", "depth", "refine", "light"}) {
    const std::size_t found = r.output.find("note: " + leuven + ": " + step + "\n", at);
    EXPECT_NE(found, std::string::npos) << step << " (in order)\n" << r.output;
    if (found != std::string::npos) at = found;
  }
  r = test::run(material(out("material.png")) + " -v 2>&1");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("note: " + leuven + ": fit\n"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find('\r'), std::string::npos) << r.output;
  // --quiet wins over -v.
  r = test::run(fog_sun() + " -o " + shell_quoted(out("quiet")) + " -v -q 2>&1");
  EXPECT_EQ(r.output.find("note:"), std::string::npos) << r.output;
}

TEST_F(ProgressCli, TerminalGetsABarWithTheStageAndFraction) {
  if (test::run("script --version").exit_code != 0) GTEST_SKIP() << "no util-linux script";
  // `script` runs the command on a pseudo-terminal and copies what it shows to stdout.
  auto on_tty = [](const std::string& command) {
    return test::run("script -qfec " + shell_quoted(command) + " /dev/null");
  };
  auto r = on_tty(fog_sun() + " -o " + shell_quoted(out("sun")));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("\r\033[K["), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("leuven.png: render "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("[==============================] leuven.png"), std::string::npos)
      << r.output;  // done: the bar full
  r = on_tty(estimate(out("scene.json")));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find(": horizon 0%"), std::string::npos) << r.output;
  // --quiet: no bar on a terminal either.
  r = on_tty(fog_sun() + " -o " + shell_quoted(out("quiet")) + " -q");
  EXPECT_EQ(r.output.find("\033[K"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace mr
