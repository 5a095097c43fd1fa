// The streaming sky-only pipeline (mr/fog_stream.h, issue 12) against the full-frame path it
// replaces for sky-only scenes: read_image -> read_depth -> mr::fog (the scattering core) ->
// write_image. Tolerance: none. Both paths run the same per-pixel code (OCIO processors,
// stored_depth_to_distance, sky_only_inscatter, photo::composite), so the stored outputs must
// be equal value for value; a difference of one code means the paths have drifted apart.
// Also: what does not stream is declined (nothing written), errors name the file, and a 12 MP
// `mr fog` stays under the memory target (peak RSS from the OS).
#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "mr/mr.h"
#include "test_support.h"

namespace fs = std::filesystem;

namespace mr {
namespace {

const fs::path kSamples = fs::path(MR_SOURCE_DIR) / "sample_photos";

Image read_stored(const fs::path& path) {
  ReadOptions o;
  o.to_scene_linear = false;
  o.reject_non_finite = false;
  o.apply_orientation = false;
  return read_image(path, o);
}

// Equal stored values (codes as normalised floats, or floats), same shape and channel names.
void expect_same_pixels(const fs::path& a, const fs::path& b) {
  const Image ia = read_stored(a), ib = read_stored(b);
  ASSERT_EQ(ia.width(), ib.width());
  ASSERT_EQ(ia.height(), ib.height());
  ASSERT_EQ(ia.channels(), ib.channels());
  EXPECT_EQ(ia.channel_names(), ib.channel_names());
  std::size_t differ = 0;
  double worst = 0;
  for (std::size_t i = 0; i < ia.pixels().size(); ++i) {
    const float x = ia.pixels()[i], y = ib.pixels()[i];
    if (!(x == y) && !(std::isnan(x) && std::isnan(y))) {
      ++differ;
      worst = std::max(worst, double(std::fabs(x - y)));
    }
  }
  EXPECT_EQ(differ, 0u) << a << " vs " << b << ": worst difference " << worst;
  const ImageFileInfo fa = probe_image(a), fb = probe_image(b);
  EXPECT_EQ(fa.pixel_type, fb.pixel_type);
  EXPECT_EQ(fa.format, fb.format);
}

FogScene sky_scene(float sigma = 0.026f) {
  FogScene s;
  s.medium.sigma_t_per_m = {sigma, sigma * 1.1f, sigma * 1.25f};
  s.medium.albedo = {0.95f, 0.97f, 1.0f};
  s.lighting.sky_radiance = Rgb{0.72f, 0.76f, 0.83f};
  s.render.backend = Backend::cpu;
  return s;
}

struct Case {
  fs::path photo, depth;
  FogScene scene = sky_scene();
  DepthOptions depth_options;
  double fov_deg = 0;  // 0: from the metadata
  WriteOptions write;
  std::string ext = ".jpg";
};

// The full-frame path, as `mr fog` ran it before streaming.
void full_frame(const Case& c, const fs::path& out) {
  const Image photo = read_image(c.photo);
  const Camera camera = c.fov_deg > 0
                            ? Camera::from_horizontal_fov(photo.width(), photo.height(), c.fov_deg)
                            : Camera::from_metadata(photo.width(), photo.height(), photo.metadata());
  const DepthMap depth = read_depth(c.depth, camera, c.depth_options);
  const FogLayers layers = fog(photo, depth.distance_m, camera, c.scene);
  write_image(out, layers.composite, c.write);
}

StreamFogResult streamed(const Case& c, const fs::path& out, FogStreamer& streamer,
                         const Image* photo_image = nullptr, int strip_rows = 0) {
  StreamFogRequest r;
  r.photo = c.photo;
  r.photo_image = photo_image;
  r.depth = c.depth;
  r.output = out;
  r.depth_options = c.depth_options;
  r.scene = &c.scene;
  const double fov = c.fov_deg;
  if (fov > 0)
    r.camera = [fov](int w, int h, const Metadata&) { return Camera::from_horizontal_fov(w, h, fov); };
  r.write = c.write;
  r.strip_rows = strip_rows;
  return streamer.fog_file(r);
}

void expect_equal_paths(const Case& c, const test::ScratchDir& dir, const std::string& name,
                        FogStreamer& streamer, int strip_rows = 0) {
  const fs::path a = dir / (name + "_full" + c.ext), b = dir / (name + "_stream" + c.ext);
  full_frame(c, a);
  const StreamFogResult r = streamed(c, b, streamer, nullptr, strip_rows);
  ASSERT_TRUE(r.streamed) << name << ": " << r.reason;
  EXPECT_GT(r.strips, 0u);
  expect_same_pixels(a, b);
}

TEST(FogStream, SamplePhotosMatchTheFullFramePath) {
  test::ScratchDir dir;
  FogStreamer streamer;  // one streamer for all: buffers reused across photos
  for (const char* stem : {"aerial", "aloe", "building", "leuven"}) {
    Case c;
    c.photo = kSamples / (std::string(stem) + ".jpg");
    c.depth = kSamples / (std::string(stem) + "_depth.exr");
    expect_equal_paths(c, dir, stem, streamer);
  }
}

TEST(FogStream, StripHeightsDoNotChangeTheResult) {
  test::ScratchDir dir;
  FogStreamer streamer;
  Case c;
  c.photo = kSamples / "leuven.jpg";
  c.depth = kSamples / "leuven_depth.exr";
  for (int rows : {1, 7, 16, 600}) expect_equal_paths(c, dir, "rows" + std::to_string(rows), streamer, rows);
}

TEST(FogStream, HeightFogLayerAndPoseMatch) {
  test::ScratchDir dir;
  FogStreamer streamer;
  Case c;
  c.photo = kSamples / "leuven.jpg";
  c.depth = kSamples / "leuven_depth.exr";
  c.fov_deg = 65;
  c.scene.medium.height_fog = Medium::HeightFog{0.5, 12.0};
  c.scene.pose.pitch_deg = 4;
  c.scene.pose.roll_deg = -2;
  c.scene.pose.yaw_deg = 10;
  expect_equal_paths(c, dir, "height", streamer);
  c.scene.medium.height_fog.reset();
  c.scene.medium.layer_bottom_m = -1;
  c.scene.medium.layer_top_m = 6;
  expect_equal_paths(c, dir, "layer", streamer);
}

TEST(FogStream, DepthKindsMatch) {
  test::ScratchDir dir;
  FogStreamer streamer;
  Case z;  // the distance file read as planar z: converted with the camera
  z.photo = kSamples / "aloe.jpg";
  z.depth = kSamples / "aloe_depth.exr";
  z.fov_deg = 50;
  z.depth_options.kind = DepthKind::planar_z;
  z.depth_options.scale = 20;
  expect_equal_paths(z, dir, "planar_z", streamer);
  Case disparity;  // an 8-bit disparity PNG: integer codes
  disparity.photo = kSamples / "aloe.jpg";
  disparity.depth = kSamples / "aloe_disparity.png";
  disparity.depth_options.kind = DepthKind::disparity;
  disparity.depth_options.baseline_m = 0.16;
  disparity.depth_options.doffs_px = 90;
  disparity.depth_options.scale = 1.0 / 3.0;
  disparity.scene = sky_scene(0.4f);
  expect_equal_paths(disparity, dir, "disparity", streamer);
}

TEST(FogStream, FormatsAndBitDepthsMatch) {
  test::ScratchDir dir;
  FogStreamer streamer;
  // A 16-bit RGBA PNG photo with a 16-bit depth PNG (millimetres), out as 16-bit PNG, 8-bit
  // TIFF, float and half EXR, and a second colour space.
  Image photo = test::make_test_photo(131, 77);
  Image rgba(131, 77, 4);
  Image depth_mm(131, 77, 1, {"Z"});
  for (int y = 0; y < 77; ++y)
    for (int x = 0; x < 131; ++x) {
      for (int ch = 0; ch < 3; ++ch) rgba.at(x, y, ch) = photo.at(x, y, ch);
      rgba.at(x, y, 3) = float(x) / 130.0f;
      depth_mm.at(x, y, 0) = y < 10 ? 0.0f : float(2000 + 500 * x + 30 * y) / 65535.0f;
    }
  WriteOptions w16;
  w16.pixel_type = PixelType::uint16;
  write_image(dir / "rgba.png", rgba, w16);
  WriteOptions raw16 = w16;
  raw16.colorspace = colorspace::raw;
  write_image(dir / "rgba_depth.png", depth_mm, raw16);
  Case c;
  c.photo = dir / "rgba.png";
  c.depth = dir / "rgba_depth.png";
  c.depth_options.scale = 0.001;
  c.fov_deg = 60;
  for (auto [type, ext] : {std::pair{PixelType::uint16, ".png"}, {PixelType::uint8, ".tif"},
                           {PixelType::float32, ".exr"}, {PixelType::half, ".exr"},
                           {PixelType::uint8, ".jpg"}}) {
    c.write.pixel_type = type;
    c.ext = ext;
    expect_equal_paths(c, dir, std::string("out_") + to_string(type), streamer);
  }
  c.write.pixel_type = PixelType::uint16;
  c.write.colorspace = colorspace::acescg;
  c.ext = ".tif";
  expect_equal_paths(c, dir, "acescg", streamer);
}

TEST(FogStream, PhotoInMemoryWithEstimatedSkyMatches) {
  // `mr fog --airlight auto`: the photo decoded whole (the dark channel prior needs it), the
  // sky radiance estimated from it, then the depth, the fog and the encoding stream.
  test::ScratchDir dir;
  FogStreamer streamer;
  Case c;
  c.photo = kSamples / "building.jpg";
  c.depth = kSamples / "building_depth.exr";
  c.scene.lighting.sky_radiance.reset();
  full_frame(c, dir / "full.jpg");
  const Image photo = read_image(c.photo);
  Case with_sky = c;
  with_sky.scene.lighting.sky_radiance = estimate_airlight(photo);
  const StreamFogResult r = streamed(with_sky, dir / "stream.jpg", streamer, &photo);
  ASSERT_TRUE(r.streamed) << r.reason;
  expect_same_pixels(dir / "full.jpg", dir / "stream.jpg");
}

TEST(FogStream, SkyLightByDirectionMatchesTheFullFramePath) {
  // Issue 11: the photo's sky by direction, its low-resolution map sampled per pixel as the
  // strips are fogged; without the map the request declines.
  test::ScratchDir dir;
  FogStreamer streamer;
  Case c;
  c.photo = kSamples / "building.jpg";
  c.depth = kSamples / "building_depth.exr";
  c.scene.lighting.sky_by_direction = true;
  c.scene.medium.g = 0.6;
  full_frame(c, dir / "full.jpg");
  StreamFogResult r = streamed(c, dir / "declined.jpg", streamer);
  EXPECT_FALSE(r.streamed);
  const Image photo = read_image(c.photo);
  const Camera camera = Camera::from_metadata(photo.width(), photo.height(), photo.metadata());
  const SkyLight sky_light = sky_light_from_photo(
      photo, read_depth(c.depth, camera).distance_m, camera, c.scene, *c.scene.lighting.sky_radiance);
  ASSERT_FALSE(sky_light.deviation.empty());
  StreamFogRequest req;
  req.photo = c.photo;
  req.depth = c.depth;
  req.output = dir / "stream.jpg";
  req.scene = &c.scene;
  req.sky_light = &sky_light;
  r = streamer.fog_file(req);
  ASSERT_TRUE(r.streamed) << r.reason;
  expect_same_pixels(dir / "full.jpg", dir / "stream.jpg");
  // And it changed the picture (the sky's map is not uniform).
  Case uniform = c;
  uniform.scene.lighting.sky_by_direction = false;
  full_frame(uniform, dir / "uniform.jpg");
  const Image a = read_stored(dir / "full.jpg"), b = read_stored(dir / "uniform.jpg");
  double diff = 0;
  for (std::size_t i = 0; i < a.pixels().size(); ++i)
    diff = std::max(diff, double(std::fabs(a.pixels()[i] - b.pixels()[i])));
  EXPECT_GT(diff, 2.0 / 255);
}

TEST(FogStream, DeclinesWhatNeedsTheWholeFrame) {
  test::ScratchDir dir;
  FogStreamer streamer;
  Case c;
  c.photo = kSamples / "leuven.jpg";
  c.depth = kSamples / "leuven_depth.exr";
  c.scene.lighting.sun = Sun{direction_from_azimuth_elevation(30, 20), {3, 3, 3}, 0.27};
  StreamFogResult r = streamed(c, dir / "sun.jpg", streamer);
  EXPECT_FALSE(r.streamed);
  c.scene = sky_scene();
  c.scene.lighting.sky_radiance.reset();
  r = streamed(c, dir / "auto.jpg", streamer);
  EXPECT_FALSE(r.streamed);
  // A photo its EXIF Orientation turns.
  {
    OIIO::ImageSpec spec(64, 48, 3, OIIO::TypeDesc::UINT8);
    spec.attribute("Orientation", 6);
    std::vector<unsigned char> codes(64 * 48 * 3, 128);
    auto out = OIIO::ImageOutput::create((dir / "turned.jpg").string());
    ASSERT_TRUE(out && out->open((dir / "turned.jpg").string(), spec));
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, codes.data()));
    out->close();
  }
  c.scene = sky_scene();
  c.photo = dir / "turned.jpg";
  r = streamed(c, dir / "turned_out.jpg", streamer);
  EXPECT_FALSE(r.streamed);
  EXPECT_NE(r.reason.find("orientation"), std::string::npos) << r.reason;
  // A depth map of another size: the full-frame path names both sizes.
  c.photo = kSamples / "aerial.jpg";
  r = streamed(c, dir / "size.jpg", streamer);
  EXPECT_FALSE(r.streamed);
  EXPECT_TRUE(dir.list().size() == 1) << "nothing written but the turned photo";
}

