// Integration tests: the `mr` command driven the way a user drives it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <regex>
#include <stdexcept>

#include "mr/color.h"
#include "mr/io.h"
#include "mr/scene_json.h"
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
      d.at(x, y, 0) =
          y < h / 4 ? 0.0f : far_m + (near_m - far_m) * float(y) / float(h - 1);  // sky at top
  write_raw(path, d, PixelType::float32);
}

void write_photo(const fs::path& path, int w, int h) {
  write_image(path, test::make_test_photo(w, h));
}

std::map<std::string, std::uint64_t> checksums(const fs::path& dir) {
  std::map<std::string, std::uint64_t> out;
  for (const auto& e : fs::directory_iterator(dir))
    out[e.path().filename().string()] = test::file_checksum(e.path());
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
  test::CommandResult mr_fog(const std::string& args) { return test::run(kMr + " fog " + args); }
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
  EXPECT_NE(r.output.find("2 done, 0 skipped (outputs exist), 3 failed"), std::string::npos)
      << r.output;

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
  const auto r =
      mr_fog((in / "good1.png").string() + " -o " + in.string() + " --suffix '' --overwrite");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("refusing to overwrite"), std::string::npos) << r.output;
  EXPECT_EQ(checksums(in), before);
}

TEST_F(CliBatch, AovsGoIntoTheExrOrBesideTheOutput) {
  auto r = mr_fog((in / "good1.png").string() + " -o " + out.string() + " --aovs --format exr -q");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const Image layered = read_raw(out / "good1_fog.exr");
  for (const char* name :
       {"R", "G", "B", "transmittance.R", "transmittance.B", "inscatter.G", "depth.Z"})
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
             (dir / "disp.png").string() +
             " --depth-kind disparity --baseline 0.16 --focal-px 500 -q");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  r = mr_fog((in / "good1.png").string() + " -o " + (dir / "o3").string() + " --depth " +
             (dir / "disp.png").string() + " --depth-kind disparity");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--baseline"), std::string::npos) << r.output;
}

TEST_F(CliBatch, UsageErrorsExitTwo) {
  for (const std::string args :
       {"", "--no-such-option x.jpg", "x.jpg --visibility fog", "x.jpg --visibility -3m",
        "x.jpg --airlight 1,2", "x.jpg --bit-depth 12", "x.jpg --format xyz",
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
  // On a loaded machine the signal can arrive before mr has even made the output folder.
  if (fs::exists(out)) {
    for (const auto& e : fs::directory_iterator(out)) {
      EXPECT_NO_THROW(read_image(e.path())) << e.path();
    }
  }
  EXPECT_EQ(checksums(many), before);
}

// ---------------------------------------------------------------------------------------------
// The physical model's options (--scene, --save-scene, sun, lamps, shadows, ...), end to end.
// Each run fogs one 64x40 photo at --quality draft (about 0.2 s); outputs are float EXRs with
// the AOV layers, so the checks below read exact values, not 8-bit codes.

constexpr int kW = 64, kH = 40;

// Depth `metres` everywhere: along each ray (a bowl around the camera) or, read with
// --depth-kind z, a wall facing the camera.
void write_constant_depth(const fs::path& path, float metres) {
  Image d(kW, kH, 1, {"Z"});
  for (float& v : d.pixels()) v = metres;
  write_raw(path, d, PixelType::float32);
}

double channel_mean(const Image& im, const std::string& name) {
  const int c = im.channel_index(name);
  if (c < 0) throw std::runtime_error("no channel " + name);
  double sum = 0;
  for (int y = 0; y < im.height(); ++y)
    for (int x = 0; x < im.width(); ++x) sum += im.at(x, y, c);
  return sum / double(im.pixel_count());
}

// Mean of inscatter.R/G/B.
double inscatter_mean(const Image& im) {
  return (channel_mean(im, "inscatter.R") + channel_mean(im, "inscatter.G") +
          channel_mean(im, "inscatter.B")) /
         3;
}

// A scene document with fog in a layer below 8 m, a sun and the sky given.
std::string valley_scene(double g, double sun_azimuth_deg, double sun_elevation_deg) {
  return R"({"format": "libmr-scene", "version": 1,
  "medium": {"visibility_m": 40, "g": )" +
         std::to_string(g) + R"(, "layer_top_m": 8},
  "lighting": {"sun": {"azimuth_deg": )" +
         std::to_string(sun_azimuth_deg) + R"(, "elevation_deg": )" +
         std::to_string(sun_elevation_deg) + R"(, "irradiance": [6, 5, 4]},
               "sky_radiance": [0.2, 0.22, 0.25]}})";
}

