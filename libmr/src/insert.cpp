// mr::insert_objects (mr/insert.h): the light resolved as the scattering core resolves it, the
// photo's geometry (normals, occluder mesh with the scene's blockers, Embree), the objects in
// world space, the differential render (render/insertion/differential.h), then optionally the
// fog over the composite with the objects' depth and shadows.
#include "mr/insert.h"

#include <chrono>
#include <cmath>
#include <optional>
#include <string>

#include "mr/error.h"
#include "mr/scattering.h"
#include "photo/airlight.h"
#include "photo/illumination.h"
#include "photo/lamps.h"
#include "render/blockers.h"
#include "render/depth_downsample.h"
#include "render/embree_scene.h"
#include "render/insertion/differential.h"
#include "render/insertion/object_scene.h"
#include "render/occluder_mesh.h"

namespace mr {

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

}  // namespace

InsertOptions InsertOptions::preview() {
  InsertOptions o;
  o.samples_per_axis = 1;
  o.sun_rays = 4;
  o.sky_rays = 8;
  o.mesh_step = 2;
  o.sky_influence_radii = 4;
  return o;
}

std::vector<Blockers::Polygon> object_shadow_polygons(std::span<const InsertObject> objects) {
  render::insertion::WorldObjects world;
  for (const InsertObject& o : objects) render::insertion::append_object(world, o.mesh, o.placement, o.material);
  std::vector<Blockers::Polygon> polygons;
  polygons.reserve(world.triangle_count());
  for (std::size_t t = 0; t < world.triangle_count(); ++t) {
    Blockers::Polygon p;
    for (int k = 0; k < 3; ++k) {
      const float* q = &world.positions[3 * std::size_t(world.indices[3 * t + std::size_t(k)])];
      p.corners_m.push_back({q[0], q[1], q[2]});
    }
    polygons.push_back(std::move(p));
  }
  return polygons;
}