TEST(FogStream, CorruptPhotoIsAnErrorNamingItAndWritesNothing) {
  test::ScratchDir dir;
  FogStreamer streamer;
  write_image(dir / "p.jpg", test::make_test_photo(320, 240));
  const std::string bytes = test::read_bytes(dir / "p.jpg");
  test::write_bytes(dir / "p.jpg", bytes.substr(0, bytes.size() / 3));
  Image depth(320, 240, 1, {"Z"});
  for (float& v : depth.pixels()) v = 50;
  WriteOptions raw;
  raw.colorspace = colorspace::raw;
  raw.pixel_type = PixelType::float32;
  write_image(dir / "p_depth.exr", depth, raw);
  Case c;
  c.photo = dir / "p.jpg";
  c.depth = dir / "p_depth.exr";
  fs::create_directories(dir / "out");
  try {
    const StreamFogResult r = streamed(c, dir / "out" / "p.jpg", streamer);
    // libjpeg may pad a truncated file with grey and only warn; then it must have streamed.
    EXPECT_TRUE(r.streamed) << r.reason;
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("p.jpg"), std::string::npos) << e.what();
    EXPECT_TRUE(fs::is_empty(dir / "out")) << "no partial or temporary file left";
  }
}

// `mr fog` end to end: the command streams sky-only photos, and its output equals the library's
// full-frame path (given sky, and estimated sky).
TEST(FogStream, CommandLineMatchesTheFullFramePath) {
  test::ScratchDir dir;
  fs::create_directories(dir / "in");
  fs::copy_file(kSamples / "leuven.jpg", dir / "in" / "leuven.jpg");
  fs::copy_file(kSamples / "leuven_depth.exr", dir / "in" / "leuven_depth.exr");
  for (bool auto_sky : {false, true}) {
    const fs::path out = dir / (auto_sky ? "out_auto" : "out");
    const std::string cmd = std::string(MR_CLI_PATH) + " fog " + (dir / "in").string() +
                            " --out-dir " + out.string() + " --visibility 120m --backend cpu" +
                            (auto_sky ? "" : " --airlight 0.7,0.75,0.8") + " -q 2>&1";
    const test::CommandResult run = test::run(cmd);
    ASSERT_EQ(run.exit_code, 0) << run.output;
    Case c;
    c.photo = dir / "in" / "leuven.jpg";
    c.depth = dir / "in" / "leuven_depth.exr";
    const float sigma = float(extinction_from_visibility(120));
    c.scene = FogScene{};
    c.scene.medium.sigma_t_per_m = {sigma, sigma, sigma};
    c.scene.render.backend = Backend::cpu;
    if (!auto_sky) c.scene.lighting.sky_radiance = Rgb{0.7f, 0.75f, 0.8f};
    // mr fog's default for display-referred outputs: the highlight roll-off (mr/color.h).
    c.write.colorspace = ColorConfig::builtin().display_colorspace();
    full_frame(c, dir / (auto_sky ? "full_auto.jpg" : "full.jpg"));
    expect_same_pixels(dir / (auto_sky ? "full_auto.jpg" : "full.jpg"), out / "leuven_fog.jpg");
  }
}