class CliScene : public ::testing::Test {
 protected:
  void SetUp() override {
    in = dir / "in";
    fs::create_directories(in);
    write_photo(in / "photo.png", kW, kH);
    write_constant_depth(in / "photo_depth.exr", 60.0f);
    write_constant_depth(in / "wall_depth.exr", 25.0f);
  }
  // --quality draft unless args say otherwise.
  std::string command(const std::string& out_name, const std::string& args) const {
    return kMr + " fog " + (in / "photo.png").string() + " -o " + (dir / out_name).string() +
           " -q " + (args.find("--quality") == std::string::npos ? "--quality draft " : "") + args;
  }
  test::CommandResult fog(const std::string& out_name, const std::string& args) const {
    return test::run(command(out_name, args));
  }
  // Only what the command writes to stderr (stdout is dropped).
  test::CommandResult fog_stderr(const std::string& out_name, const std::string& args) const {
    return test::run("{ " + command(out_name, args) + " 2>&1 1>/dev/null; }");
  }
  // Runs into out_name/ and reads the layered float EXR back (composite + AOVs).
  Image render(const std::string& out_name, const std::string& args) const {
    const auto r = fog(out_name, "--format exr --bit-depth float --aovs " + args);
    if (r.exit_code != 0)
      throw std::runtime_error("mr fog " + args + " exited " + std::to_string(r.exit_code) + ":\n" +
                               r.output);
    return read_raw(dir / out_name / "photo_fog.exr");
  }
  fs::path write_scene(const std::string& name, const std::string& json) const {
    test::write_bytes(dir / name, json);
    return dir / name;
  }
  test::ScratchDir dir;
  fs::path in;
};

TEST_F(CliScene, SceneFileChangesTheFogAndOptionsOverrideIt) {
  const fs::path valley = write_scene("valley.json", valley_scene(0.6, 0, 30));
  const Image plain = render("plain", "");
  const Image scene = render("scene", "--scene " + valley.string());
  // 40 m visibility, a sun and a given sky instead of 150 m under the estimated sky.
  EXPECT_GT(test::max_abs_diff(scene, plain), 0.05);
  // The scene's 40 m visibility: tau = 3.912 / 40 * 60 m along the central ray (inside the layer).
  EXPECT_NEAR(scene.at(kW / 2, kH / 2, scene.channel_index("optical_depth.G")), 3.912 / 40 * 60,
              1e-3 * 5.9);

  // An option overrides that one value and keeps the rest of the scene: the result is exactly
  // that of a scene file holding the option's value.
  const Image g_option = render("g_option", "--scene " + valley.string() + " --g -0.5");
  const Image g_file =
      render("g_file", "--scene " + write_scene("g.json", valley_scene(-0.5, 0, 30)).string());
  EXPECT_EQ(test::max_abs_diff(g_option, g_file), 0.0);
  EXPECT_GT(test::max_abs_diff(g_option, scene), 0.1);  // g changes the sun's in-scatter (1.6)

  const Image sun_option =
      render("sun_option", "--scene " + valley.string() + " --sun-azimuth 180 --sun-elevation 60");
  const Image sun_file =
      render("sun_file", "--scene " + write_scene("sun.json", valley_scene(0.6, 180, 60)).string());
  EXPECT_EQ(test::max_abs_diff(sun_option, sun_file), 0.0);
  EXPECT_GT(test::max_abs_diff(sun_option, scene), 0.1);  // measured: 1.6
}

