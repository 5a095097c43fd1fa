// The library example from README.md, compiled and run, so the README stays true.
#include <gtest/gtest.h>

#include <filesystem>

#include "test_support.h"

// --- README example begins ---
#include <mr/mr.h>

void fog_one_photo(const std::string& photo_path, const std::string& depth_path,
                   const std::string& out_path) {
  mr::Image photo = mr::read_image(photo_path);  // scene-linear float, EXIF kept
  mr::Camera camera = mr::Camera::from_metadata(photo.width(), photo.height(), photo.metadata());
  mr::DepthMap depth = mr::read_depth(depth_path, camera);  // metres along each ray

  mr::FogParams fog;
  const float sigma = float(mr::extinction_from_visibility(150.0));  // 150 m visibility
  fog.sigma_t_per_m = {sigma, sigma, sigma};                         // airlight: estimated
  mr::FogLayers layers = mr::fog(photo, depth.distance_m, fog);

  mr::write_image(out_path, layers.composite);  // sRGB JPEG, written atomically
  const mr::ExrLayer aovs[] = {{"transmittance", &layers.transmittance},
                               {"inscatter", &layers.inscatter},
                               {"depth", &depth.distance_m, /*is_data=*/true}};
  mr::write_exr_layers(out_path + ".aovs.exr", aovs, photo.metadata());
}
// --- README example ends ---

TEST(ReadmeExample, FogsASamplePhoto) {
  mr::test::ScratchDir dir;
  const std::filesystem::path samples = std::filesystem::path(MR_SOURCE_DIR) / "sample_photos";
  const std::string out = (dir / "leuven_fog.jpg").string();
  fog_one_photo((samples / "leuven.jpg").string(), (samples / "leuven_depth.exr").string(), out);
  const mr::Image fogged = mr::read_image(out);
  const mr::Image original = mr::read_image(samples / "leuven.jpg");
  EXPECT_EQ(fogged.width(), original.width());
  // The fog brightens and flattens: the mean moves toward the airlight, contrast drops.
  double mean_o = 0, mean_f = 0;
  for (std::size_t i = 0; i < original.pixels().size(); ++i) {
    mean_o += original.pixels()[i];
    mean_f += fogged.pixels()[i];
  }
  EXPECT_GT(mean_f, mean_o);
  EXPECT_TRUE(std::filesystem::exists(out + ".aovs.exr"));
}
