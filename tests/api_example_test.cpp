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

// --- README scattering example begins ---
void sun_fog(const std::string& photo_path, const std::string& depth_path,
             const std::string& out_path) {
  mr::Image photo = mr::read_image(photo_path);
  mr::Camera camera = mr::Camera::from_horizontal_fov(photo.width(), photo.height(), 60.0);
  mr::DepthMap depth = mr::read_depth(depth_path, camera);

  mr::FogScene scene;  // or mr::load_scene("scene.json"), docs/scene.md
  scene.pose.position_m = {0, 1.6, 0};  // camera 1.6 m above the ground (+Y up)
  scene.pose.pitch_deg = 7.05;
  const float sigma = float(mr::extinction_from_visibility(80.0));
  scene.medium.sigma_t_per_m = {sigma, sigma, sigma};
  scene.medium.g = 0.7;  // forward scattering: bright toward the sun
  scene.lighting.sun = mr::Sun{mr::direction_from_azimuth_elevation(25, 12), {8, 8, 8}, 0.27};
  scene.lighting.sky_radiance = mr::Rgb{0.16f, 0.17f, 0.2f};

  mr::ScatteringLayers layers;  // optional: AOVs and timings
  mr::FogLayers fogged = mr::fog(photo, depth.distance_m, camera, scene, &layers);
  mr::write_image(out_path, fogged.composite);
}
// --- README scattering example ends ---

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

TEST(ReadmeExample, SunFogOnASamplePhoto) {
  mr::test::ScratchDir dir;
  const std::filesystem::path samples = std::filesystem::path(MR_SOURCE_DIR) / "sample_photos";
  const std::string out = (dir / "leuven_sun.exr").string();
  sun_fog((samples / "leuven.jpg").string(), (samples / "leuven_depth.exr").string(), out);
  const mr::Image fogged = mr::read_image(out);
  const mr::Image original = mr::read_image(samples / "leuven.jpg");
  ASSERT_EQ(fogged.width(), original.width());
  // Not black, not the photo: the fog changed every part of the image by a visible amount.
  double diff = 0, mean = 0;
  for (std::size_t i = 0; i < original.pixels().size(); ++i) {
    diff += std::abs(fogged.pixels()[i] - original.pixels()[i]);
    mean += fogged.pixels()[i];
  }
  const double n = double(original.pixels().size());
  EXPECT_GT(mean / n, 0.05);
  EXPECT_GT(diff / n, 0.02);
}