TEST_F(CliScene, BadSceneFilesAreUsageErrorsNamingTheValue) {
  const std::string head = R"({"format": "libmr-scene", "version": 1, )";
  struct Case {
    std::string json;
    std::vector<std::string> expected;  // in the one ERROR line
  };
  const Case cases[] = {
      {head + R"("medium": {"g" 0.5}})", {"line 1, column", "syntax error"}},
      {head + R"("medium": {"sigma_t_per_m": [0.02, -0.1, 0.02]}})",
       {"/medium/sigma_t_per_m", "medium.sigma_t_per_m[1] = -0.1", "[0, 10000]"}},
      {head + R"("medium": {"g": 1.5}})", {"/medium/g", "medium.g = 1.5", "(-1, 1)"}},
      {head + R"("medium": {"g": "NaN"}})", {"/medium/g", "string"}},
      {head + R"("medium": {"g": null}})", {"/medium/g"}},
      {head + R"("medium": {"albdo": 0.9}})", {"/medium/albdo", "unknown key", "\"albedo\""}},
      {head + R"("medium": {"visibility_m": -5}})", {"/medium/visibility_m"}},
      {head + R"("lighting": {"lamps": [{"position_m": [0, "up", 0]}]}})",
       {"/lighting/lamps/0/position_m"}},
      {head + R"("lighting": {"sun": {"azimuth_deg": 10}}})", {"/lighting/sun", "elevation_deg"}},
      {R"({"format": "libmr-scene", "version": 6})", {"/version", "version 6"}},
  };
  const auto inputs_before = checksums(in);
  for (const Case& c : cases) {
    const fs::path scene = write_scene("bad.json", c.json);
    const std::string scene_bytes = test::read_bytes(scene);
    const auto r = fog_stderr(
        "out", "--scene " + scene.string() + " --save-scene " + (dir / "saved.json").string());
    SCOPED_TRACE(c.json + "\n" + r.output);
    EXPECT_EQ(r.exit_code, 2);
    EXPECT_EQ(r.output.rfind("ERROR: ", 0), 0u);  // first line, on stderr
    EXPECT_EQ(count(r.output, "\n"), 1);          // one line
    EXPECT_NE(r.output.find("bad.json"), std::string::npos);
    for (const std::string& e : c.expected) EXPECT_NE(r.output.find(e), std::string::npos) << e;
    EXPECT_FALSE(fs::exists(dir / "out"));         // no output (not even its folder)
    EXPECT_FALSE(fs::exists(dir / "saved.json"));  // nor a saved scene
    EXPECT_EQ(test::read_bytes(scene), scene_bytes);
  }
  EXPECT_EQ(checksums(in), inputs_before);
}

