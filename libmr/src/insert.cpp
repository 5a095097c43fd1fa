// mr::insert_objects (mr/insert.h): the light resolved as the scattering core resolves it, the
// photo's geometry (normals, occluder mesh with the scene's blockers, Embree), the objects in
// world space, the differential render (render/insertion/differential.h), then optionally the
// fog over the composite with the objects' depth and shadows.
#include "mr/insert.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

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
  // One sun ray: the real sun's penumbra (0.27 degrees: 1 cm per 1 m of distance to the caster)
  // is below a preview pixel; the idle refinement samples the disk.
  o.sun_rays = 1;
  o.sky_rays = 8;
  o.mesh_step = 2;
  o.sky_influence_radii = 4;
  o.fixed_pattern = true;
  o.sky_influence_tight = true;
  return o;
}

InsertOptions InsertOptions::preview_refined() {
  InsertOptions o = preview();
  o.samples_per_axis = 2;
  o.sun_rays = 8;
  o.sky_rays = 32;
  return o;
}

std::vector<Blockers::Polygon> object_shadow_polygons(std::span<const InsertObject> objects) {
  render::insertion::WorldObjects world;
  for (const InsertObject& o : objects)
    render::insertion::append_object(world, o.mesh, o.placement, o.material);
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

namespace {

// What does not depend on the objects: the light resolved as render_scattering resolves it, the
// photo's normals and its occluder mesh (with the scene's blockers) in Embree.
struct PreparedPhoto {
  FogScene scene;
  Image normals;
  std::optional<render::OccluderScene> photo_scene;
};

void check_inputs(const Image& photo, const Image& distance_m, const Camera& camera,
                  const FogScene& scene_given, const InsertOptions& options) {
  validate_scene(scene_given);
  if (photo.empty() || photo.channels() < 3)
    throw Error(ErrorCode::invalid_argument,
                "insert objects: the photo must have at least 3 channels");
  if (distance_m.empty() || distance_m.channels() != 1)
    throw Error(ErrorCode::invalid_argument, "insert objects: the depth map must have 1 channel");
  if (photo.width() != camera.width || photo.height() != camera.height ||
      distance_m.width() != camera.width || distance_m.height() != camera.height)
    throw Error(ErrorCode::size_mismatch, "insert objects: photo " + std::to_string(photo.width()) +
                                              "x" + std::to_string(photo.height()) +
                                              ", depth map " + std::to_string(distance_m.width()) +
                                              "x" + std::to_string(distance_m.height()) +
                                              " and camera " + std::to_string(camera.width) + "x" +
                                              std::to_string(camera.height) + " must agree");
  for (float d : distance_m.pixels())
    if (std::isnan(d) || d <= 0)
      throw Error(
          ErrorCode::invalid_argument,
          "insert objects: the distance map holds NaN, zero or negative values (+inf = sky)");
  if (options.mesh_step < 1 || options.mesh_step > 16)
    throw Error(ErrorCode::invalid_argument, "insert objects: mesh_step must be in 1..16, got " +
                                                 std::to_string(options.mesh_step));
}

Lighting resolve_lighting(const Image& photo, const Image& distance_m, const Camera& camera,
                          const FogScene& scene) {
  Lighting lighting = scene.lighting;
  if (!lighting.sky_radiance)
    lighting.sky_radiance = photo::estimate_airlight_dark_channel(photo.view());
  if (lighting.sun && lighting.sun->irradiance_auto) {
    lighting.sun->irradiance =
        photo::exposure_relative_sun(photo.view(), distance_m.view(), *lighting.sky_radiance)
            .irradiance;
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
  return lighting;
}

void build_photo_geometry(PreparedPhoto& prep, const Image& distance_m, const Camera& camera,
                          const InsertOptions& options) {
  const FogScene& scene = prep.scene;
  prep.normals = render::estimate_normals(distance_m.view(), camera, scene.pose);
  if (scene.render.volumetric_shadows) {
    int step = options.mesh_step;
    if (camera.width / step < 16 || camera.height / step < 16) step = 1;
    render::TriangleMesh mesh;
    if (step > 1) {
      const render::DownsampledDistance coarse =
          render::downsample_distance_nearest(distance_m.view(), camera, step);
      mesh = render::reconstruct_occluder_mesh(coarse.distance_m.view(), coarse.camera, scene.pose);
    } else {
      mesh = render::reconstruct_occluder_mesh(distance_m.view(), camera, scene.pose, {},
                                               prep.normals.view());
    }
    render::append_blockers(mesh, distance_m.view(), prep.normals.view(), camera, scene.pose,
                            scene.blockers);
    if (mesh.triangle_count() > 0) prep.photo_scene.emplace(std::move(mesh));
  }
}

render::insertion::InsertionSettings settings_of(const InsertOptions& options) {
  render::insertion::InsertionSettings settings;
  settings.samples_per_axis = options.samples_per_axis;
  settings.sun_rays = options.sun_rays;
  settings.sky_rays = options.sky_rays;
  settings.depth_tolerance = options.depth_tolerance;
  if (!(options.sky_influence_radii >= 1))
    throw Error(ErrorCode::invalid_argument, "insert objects: sky_influence_radii must be >= 1");
  settings.sky_influence_radii = options.sky_influence_radii;
  settings.fixed_pattern = options.fixed_pattern;
  settings.sky_influence_tight = options.sky_influence_tight;
  settings.threads = options.threads;
  return settings;
}

}  // namespace

InsertResult insert_objects(const Image& photo, const Image& distance_m, const Camera& camera,
                            const FogScene& scene_given, std::span<const InsertObject> objects,
                            const InsertOptions& options, const CancelToken* cancel) {
  const auto start = Clock::now();
  throw_if_cancelled(cancel, "insert objects");
  check_inputs(photo, distance_m, camera, scene_given, options);

  // The light in the photo's units, resolved as render_scattering resolves it.
  PreparedPhoto prep;
  prep.scene = scene_given;
  FogScene& scene = prep.scene;
  scene.lighting = resolve_lighting(photo, distance_m, camera, scene_given);
  const Lighting& lighting = scene.lighting;

  InsertResult result;
  result.lighting = lighting;

  // The objects in world space.
  render::insertion::WorldObjects world;
  for (const InsertObject& o : objects)
    render::insertion::append_object(world, o.mesh, o.placement, o.material);
  result.timings.triangles = world.triangle_count();

  // The photo's geometry.
  const auto mesh_start = Clock::now();
  build_photo_geometry(prep, distance_m, camera, options);
  const Image& normals = prep.normals;
  std::optional<render::OccluderScene>& photo_scene = prep.photo_scene;
  throw_if_cancelled(cancel, "insert objects");
  const render::insertion::ObjectScene object_scene(world);
  const render::insertion::EmbreeVisibility visibility(photo_scene ? &*photo_scene : nullptr,
                                                       object_scene);
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
  const render::insertion::InsertionSettings settings = settings_of(options);
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
    FogLayers fogged =
        fog(result.clear_composite, result.distance_m, camera, fog_scene, nullptr, cancel);
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

// ---- The interactive preview -------------------------------------------------------------

namespace {

bool same_placements(std::span<const InsertObject> a, std::span<const InsertObject> b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    const ObjectPlacement &p = a[i].placement, &q = b[i].placement;
    if (p.position_m.x != q.position_m.x || p.position_m.y != q.position_m.y ||
        p.position_m.z != q.position_m.z || p.up.x != q.up.x || p.up.y != q.up.y ||
        p.up.z != q.up.z || p.yaw_deg != q.yaw_deg || p.scale != q.scale)
      return false;
  }
  return true;
}

// Whether two object lists hold the same meshes and materials (placements aside): then a move
// only refits the objects' BVH. Meshes are compared by content (cheap next to building a BVH of
// them); an object with a material override always counts as changed (mr::Material has no
// comparison).
bool same_meshes(std::span<const InsertObject> a, std::span<const InsertObject> b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    const InsertObject &x = a[i], &y = b[i];
    if (x.material || y.material) return false;
    const ObjectMesh &m = x.mesh, &n = y.mesh;
    if (m.source != n.source || m.positions != n.positions || m.triangles != n.triangles ||
        m.normals != n.normals || m.uvs != n.uvs || m.tangents != n.tangents ||
        m.triangle_material != n.triangle_material || m.materials.size() != n.materials.size() ||
        m.textures.size() != n.textures.size())
      return false;
    for (std::size_t k = 0; k < m.materials.size(); ++k) {
      const ObjectMaterial &u = m.materials[k], &v = n.materials[k];
      if (u.material || v.material || u.base_color != v.base_color || u.metallic != v.metallic ||
          u.roughness != v.roughness || u.base_color_texture != v.base_color_texture ||
          u.metallic_roughness_texture != v.metallic_roughness_texture ||
          u.normal_texture != v.normal_texture)
        return false;
    }
    for (std::size_t k = 0; k < m.textures.size(); ++k)
      if (m.textures[k].image.pixels().data() != n.textures[k].image.pixels().data() &&
          !(m.textures[k].image.width() == n.textures[k].image.width() &&
            m.textures[k].image.height() == n.textures[k].image.height() &&
            m.textures[k].image.channels() == n.textures[k].image.channels() &&
            std::equal(m.textures[k].image.pixels().begin(), m.textures[k].image.pixels().end(),
                       n.textures[k].image.pixels().begin())))
        return false;
  }
  return true;
}

}  // namespace

struct InsertPreview::Impl {
  Image photo, distance_m;
  Camera camera;
  InsertOptions prepare_options;
  PreparedPhoto prep;
  render::insertion::PhotoTiles tiles;
  double prepare_s = 0;
  // The objects of the last frame and their scene (reused while they do not change).
  std::vector<InsertObject> objects;
  std::unique_ptr<render::insertion::WorldObjects> world;
  std::unique_ptr<render::insertion::ObjectScene> object_scene;
  bool have_objects = false;
  // The layers, kept between frames: only tiles in `dirty` differ from the photo.
  InsertResult result;
  Image object_radiance;
  std::vector<std::uint8_t> dirty;
  FrameStats stats;

  render::insertion::InsertionInputs inputs(const render::insertion::VisibilityPath* visibility,
                                            const CancelToken* cancel) const {
    render::insertion::InsertionInputs in;
    in.camera = camera;
    in.pose = prep.scene.pose;
    in.lighting = prep.scene.lighting;
    in.photo = photo.view();
    in.distance_m = distance_m.view();
    in.normals = prep.normals.view();
    in.objects = object_scene.get();
    in.visibility = visibility;
    in.cancel = cancel;
    return in;
  }
};

InsertPreview::InsertPreview(const Image& photo, const Image& distance_m, const Camera& camera,
                             const FogScene& scene, const InsertOptions& options,
                             const CancelToken* cancel)
    : impl_(std::make_unique<Impl>()) {
  const auto start = Clock::now();
  throw_if_cancelled(cancel, "insert objects");
  check_inputs(photo, distance_m, camera, scene, options);
  Impl& m = *impl_;
  m.photo = photo;
  m.distance_m = distance_m;
  m.camera = camera;
  m.prepare_options = options;
  m.prep.scene = scene;
  m.prep.scene.lighting = resolve_lighting(photo, distance_m, camera, scene);
  build_photo_geometry(m.prep, m.distance_m, camera, options);
  throw_if_cancelled(cancel, "insert objects");
  // The tile bounds need only the camera, the depth and the normals.
  m.world = std::make_unique<render::insertion::WorldObjects>();
  m.object_scene = std::make_unique<render::insertion::ObjectScene>(*m.world);
  const render::insertion::EmbreeVisibility none(nullptr, *m.object_scene);
  m.tiles = render::insertion::photo_tiles(m.inputs(&none, cancel));
  // Every tile starts as the photo.
  m.result.lighting = m.prep.scene.lighting;
  m.result.composite = photo;
  m.result.matte = Image(camera.width, camera.height, 1, {"A"});
  m.result.shadow = Image(camera.width, camera.height, 3);
  for (float& v : m.result.shadow.pixels()) v = 1.0f;
  m.result.difference = Image(camera.width, camera.height, 3);
  m.result.distance_m = distance_m;
  m.object_radiance = Image(camera.width, camera.height, 3);
  m.dirty.assign(m.tiles.bounds.size(), 0);
  m.prepare_s = seconds_since(start);
}

InsertPreview::~InsertPreview() = default;
InsertPreview::InsertPreview(InsertPreview&&) noexcept = default;
InsertPreview& InsertPreview::operator=(InsertPreview&&) noexcept = default;

const InsertResult& InsertPreview::render(std::span<const InsertObject> objects,
                                          const InsertOptions& options, const CancelToken* cancel) {
  const auto start = Clock::now();
  throw_if_cancelled(cancel, "insert objects");
  if (options.fog)
    throw Error(ErrorCode::invalid_argument,
                "insert objects: the preview does not fog; fog its composite with mr::fog");
  Impl& m = *impl_;
  const render::insertion::InsertionSettings settings = settings_of(options);
  FrameStats stats;
  stats.tiles_total = m.tiles.bounds.size();

  // The objects' scene: built when the meshes changed; when only placements changed (a drag, a
  // turn, a scale), the vertices are moved in place and the BVH refitted. The placed vertices
  // are append_object's, as insert_objects' are, so the frame stays the same bit for bit.
  const auto objects_start = Clock::now();
  const bool meshes_kept = m.have_objects && same_meshes(objects, m.objects);
  if (!meshes_kept || !same_placements(objects, m.objects)) {
    std::vector<const ObjectMesh*> meshes;
    std::vector<ObjectPlacement> placements;
    for (const InsertObject& o : objects) {
      meshes.push_back(&o.mesh);
      placements.push_back(o.placement);
    }
    // A failed or throwing move leaves the world partly moved: rebuilt at the next frame.
    m.have_objects = false;
    if (meshes_kept && render::insertion::move_objects(*m.world, meshes, placements)) {
      m.have_objects = true;
      // The scene shares the world's buffers, rewritten in place: refit its BVH.
      m.object_scene->refit();
      for (std::size_t i = 0; i < objects.size(); ++i)
        m.objects[i].placement = objects[i].placement;
      stats.objects_refit = true;
    } else {
      // (A scale small enough to drop degenerate triangles changes the topology: rebuilt.)
      auto world = std::make_unique<render::insertion::WorldObjects>();
      for (const InsertObject& o : objects)
        render::insertion::append_object(*world, o.mesh, o.placement, o.material);
      auto scene = std::make_unique<render::insertion::ObjectScene>(*world, /*fast_build=*/true,
                                                                    /*refittable=*/true);
      m.object_scene = std::move(scene);
      m.world = std::move(world);
      m.objects.assign(objects.begin(), objects.end());
      m.have_objects = true;
      stats.objects_rebuilt = true;
    }
  }
  stats.objects_s = seconds_since(objects_start);
  m.result.timings.triangles = m.world->triangle_count();

  const auto render_start = Clock::now();
  const render::insertion::EmbreeVisibility visibility(
      m.prep.photo_scene ? &*m.prep.photo_scene : nullptr, *m.object_scene);
  const render::insertion::InsertionInputs in = m.inputs(&visibility, cancel);
  const std::vector<std::uint8_t> touched =
      render::insertion::influenced_tiles(in, settings, m.tiles);
  std::vector<std::uint8_t> reset(touched.size(), 0);
  for (std::size_t i = 0; i < touched.size(); ++i) {
    reset[i] = m.dirty[i] && !touched[i];
    stats.tiles_rendered += touched[i];
    stats.tiles_reset += reset[i];
  }
  // The kept layers go into the renderer and come back, also when it throws (cancelled): then
  // every tile it may have touched counts as dirty, so the next frame resets or renders it.
  render::insertion::InsertionLayers layers;
  layers.composite = std::move(m.result.composite);
  layers.matte = std::move(m.result.matte);
  layers.shadow = std::move(m.result.shadow);
  layers.difference = std::move(m.result.difference);
  layers.distance_m = std::move(m.result.distance_m);
  layers.object_radiance = std::move(m.object_radiance);
  auto give_back = [&] {
    m.result.composite = std::move(layers.composite);
    m.result.matte = std::move(layers.matte);
    m.result.shadow = std::move(layers.shadow);
    m.result.difference = std::move(layers.difference);
    m.result.distance_m = std::move(layers.distance_m);
    m.object_radiance = std::move(layers.object_radiance);
  };
  try {
    render::insertion::render_insertion_tiles(in, settings, m.tiles, touched, reset, layers);
  } catch (...) {
    give_back();
    for (std::size_t i = 0; i < touched.size(); ++i) m.dirty[i] = m.dirty[i] || touched[i];
    throw;
  }
  give_back();
  m.dirty = touched;
  m.result.composite.metadata() = m.photo.metadata();
  m.result.timings.mesh_s = stats.objects_s;
  m.result.timings.render_s = stats.render_s = seconds_since(render_start);
  m.result.timings.shadow_rays = layers.shadow_rays;
  m.result.timings.camera_rays = layers.camera_rays;
  m.result.timings.total_s = stats.total_s = seconds_since(start);
  m.stats = stats;
  return m.result;
}

void InsertPreview::set_lighting(const Lighting& lighting) {
  Impl& m = *impl_;
  FogScene scene = m.prep.scene;
  scene.lighting = lighting;
  validate_scene(scene);
  m.prep.scene.lighting = resolve_lighting(m.photo, m.distance_m, m.camera, scene);
  m.result.lighting = m.prep.scene.lighting;
}

const InsertPreview::FrameStats& InsertPreview::last_frame() const {
  return impl_->stats;
}
double InsertPreview::prepare_seconds() const {
  return impl_->prepare_s;
}
const Lighting& InsertPreview::lighting() const {
  return impl_->prep.scene.lighting;
}
const Camera& InsertPreview::camera() const {
  return impl_->camera;
}

}  // namespace mr
