// Issue 13 section 4, the library's side: hostile documents, files that are not regular files,
// decoded-size limits checked from headers, absurd depths. Each test names the defect it covers.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <functional>
#include <limits>
#include <string>

#include "mr/annotations.h"
#include "mr/camera.h"
#include "mr/depth.h"
#include "mr/error.h"
#include "mr/io.h"
#include "mr/scattering.h"
#include "mr/scene_json.h"
#include "test_support.h"

namespace fs = std::filesystem;

namespace mr {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

// The message of the mr::Error `f` throws (with its code checked), or "" when it throws none.
std::string error_of(const std::function<void()>& f, ErrorCode code) {
  try {
    f();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), code) << e.what();
    return e.what();
  }
  ADD_FAILURE() << "no mr::Error";
  return "";
}

#define EXPECT_CONTAINS(haystack, needle) \
  EXPECT_NE(std::string(haystack).find(needle), std::string::npos) << (haystack)

std::string nested_arrays(std::size_t levels) {
  return "{\"format\": \"mr-scene\", \"version\": 1, \"medium\": " + std::string(levels, '[') +
         std::string(levels, ']') + "}";
}

// Defect: a scene or annotations document with 100,000 nested arrays crashed the reader
// (SIGSEGV, recursion). Nesting past 256 levels is a one-line error naming the source.
TEST(Reliability, DeeplyNestedJsonIsAnErrorNotACrash) {
  for (std::size_t levels : {257, 100000}) {
    const std::string scene_error = error_of(
        [&] { scene_from_json(nested_arrays(levels), "deep.json"); }, ErrorCode::invalid_argument);
    EXPECT_CONTAINS(scene_error, "deep.json: ");
    EXPECT_CONTAINS(scene_error, "nested more than 256 levels deep");
    EXPECT_EQ(scene_error.find('\n'), std::string::npos);
    const std::string annotations_error =
        error_of([&] { annotations_from_json(std::string(levels, '[') + std::string(levels, ']'),
                                             "a.json"); },
                 ErrorCode::invalid_argument);
    EXPECT_CONTAINS(annotations_error, "a.json: ");
    EXPECT_CONTAINS(annotations_error, "nested more than 256 levels deep");
  }
  // 256 levels parse (and then fail as a scene for what they are, not for their depth).
  const std::string ok = error_of([&] { scene_from_json(nested_arrays(255), "ok.json"); },
                                  ErrorCode::invalid_argument);
  EXPECT_EQ(ok.find("nested more than"), std::string::npos) << ok;
}

// Defect: trailing NUL bytes (and garbage after them) were accepted.
TEST(Reliability, TrailingNulAndGarbageAfterTheDocumentAreRejected) {
  const std::string scene = scene_to_json(FogScene{});
  EXPECT_NO_THROW(scene_from_json(scene + " \n\t", "s.json"));
  const std::string nul =
      error_of([&] { scene_from_json(scene + std::string(1, '\0'), "s.json"); },
               ErrorCode::invalid_argument);
  EXPECT_CONTAINS(nul, "s.json: line ");
  EXPECT_CONTAINS(nul, "NUL byte");
  EXPECT_CONTAINS(error_of([&] { scene_from_json(scene + std::string("\0{}garbage", 10), "s.json"); },
                           ErrorCode::invalid_argument),
                  "NUL byte");
  EXPECT_CONTAINS(error_of([&] { scene_from_json(scene + "garbage", "s.json"); },
                           ErrorCode::invalid_argument),
                  "s.json: line ");
  EXPECT_CONTAINS(error_of([&] { scene_from_json(scene + "{}", "s.json"); },
                           ErrorCode::invalid_argument),
                  "s.json: line ");
  const std::string annotations = annotations_to_json(Annotations{});
  EXPECT_CONTAINS(error_of([&] { annotations_from_json(annotations + std::string(3, '\0'), "a.json"); },
                           ErrorCode::invalid_argument),
                  "NUL byte");
}