TEST_F(CliScene, SavedSceneReproducesTheImage) {
  const std::string options =
      "--visibility 60m --albedo 0.9,0.95,1 --g 0.4 --height-fog 0,15 --layer -5,40 "
      "--noise 0.3,8,3,7 --sun-azimuth 20 --sun-elevation 15 --sun-irradiance 4,3,2 "
      "--sun-radius 0.5 --lamp '6,3,20;80,60,40;0,-1,0;30,60' --lamp '-5,2,30;40,40,40' "
      "--camera-height 2 --pitch 3 --roll 2 --yaw 5 --seed 9 --march-steps 24 "
      "--airlight 0.3,0.32,0.35";
  const fs::path saved = dir / "saved.json";
  const Image first = render("first", options + " --save-scene " + saved.string());
  ASSERT_TRUE(fs::exists(saved));
  // The document holds what the options said.
  const FogScene s = load_scene(saved);
  EXPECT_FLOAT_EQ(s.medium.sigma_t_per_m[1], float(3.912 / 60));
  EXPECT_EQ(s.medium.albedo, (Rgb{0.9f, 0.95f, 1.0f}));
  EXPECT_EQ(s.medium.g, 0.4);
  ASSERT_TRUE(s.medium.height_fog);
  EXPECT_EQ(s.medium.height_fog->scale_height_m, 15);
  EXPECT_EQ(s.medium.layer_bottom_m, -5);
  EXPECT_EQ(s.medium.layer_top_m, 40);
  EXPECT_EQ(s.medium.noise.amplitude, 0.3);
  EXPECT_EQ(s.medium.noise.scale_m, 8);
  EXPECT_EQ(s.medium.noise.octaves, 3);
  EXPECT_EQ(s.medium.noise.seed, 7u);
  ASSERT_TRUE(s.lighting.sun);
  EXPECT_NEAR(s.lighting.sun->direction_to_sun.y, std::sin(15 * std::numbers::pi / 180), 1e-12);
  EXPECT_EQ(s.lighting.sun->irradiance, (Rgb{4, 3, 2}));
  EXPECT_EQ(s.lighting.sun->angular_radius_deg, 0.5);
  ASSERT_TRUE(s.lighting.sky_radiance);
  EXPECT_EQ(*s.lighting.sky_radiance, (Rgb{0.3f, 0.32f, 0.35f}));
  ASSERT_EQ(s.lighting.lamps.size(), 2u);
  EXPECT_EQ(s.lighting.lamps[0].position_m.z, 20);
  EXPECT_EQ(s.lighting.lamps[0].outer_angle_deg, 60);
  EXPECT_EQ(s.lighting.lamps[1].intensity_per_sr, (Rgb{40, 40, 40}));
  EXPECT_EQ(s.pose.position_m.y, 2);
  EXPECT_EQ(s.pose.pitch_deg, 3);
  EXPECT_EQ(s.pose.roll_deg, 2);
  EXPECT_EQ(s.pose.yaw_deg, 5);
  EXPECT_EQ(s.render.quality, Quality::draft);
  EXPECT_EQ(s.render.seed, 9u);
  EXPECT_EQ(s.render.march_steps, 24);

  // Fed back alone, it gives the same pixels, bit for bit, in every layer. (Not the same file
  // bytes: OpenEXR headers hold the time of writing.)
  const Image again = render("again", "--scene " + saved.string());
  EXPECT_EQ(test::max_abs_diff(again, first), 0.0);
  // ... and the options did matter.
  EXPECT_GT(test::max_abs_diff(first, render("plain", "")), 0.05);
}

// Fog between -10 m and 5 m (so that sunlight reaches into it), 80 m visibility, sky 0.2.
const std::string kLayerFog = "--layer -10,5 --visibility 80m --airlight 0.2 ";

TEST_F(CliScene, SunBrightensTheInScatter) {
  const Image no_sun = render("no_sun", kLayerFog);
  const Image sun =
      render("sun", kLayerFog + "--sun-azimuth 0 --sun-elevation 45 --sun-irradiance 10");
  // Sky alone: about 0.16; the sun adds about 0.44 (measured). Required: at least +50 %.
  EXPECT_GT(inscatter_mean(sun), 1.5 * inscatter_mean(no_sun));
  for (const char* c : {"R", "G", "B"})
    EXPECT_GT(channel_mean(sun, c), channel_mean(no_sun, c) + 0.1) << c;
  // Forward scattering (g > 0): a sun ahead of the camera lights the fog more than one behind.
  // (--no-shadows: a sun this low ahead would be behind the depth map's surface.)
  const std::string g = kLayerFog + "--g 0.7 --no-shadows --sun-elevation 15 --sun-irradiance 10 ";
  const double ahead = inscatter_mean(render("ahead", g + "--sun-azimuth 0"));
  const double behind = inscatter_mean(render("behind", g + "--sun-azimuth 180"));
  EXPECT_GT(ahead, 3 * behind);  // measured: 2.27 vs 0.19
}