// Peak resident memory of `mr fog` on a 12 MP JPEG with a float depth EXR, from the OS
// (wait4's rusage of the child). Target (issue 12): 400 MiB. The full-frame path needed ~1.6 GiB.
TEST(FogStream, TwelveMegapixelRunStaysUnderTheMemoryTarget) {
  test::ScratchDir dir;
  const int w = 4000, h = 3000;
  {
    Image photo = test::make_test_photo(w, h);
    write_image(dir / "big.jpg", photo);
    Image depth(w, h, 1, {"Z"});
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        depth.at(x, y, 0) = y < h / 3 ? std::numeric_limits<float>::infinity()
                                      : 5.0f + 2000.0f * float(h - y) / float(h);
    WriteOptions raw;
    raw.colorspace = colorspace::raw;
    raw.pixel_type = PixelType::float32;
    write_image(dir / "big_depth.exr", depth, raw);
  }
  rusage usage{};
  ASSERT_EQ(
      test::run_measured(MR_CLI_PATH,
                         {"fog", (dir / "big.jpg").string(), "--out-dir", (dir / "out").string(),
                          "--visibility", "150m", "--airlight", "0.8", "--backend", "cpu", "-q"},
                         &usage),
      0);
  ASSERT_TRUE(fs::exists(dir / "out" / "big_fog.jpg"));
  const double peak_mib = double(usage.ru_maxrss) / 1024.0;  // ru_maxrss is in KiB on Linux
  std::printf("12 MP mr fog: peak RSS %.1f MiB\n", peak_mib);
#if !defined(__SANITIZE_ADDRESS__)
  EXPECT_LT(peak_mib, 400.0);
#else
  // Under AddressSanitizer the peak is its quarantine (256 MiB by default) and shadow memory,
  // 380-406 MiB from run to run against ~62 MiB in the normal build, which holds the bar (as
  // ReadMemory.* does); the fog's pixels are still checked below.
  (void)peak_mib;
#endif
  // And the image is fogged, not black or blank: the sky rows are the airlight, and the
  // nearest row's dark corner (red ~ 0 in the test photo) holds Koschmieder's in-scatter.
  const Image result = read_image(dir / "out" / "big_fog.jpg");
  EXPECT_NEAR(result.at(w / 2, 10, 1), 0.8, 0.02);
  const double d = 5.0 + 2000.0 / h, sigma = 3.912 / 150.0;
  EXPECT_NEAR(result.at(0, h - 1, 0), 0.8 * (1 - std::exp(-sigma * d)), 0.02);
}