// Defect: a FIFO or /dev/zero given as a scene, photo or depth map blocked or spun for ever.
// Only regular files are read; everything else is a clear error naming the file.
TEST(Reliability, OnlyRegularFilesAreRead) {
  test::ScratchDir dir;
  const fs::path fifo = dir / "pipe.json";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const fs::path fifo_image = dir / "pipe.exr";
  ASSERT_EQ(::mkfifo(fifo_image.c_str(), 0600), 0);
  EXPECT_CONTAINS(error_of([&] { load_scene(fifo); }, ErrorCode::io), "pipe.json: is a FIFO");
  EXPECT_CONTAINS(error_of([&] { load_annotations(fifo); }, ErrorCode::io), "pipe.json: is a FIFO");
  EXPECT_CONTAINS(error_of([&] { read_image(fifo_image); }, ErrorCode::io), "pipe.exr: is a FIFO");
  EXPECT_CONTAINS(error_of([&] { probe_image(fifo_image); }, ErrorCode::io), "is a FIFO");
  const Camera cam = Camera::from_horizontal_fov(8, 8, 60);
  EXPECT_CONTAINS(error_of([&] { read_depth(fifo_image, cam); }, ErrorCode::io), "is a FIFO");
  EXPECT_CONTAINS(error_of([&] { load_scene("/dev/zero"); }, ErrorCode::io),
                  "/dev/zero: is a character device");
  EXPECT_CONTAINS(error_of([&] { read_image("/dev/urandom"); }, ErrorCode::io),
                  "/dev/urandom: is a character device");
  // Links: a loop and a dangling link say so (not "no such file").
  fs::create_symlink("loop_b.png", dir / "loop_a.png");
  fs::create_symlink("loop_a.png", dir / "loop_b.png");
  fs::create_symlink("gone.png", dir / "dangling.png");
  EXPECT_CONTAINS(error_of([&] { read_image(dir / "loop_a.png"); }, ErrorCode::io),
                  "loop_a.png: a symbolic link loop");
  EXPECT_CONTAINS(error_of([&] { read_image(dir / "dangling.png"); }, ErrorCode::io),
                  "dangling.png: a dangling symbolic link (to gone.png)");
  EXPECT_CONTAINS(error_of([&] { read_image(dir / "missing.png"); }, ErrorCode::io),
                  "missing.png: no such file");
  // A depth map this process may not read: "cannot open: Permission denied", not the decoder's
  // "not an OpenEXR file" (root reads everything: then only the read succeeds).
  Image depth(8, 8, 1, {"Z"});
  for (float& v : depth.pixels()) v = 5;
  WriteOptions raw;
  raw.pixel_type = PixelType::float32;
  raw.colorspace = colorspace::raw;
  write_image(dir / "locked_depth.exr", depth, raw);
  fs::permissions(dir / "locked_depth.exr", fs::perms::none);
  if (::geteuid() != 0) {
    EXPECT_CONTAINS(error_of([&] { read_depth(dir / "locked_depth.exr", cam); }, ErrorCode::io),
                    "locked_depth.exr: cannot open: Permission denied");
  }
  fs::permissions(dir / "locked_depth.exr", fs::perms::owner_all);
}

// Defect: a small PNG that decodes to 20000x20000 took 6 GB before anything was checked, and
// "image size ... is out of range" did not name the file. The header is checked first.
TEST(Reliability, DecodedSizeIsLimitedFromTheHeader) {
  test::ScratchDir dir;
  write_image(dir / "wide.png", test::make_test_photo(400, 300));  // 0.12 MP
  EXPECT_EQ(max_decoded_pixels(), kDefaultMaxDecodedPixels);
  set_max_decoded_pixels(100000);  // 0.1 MP
  const std::string e = error_of([&] { read_image(dir / "wide.png"); }, ErrorCode::corrupt_input);
  EXPECT_CONTAINS(e, "wide.png: 400x300 is 0.1 megapixels, more than the limit of 0.1");
  EXPECT_CONTAINS(e, "--max-megapixels");
  EXPECT_NO_THROW(probe_image(dir / "wide.png"));  // the header alone is fine
  set_max_decoded_pixels(0);                        // back to the default
  EXPECT_EQ(max_decoded_pixels(), kDefaultMaxDecodedPixels);
  EXPECT_NO_THROW(read_image(dir / "wide.png"));
  // A wrong-size depth map is noticed from its header, naming the file and both sizes.
  Image depth(40, 30, 1, {"Z"});
  for (float& v : depth.pixels()) v = 5;
  WriteOptions raw;
  raw.pixel_type = PixelType::float32;
  raw.colorspace = colorspace::raw;
  write_image(dir / "d.exr", depth, raw);
  EXPECT_CONTAINS(error_of([&] { read_depth(dir / "d.exr", Camera::from_horizontal_fov(400, 300, 60)); },
                           ErrorCode::size_mismatch),
                  "d.exr: depth map is 40x30, photo is 400x300");
}