TEST_F(CliScene, LampBrightensPixelsNearItsProjectionMost) {
  // Camera at (0, 1.6, 0) looking along +Z with f = 50 px; a lamp at (4, 1.6, 12) projects to
  // x = 32 + 50 * 4 / 12 = 48.7, y = 20 (pixel centres at +0.5).
  const std::string fog = "--visibility 80m --airlight 0.2 --focal-px 50 ";
  const Image dark = render("dark", fog);
  const Image lit = render("lit", fog + "--lamp '4,1.6,12;200,200,200'");
  const int c = lit.channel_index("inscatter.G");
  auto gain = [&](int x, int y) { return lit.at(x, y, c) - dark.at(x, y, c); };
  const double near = gain(48, 20), same_row_far = gain(4, 20), corner = gain(4, 2);
  // Measured: +10.2 at the lamp, +0.06 at the row's far end and in the corner.
  EXPECT_GT(near, 1.0);
  EXPECT_GT(near, 10 * same_row_far);
  EXPECT_GT(near, 10 * corner);
  EXPECT_GE(same_row_far, 0.0);  // light only adds
  // The gain falls off away from the projection along the row.
  EXPECT_GT(gain(48, 20), gain(40, 20));
  EXPECT_GT(gain(40, 20), gain(24, 20));
}

TEST_F(CliScene, NoShadowsLetsTheSunThroughAWall) {
  // The depth map, read as planar z, is a wall 25 m ahead; the sun is low behind it, so the
  // wall shadows all the fog in front of it.
  const std::string wall =
      kLayerFog + "--depth " + (in / "wall_depth.exr").string() + " --depth-kind z ";
  const std::string sun_ahead = "--sun-azimuth 0 --sun-elevation 10 --sun-irradiance 10 ";
  const Image no_sun = render("no_sun", wall);
  const Image shadowed = render("shadowed", wall + sun_ahead);
  const Image unshadowed = render("unshadowed", wall + sun_ahead + "--no-shadows");
  // Measured: 0.1334 without a sun, 0.1336 shadowed, 0.340 with --no-shadows.
  EXPECT_LT(inscatter_mean(shadowed) - inscatter_mean(no_sun), 0.01);
  EXPECT_GT(inscatter_mean(unshadowed) - inscatter_mean(shadowed), 0.1);
  // Control: with the sun behind the camera nothing blocks it, and the flag changes nothing.
  const std::string sun_behind = "--sun-azimuth 180 --sun-elevation 10 --sun-irradiance 10 ";
  const Image lit = render("lit", wall + sun_behind);
  EXPECT_GT(inscatter_mean(lit) - inscatter_mean(no_sun), 0.1);
  EXPECT_EQ(test::max_abs_diff(lit, render("lit_no_shadows", wall + sun_behind + "--no-shadows")),
            0.0);
}

// Bad option values, in groups of a few (each case is one `mr` run of about 0.2 s).
struct BadOptions {
  std::string group;
  std::vector<std::pair<std::string, std::string>> cases;  // args, text expected in the ERROR line
};
void PrintTo(const BadOptions& b, std::ostream* os) {
  *os << b.group;
}
class CliBadOptions : public CliScene, public ::testing::WithParamInterface<BadOptions> {};

// A bad value is a usage error (exit 2, not a crash), one ERROR line on stderr naming it, and
// nothing is written: no output folder, no --save-scene file.
TEST_P(CliBadOptions, AreUsageErrorsNamingTheValue) {
  for (const auto& [args, expected] : GetParam().cases) {
    const auto r = fog_stderr("out", args + " --save-scene " + (dir / "saved.json").string());
    SCOPED_TRACE(args + "\n" + r.output);
    EXPECT_EQ(r.exit_code, 2);  // a signal gives -1
    EXPECT_EQ(r.output.rfind("ERROR: ", 0), 0u);
    EXPECT_EQ(count(r.output, "\n"), 1);
    EXPECT_NE(r.output.find(expected), std::string::npos) << expected;
    EXPECT_FALSE(fs::exists(dir / "out"));
    EXPECT_FALSE(fs::exists(dir / "saved.json"));
  }
}

