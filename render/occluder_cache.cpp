#include "render/occluder_cache.h"

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "render/blockers.h"
#include "render/depth_downsample.h"
#include "render/huge_pages.h"
#include "render/shadow_traversal/multi_index_query.h"

namespace mr::render {

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

bool same(const Vec3& a, const Vec3& b) {
  return a.x == b.x && a.y == b.y && a.z == b.z;
}

// Every field of Blockers (mr/scene.h): a field added there must be compared here, or renders
// that differ only in it would share geometry.
bool same(const Blockers& a, const Blockers& b) {
  const auto& ca = a.completion;
  const auto& cb = b.completion;
  if (ca.enabled != cb.enabled || ca.max_height_m != cb.max_height_m ||
      ca.max_extent_m != cb.max_extent_m || ca.prism_max_width_m != cb.prism_max_width_m)
    return false;
  if (a.skyline.has_value() != b.skyline.has_value()) return false;
  if (a.skyline) {
    if (a.skyline->distance_m != b.skyline->distance_m ||
        a.skyline->samples.size() != b.skyline->samples.size())
      return false;
    for (std::size_t i = 0; i < a.skyline->samples.size(); ++i)
      if (a.skyline->samples[i].azimuth_deg != b.skyline->samples[i].azimuth_deg ||
          a.skyline->samples[i].height_m != b.skyline->samples[i].height_m)
        return false;
  }
  if (a.polygons.size() != b.polygons.size()) return false;
  for (std::size_t i = 0; i < a.polygons.size(); ++i) {
    const auto &pa = a.polygons[i].corners_m, &pb = b.polygons[i].corners_m;
    if (pa.size() != pb.size()) return false;
    for (std::size_t k = 0; k < pa.size(); ++k)
      if (!same(pa[k], pb[k])) return false;
  }
  if (a.canopy.has_value() != b.canopy.has_value()) return false;
  if (a.canopy && (a.canopy->height_m != b.canopy->height_m ||
                   a.canopy->gap_fraction != b.canopy->gap_fraction ||
                   a.canopy->radius_m != b.canopy->radius_m ||
                   a.canopy->cell_m != b.canopy->cell_m || a.canopy->seed != b.canopy->seed))
    return false;
  return true;
}

bool same(const MeshOptions& a, const MeshOptions& b) {
  return a.discontinuity_ratio == b.discontinuity_ratio && a.thickness_m == b.thickness_m &&
         a.centre_tolerance == b.centre_tolerance &&
         a.planar_merge_tolerance == b.planar_merge_tolerance;
}

struct Entry {
  std::vector<float> distance_m;  // the depth map it was built from, row-major
  int width = 0, height = 0;
  Camera camera;
  CameraPose pose;
  Blockers blockers;
  int mesh_step = 1;
  MeshOptions mesh_options;
  ShadowTraversal shadow_traversal = ShadowTraversal::embree;
  SurfaceTraversal surface_traversal = SurfaceTraversal::automatic;
  std::shared_ptr<const OccluderGeometry> geometry;
};

// Memory an entry holds, roughly (bytes; only compared with other entries'): per pixel of the
// distance map its copy and the normals, per pixel of the mesh (mesh_step x mesh_step pixels)
// about two triangles with their vertices and Embree's BVH (~75 bytes a quad, README issue 12).
double entry_weight(int width, int height, int mesh_step) {
  const double pixels = double(width) * height;
  return 16.0 * pixels + 150.0 * pixels / (double(mesh_step) * mesh_step);
}

// The entries, most recently used first (guarded by cache_mutex). mr-studio renders every edit
// twice, a small draft and then the view's size: two distance maps of one photo, each with its
// geometry. So an entry stays beside a new one when it is small against it (kKeptShare of the
// new one's weight, all kept entries together, at most kMaxEntries): the draft's geometry stays
// while the view's is built. A photo of similar or larger size (the next photo of a batch)
// drops it first, as before, so that two large geometries are never held for one render.
constexpr std::size_t kMaxEntries = 3;
constexpr double kKeptShare = 0.25;
std::mutex cache_mutex;
std::vector<std::shared_ptr<const Entry>> cache_entries;

bool matches(const Entry& e, const OccluderGeometryRequest& r) {
  const ConstImageView& d = r.distance_m;
  if (e.width != d.width || e.height != d.height) return false;
  const Camera &ca = e.camera, &cb = *r.camera;
  if (ca.width != cb.width || ca.height != cb.height || ca.focal_px != cb.focal_px ||
      ca.cx != cb.cx || ca.cy != cb.cy)
    return false;
  const CameraPose &pa = e.pose, &pb = *r.pose;
  if (!same(pa.position_m, pb.position_m) || pa.yaw_deg != pb.yaw_deg ||
      pa.pitch_deg != pb.pitch_deg || pa.roll_deg != pb.roll_deg)
    return false;
  if (e.mesh_step != r.mesh_step || !same(e.mesh_options, r.mesh_options) ||
      !same(e.blockers, *r.blockers) || e.shadow_traversal != r.shadow_traversal ||
      e.surface_traversal != r.surface_traversal)
    return false;
  // Bit for bit (memcmp: +inf sky compares equal to itself, as it should).
  for (int y = 0; y < d.height; ++y)
    if (std::memcmp(&e.distance_m[std::size_t(y) * d.width], &d.at(0, y, 0),
                    sizeof(float) * std::size_t(d.width)) != 0)
      return false;
  return true;
}

// Whether the render traces the mesh's surface in the image (a walk over a depth pyramid, no
// BVH to build) instead of through Embree's BVH. Both give the same answers (but for rays that
// graze a vertex or an edge, where each test's rounding decides). Embree's BVH is the faster on
// a smooth surface (the bench's street at 1080p: its build included, ~15 % less wall; a flat
// ground to the horizon: 20 % less CPU); on jagged estimated depth, a fur of slivers along the
// view rays, a shadow ray crosses tens of the slivers' boxes before its hit while its walk in
// the image stays short (gallery sun bank, README issue 12: dragonfly 46 -> 14 s). A fur has
// both: many long triangles (surface_sliver_share; the tuning photos put the break-even between
// 5 %, the street, and 9 %, valendas) and a zig-zagging depth (depth_fur_share: 0 on every
// tuning photo where the BVH was faster, 0.45 % and more where the walk was). Long triangles
// alone are a surface seen at a grazing angle (the flat ground: 19.5 %), a zig-zag alone can be
// a staircase of nearest-upsampled depth (the bench's street). Small surfaces keep the BVH: it
// builds fast, and the choice hardly matters there.
constexpr double kImageSliverShare = 0.07;
constexpr double kImageFurShare = 0.002;
constexpr std::size_t kImageMinTriangles = 100000;

bool trace_surface_in_image(const OccluderGeometryRequest& r, const TriangleMesh& mesh) {
  if (r.shadow_traversal != ShadowTraversal::embree || !mesh.layout) return false;
  if (r.surface_traversal != SurfaceTraversal::automatic)
    return r.surface_traversal == SurfaceTraversal::image;
  if (mesh.surface_triangle_count < kImageMinTriangles) return false;
  const double pixel_angle_rad = double(r.mesh_step) / r.camera->focal_px;
  if (surface_sliver_share(mesh, r.pose->position_m, pixel_angle_rad) < kImageSliverShare)
    return false;
  return depth_fur_share(r.distance_m, *r.camera, r.mesh_options.discontinuity_ratio).share >=
         kImageFurShare;
}

}  // namespace

