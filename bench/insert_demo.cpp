// Issue 16, a look at the results: objects inserted into the sample street photo
// (sample_photos/leuven.jpg with its approximate depth, pose from its annotated horizon):
// a sphere and a box on the cobbles, under a sun (soft shadows on the street), in fog with the
// same sun (shafts), and overcast (sky only). Writes PNGs (display sRGB) into the folder given,
// for a contact sheet:
//   build/bench/mr_insert_demo /tmp/objb/demo && oiiotool /tmp/objb/demo/*.png --mosaic 2x3 -o sheet.png
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "../tests/insert_test_meshes.h"
#include "mr/depth.h"
#include "mr/estimate.h"
#include "mr/insert.h"
#include "mr/io.h"

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: mr_insert_demo OUT_DIR [SOURCE_DIR]\n");
    return 2;
  }
  const std::filesystem::path out = argv[1];
  const std::filesystem::path src = argc > 2 ? argv[2] : MR_SOURCE_DIR;
  std::filesystem::create_directories(out);
  const mr::Image photo = mr::read_image(src / "sample_photos/leuven.jpg");
  const mr::Camera camera = mr::Camera::from_horizontal_fov(photo.width(), photo.height(), 60);
  const mr::Image distance = mr::read_depth(src / "sample_photos/leuven_depth.exr", camera, {}).distance_m;
  mr::FogScene scene;
  scene.pose = mr::pose_from_horizon(camera, {mr::PixelPoint{0, 361.5}, mr::PixelPoint{750, 361.5}}, 1.6);

  // Objects standing on the street: a sphere (r 0.5 m) and a box, placed on the ground where
  // the pixel's ray meets it.
  auto on_ground = [&](double x, double y) {
    const mr::Vec3 d = scene.pose.ray_direction(camera, x - 0.5, y - 0.5);
    const double t = -scene.pose.position_m.y / d.y;
    return mr::Vec3{scene.pose.position_m.x + t * d.x, 0.0, scene.pose.position_m.z + t * d.z};
  };
  std::vector<mr::InsertObject> objects(2);
  objects[0].mesh = mr::test::uv_sphere(0.5, 64, 128, {0.75f, 0.2f, 0.15f}, 0.35f);
  objects[0].placement.position_m = on_ground(300, 470);
  objects[0].placement.position_m.y = 0.5;
  objects[1].mesh = mr::test::box_mesh({-0.4f, 0, -0.4f}, {0.4f, 0.9f, 0.4f}, {0.8f, 0.78f, 0.7f}, 0.8f);
  objects[1].placement.position_m = on_ground(470, 440);
  objects[1].placement.yaw_deg = 30;

  struct Look {
    std::string name;
    bool sun, fog;
  };
  for (const Look& look : {Look{"1_sun", true, false}, Look{"2_sun_fog", true, true}, Look{"3_overcast", false, false},
                           Look{"4_overcast_fog", false, true}}) {
    mr::FogScene s = scene;
    if (look.sun) {
      s.lighting.sun = mr::Sun{mr::direction_from_azimuth_elevation(110, 35), {3, 3, 3}, 0.27};
      s.lighting.sun->irradiance_auto = true;
    }
    mr::InsertOptions options;
    options.fog = look.fog;
    if (look.fog) {
      const float sigma = float(3.912 / 60.0);
      s.medium.sigma_t_per_m = {sigma, sigma, sigma};
      s.medium.layer_top_m = 30;
    }
    const mr::InsertResult r = mr::insert_objects(photo, distance, camera, s, objects, options);
    std::printf("%s: %zu triangles, mesh %.2f s, render %.2f s, fog %.2f s; sun E %.2f, sky %.3f\n",
                look.name.c_str(), r.timings.triangles, r.timings.mesh_s, r.timings.render_s, r.timings.fog_s,
                r.lighting.sun ? r.lighting.sun->irradiance[1] : 0.0f, (*r.lighting.sky_radiance)[1]);
    mr::write_image(out / (look.name + ".png"), r.composite);
    if (!look.fog) {
      mr::Image shadow = r.shadow;
      mr::write_image(out / (look.name + "_shadow.png"), shadow);
    }
  }
  mr::write_image(out / "0_photo.png", photo);
  return 0;
}
