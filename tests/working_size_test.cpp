// Camera-size photos worked on at a working size (mr/working_size.h, photo/fog_upsample.h;
// issue 11): the working size and camera, the guided upsampling of T and R against a fog whose
// full-size truth is known (a near object's outline between working pixels), its range and
// composite, its errors, and `mr fog --depth auto` on a photo larger than the working size.
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "mr/error.h"
#include "mr/io.h"
#include "mr/working_size.h"
#include "photo/fog_upsample.h"
#include "tests/test_support.h"

namespace mr {
namespace {

namespace fs = std::filesystem;

TEST(WorkingSize, KeepsTheAspectAndOnlyShrinks) {
  const auto s = working_size(6000, 4000, 1600);
  ASSERT_TRUE(s.has_value());
  EXPECT_EQ(s->width, 1600);
  EXPECT_EQ(s->height, 1067);
  const auto portrait = working_size(2000, 3000, 1600);
  ASSERT_TRUE(portrait.has_value());
  EXPECT_EQ(portrait->width, 1067);
  EXPECT_EQ(portrait->height, 1600);
  EXPECT_FALSE(working_size(1600, 900, 1600).has_value());  // not larger: its own size
  EXPECT_FALSE(working_size(6000, 4000, 0).has_value());    // 0: no limit
  EXPECT_THROW(working_size(0, 10, 1600), Error);
}

TEST(WorkingSize, TheScaledCameraSeesTheSameField) {
  const Camera full = Camera::from_horizontal_fov(6000, 4000, 63.0);
  const Camera work = scale_camera(full, 1600, 1067);
  EXPECT_NEAR(work.horizontal_fov_deg(), 63.0, 0.01);
  // The ray through a working pixel's centre is the ray through the same point of the frame.
  const double sx = 6000.0 / 1600, sy = 4000.0 / 1067;
  for (auto [x, y] : {std::pair{0, 0}, {800, 533}, {1599, 1066}, {123, 987}}) {
    const auto a = work.ray_direction(x, y);
    // The full camera's ray through the continuous point ((x + 0.5) sx, (y + 0.5) sy).
    const double u = ((x + 0.5) * sx - full.cx) / full.focal_px;
    const double v = ((y + 0.5) * sy - full.cy) / full.focal_px;
    const double n = std::sqrt(u * u + v * v + 1);
    const double b[3] = {u / n, v / n, 1 / n};
    double dot = 0;
    for (int k = 0; k < 3; ++k) dot += a[k] * b[k];
    EXPECT_GT(dot, std::cos(0.02 * 3.14159265 / 180)) << x << "," << y;
  }
  EXPECT_THROW(scale_camera(full, 0, 10), Error);
}

// A haze scene whose full-size fog is known: a bright, finely textured far background (2 km)
// and a dark near disk (20 m) whose outline crosses working pixels at every phase.
struct Scene {
  static constexpr int kW = 1200, kH = 800;
  static constexpr float kSigma = 0.002f;  // 1/m
  static constexpr float kAir[3] = {0.80f, 0.82f, 0.85f};
  Image photo{kW, kH, 3}, distance{kW, kH, 1};
  Scene() {
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> grain(-0.03f, 0.03f);
    for (int y = 0; y < kH; ++y)
      for (int x = 0; x < kW; ++x) {
        const double dx = x + 0.5 - 601.3, dy = y + 0.5 - 398.7;
        const bool near = dx * dx + dy * dy < 250.4 * 250.4;
        const float g = grain(rng);
        const float near_rgb[3] = {0.05f, 0.04f, 0.03f}, far_rgb[3] = {0.55f, 0.62f, 0.70f};
        for (int c = 0; c < 3; ++c)
          photo.at(x, y, c) = near ? near_rgb[c] * (1 + g) : far_rgb[c] + g;
        distance.at(x, y, 0) = near ? 20.0f : 2000.0f;
      }
  }
  // T and R of the fog over a distance map (Koschmieder, grey).
  static void fog(const Image& d, Image& t, Image& r) {
    t = Image(d.width(), d.height(), 3);
    r = Image(d.width(), d.height(), 3);
    for (int y = 0; y < d.height(); ++y)
      for (int x = 0; x < d.width(); ++x) {
        const float tv = std::exp(-kSigma * d.at(x, y, 0));
        for (int c = 0; c < 3; ++c) {
          t.at(x, y, c) = tv;
          r.at(x, y, c) = kAir[c] * (1 - tv);
        }
      }
  }
};

// The pixels within `band` px of the disk's outline, and those farther than `far` px from it.
bool near_outline(int x, int y, double band) {
  const double r = std::hypot(x + 0.5 - 601.3, y + 0.5 - 398.7);
  return std::abs(r - 250.4) <= band;
}

TEST(FogUpsample, FollowsTheFullSizeOutlineNotTheWorkingGrid) {
  const Scene s;
  const int ww = 400, wh = 267;  // a third
  const Image work_photo = working_copy(s.photo, ww, wh);
  // The working fog as an estimate at that size would give it: each working pixel one distance.
  Image work_t, work_r, true_t, true_r;
  Scene::fog(resize_nearest(s.distance, ww, wh), work_t, work_r);
  Scene::fog(s.distance, true_t, true_r);
  FogLayers working;
  working.transmittance = work_t;
  working.inscatter = work_r;
  const FogLayers up = upsample_fog_layers(s.photo, work_photo, working);
  ASSERT_EQ(up.transmittance.width(), Scene::kW);
  ASSERT_EQ(up.composite.height(), Scene::kH);
  // Against plain bilinear upsampling (what a resize gives), on the outline's pixels.
  const Image bilinear_t = [&] {
    Image b(Scene::kW, Scene::kH, 3);
    for (int y = 0; y < Scene::kH; ++y)
      for (int x = 0; x < Scene::kW; ++x) {
        const double fx = std::clamp((x + 0.5) * ww / Scene::kW - 0.5, 0.0, ww - 1.0);
        const double fy = std::clamp((y + 0.5) * wh / Scene::kH - 0.5, 0.0, wh - 1.0);
        const int x0 = int(fx), y0 = int(fy), x1 = std::min(x0 + 1, ww - 1),
                  y1 = std::min(y0 + 1, wh - 1);
        const double ax = fx - x0, ay = fy - y0;
        const double v = (1 - ay) * ((1 - ax) * work_t.at(x0, y0, 0) + ax * work_t.at(x1, y0, 0)) +
                         ay * ((1 - ax) * work_t.at(x0, y1, 0) + ax * work_t.at(x1, y1, 0));
        for (int c = 0; c < 3; ++c) b.at(x, y, c) = float(v);
      }
    return b;
  }();
  double guided_err = 0, bilinear_err = 0, far_err = 0, composite_err = 0;
  int n_edge = 0, n_far = 0;
  for (int y = 0; y < Scene::kH; ++y)
    for (int x = 0; x < Scene::kW; ++x) {
      const double e = std::abs(up.transmittance.at(x, y, 0) - true_t.at(x, y, 0));
      if (near_outline(x, y, 2.0)) {
        guided_err += e;
        bilinear_err += std::abs(bilinear_t.at(x, y, 0) - true_t.at(x, y, 0));
        ++n_edge;
      } else if (!near_outline(x, y, 8.0)) {
        far_err = std::max(far_err, e);
        ++n_far;
      }
      for (int c = 0; c < 3; ++c) {
        const double truth = s.photo.at(x, y, c) * true_t.at(x, y, c) + true_r.at(x, y, c);
        composite_err += std::abs(up.composite.at(x, y, c) - truth);
      }
    }
  guided_err /= n_edge;
  bilinear_err /= n_edge;
  composite_err /= 3.0 * Scene::kW * Scene::kH;
  std::printf(
      "outline: guided %.4f, bilinear %.4f mean |T error|; away: max %.2g; composite %.5f\n",
      guided_err, bilinear_err, far_err, composite_err);
  // T steps from 0.96 to 0.018 across the outline: bilinear smears it over ~6 px; the guided
  // models put the step on the photo's outline (measured 0.014 against 0.219).
  EXPECT_GT(bilinear_err, 0.15);
  EXPECT_LT(guided_err, bilinear_err / 5);
  EXPECT_LT(far_err, 1e-6);  // flat fog stays exact
  EXPECT_LT(composite_err, 0.001);
}

TEST(FogUpsample, StaysWithinItsWorkingNeighboursValues) {
  // Noise in T and R and in the photo: no model may leave the range it was fit to.
  const int w = 90, h = 70, fw = 301, fh = 233;
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  Image photo(fw, fh, 3), work_t(w, h, 3), work_r(w, h, 3);
  for (float& v : photo.pixels()) v = u(rng);
  for (float& v : work_t.pixels()) v = u(rng);
  for (float& v : work_r.pixels()) v = 2 * u(rng);
  const Image work_photo = working_copy(photo, w, h);
  FogLayers working;
  working.transmittance = work_t;
  working.inscatter = work_r;
  const FogLayers up = upsample_fog_layers(photo, work_photo, working);
  auto tap = [](int i, int full, int work) {
    const double f = std::clamp((i + 0.5) * work / full - 0.5, 0.0, work - 1.0);
    const int lo = int(f);
    return std::pair{lo, std::min(lo + 1, work - 1)};
  };
  int outside = 0;
  for (int y = 0; y < fh; ++y)
    for (int x = 0; x < fw; ++x) {
      const auto [x0, x1] = tap(x, fw, w);
      const auto [y0, y1] = tap(y, fh, h);
      for (int c = 0; c < 3; ++c)
        for (auto [layer, out] :
             {std::pair{&work_t, &up.transmittance}, std::pair{&work_r, &up.inscatter}}) {
          const float a = layer->at(x0, y0, c), b = layer->at(x1, y0, c), d = layer->at(x0, y1, c),
                      e = layer->at(x1, y1, c);
          const float v = out->at(x, y, c);
          if (v < std::min({a, b, d, e}) || v > std::max({a, b, d, e})) ++outside;
        }
      for (int c = 0; c < 3; ++c)  // and the composite is I T + R of what it returns
        ASSERT_FLOAT_EQ(up.composite.at(x, y, c), photo.at(x, y, c) * up.transmittance.at(x, y, c) +
                                                      up.inscatter.at(x, y, c));
    }
  EXPECT_EQ(outside, 0);
}

TEST(FogUpsample, CarriesAlphaAndCanSkipTheLayers) {
  Image photo(64, 48, 4), work_photo_src(64, 48, 4);
  for (int y = 0; y < 48; ++y)
    for (int x = 0; x < 64; ++x) {
      for (int c = 0; c < 3; ++c) photo.at(x, y, c) = 0.1f * (c + 1) + 0.01f * x;
      photo.at(x, y, 3) = 0.5f;
    }
  const Image work_photo = working_copy(photo, 32, 24);
  FogLayers working;
  working.transmittance = Image(32, 24, 3);
  working.inscatter = Image(32, 24, 3);
  for (float& v : working.transmittance.pixels()) v = 0.25f;
  for (float& v : working.inscatter.pixels()) v = 0.5f;
  working.airlight = {0.7f, 0.7f, 0.7f};
  const FogLayers up = upsample_fog_layers(photo, work_photo, working, false);
  EXPECT_TRUE(up.transmittance.empty());
  EXPECT_TRUE(up.inscatter.empty());
  EXPECT_EQ(up.airlight[0], 0.7f);
  ASSERT_EQ(up.composite.channels(), 4);
  EXPECT_FLOAT_EQ(up.composite.at(10, 10, 3), 0.5f);
  EXPECT_FLOAT_EQ(up.composite.at(10, 10, 1), photo.at(10, 10, 1) * 0.25f + 0.5f);
}

TEST(FogUpsample, NamesWhatDoesNotFit) {
  const Image photo(100, 80, 3), work_photo(50, 40, 3);
  FogLayers working;
  working.transmittance = Image(50, 40, 3);
  working.inscatter = Image(49, 40, 3);
  try {
    upsample_fog_layers(photo, work_photo, working);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::size_mismatch);
    EXPECT_NE(std::string(e.what()).find("49x40"), std::string::npos) << e.what();
  }
  working.inscatter = Image(50, 40, 3);
  const Image bigger(200, 160, 3);
  FogLayers big;
  big.transmittance = Image(200, 160, 3);
  big.inscatter = Image(200, 160, 3);
  EXPECT_THROW(upsample_fog_layers(photo, bigger, big), Error);  // larger than the photo
  EXPECT_THROW(working_copy(Image(), 10, 10), Error);
  EXPECT_THROW(resize_nearest(photo, 10, -1), Error);
}

// `mr fog --depth auto` on a photo larger than the working size: the photo's size comes out,
// and shrunk to the working size it is the fog made from the working-size copy itself (the
// same estimate; only the upsampling and the shrinking between them).
TEST(WorkingSizeCli, ALargePhotosFogIsItsWorkingCopysFogAtFullSize) {
  test::ScratchDir dir;
  const Image kite = read_image(fs::path(MR_SOURCE_DIR) / "gallery/tune/kite.jpg");  // 1280x800
  // Twice the size (bilinear), then the working copy the CLI will make of it.
  const int w = 2 * kite.width(), h = 2 * kite.height();
  Image big(w, h, 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const double fx = std::clamp((x + 0.5) / 2 - 0.5, 0.0, kite.width() - 1.0);
      const double fy = std::clamp((y + 0.5) / 2 - 0.5, 0.0, kite.height() - 1.0);
      const int x0 = int(fx), y0 = int(fy), x1 = std::min(x0 + 1, kite.width() - 1),
                y1 = std::min(y0 + 1, kite.height() - 1);
      const double ax = fx - x0, ay = fy - y0;
      for (int c = 0; c < 3; ++c)
        big.at(x, y, c) =
            float((1 - ay) * ((1 - ax) * kite.at(x0, y0, c) + ax * kite.at(x1, y0, c)) +
                  ay * ((1 - ax) * kite.at(x0, y1, c) + ax * kite.at(x1, y1, c)));
    }
  const auto ws = working_size(w, h, kDefaultWorkingLongSidePx);
  ASSERT_TRUE(ws.has_value());
  WriteOptions exact;
  exact.pixel_type = PixelType::float32;
  write_image(dir / "big.exr", big, exact);
  write_image(dir / "work.exr", working_copy(big, ws->width, ws->height), exact);
  const std::string look = (fs::path(MR_SOURCE_DIR) / "gallery/looks/haze.json").string();
  rusage usage{};
  for (const char* name : {"big.exr", "work.exr"})
    ASSERT_EQ(test::run_measured(MR_CLI_PATH,
                                 {"fog", (dir / name).string(), "--depth", "auto", "--scene", look,
                                  "--out-dir", (dir / "out").string(), "-q"},
                                 &usage),
              0);
  const Image big_fog = read_image(dir / "out" / "big_fog.exr");
  const Image work_fog = read_image(dir / "out" / "work_fog.exr");
  ASSERT_EQ(big_fog.width(), w);
  ASSERT_EQ(big_fog.height(), h);
  ASSERT_EQ(work_fog.width(), ws->width);
  const Image shrunk = working_copy(big_fog, ws->width, ws->height);
  const Image work_photo = working_copy(big, ws->width, ws->height);
  double sum = 0, fogged = 0;
  std::vector<float> diffs;
  for (int y = 0; y < ws->height; ++y)
    for (int x = 0; x < ws->width; ++x)
      for (int c = 0; c < 3; ++c) {
        const float d = std::abs(shrunk.at(x, y, c) - work_fog.at(x, y, c));
        diffs.push_back(d);
        sum += d;
        fogged += std::abs(work_fog.at(x, y, c) - work_photo.at(x, y, c)) > 0.02;
      }
  std::sort(diffs.begin(), diffs.end());
  const double mean = sum / diffs.size(), p99 = diffs[diffs.size() * 99 / 100];
  std::printf("full-size fog shrunk vs the working copy's: mean %.5f, 99th pct %.4f\n", mean, p99);
  EXPECT_LT(mean, 0.003);
  EXPECT_LT(p99, 0.03);
  EXPECT_GT(fogged / diffs.size(), 0.5);  // and it is fogged: most values moved
}

// Peak memory of an automatic fog of a 12 MP photo, from the OS (wait4's rusage). At the photo's
// own size it was 2.7 GiB (gallery/tune airport_snow at 4000 x 3000, haze; ~225 bytes a pixel);
// at the working size what is left is the full-size photo, its composite, decoding and encoding.
TEST(WorkingSizeCli, TwelveMegapixelAutomaticFogStaysUnderAGibibyte) {
  test::ScratchDir dir;
  const int w = 4000, h = 3000;
  write_image(dir / "big.jpg", test::make_test_photo(w, h));
  rusage usage{};
  ASSERT_EQ(test::run_measured(MR_CLI_PATH,
                               {"fog", (dir / "big.jpg").string(), "--depth", "auto", "--scene",
                                (fs::path(MR_SOURCE_DIR) / "gallery/looks/haze.json").string(),
                                "--out-dir", (dir / "out").string(), "-q"},
                               &usage),
            0);
  const double peak_mib = double(usage.ru_maxrss) / 1024.0;  // KiB on Linux
  std::printf("12 MP automatic fog: peak RSS %.0f MiB\n", peak_mib);
#if !defined(__SANITIZE_ADDRESS__)
  EXPECT_LT(peak_mib, 1024.0);
#else
  (void)peak_mib;  // AddressSanitizer's shadow memory and quarantine (see FogStream's test)
#endif
  const Image photo = read_image(dir / "big.jpg"), fogged = read_image(dir / "out" / "big_fog.jpg");
  ASSERT_EQ(fogged.width(), w);
  ASSERT_EQ(fogged.height(), h);
  double moved = 0;
  for (int y = 0; y < h; y += 7)
    for (int x = 0; x < w; x += 7) moved += std::abs(fogged.at(x, y, 2) - photo.at(x, y, 2));
  EXPECT_GT(moved / ((h / 7 + 1) * (w / 7 + 1)), 0.02);  // fogged, not copied
}

}  // namespace
}  // namespace mr