INSTANTIATE_TEST_SUITE_P(
    CliScene, CliBadOptions,
    ::testing::Values(
        BadOptions{"Lamp",
                   {{"--lamp '1,2'", "--lamp '1,2': expected x,y,z;R,G,B"},
                    {"--lamp 'a,b,c;1,1,1'", "--lamp position"},
                    {"--lamp '1,2,3;1,1'", "'1,1' must be one value or three"},
                    {"--lamp '1,2,3;1,1,1;0,-1,0'", "expected x,y,z;R,G,B"},
                    {"--lamp '1,2,3;1,1,1;0,0,0;10,20'", "lighting.lamps[0].spot_direction"},
                    {"--lamp '1,2,3;1,1,1;0,-1,0;40,30'", "lighting.lamps[0].inner_angle_deg = 40"},
                    {"--lamp '1,2,3;-1,1,1'", "lighting.lamps[0].intensity_per_sr[0] = -1"}}},
        BadOptions{"Sun",
                   {{"--sun-dir 0,0,0", "lighting.sun.direction_to_sun"},
                    {"--sun-dir 1,2", "--sun-dir x,y,z"},
                    {"--sun-elevation 30", "--sun-azimuth and --sun-elevation go together"},
                    {"--sun-azimuth 0 --sun-elevation 95", "--sun-elevation must be in [-90, 90]"},
                    {"--sun-irradiance -1", "lighting.sun.irradiance[0] = -1"},
                    {"--sun-radius 10", "lighting.sun.angular_radius_deg = 10"}}},
        BadOptions{"Medium",
                   {{"--g 1", "medium.g = 1: must be in (-1, 1)"},
                    {"--g -1", "medium.g = -1"},
                    {"--g nan", "medium.g = nan"},
                    {"--albedo 1.5", "medium.albedo[0] = 1.5"},
                    {"--density -0.1", "medium.sigma_t_per_m[0] = -0.1"},
                    {"--height-fog 0,-5", "medium.height_fog.scale_height_m = -5"},
                    {"--height-fog 5", "--height-fog base,scale"},
                    {"--layer 10,5", "medium.layer_bottom_m = 10"}}},
        BadOptions{"Noise",
                   {{"--noise 2", "medium.noise.amplitude = 2"},
                    {"--noise 0.5,10,4.5", "octaves must be a whole number in 1..8"},
                    {"--noise 0.5,10,1e10", "octaves must be a whole number"},
                    {"--noise 0.5,10,4,-1", "seed must be a whole number in 0..4294967295"},
                    {"--noise 0.5,10,4,1,5", "--noise takes at most 4 numbers"}}},
        BadOptions{"QualityCameraRender",
                   {{"--quality ultra", "--quality 'ultra'"},
                    {"--pitch 100", "pose.pitch_deg = 100"},
                    {"--march-steps 5000", "render.march_steps = 5000"},
                    {"--march-steps -1", "render.march_steps = -1"},
                    {"--camera-height inf", "pose.position_m.y = inf"}}}),
    [](const ::testing::TestParamInfo<BadOptions>& info) { return info.param.group; });

TEST_F(CliScene, OptionsRefusedByTheParserOrLaterWriteNoScene) {
  // Bad values that CLI11 itself refuses are usage errors too.
  for (const std::string args : {"--seed -1", "--g x", "--march-steps 2.5", "-j -2"}) {
    const auto r = fog("out", args);
    EXPECT_EQ(r.exit_code, 2) << args << "\n" << r.output;
    EXPECT_FALSE(fs::exists(dir / "out")) << args;
  }
  // A usage error found after the scene was resolved writes no scene file either.
  for (const std::string args :
       {"--format xyz", "--bit-depth 12", "--depth-kind disparity", "--depth-kind w"}) {
    const auto r = fog("out", args + " --g 0.5 --save-scene " + (dir / "saved.json").string());
    EXPECT_EQ(r.exit_code, 2) << args << "\n" << r.output;
    EXPECT_FALSE(fs::exists(dir / "saved.json")) << args;
  }
  // Control: the same without the error writes it.
  const auto r = fog("out", "--g 0.5 --save-scene " + (dir / "saved.json").string());
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(load_scene(dir / "saved.json").medium.g, 0.5);
}