// Defect: one depth pixel of 1e20 m aborted the render (Embree's ray.valid() assertion). Every
// finite depth works: the sky conventions of common tools (Blender's 1e10, 65504, 1e6) read as
// sky; other distances past kMaxSurfaceDistanceM are clamped to it.
TEST(Reliability, SkyConventionsAndAbsurdDepths) {
  const Camera cam = Camera::from_horizontal_fov(4, 2, 60);
  Image stored(4, 2, 1, {"Z"});
  const float values[] = {10.0f, 65504.0f, 1e6f, 1e10f, 1e20f, 65503.0f, 0.0f, kInf};
  std::copy(std::begin(values), std::end(values), stored.pixels().begin());
  const DepthMap d = depth_to_distance(stored, cam, {});
  EXPECT_EQ(d.distance_m.at(0, 0, 0), 10.0f);
  for (int x : {1, 2, 3}) EXPECT_EQ(d.distance_m.at(x, 0, 0), kInf) << x;
  EXPECT_EQ(d.distance_m.at(0, 1, 0), kInf);  // 1e20 >= the threshold: sky
  EXPECT_EQ(d.distance_m.at(1, 1, 0), 65503.0f);
  EXPECT_EQ(d.no_surface_pixels, 6u);
  EXPECT_EQ(d.sky_threshold_pixels, 4u);
  EXPECT_EQ(d.invalid_pixels, 0u);
  EXPECT_EQ(d.clamped_pixels, 0u);
  // No threshold: 1e20 is a surface, clamped to the far limit; 1e6 and 1e10 stay as they are.
  DepthOptions no_sky;
  no_sky.sky_depth_m = std::numeric_limits<double>::infinity();
  const DepthMap far = depth_to_distance(stored, cam, no_sky);
  EXPECT_EQ(far.distance_m.at(2, 0, 0), 1e6f);
  EXPECT_EQ(far.distance_m.at(3, 0, 0), float(kMaxSurfaceDistanceM));
  EXPECT_EQ(far.distance_m.at(0, 1, 0), float(kMaxSurfaceDistanceM));
  EXPECT_EQ(far.clamped_pixels, 2u);
  EXPECT_EQ(far.sky_threshold_pixels, 0u);
  // A lower threshold, after the scale: millimetres with 65535 = no data.
  DepthOptions mm;
  mm.scale = 0.001;
  mm.sky_depth_m = 65.535;
  Image codes(2, 1, 1, {"Z"});
  codes.pixels()[0] = 65535;
  codes.pixels()[1] = 65534;
  const DepthMap m = depth_to_distance(codes, Camera::from_horizontal_fov(2, 1, 60), mm);
  EXPECT_EQ(m.distance_m.at(0, 0, 0), kInf);
  EXPECT_NEAR(m.distance_m.at(1, 0, 0), 65.534, 1e-3);
  DepthOptions bad;
  bad.sky_depth_m = 0;
  EXPECT_CONTAINS(error_of([&] { depth_to_distance(stored, cam, bad); }, ErrorCode::invalid_argument),
                  "sky depth");
}

// The renderer itself: a distance map (not from a file) with 1e20 m and 1e38 m surfaces renders
// as if they were at the far limit, with shadows and a sun (the mesh and Embree see them).
TEST(Reliability, RenderClampsDistancesBeyondTheFarLimit) {
  const Camera cam = Camera::from_horizontal_fov(32, 24, 60);
  Image absurd(32, 24, 1, {"Z"});
  for (int y = 0; y < 24; ++y)
    for (int x = 0; x < 32; ++x) absurd.at(x, y, 0) = y < 8 ? kInf : 20.0f + float(y);
  absurd.at(5, 5, 0) = 1e20f;
  absurd.at(6, 5, 0) = 3e38f;
  absurd.at(10, 12, 0) = 1e20f;  // amid the ground
  Image clamped = absurd;
  for (float& v : clamped.pixels())
    if (std::isfinite(v) && v > kMaxSurfaceDistanceM) v = float(kMaxSurfaceDistanceM);
  FogScene s;
  s.pose.position_m = {0, 1.6, 0};
  s.medium.sigma_t_per_m = {0.02f, 0.02f, 0.02f};
  s.medium.layer_bottom_m = 0;
  s.medium.layer_top_m = 30;
  s.lighting.sun = Sun{direction_from_azimuth_elevation(30, 20), {3, 3, 3}, 0.27};
  s.lighting.sky_radiance = Rgb{0.3f, 0.3f, 0.35f};
  s.render.backend = Backend::cpu;
  s.render.quality = Quality::draft;
  const ScatteringLayers a = render_scattering(Image(), absurd, cam, s);
  const ScatteringLayers b = render_scattering(Image(), clamped, cam, s);
  EXPECT_EQ(test::max_abs_diff(a.transmittance, b.transmittance), 0.0);
  EXPECT_EQ(test::max_abs_diff(a.inscatter, b.inscatter), 0.0);
  for (float v : a.inscatter.pixels()) EXPECT_TRUE(std::isfinite(v));
}

}  // namespace
}  // namespace mr