InsertResult insert_objects(const Image& photo, const Image& distance_m, const Camera& camera,
                            const FogScene& scene_given, std::span<const InsertObject> objects,
                            const InsertOptions& options, const CancelToken* cancel) {
  const auto start = Clock::now();
  throw_if_cancelled(cancel, "insert objects");
  validate_scene(scene_given);
  if (photo.empty() || photo.channels() < 3)
    throw Error(ErrorCode::invalid_argument, "insert objects: the photo must have at least 3 channels");
  if (distance_m.empty() || distance_m.channels() != 1)
    throw Error(ErrorCode::invalid_argument, "insert objects: the depth map must have 1 channel");
  if (photo.width() != camera.width || photo.height() != camera.height ||
      distance_m.width() != camera.width || distance_m.height() != camera.height)
    throw Error(ErrorCode::size_mismatch,
                "insert objects: photo " + std::to_string(photo.width()) + "x" + std::to_string(photo.height()) +
                    ", depth map " + std::to_string(distance_m.width()) + "x" +
                    std::to_string(distance_m.height()) + " and camera " + std::to_string(camera.width) +
                    "x" + std::to_string(camera.height) + " must agree");
  for (float d : distance_m.pixels())
    if (std::isnan(d) || d <= 0)
      throw Error(ErrorCode::invalid_argument,
                  "insert objects: the distance map holds NaN, zero or negative values (+inf = sky)");
  if (options.mesh_step < 1 || options.mesh_step > 16)
    throw Error(ErrorCode::invalid_argument,
                "insert objects: mesh_step must be in 1..16, got " + std::to_string(options.mesh_step));

  // The light in the photo's units, resolved as render_scattering resolves it.
  FogScene scene = scene_given;
  Lighting& lighting = scene.lighting;
  if (!lighting.sky_radiance) lighting.sky_radiance = photo::estimate_airlight_dark_channel(photo.view());
  if (lighting.sun && lighting.sun->irradiance_auto) {
    lighting.sun->irradiance =
        photo::exposure_relative_sun(photo.view(), distance_m.view(), *lighting.sky_radiance).irradiance;
    lighting.sun->irradiance_auto = false;
  }
  for (Lamp& lamp : lighting.lamps)
    if (lamp.intensity_auto) {
      lamp.intensity_per_sr =
          photo::exposure_relative_lamp(photo, distance_m, camera, scene.pose, lamp.position_m,
                                        lamp.intensity_per_sr, scene.medium)
              .intensity_per_sr;
      lamp.intensity_auto = false;
    }

  InsertResult result;
  result.lighting = lighting;

  // The objects in world space.
  render::insertion::WorldObjects world;
  for (const InsertObject& o : objects) render::insertion::append_object(world, o.mesh, o.placement, o.material);
  result.timings.triangles = world.triangle_count();

  // The photo's geometry.
  const auto mesh_start = Clock::now();
  const Image normals = render::estimate_normals(distance_m.view(), camera, scene.pose);
  std::optional<render::OccluderScene> photo_scene;
  if (scene.render.volumetric_shadows) {
    int step = options.mesh_step;
    if (camera.width / step < 16 || camera.height / step < 16) step = 1;
    render::TriangleMesh mesh;
    if (step > 1) {
      const render::DownsampledDistance coarse =
          render::downsample_distance_nearest(distance_m.view(), camera, step);
      mesh = render::reconstruct_occluder_mesh(coarse.distance_m.view(), coarse.camera, scene.pose);
    } else {
      mesh = render::reconstruct_occluder_mesh(distance_m.view(), camera, scene.pose, {}, normals.view());
    }
    render::append_blockers(mesh, distance_m.view(), normals.view(), camera, scene.pose, scene.blockers);
    if (mesh.triangle_count() > 0) photo_scene.emplace(std::move(mesh));
  }
  throw_if_cancelled(cancel, "insert objects");
  const render::insertion::ObjectScene object_scene(world);
  const render::insertion::EmbreeVisibility visibility(photo_scene ? &*photo_scene : nullptr, object_scene);
  result.timings.mesh_s = seconds_since(mesh_start);

  const auto render_start = Clock::now();
  render::insertion::InsertionInputs in;
  in.camera = camera;
  in.pose = scene.pose;
  in.lighting = lighting;
  in.photo = photo.view();
  in.distance_m = distance_m.view();
  in.normals = normals.view();
  in.objects = &object_scene;
  in.visibility = &visibility;
  in.cancel = cancel;
  render::insertion::InsertionSettings settings;
  settings.samples_per_axis = options.samples_per_axis;
  settings.sun_rays = options.sun_rays;
  settings.sky_rays = options.sky_rays;
  settings.depth_tolerance = options.depth_tolerance;
  if (!(options.sky_influence_radii >= 1))
    throw Error(ErrorCode::invalid_argument, "insert objects: sky_influence_radii must be >= 1");
  settings.sky_influence_radii = options.sky_influence_radii;
  settings.threads = options.threads;
  render::insertion::InsertionLayers layers = render::insertion::render_insertion(in, settings);
  result.timings.render_s = seconds_since(render_start);
  result.timings.shadow_rays = layers.shadow_rays;
  result.timings.camera_rays = layers.camera_rays;
  layers.composite.metadata() = photo.metadata();
  result.clear_composite = std::move(layers.composite);
  result.matte = std::move(layers.matte);
  result.shadow = std::move(layers.shadow);
  result.difference = std::move(layers.difference);
  result.distance_m = std::move(layers.distance_m);

  if (options.fog) {
    // The objects join the fog like the photo's surfaces: their distance replaces the photo's
    // where they are in front (result.distance_m), and their triangles join the shadow casters
    // as blocker polygons, so they cast shafts (the scattering core itself is unchanged).
    const auto fog_start = Clock::now();
    FogScene fog_scene = scene;
    for (std::size_t t = 0; t < world.triangle_count(); ++t) {
      Blockers::Polygon p;
      for (int k = 0; k < 3; ++k) {
        const float* q = &world.positions[3 * std::size_t(world.indices[3 * t + std::size_t(k)])];
        p.corners_m.push_back({q[0], q[1], q[2]});
      }
      fog_scene.blockers.polygons.push_back(std::move(p));
    }
    FogLayers fogged = fog(result.clear_composite, result.distance_m, camera, fog_scene, nullptr, cancel);
    result.composite = std::move(fogged.composite);
    result.transmittance = std::move(fogged.transmittance);
    result.inscatter = std::move(fogged.inscatter);
    result.timings.fog_s = seconds_since(fog_start);
  } else {
    result.composite = result.clear_composite;
  }
  result.timings.total_s = seconds_since(start);
  return result;
}

}  // namespace mr