TEST_F(CliScene, SaveSceneNeverOverwritesAnInput) {
  const auto before = checksums(in);
  for (const fs::path& target : {in / "photo.png", in / "photo_depth.exr"}) {
    const auto r = fog("out", "--save-scene " + target.string());
    EXPECT_EQ(r.exit_code, 2) << target << "\n" << r.output;
    EXPECT_NE(r.output.find("refusing to overwrite"), std::string::npos) << r.output;
  }
  EXPECT_EQ(checksums(in), before);
}

TEST_F(CliScene, ThreadCountDoesNotChangeTheOutput) {
  write_photo(in / "second.png", kW, kH);
  write_constant_depth(in / "second_depth.exr", 30.0f);
  // Everything that has per-thread state: noise, jitter, sun shadows through the mesh, lamps.
  const std::string args =
      " --format exr --bit-depth float --aovs --layer -10,8 --noise 0.4,6 "
      "--sun-azimuth 10 --sun-elevation 20 --lamp '3,2,10;100,100,100' --g 0.3 -q ";
  const char* threads[] = {"-j 1", "", "-j 3"};
  std::vector<Image> outputs[3];
  for (int i = 0; i < 3; ++i) {
    const fs::path out = dir / ("out" + std::to_string(i));
    const auto r = test::run(kMr + " fog " + in.string() + " -o " + out.string() +
                             " --quality draft " + args + threads[i]);
    ASSERT_EQ(r.exit_code, 0) << threads[i] << "\n" << r.output;
    for (const char* name : {"photo_fog.exr", "second_fog.exr"})
      outputs[i].push_back(read_raw(out / name));
  }
  // Identical pixels in every layer. (Not the files' bytes: OpenEXR headers hold the time of
  // writing.)
  for (int i = 1; i < 3; ++i)
    for (int k = 0; k < 2; ++k)
      EXPECT_EQ(test::max_abs_diff(outputs[i][k], outputs[0][k]), 0.0) << threads[i] << " " << k;
}

// `mr insert` writes display-referred (8-bit) outputs through the highlight roll-off, as `mr fog`
// does (issue 16: sunlit white objects, lit relative to the photo's exposure, are brighter than
// its white and clipped flat under plain sRGB): each PNG code is the sRGB code of the roll-off of
// the float output's value (within 1.5 codes: OCIO's LUTs and rounding), so a sphere in a strong
// sun keeps its shading above 1.0 linear; the EXR stays linear and unclipped.
TEST_F(CliScene, InsertWritesDisplayOutputsThroughTheRolloff) {
  const std::string base = kMr + " insert " + (in / "photo.png").string() + " --depth " +
                           (in / "photo_depth.exr").string() +
                           " -q --quality preview --object primitive:sphere --position 0,-1.5,7"
                           " --scale 3 --sun-azimuth 180 --sun-elevation 50"
                           " --sun-irradiance 12 --sky 0.3 -o " +
                           (dir / "ins").string();
  ASSERT_EQ(test::run(base).exit_code, 0);
  ASSERT_EQ(test::run(base + " --format exr").exit_code, 0);
  const Image display = read_raw(dir / "ins" / "photo_insert.png");
  const Image linear = read_raw(dir / "ins" / "photo_insert.exr");
  ASSERT_EQ(display.width(), linear.width());
  auto srgb = [](double x) {
    return x <= 0.0031308 ? 12.92 * x : 1.055 * std::pow(x, 1 / 2.4) - 0.055;
  };
  std::size_t above_white = 0;
  double worst = 0;
  for (int y = 0; y < linear.height(); ++y)
    for (int x = 0; x < linear.width(); ++x)
      for (int c = 0; c < 3; ++c) {
        const double v = linear.at(x, y, c);
        above_white += v > 1.05;
        const double want = 255 * srgb(highlight_rolloff(std::max(v, 0.0)));
        worst = std::max(worst, std::fabs(255.0 * display.at(x, y, c) - want));
      }
  EXPECT_GT(above_white, 30u);  // the sunlit sphere is above the photo's white
  EXPECT_LT(worst, 1.5);
  // A 16-bit photo stays 16-bit in a PNG output (as `mr fog` keeps it); an 8-bit one 8-bit.
  const fs::path in16 = dir / "in16";
  fs::create_directories(in16);
  WriteOptions png16;
  png16.pixel_type = PixelType::uint16;
  write_image(in16 / "photo.png", read_image(in / "photo.png"), png16);
  fs::copy_file(in / "photo_depth.exr", in16 / "photo_depth.exr");
  ASSERT_EQ(test::run(kMr + " insert " + (in16 / "photo.png").string() + " --depth " +
                      (in16 / "photo_depth.exr").string() +
                      " -q --quality preview --object primitive:sphere --position 0,-1.5,7"
                      " --scale 3 -o " +
                      (dir / "ins16").string())
                .exit_code,
            0);
  EXPECT_EQ(probe_image(dir / "ins16" / "photo_insert.png").pixel_type, PixelType::uint16);
  EXPECT_EQ(probe_image(dir / "ins" / "photo_insert.png").pixel_type, PixelType::uint8);
}

