// The CPU backend's occluder geometry reused across renders of one photo (render/occluder_cache.*,
// issue 12 item 4): a render whose fog and sun changed but whose depth map, camera, pose and
// blockers did not reuses the normals, mesh and BVH (mr::ScatteringLayers::Timings reports no
// mesh or BVH time then), and gives output identical, bit for bit, to a fresh render; any change
// of the geometry's inputs builds afresh. The surface's AO and sun-disk answers kept with the
// geometry (render/surface_query_cache.h) save a slider's render their rays, with output still
// identical to a fresh render's.
#include <gtest/gtest.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstring>
#include <numbers>

#include "mr/mr.h"
#include "render/occluder_cache.h"
#include "render/surface_query_cache.h"
#include "scattering_scenes.h"

namespace mr {
namespace {

bool identical(const Image& a, const Image& b) {
  return a.width() == b.width() && a.height() == b.height() && a.channels() == b.channels() &&
         std::memcmp(a.data(), b.data(), sizeof(float) * a.pixels().size()) == 0;
}

struct Fixture {
  Camera camera = Camera::from_horizontal_fov(96, 64, 70);
  FogScene scene;
  Image depth, photo;
  Fixture() {
    scene.pose.position_m = {0, 1.6, 0};
    scene.pose.pitch_deg = 5;
    scene.medium.sigma_t_per_m = {0.03f, 0.03f, 0.03f};
    scene.medium.albedo = {0.9f, 0.9f, 0.9f};
    scene.medium.g = 0.5;
    scene.lighting.sky_radiance = Rgb{0.2f, 0.2f, 0.25f};
    scene.lighting.sun = Sun{direction_from_azimuth_elevation(-60, 20), {3, 3, 3}, 0.27};
    scene.render.quality = Quality::normal;
    scene.render.backend = Backend::cpu;
    depth = test::street_depth(camera, scene.pose);
    photo = Image(camera.width, camera.height, 3);
    for (float& v : photo.pixels()) v = 0.3f;
  }
  ScatteringLayers render(const FogScene& s, const Image& d) const {
    return render_scattering(photo, d, camera, s);
  }
};

TEST(OccluderCache, SliderChangesReuseTheGeometryWithIdenticalOutput) {
  const Fixture f;
  render::clear_occluder_geometry_cache();
  const ScatteringLayers first = f.render(f.scene, f.depth);
  EXPECT_GT(first.timings.mesh_s + first.timings.bvh_s, 0.0);  // built

  // The fog thickens and the sun moves (what mr-studio's sliders change).
  FogScene changed = f.scene;
  changed.medium.sigma_t_per_m = {0.05f, 0.05f, 0.05f};
  changed.lighting.sun->direction_to_sun = direction_from_azimuth_elevation(-40, 30);
  const ScatteringLayers reused = f.render(changed, f.depth);
  EXPECT_EQ(reused.timings.mesh_s, 0.0);  // reused: no mesh or BVH built
  EXPECT_EQ(reused.timings.bvh_s, 0.0);

  render::clear_occluder_geometry_cache();
  const ScatteringLayers fresh = f.render(changed, f.depth);
  EXPECT_GT(fresh.timings.mesh_s + fresh.timings.bvh_s, 0.0);
  EXPECT_TRUE(identical(reused.transmittance, fresh.transmittance));
  EXPECT_TRUE(identical(reused.inscatter, fresh.inscatter));
  EXPECT_TRUE(identical(reused.sun_visibility, fresh.sun_visibility));
  EXPECT_TRUE(identical(reused.optical_depth, fresh.optical_depth));
  // The shafts are there (the test would pass vacuously on an unshadowed scene).
  double shadowed = 0;
  for (float v : fresh.sun_visibility.pixels()) shadowed += v < 0.5f;
  EXPECT_GT(shadowed, 0.05 * f.camera.width * f.camera.height);
}

TEST(OccluderCache, AnyChangeOfTheGeometrysInputsBuildsAfresh) {
  const Fixture f;
  render::clear_occluder_geometry_cache();
  f.render(f.scene, f.depth);
  EXPECT_EQ(f.render(f.scene, f.depth).timings.mesh_s, 0.0);  // same inputs: reused

  Image depth = f.depth;
  depth.at(40, 40, 0) *= 1.01f;  // one pixel's depth
  EXPECT_GT(f.render(f.scene, depth).timings.mesh_s, 0.0);
  EXPECT_GT(f.render(f.scene, f.depth).timings.mesh_s, 0.0);  // back to the first map

  FogScene pose = f.scene;
  pose.pose.pitch_deg += 0.5;
  EXPECT_GT(f.render(pose, f.depth).timings.mesh_s, 0.0);

  FogScene blockers = f.scene;
  blockers.blockers.canopy = Blockers::Canopy{};
  EXPECT_GT(f.render(blockers, f.depth).timings.mesh_s, 0.0);

  FogScene quality = blockers;
  quality.render.quality = Quality::draft;  // a coarser mesh (mesh_step 2)
  EXPECT_GT(f.render(quality, f.depth).timings.mesh_s, 0.0);

  // And a reused render after all that equals a fresh one.
  const ScatteringLayers reused = f.render(quality, f.depth);
  EXPECT_EQ(reused.timings.mesh_s, 0.0);
  render::clear_occluder_geometry_cache();
  const ScatteringLayers fresh = f.render(quality, f.depth);
  EXPECT_TRUE(identical(reused.inscatter, fresh.inscatter));
  EXPECT_TRUE(identical(reused.transmittance, fresh.transmittance));
}

void expect_identical(const ScatteringLayers& a, const ScatteringLayers& b) {
  EXPECT_TRUE(identical(a.transmittance, b.transmittance));
  EXPECT_TRUE(identical(a.inscatter, b.inscatter));
  EXPECT_TRUE(identical(a.sun_visibility, b.sun_visibility));
  EXPECT_TRUE(identical(a.optical_depth, b.optical_depth));
}

// The render of `scene` after `before` (same photo: geometry and kept answers reused) against a
// fresh render of `scene`; returns the reused render's shadow rays over the fresh one's.
double reused_over_fresh_rays(const Fixture& f, const FogScene& before, const FogScene& scene) {
  render::clear_occluder_geometry_cache();
  f.render(before, f.depth);
  const ScatteringLayers reused = f.render(scene, f.depth);
  EXPECT_EQ(reused.timings.mesh_s, 0.0);
  render::clear_occluder_geometry_cache();
  const ScatteringLayers fresh = f.render(scene, f.depth);
  expect_identical(reused, fresh);
  EXPECT_GT(fresh.timings.shadow_rays, 0u);
  return double(reused.timings.shadow_rays) / double(fresh.timings.shadow_rays);
}

TEST(OccluderCache, TheDraftsGeometryStaysBesideTheViews) {
  // mr-studio renders every edit twice: a small draft, then the view's size (two distance maps
  // of one photo). After one such pair both geometries are reused.
  const Fixture f;
  Fixture draft;
  draft.camera = Camera::from_horizontal_fov(48, 32, 70);
  draft.depth = test::street_depth(draft.camera, draft.scene.pose);
  draft.photo = Image(48, 32, 3);
  for (float& v : draft.photo.pixels()) v = 0.3f;
  draft.scene.render.quality = Quality::draft;
  render::clear_occluder_geometry_cache();
  EXPECT_GT(draft.render(draft.scene, draft.depth).timings.mesh_s, 0.0);
  EXPECT_GT(f.render(f.scene, f.depth).timings.mesh_s, 0.0);
  for (int edit = 0; edit < 2; ++edit) {
    FogScene fog = f.scene;
    fog.medium.sigma_t_per_m = {0.04f + 0.01f * edit, 0.04f, 0.04f};
    FogScene draft_fog = fog;
    draft_fog.render.quality = Quality::draft;
    const ScatteringLayers small = draft.render(draft_fog, draft.depth);
    const ScatteringLayers view = f.render(fog, f.depth);
    EXPECT_EQ(small.timings.mesh_s + small.timings.bvh_s, 0.0);  // both reused
    EXPECT_EQ(view.timings.mesh_s + view.timings.bvh_s, 0.0);
    render::clear_occluder_geometry_cache();  // and the same as fresh renders
    expect_identical(view, f.render(fog, f.depth));
    expect_identical(small, draft.render(draft_fog, draft.depth));
    f.render(fog, f.depth);  // (both back in the cache, the view's last)
  }
  // Another photo of the view's size (a batch's next) drops both before it is built.
  Image other = f.depth;
  other.at(10, 50, 0) *= 1.1f;
  EXPECT_GT(f.render(f.scene, other).timings.mesh_s, 0.0);
  EXPECT_GT(draft.render(draft.scene, draft.depth).timings.mesh_s, 0.0);
  EXPECT_GT(f.render(f.scene, f.depth).timings.mesh_s, 0.0);
}

TEST(OccluderCache, KeptSurfaceAnswersSaveRaysWithIdenticalOutput) {
  const Fixture f;
  // A fog slider: every AO and sun-disk answer is kept; only the march traces.
  FogScene fog = f.scene;
  fog.medium.sigma_t_per_m = {0.05f, 0.05f, 0.05f};
  fog.medium.albedo = {0.7f, 0.8f, 0.9f};
  const double fog_rays = reused_over_fresh_rays(f, f.scene, fog);
  EXPECT_LT(fog_rays, 0.95);
  // A sun slider: the AO is kept, the sun disk traced again.
  FogScene sun = f.scene;
  sun.lighting.sun->direction_to_sun = direction_from_azimuth_elevation(-40, 30);
  const double sun_rays = reused_over_fresh_rays(f, f.scene, sun);
  EXPECT_LT(sun_rays, 1.0);
  EXPECT_GT(sun_rays, fog_rays);
  FogScene disk = f.scene;  // the sun's size alone
  disk.lighting.sun->angular_radius_deg = 0.5;
  EXPECT_LT(reused_over_fresh_rays(f, f.scene, disk), 1.0);
  // Settings the answers depend on: nothing kept is used, and nothing is saved.
  FogScene seed = f.scene;
  seed.render.seed = 7;
  EXPECT_GE(reused_over_fresh_rays(f, f.scene, seed), 1.0);
  FogScene final_quality = f.scene;  // more AO and sun-disk rays, the same mesh
  final_quality.render.quality = Quality::final;
  EXPECT_GE(reused_over_fresh_rays(f, f.scene, final_quality), 1.0);
  // And back to normal after final: the answers were replaced, and are right again.
  EXPECT_GE(reused_over_fresh_rays(f, final_quality, f.scene), 1.0);
}

TEST(OccluderCache, ACancelledRendersAnswersServeTheNext) {
  // A render cancelled halfway (mr-studio cancels a stale pass) gives its answers back: each one
  // complete, so the next render of the photo uses them and still equals a fresh render.
  const Fixture f;
  render::clear_occluder_geometry_cache();
  CancelToken token;
  token.set_progress(
      [&](const Progress& p) {
        if (p.stage == "render" && p.fraction() >= 0.4) token.request();
      },
      std::chrono::milliseconds(0));
  EXPECT_THROW(
      {
        try {
          render_scattering(f.photo, f.depth, f.camera, f.scene, &token);
        } catch (const Error& e) {
          EXPECT_EQ(e.code(), ErrorCode::cancelled);
          throw;
        }
      },
      Error);
  FogScene fog = f.scene;
  fog.medium.sigma_t_per_m = {0.05f, 0.05f, 0.05f};
  const ScatteringLayers reused = f.render(fog, f.depth);
  EXPECT_EQ(reused.timings.mesh_s, 0.0);
  render::clear_occluder_geometry_cache();
  const ScatteringLayers fresh = f.render(fog, f.depth);
  expect_identical(reused, fresh);
  EXPECT_LT(reused.timings.shadow_rays, fresh.timings.shadow_rays);  // some answers were kept
}

TEST(OccluderCache, KeptSurfaceAnswersFollowTheMeshStep) {
  // Below 16 mesh rows draft keeps the full-resolution mesh (render/cpu_backend.cpp), so draft
  // and normal share one geometry while their rays start differently (shadow_origin).
  Fixture f;
  f.camera = Camera::from_horizontal_fov(30, 24, 70);
  f.depth = test::street_depth(f.camera, f.scene.pose);
  f.photo = Image(f.camera.width, f.camera.height, 3);
  for (float& v : f.photo.pixels()) v = 0.3f;
  FogScene draft = f.scene;  // the same AO rays as normal's
  draft.render.quality = Quality::draft;
  const FogScene& normal = f.scene;
  EXPECT_GE(reused_over_fresh_rays(f, draft, normal), 1.0);
  EXPECT_GE(reused_over_fresh_rays(f, normal, draft), 1.0);
}

// Issue 12: the geometry traces its surface in the image where the depth is a fur of slivers
// (render/occluder_cache.cpp, trace_surface_in_image), through Embree's BVH where it is smooth,
// and keeps that choice for every render of the photo; both answer the same shadow rays alike.
TEST(OccluderCache, JaggedDepthIsTracedInTheImageForEveryRender) {
  // A long lens (1000 px focal length): a 4 % step in depth is 20 pixel footprints deep.
  const Camera camera =
      Camera::from_horizontal_fov(400, 300, 2 * std::atan(0.2) * 180 / std::numbers::pi);
  CameraPose pose;
  pose.pitch_deg = -2;
  const Image smooth = test::street_depth(camera, pose);
  // The street with every other pixel 4 % farther (a checkerboard): every neighbour stays
  // within the mesh's 5 % continuity, so the surface becomes slivers along the view rays.
  Image jagged = smooth;
  for (int y = 0; y < camera.height; ++y)
    for (int x = 0; x < camera.width; ++x)
      if ((x + y) % 2) jagged.at(x, y, 0) *= 1.04f;
  const Blockers blockers;
  auto request = [&](const Image& depth, render::SurfaceTraversal traversal) {
    render::OccluderGeometryRequest r;
    r.distance_m = depth.view();
    r.camera = &camera;
    r.pose = &pose;
    r.blockers = &blockers;
    r.surface_traversal = traversal;
    return r;
  };
  auto geometry = [&](const Image& depth, render::SurfaceTraversal traversal,
                      render::OccluderGeometryTimings* timings = nullptr) {
    render::OccluderGeometryTimings t;
    auto g = render::occluder_geometry(request(depth, traversal), &t);
    if (timings) *timings = t;
    EXPECT_TRUE(g->occluders.has_value());
    return g;
  };
  using render::SurfaceTraversal;
  render::clear_occluder_geometry_cache();
  EXPECT_FALSE(geometry(smooth, SurfaceTraversal::automatic)->occluders->traces_surface_in_image());
  render::clear_occluder_geometry_cache();
  const auto image = geometry(jagged, SurfaceTraversal::automatic);
  EXPECT_TRUE(image->occluders->traces_surface_in_image());
  // Reused: nothing built, the same scene still traced in the image.
  render::OccluderGeometryTimings reused;
  const auto again = geometry(jagged, SurfaceTraversal::automatic, &reused);
  EXPECT_TRUE(reused.reused);
  EXPECT_EQ(reused.bvh_s, 0.0);
  EXPECT_EQ(again.get(), image.get());
  EXPECT_TRUE(again->occluders->traces_surface_in_image());
  // Forced either way; a forced request is its own cache entry.
  const auto bvh = geometry(jagged, SurfaceTraversal::bvh);
  EXPECT_FALSE(bvh->occluders->traces_surface_in_image());
  EXPECT_NE(bvh.get(), image.get());
  EXPECT_TRUE(geometry(smooth, SurfaceTraversal::image)->occluders->traces_surface_in_image());

  // Sun rays from points above the jagged surface (a march's samples) and from just off it:
  // the same answers from the walk and the BVH.
  const render::OccluderScene& walk = *image->occluders;
  const render::OccluderScene& tree = *bvh->occluders;
  std::size_t rays = 0, differ = 0, blocked = 0;
  for (int y = 0; y < camera.height; y += 3)
    for (int x = 0; x < camera.width; x += 3) {
      const double d = jagged.at(x, y, 0);
      if (!std::isfinite(d)) continue;
      const Vec3 w = pose.ray_direction(camera, x, y);
      for (const double along : {0.3, 0.7, 0.98}) {
        const std::array<float, 3> o{float(pose.position_m.x + along * d * w.x),
                                     float(pose.position_m.y + along * d * w.y),
                                     float(pose.position_m.z + along * d * w.z)};
        for (const double azimuth : {-60.0, 10.0, 160.0}) {
          const Vec3 s = direction_from_azimuth_elevation(azimuth, 12);
          const std::array<float, 3> dir{float(s.x), float(s.y), float(s.z)};
          const bool a = walk.occluded(o, dir, 0.0f, 1e4f), b = tree.occluded(o, dir, 0.0f, 1e4f);
          differ += a != b;
          blocked += b;
          ++rays;
        }
      }
    }
  EXPECT_LE(differ, rays / 1000) << "of " << rays;  // rounding at edges and vertices only
  EXPECT_GT(blocked, rays / 10);                    // not vacuous
  EXPECT_LT(blocked, rays * 9 / 10);
  render::clear_occluder_geometry_cache();
}

TEST(SurfaceQueryCache, KeepsEachAnswerUnderItsOwnSettings) {
  render::SurfaceQueryCache cache(5, 4);
  render::SurfaceQuerySettings settings;
  settings.ao_rays = 8;
  settings.ao_partial_rays = 32;
  settings.sun_disk_directions = {{0, 1, 0}, {0.01, 1, 0}};
  EXPECT_FALSE(cache.ambient_occlusion(0, 0));  // nothing before use()
  cache.use(settings);
  EXPECT_FALSE(cache.ambient_occlusion(4, 3));
  EXPECT_FALSE(cache.sun_disk_seen(4, 3));
  cache.set_ambient_occlusion(4, 3, 0.0f);  // every float value, exactly
  cache.set_ambient_occlusion(0, 0, 1.0f);
  cache.set_ambient_occlusion(1, 0, 0.3f);
  cache.set_sun_disk_seen(4, 3, 0);
  cache.set_sun_disk_seen(1, 0, 2);
  cache.set_sun_disk_seen(2, 0, 3);  // more than there are rays: not kept
  EXPECT_EQ(cache.ambient_occlusion(4, 3), 0.0f);
  EXPECT_EQ(cache.ambient_occlusion(0, 0), 1.0f);
  EXPECT_EQ(cache.ambient_occlusion(1, 0), 0.3f);
  EXPECT_EQ(cache.sun_disk_seen(4, 3), 0);
  EXPECT_EQ(cache.sun_disk_seen(1, 0), 2);
  EXPECT_FALSE(cache.sun_disk_seen(2, 0));
  EXPECT_FALSE(cache.ambient_occlusion(3, 3));

  cache.use(settings);  // the same settings: everything stays
  EXPECT_EQ(cache.ambient_occlusion(1, 0), 0.3f);
  EXPECT_EQ(cache.sun_disk_seen(1, 0), 2);
  settings.sun_disk_directions[1][0] = 0.02;  // the sun moved: AO stays, the disk goes
  cache.use(settings);
  EXPECT_EQ(cache.ambient_occlusion(1, 0), 0.3f);
  EXPECT_FALSE(cache.sun_disk_seen(1, 0));
  cache.set_sun_disk_seen(1, 0, 1);
  for (auto change : {+[](render::SurfaceQuerySettings& s) { s.mesh_step = 2; },
                      +[](render::SurfaceQuerySettings& s) { s.ao_rays = 32; },
                      +[](render::SurfaceQuerySettings& s) { s.ao_partial_rays = 64; },
                      +[](render::SurfaceQuerySettings& s) { s.seed = 9; },
                      +[](render::SurfaceQuerySettings& s) {
                        s.camera_forward = {0, 0, -1};
                      }}) {
    change(settings);  // any AO setting: both go
    cache.use(settings);
    EXPECT_FALSE(cache.ambient_occlusion(1, 0));
    EXPECT_FALSE(cache.sun_disk_seen(1, 0));
    cache.set_ambient_occlusion(1, 0, 0.5f);
    cache.set_sun_disk_seen(1, 0, 1);
  }
  EXPECT_THROW(render::SurfaceQueryCache(0, 4), Error);

  // The slot hands its cache to one render at a time, and a new one for another size.
  render::SurfaceQuerySlot slot;
  auto taken = slot.take(5, 4);
  taken->use(settings);
  taken->set_ambient_occlusion(2, 2, 0.25f);
  const render::SurfaceQueryCache* kept = taken.get();
  EXPECT_NE(slot.take(5, 4).get(), kept);  // taken: a second render starts empty
  slot.give_back(std::move(taken));
  auto again = slot.take(5, 4);
  EXPECT_EQ(again.get(), kept);
  again->use(settings);
  EXPECT_EQ(again->ambient_occlusion(2, 2), 0.25f);
  slot.give_back(std::move(again));
  EXPECT_NE(slot.take(6, 4).get(), kept);
}

}  // namespace
}  // namespace mr
