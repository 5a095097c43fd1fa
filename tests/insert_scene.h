// Issue 16's acceptance scene, shared by the Monte Carlo and the Cycles comparisons
// (tests/insert_test.cpp, tests/insert_cycles_test.cpp; tests/data/cycles/make_insert_reference.py
// builds the same scene in Blender): ground, a side wall, a back wall and a foreground pillar
// (the "photo"), a sphere and a box inserted; a sun from behind the camera's right (shadows fall
// away to the left) and a blue sky. And the composite's error measure both comparisons use.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <vector>

#include "insert_test_meshes.h"
#include "mc_insert_reference.h"
#include "mc_reference.h"
#include "mr/insert.h"

namespace mr::test {

struct InsertScene {
  Camera camera = Camera::from_horizontal_fov(128, 96, 60);
  FogScene scene;
  mcref::Geometry photo_geometry, full_geometry;
  mcref::MaterialTable photo_materials, full_materials;
  std::vector<InsertObject> objects;
};

inline InsertScene make_insert_scene() {
  using mcref::Box;
  InsertScene s;
  s.scene.pose.position_m = {0, 1.6, 0};
  s.scene.pose.pitch_deg = -9;
  s.scene.lighting.sun = Sun{direction_from_azimuth_elevation(125, 38), {3.0f, 2.9f, 2.7f}, 0.27};
  s.scene.lighting.sky_radiance = Rgb{0.30f, 0.36f, 0.48f};
  // The side wall is cut by the frame's top; completion would continue it to 30 m (a guess for
  // real photos), which the reference's 3.5 m wall does not have.
  s.scene.blockers.completion.enabled = false;
  s.photo_geometry.ground = true;
  s.photo_geometry.boxes = {Box{{3.5, 0, 5}, {4.5, 3.5, 20}},      // side wall (right)
                            Box{{-10, 0, 20}, {10, 6, 21}},        // back wall
                            Box{{-2.4, 0, 5}, {-1.9, 2.2, 5.5}}};  // pillar (left foreground)
  mcref::SurfaceMaterial ground, wall, pillar;
  ground.diffuse_albedo = {0.40, 0.38, 0.35};
  wall.diffuse_albedo = {0.60, 0.55, 0.50};
  pillar.diffuse_albedo = {0.30, 0.30, 0.32};
  s.photo_materials.ground = ground;
  s.photo_materials.boxes = {wall, wall, pillar};

  const Rgb sphere_color{0.80f, 0.25f, 0.20f}, box_color{0.20f, 0.45f, 0.75f};
  const double r = 0.7;
  const Vec3 sphere_centre{-0.6, r, 9};
  const Box box{{0.9, 0, 10}, {2.1, 1.2, 11.2}};
  s.full_geometry = s.photo_geometry;
  s.full_geometry.spheres.push_back(mcref::Sphere{sphere_centre, r});
  s.full_geometry.boxes.push_back(box);
  s.full_materials = s.photo_materials;
  mcref::SurfaceMaterial sm, bm;
  sm.diffuse_albedo = {sphere_color[0], sphere_color[1], sphere_color[2]};
  sm.specular = true;
  sm.roughness = 0.5;
  bm.diffuse_albedo = {box_color[0], box_color[1], box_color[2]};
  bm.specular = true;
  bm.roughness = 0.7;
  s.full_materials.spheres.push_back(sm);
  s.full_materials.boxes.push_back(bm);

  InsertObject sphere;
  sphere.mesh = uv_sphere(r, 96, 192, sphere_color, 0.5f);
  sphere.placement.position_m = sphere_centre;
  s.objects.push_back(sphere);
  InsertObject cube;
  cube.mesh = box_mesh({-0.6f, 0, -0.6f}, {0.6f, 1.2f, 0.6f}, box_color, 0.7f);
  cube.placement.position_m = {1.5, 0, 10.6};
  s.objects.push_back(cube);
  return s;
}

/// Mean relative error of a composite against a reference with the objects, per channel over
/// pixels whose reference is > 1e-4: everywhere, on the object pixels (by the reference's own
/// geometry: full_distance nearer than the photo's), and in the object-shadow region (the
/// reference darker than the photo by > 3 % in some channel, away from the objects' pixels and
/// their 8 neighbours).
struct CompositeError {
  double mean = 0, objects = 0, shadow = 0;
  std::size_t n = 0, n_objects = 0, n_shadow = 0;
};

inline CompositeError composite_error(const Image& photo, const Image& want, const Image& got,
                                      const Image& distance, const Image& full_distance) {
  const int w = want.width(), h = want.height();
  auto object_pixel = [&](int x, int y) {
    return full_distance.at(x, y, 0) < distance.at(x, y, 0) * (1 - 1e-6f);
  };
  CompositeError e;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      bool near_object = false;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int xx = std::clamp(x + dx, 0, w - 1), yy = std::clamp(y + dy, 0, h - 1);
          near_object = near_object || object_pixel(xx, yy);
        }
      bool shadowed = false;
      for (int c = 0; c < 3; ++c)
        shadowed = shadowed || want.at(x, y, c) < 0.97f * photo.at(x, y, c);
      for (int c = 0; c < 3; ++c) {
        const double ref = want.at(x, y, c);
        if (!(ref > 1e-4)) continue;
        const double rel = std::fabs(got.at(x, y, c) - ref) / ref;
        e.mean += rel, ++e.n;
        if (object_pixel(x, y)) e.objects += rel, ++e.n_objects;
        if (shadowed && !near_object) e.shadow += rel, ++e.n_shadow;
      }
    }
  e.mean /= double(std::max<std::size_t>(e.n, 1));
  e.objects /= double(std::max<std::size_t>(e.n_objects, 1));
  e.shadow /= double(std::max<std::size_t>(e.n_shadow, 1));
  return e;
}

}  // namespace mr::test