// `mr` keeps the memory a photo's stages free for the next buffer (cli/main.cpp) instead of
// letting glibc unmap every block over 32 MiB, which the kernel then faults and zeroes in again
// page by page. Scale-free check from the OS (wait4's rusage of the child): the minor page
// faults, 4 KiB each, add up to at most the peak resident memory, i.e. each page is faulted in
// about once. An automatic haze of a 1280 x 800 photo: 1.6x its peak before (172 k faults, 415
// MiB), 0.66x with the reuse; with transparent huge pages always on, fewer faults still.
TEST(CliMemory, AnAutomaticFogFaultsEachPageInAboutOnce) {
  test::ScratchDir dir;
  const fs::path gallery = fs::path(MR_SOURCE_DIR) / "gallery";
  const std::string photo = (gallery / "tune" / "kite.jpg").string();
  const std::string look = (gallery / "looks" / "haze.json").string();
  rusage usage{};
  ASSERT_EQ(test::run_measured(MR_CLI_PATH,
                               {"fog", photo, "--depth", "auto", "--scene", look, "--out-dir",
                                (dir / "out").string(), "-q"},
                               &usage),
            0);
  // (And it fogged: the haze veils the deep blue sky, so the picture changed.)
  const Image photo_in = read_image(photo), result = read_image(dir / "out" / "kite_fog.jpg");
  ASSERT_EQ(result.width(), photo_in.width());
  ASSERT_EQ(result.height(), photo_in.height());
  double changed = 0;
  for (int y = 0; y < result.height(); ++y)
    for (int x = 0; x < result.width(); ++x)
      changed += std::abs(result.at(x, y, 2) - photo_in.at(x, y, 2));
  changed /= double(result.width()) * result.height();
  std::printf("mean |fogged - photo| (blue, linear): %.3f\n", changed);
  EXPECT_GT(changed, 0.05);
  const double faulted_mib = double(usage.ru_minflt) * double(sysconf(_SC_PAGESIZE)) / (1 << 20);
  const double peak_mib = double(usage.ru_maxrss) / 1024.0;
  std::printf("automatic haze, 1280 x 800: %ld minor faults (%.0f MiB), peak RSS %.0f MiB\n",
              usage.ru_minflt, faulted_mib, peak_mib);
#if !defined(__SANITIZE_ADDRESS__)
  EXPECT_LT(faulted_mib, peak_mib);
#else
  (void)faulted_mib;  // AddressSanitizer's allocator maps and unmaps as it likes
#endif
}

}  // namespace
}  // namespace mr