SurfaceTraversal surface_traversal_from_environment() {
  static const SurfaceTraversal chosen = [] {
    const char* v = std::getenv("MR_SURFACE_TRAVERSAL");
    const std::string value = v ? v : "";
    return value == "bvh"     ? SurfaceTraversal::bvh
           : value == "image" ? SurfaceTraversal::image
                              : SurfaceTraversal::automatic;
  }();
  return chosen;
}

std::shared_ptr<const OccluderGeometry> occluder_geometry(const OccluderGeometryRequest& r,
                                                          OccluderGeometryTimings* timings) {
  OccluderGeometryTimings t;
  {
    std::vector<std::shared_ptr<const Entry>> entries;
    {
      const std::lock_guard lock(cache_mutex);
      entries = cache_entries;
    }
    for (const auto& entry : entries)
      if (matches(*entry, r)) {
        {
          const std::lock_guard lock(cache_mutex);
          const auto at = std::find(cache_entries.begin(), cache_entries.end(), entry);
          if (at != cache_entries.end()) std::rotate(cache_entries.begin(), at, at + 1);
        }
        t.reused = true;
        if (timings) *timings = t;
        return entry->geometry;
      }
  }
  {
    // Drop what is not small against the geometry about to be built (see kKeptShare) before
    // building it: the least recently used first.
    const double budget =
        kKeptShare * entry_weight(r.distance_m.width, r.distance_m.height, r.mesh_step);
    const std::lock_guard lock(cache_mutex);
    double kept = 0;
    std::size_t keep = 0;
    for (; keep < cache_entries.size() && keep + 1 < kMaxEntries; ++keep) {
      const Entry& e = *cache_entries[keep];
      kept += entry_weight(e.width, e.height, e.mesh_step);
      if (kept > budget) break;
    }
    cache_entries.resize(keep);
  }
  const char* what = "render_scattering";
  auto start = Clock::now();
  auto geometry = std::make_shared<OccluderGeometry>();
  geometry->normals = estimate_normals(r.distance_m, *r.camera, *r.pose);
  throw_if_cancelled(r.cancel, what);
  TriangleMesh mesh;
  // The surface may be traced in the image (render/shadow_traversal/depth_image_surface.h;
  // chosen below): the mesh keeps its pixel layout for it.
  MeshOptions mesh_options = r.mesh_options;
  mesh_options.pixel_layout =
      r.shadow_traversal == ShadowTraversal::embree && r.surface_traversal != SurfaceTraversal::bvh;
  OccluderSceneOptions scene_options;
  if (r.mesh_step > 1) {
    const DownsampledDistance coarse =
        downsample_distance_nearest(r.distance_m, *r.camera, r.mesh_step);
    mesh =
        reconstruct_occluder_mesh(coarse.distance_m.view(), coarse.camera, *r.pose, mesh_options);
    scene_options.depth_image = OccluderSceneOptions::DepthImageView{coarse.camera, *r.pose};
  } else {
    scene_options.depth_image = OccluderSceneOptions::DepthImageView{*r.camera, *r.pose};
    // Normals as estimate_normals computed them above (the same discontinuity ratio).
    mesh = reconstruct_occluder_mesh(
        r.distance_m, *r.camera, *r.pose, mesh_options,
        r.mesh_options.discontinuity_ratio == MeshOptions{}.discontinuity_ratio
            ? ConstImageView(geometry->normals.view())
            : ConstImageView{});
  }
  geometry->completed_blockers =
      append_blockers(mesh, r.distance_m, geometry->normals.view(), *r.camera, *r.pose, *r.blockers)
          .completed;
  if (!trace_surface_in_image(r, mesh)) {
    scene_options.depth_image.reset();
    mesh.layout.reset();  // only the image's walk reads it
  }
  t.mesh_s = seconds_since(start);
  throw_if_cancelled(r.cancel, what);
  start = Clock::now();
  if (mesh.triangle_count() > 0) geometry->occluders.emplace(std::move(mesh), scene_options);
  if (geometry->occluders && r.shadow_traversal == ShadowTraversal::multi_index)
    geometry->occluders->set_shadow_query(
        std::make_shared<MultiIndexShadowQuery>(geometry->occluders->mesh()));
  t.bvh_s = seconds_since(start);

  auto entry = std::make_shared<Entry>();
  const ConstImageView& d = r.distance_m;
  entry->width = d.width;
  entry->height = d.height;
  // 8 MB at 1080p: on huge pages, 4 faults instead of 2000 (render/huge_pages.h).
  entry->distance_m.reserve(std::size_t(d.width) * d.height);
  advise_huge_pages(entry->distance_m.data(), sizeof(float) * entry->distance_m.capacity());
  entry->distance_m.resize(std::size_t(d.width) * d.height);
  for (int y = 0; y < d.height; ++y)
    std::memcpy(&entry->distance_m[std::size_t(y) * d.width], &d.at(0, y, 0),
                sizeof(float) * std::size_t(d.width));
  entry->camera = *r.camera;
  entry->pose = *r.pose;
  entry->blockers = *r.blockers;
  entry->mesh_step = r.mesh_step;
  entry->mesh_options = r.mesh_options;
  entry->shadow_traversal = r.shadow_traversal;
  entry->surface_traversal = r.surface_traversal;
  entry->geometry = geometry;
  {
    const std::lock_guard lock(cache_mutex);
    cache_entries.insert(cache_entries.begin(), entry);
    if (cache_entries.size() > kMaxEntries) cache_entries.resize(kMaxEntries);
  }
  if (timings) *timings = t;
  return geometry;
}

void clear_occluder_geometry_cache() {
  {
    const std::lock_guard lock(cache_mutex);
    cache_entries.clear();
  }
  // And the scratch blocks kept for the next render (render/huge_pages.h).
  trim_huge_page_pool();
}

}  // namespace mr::render
