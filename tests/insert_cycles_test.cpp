// Issue 16's acceptance against a path tracer: Blender's Cycles renders the acceptance scene
// (tests/insert_scene.h) without and with the inserted sphere and box
// (tests/data/cycles/make_insert_reference.py, 2048 samples per pixel, direct light only as the
// product models it; the EXRs are in the repo). The product inserts the objects into Cycles'
// "photo" with the scene's exact depth and light and is compared with Cycles' render of the
// objects. Cycles shares no code with the product or with the Monte Carlo reference, so it also
// checks the reference: its "photo" must match Cycles'.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>

#include "insert_scene.h"
#include "mc_comparison_scene.h"
#include "mr/io.h"

namespace mr {
namespace {

const std::filesystem::path kCycles = std::filesystem::path(MR_SOURCE_DIR) / "tests/data/cycles";

double mean_relative_difference(const Image& a, const Image& want) {
  double sum = 0;
  std::size_t n = 0;
  for (int y = 0; y < want.height(); ++y)
    for (int x = 0; x < want.width(); ++x)
      for (int c = 0; c < 3; ++c) {
        const double ref = want.at(x, y, c);
        if (!(ref > 1e-4)) continue;
        sum += std::fabs(a.at(x, y, c) - ref) / ref;
        ++n;
      }
  return sum / double(n);
}

// Cycles and the brute-force Monte Carlo reference (tests/mc_insert_reference.*) render the same
// scene: they agree within both renderers' noise (Cycles at 2048 samples, the reference at
// 4 x 4 pixel samples with 256 sky and 16 sun rays each: a few tenths of a percent each), so the
// Cycles scene is the reference's scene (camera, light, geometry, albedos).
TEST(InsertCycles, CyclesPhotoMatchesTheMonteCarloReference) {
  const test::InsertScene s = test::make_insert_scene();
  const Image cycles = read_image(kCycles / "photo.exr");
  ASSERT_EQ(cycles.width(), s.camera.width);
  ASSERT_EQ(cycles.height(), s.camera.height);
  mcref::RadianceSettings st;
  st.pixel_samples_per_axis = test::kMcSlowBuild ? 2 : 4;
  st.sky_samples = test::kMcSlowBuild ? 64 : 256;
  st.seed = 11;
  const Image mc = mcref::surface_radiance(s.camera, s.scene.pose, s.scene.lighting,
                                           s.photo_geometry, s.photo_materials, st);
  const double err = mean_relative_difference(mc, cycles);
  std::printf("Cycles photo vs Monte Carlo reference: mean relative difference %.4f\n", err);
  EXPECT_LT(err, 0.02);
}

// The product's composite against Cycles' render with the objects: the bars (mean
// relative error of the composite below 2 %, of the object-shadow region below 5 %).
TEST(InsertCycles, CompositeMatchesCycles) {
  const test::InsertScene s = test::make_insert_scene();
  const Image photo = read_image(kCycles / "photo.exr");
  const Image want = read_image(kCycles / "with_objects.exr");
  const Image distance = mcref::distance_map(s.camera, s.scene.pose, s.photo_geometry);
  const Image full_distance = mcref::distance_map(s.camera, s.scene.pose, s.full_geometry);
  const InsertResult got =
      insert_objects(photo, distance, s.camera, s.scene, s.objects, InsertOptions{});
  if (const char* dir = std::getenv("MR_INSERT_TEST_IMAGES"))
    write_image(std::filesystem::path(dir) / "cycles_product_composite.exr", got.composite);
  const test::CompositeError e =
      test::composite_error(photo, want, got.composite, distance, full_distance);
  std::printf(
      "vs Cycles: composite mean rel error %.4f (n %zu); object pixels %.4f (n %zu); "
      "object-shadow region %.4f (n %zu)\n",
      e.mean, e.n, e.objects, e.n_objects, e.shadow, e.n_shadow);
  ASSERT_GT(e.n_shadow, 300u);  // the shadows are there to compare
  ASSERT_GT(e.n_objects, 600u);
  EXPECT_LT(e.mean, 0.02);
  EXPECT_LT(e.shadow, 0.05);
  // Not the photo passed through: the objects changed it (Cycles' objects differ from the photo
  // by far more than the bar on their pixels).
  EXPECT_GT(mean_relative_difference(photo, want), 0.02);
}

}  // namespace
}  // namespace mr