TEST_F(CliScene, AovLayersInTheExr) {
  std::vector<std::string> layers = {"R", "G", "B", "depth.Z", "sun_visibility.Y"};
  for (const std::string layer : {"transmittance", "inscatter", "optical_depth"})
    for (const char* c : {".R", ".G", ".B"}) layers.push_back(layer + c);
  auto sorted = [](std::vector<std::string> v) {
    std::sort(v.begin(), v.end());  // OpenEXR stores channels sorted by name
    return v;
  };
  // Homogeneous fog, no lights: T = exp(-tau), tau = sigma * 60 m everywhere.
  const Image exr = render("exr", "--visibility 80m --airlight 0.2");
  EXPECT_EQ(sorted(exr.channel_names()), sorted(layers));  // channel names of the file's header
  const double tau = 3.912 / 80 * 60;
  for (const auto& [x, y] :
       {std::pair{0, 0}, std::pair{kW / 2, kH / 2}, std::pair{kW - 1, kH - 1}}) {
    EXPECT_EQ(exr.at(x, y, exr.channel_index("depth.Z")), 60.0f);
    EXPECT_EQ(exr.at(x, y, exr.channel_index("sun_visibility.Y")), 1.0f);  // no sun
    EXPECT_NEAR(exr.at(x, y, exr.channel_index("optical_depth.B")), tau, 1e-4 * tau);
    EXPECT_NEAR(exr.at(x, y, exr.channel_index("transmittance.R")), std::exp(-tau),
                1e-4 * std::exp(-tau));
    EXPECT_NEAR(exr.at(x, y, exr.channel_index("inscatter.G")), 0.2 * (1 - std::exp(-tau)), 1e-4);
  }
  // A PNG output gets the same layers in <name>_fog_aovs.exr beside it. The sun's visibility
  // is 0 on surfaces facing away from the sun (the bowl, with the sun ahead), a fraction in
  // [0, 1] otherwise (measured mean with the sun behind the camera: 0.61).
  double mean_visibility[2];
  for (int behind = 0; behind < 2; ++behind) {
    const std::string out = behind ? "png_behind" : "png_ahead";
    const auto r =
        fog(out, "--aovs --visibility 80m --layer -10,5 --sun-elevation 30 --sun-azimuth " +
                     std::string(behind ? "180" : "0"));
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_TRUE(fs::exists(dir / out / "photo_fog.png"));
    const Image aovs = read_raw(dir / out / "photo_fog_aovs.exr");
    EXPECT_EQ(sorted(aovs.channel_names()), sorted(layers));
    const int v = aovs.channel_index("sun_visibility.Y");
    for (int y = 0; y < kH; ++y)
      for (int x = 0; x < kW; ++x) {
        EXPECT_GE(aovs.at(x, y, v), 0.0f);
        EXPECT_LE(aovs.at(x, y, v), 1.0f);
      }
    mean_visibility[behind] = channel_mean(aovs, "sun_visibility.Y");
  }
  EXPECT_EQ(mean_visibility[0], 0.0);
  EXPECT_GT(mean_visibility[1], 0.3);
}

}  // namespace
}  // namespace mr
