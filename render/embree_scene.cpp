#include "render/embree_scene.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <mutex>
#include <numbers>
#include <string>
#include <utility>
#include <vector>

#include "mr/error.h"
#include "render/huge_pages.h"
#include "render/physics/occlusion.h"
#include "render/shadow_traversal/depth_image_surface.h"
#include "render/triangle_pairs.h"

namespace mr::render {

/// Collects the errors Embree reports through its callback. The callback runs inside Embree
/// (possibly on a TBB worker during a build), where throwing would unwind through C code; so it
/// only records, and the constructor throws mr::Error(internal) after each Embree call sequence.
struct OccluderScene::ErrorSink {
  std::mutex mutex;
  std::string first_message;
  bool failed = false;

  static void callback(void* user, RTCError code, const char* message) {
    auto* sink = static_cast<ErrorSink*>(user);
    const std::lock_guard lock(sink->mutex);
    if (sink->failed) return;
    sink->failed = true;
    sink->first_message =
        "Embree error " + std::to_string(int(code)) + ": " + (message ? message : "(no message)");
  }
  void throw_if_failed() {
    const std::lock_guard lock(mutex);
    if (failed) throw Error(ErrorCode::internal, first_message);
  }
};

namespace {

/// The lowest i in [0, n) with bad(i), or n if there is none; in parallel (TBB), as the 1080p
/// occluder mesh has 12 M indices and 6 M coordinates to check before every build.
template <class Bad>
std::size_t first_bad(std::size_t n, const Bad& bad) {
  return tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, n, 65536), n,
      [&](const tbb::blocked_range<std::size_t>& r, std::size_t found) {
        for (std::size_t i = r.begin(); i < std::min(r.end(), found); ++i)
          if (bad(i)) return i;
        return found;
      },
      [](std::size_t a, std::size_t b) { return std::min(a, b); });
}

void validate_mesh(const TriangleMesh& mesh) {
  if (mesh.positions.size() % 3 != 0)
    throw Error(ErrorCode::invalid_argument, "occluder mesh has " +
                                                 std::to_string(mesh.positions.size()) +
                                                 " position floats, not a multiple of 3");
  if (mesh.indices.size() % 3 != 0)
    throw Error(ErrorCode::invalid_argument, "occluder mesh has " +
                                                 std::to_string(mesh.indices.size()) +
                                                 " indices, not a multiple of 3");
  const std::size_t vertices = mesh.vertex_count();
  const std::uint32_t* indices = mesh.indices.data();
  if (const std::size_t i =
          first_bad(mesh.indices.size(), [&](std::size_t k) { return indices[k] >= vertices; });
      i < mesh.indices.size())
    throw Error(ErrorCode::invalid_argument, "occluder mesh index " + std::to_string(i) + " is " +
                                                 std::to_string(mesh.indices[i]) +
                                                 ", but the mesh has " + std::to_string(vertices) +
                                                 " vertices");
  const float* positions = mesh.positions.data();
  if (const std::size_t i = first_bad(mesh.positions.size(),
                                      [&](std::size_t k) { return !std::isfinite(positions[k]); });
      i < mesh.positions.size())
    throw Error(ErrorCode::invalid_argument,
                "occluder mesh vertex " + std::to_string(i / 3) + " is not finite");
}

constexpr float kInfF = std::numeric_limits<float>::infinity();

}  // namespace

bool surface_grid_covers(const SurfacePixelLayout& layout, int x, int y) {
  const int partner = y ^ 1;
  if (partner >= layout.height) return false;
  const std::size_t w = std::size_t(layout.width);
  constexpr std::uint8_t kEligible = SurfacePixelLayout::kGridEligible;
  return (layout.pixel[std::size_t(y) * w + x] & kEligible) &&
         (layout.pixel[std::size_t(partner) * w + x] & kEligible);
}

namespace {

/// Appends band b's runs of covered pixels to `runs`.
void band_runs(const SurfacePixelLayout& layout, int band, std::vector<SurfaceGridRun>& runs) {
  const int y = 2 * band;
  if (y + 1 >= layout.height) return;
  const std::uint8_t* top = layout.pixel.data() + std::size_t(y) * layout.width;
  const std::uint8_t* bottom = top + layout.width;
  constexpr std::uint8_t kEligible = SurfacePixelLayout::kGridEligible;
  int x = 0;
  while (x < layout.width) {
    while (x < layout.width && !(top[x] & bottom[x] & kEligible)) ++x;
    const int begin = x;
    while (x < layout.width && (top[x] & bottom[x] & kEligible)) ++x;
    if (x > begin) runs.push_back({band, begin, x});
  }
}

}  // namespace

std::vector<SurfaceGridRun> surface_grid_runs(const SurfacePixelLayout& layout) {
  std::vector<SurfaceGridRun> runs;
  for (int band = 0; 2 * band + 1 < layout.height; ++band) band_runs(layout, band, runs);
  return runs;
}

/// The buffers Embree reads the surface's grids and remaining quads from.
struct OccluderScene::SurfaceGrids {
  /// (W + 1) x (H + 1) corners, each row mirrored in x (see attach_surface_grids), 3 floats
  /// each plus one of padding; only corners of covered pixels are written.
  HugePageArray<float> vertices;
  /// The other surface pairs as quads, 4 indices each (render/triangle_pairs.h's order).
  HugePageArray<std::uint32_t> quads;
  std::size_t grid_pixels = 0;
};

OccluderScene::OccluderScene(TriangleMesh mesh, const OccluderSceneOptions& options)
    : mesh_(std::move(mesh)), errors_(std::make_unique<ErrorSink>()) {
  validate_mesh(mesh_);
  device_ = rtcNewDevice(embree_device_config());
  if (!device_)
    throw Error(ErrorCode::internal, "Embree could not create a device (error " +
                                         std::to_string(int(rtcGetDeviceError(nullptr))) + ")");
  rtcSetDeviceErrorFunction(device_, &ErrorSink::callback, errors_.get());
  try {
    native_ray8_ = rtcGetDeviceProperty(device_, RTC_DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED) != 0;
    const RTCBuildQuality quality =
        options.build_quality == BuildQuality::low    ? RTC_BUILD_QUALITY_LOW
        : options.build_quality == BuildQuality::high ? RTC_BUILD_QUALITY_HIGH
                                                      : RTC_BUILD_QUALITY_MEDIUM;
    scene_ = rtcNewScene(device_);
    errors_->throw_if_failed();
    rtcSetSceneBuildQuality(scene_, quality);
    // Not compact by default (OccluderSceneOptions::compact). Compact was chosen when most of a
    // full-resolution build's time went into the kernel zeroing fresh pages (at 1080p, one
    // thread, it built in 0.89 s instead of 1.51 s and traced 12 % slower); with the build's
    // memory on huge pages that saving shrank, and on jagged estimated depth the indexed
    // leaves' vertex gathers made every shadow ray dearer (issue 12, README).
    const std::size_t triangles = mesh_.triangle_count();
    // The occluder mesh's surface, two triangles per pixel, goes in as one quad per pixel
    // (render/triangle_pairs.h): the same triangles, read in place, half the primitives.
    const std::size_t surface = mesh_.surface_triangle_count;
    const bool surface_quads =
        surface > 0 && surface <= triangles && triangle_pairs(mesh_.indices, 0, surface);
    // Robust (watertight) with quads: the non-robust quad test lets rays that run exactly along
    // the shared diagonal slip through both triangles, and every pixel's centre ray does (the
    // mesh puts it on that edge): OccluderMesh.RerenderedDepthMatchesInput lost 3050 of them.
    // The triangle test did not; robust quads still build and trace faster than the triangles
    // (BM_Stages 1080p normal, process CPU: geometry 3.29 -> 1.96 s, render 6.86 -> 5.96 s).
    const bool robust = options.robust || surface_quads;
    rtcSetSceneFlags(scene_, (options.compact ? RTC_SCENE_FLAG_COMPACT : RTC_SCENE_FLAG_NONE) |
                                 (robust ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE));
    // The surface (many small triangles, each about a pixel's footprint) and what follows it
    // (silhouette extrusions and blockers: few triangles, some tens of metres long) get a BVH
    // each, so that the long triangles' boxes do not overlap the surface's nodes. (The split's
    // gain was within the noise of a heavily loaded machine, so it is kept as the standard
    // remedy, not as a measured one. What had made the completion of issue 13 cost 1.8x per
    // shadow ray at 1080p was the blockers' own per-pixel slivers overlapping each other: see
    // kOutlineTolerance in render/blockers.cpp.)
    const std::size_t split =
        mesh_.surface_triangle_count > 0 && mesh_.surface_triangle_count < triangles
            ? mesh_.surface_triangle_count
            : triangles;
    // Issue 12 item 4: the surface traced in the image instead of a BVH built over it.
    const bool image_surface = options.depth_image && mesh_.layout && surface > 0 &&
                               split == surface &&
                               DepthImageSurface::supports(options.depth_image->camera);
    if (triangles > 0) {
      // Embree reads vertices with 16-byte loads: the last one needs a float of padding.
      mesh_.positions.push_back(0.0f);
      auto attach = [&](RTCScene target, std::size_t first, std::size_t count) {
        if (surface_quads && first == 0 && count == surface)
          attach_indexed(target, RTC_GEOMETRY_TYPE_QUAD, mesh_.indices.data(),
                         quad_index_offset_bytes(first), kQuadIndexStrideBytes, count / 2, quality);
        else
          attach_indexed(target, RTC_GEOMETRY_TYPE_TRIANGLE, mesh_.indices.data(),
                         3 * sizeof(std::uint32_t) * first, 3 * sizeof(std::uint32_t), count,
                         quality);
      };
      // The grids' cells are the pixels' quads with the winding reversed (see
      // attach_surface_grids): not with an Embree that culls back faces.
      const bool grids =
          options.surface_grids && surface_quads && split == surface && mesh_.layout &&
          rtcGetDeviceProperty(device_, RTC_DEVICE_PROPERTY_BACKFACE_CULLING_ENABLED) == 0;
      if (image_surface) {
        // The surface goes to the depth-image traversal below; scene_ stays empty until
        // build_surface_bvh (if ever).
        surface_bvh_quads_ = surface_quads;
        surface_bvh_quality_ = quality;
      } else if (grids) {
        attach_surface_grids(surface, quality);
      } else {
        attach(scene_, 0, split);
      }
      surface_quads_ = image_surface ? 0 : grids ? surface_quads_ : surface_quads ? surface / 2 : 0;
      if (split < triangles) {
        extra_scene_ = rtcNewScene(device_);
        errors_->throw_if_failed();
        rtcSetSceneBuildQuality(extra_scene_, quality);
        rtcSetSceneFlags(extra_scene_,
                         options.robust ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE);
        attach(extra_scene_, split, triangles - split);
        rtcCommitScene(extra_scene_);
        errors_->throw_if_failed();
      }
    }
    rtcCommitScene(scene_);
    errors_->throw_if_failed();
    if (image_surface)
      image_surface_ = std::make_unique<DepthImageSurface>(mesh_, options.depth_image->camera,
                                                           options.depth_image->pose);
    // Only the build needed the pixel layout (10 MB at 1080p): back to the scratch pool.
    mesh_.layout.reset();
  } catch (...) {
    release();
    throw;
  }
}

void OccluderScene::attach_surface_grids(std::size_t surface, RTCBuildQuality quality) {
  const SurfacePixelLayout& layout = *mesh_.layout;
  const int width = layout.width, height = layout.height;
  const std::size_t corner_width = std::size_t(width) + 1;
  const std::uint32_t* corner = layout.corner_vertex.data();
  const std::uint8_t* pixel = layout.pixel.data();
  const int bands = (height + 1) / 2;  // the last band of an odd height has one row, no grid
  // 1. Per band: its runs, and per row the surface pixels and those left to quads.
  std::vector<std::vector<SurfaceGridRun>> band_grids(static_cast<std::size_t>(bands));
  std::vector<std::size_t> row_pairs(std::size_t(height) + 1, 0),
      row_left(std::size_t(height) + 1, 0);
  tbb::parallel_for(tbb::blocked_range<int>(0, bands, 8), [&](const tbb::blocked_range<int>& r) {
    for (int band = r.begin(); band < r.end(); ++band) {
      band_runs(layout, band, band_grids[std::size_t(band)]);
      for (int y = 2 * band; y < std::min(2 * band + 2, height); ++y) {
        std::size_t pairs = 0, left = 0;
        for (int x = 0; x < width; ++x) {
          if (!(pixel[std::size_t(y) * width + x] & SurfacePixelLayout::kSurface)) continue;
          ++pairs;
          left += surface_grid_covers(layout, x, y) ? 0 : 1;
        }
        row_pairs[std::size_t(y) + 1] = pairs;
        row_left[std::size_t(y) + 1] = left;
      }
    }
  });
  for (int y = 0; y < height; ++y) {
    row_pairs[std::size_t(y) + 1] += row_pairs[std::size_t(y)];
    row_left[std::size_t(y) + 1] += row_left[std::size_t(y)];
  }
  const std::size_t pixels = row_pairs[std::size_t(height)];
  if (2 * pixels > surface || (surface - 2 * pixels) % 2 != 0)
    throw Error(ErrorCode::internal, "occluder mesh layout has " + std::to_string(pixels) +
                                         " surface pixels for " + std::to_string(surface) +
                                         " surface triangles");
  const std::size_t fan_pairs = (surface - 2 * pixels) / 2;
  const std::size_t left = row_left[std::size_t(height)];
  auto grids = std::make_unique<SurfaceGrids>(
      SurfaceGrids{HugePageArray<float>(3 * corner_width * (std::size_t(height) + 1) + 1),
                   HugePageArray<std::uint32_t>(std::max<std::size_t>(4 * (left + fan_pairs), 1)),
                   pixels - left});

  // 2. The pairs of the pixels not covered, then the fanned pixels' second pairs, as quads;
  // the covered pixels' pairs checked against the layout (its corners must be their vertices).
  const std::uint32_t* indices = mesh_.indices.data();
  std::uint32_t* quads = grids->quads.data();
  auto put_quad = [&](std::size_t quad, std::size_t pair) {
    const std::uint32_t* t = indices + 6 * pair;  // (A, B, C), (A, D, B) -> (C, A, D, B)
    std::uint32_t* q = quads + 4 * quad;
    q[0] = t[2], q[1] = t[0], q[2] = t[4], q[3] = t[1];
  };
  std::atomic<bool> mismatch{false};
  tbb::parallel_for(tbb::blocked_range<int>(0, height, 8), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y < r.end(); ++y) {
      std::size_t pair = row_pairs[std::size_t(y)], quad = row_left[std::size_t(y)];
      for (int x = 0; x < width; ++x) {
        if (!(pixel[std::size_t(y) * width + x] & SurfacePixelLayout::kSurface)) continue;
        if (surface_grid_covers(layout, x, y)) {
          const std::uint32_t* t = indices + 6 * pair;
          const std::size_t c = std::size_t(y) * corner_width + x;
          if (t[0] != corner[c] || t[1] != corner[c + corner_width + 1] ||
              t[2] != corner[c + corner_width] || t[3] != t[0] || t[4] != corner[c + 1] ||
              t[5] != t[1])
            mismatch = true;
        } else {
          put_quad(quad++, pair);
        }
        ++pair;
      }
    }
  });
  if (mismatch)
    throw Error(ErrorCode::internal, "occluder mesh layout does not match its surface triangles");
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, fan_pairs, 4096),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t f = r.begin(); f < r.end(); ++f)
                        put_quad(left + f, pixels + f);
                    });

  // 3. The corner buffer. Embree splits a grid cell (v00, v01, v11, v10) on the diagonal
  // v01-v10 (from the cell's top-right vertex to its bottom-left one), the mesh each pixel on
  // c00-c11: with each row laid out mirrored in x (grid column W - i holds corner column i)
  // the cell of pixel (x, y) is (c10, c00, c01, c11), its diagonal c00-c11, and its two
  // triangles (c10, c00, c11) and (c01, c11, c00) are the pixel's own (winding reversed, which
  // Embree, built without back-face culling, does not see). A corner is written when a covered
  // pixel uses it (its only vertex, then); the others are never read.
  float* out = grids->vertices.data();
  const float* positions = mesh_.positions.data();
  tbb::parallel_for(
      tbb::blocked_range<int>(0, height + 1, 8), [&](const tbb::blocked_range<int>& r) {
        for (int j = r.begin(); j < r.end(); ++j) {
          for (int i = 0; i <= width; ++i) {
            const bool used = (j > 0 && i > 0 && surface_grid_covers(layout, i - 1, j - 1)) ||
                              (j > 0 && i < width && surface_grid_covers(layout, i, j - 1)) ||
                              (j < height && i > 0 && surface_grid_covers(layout, i - 1, j)) ||
                              (j < height && i < width && surface_grid_covers(layout, i, j));
            if (!used) continue;
            const float* v = positions + 3 * std::size_t(corner[std::size_t(j) * corner_width + i]);
            float* o = out + 3 * (std::size_t(j) * corner_width + std::size_t(width - i));
            o[0] = v[0], o[1] = v[1], o[2] = v[2];
          }
        }
      });
  out[3 * corner_width * (std::size_t(height) + 1)] = 0.0f;  // Embree's 16-byte loads

  std::size_t runs = 0;
  for (const auto& b : band_grids) runs += b.size();
  if (runs > 0) {
    RTCGeometry geometry = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_GRID);
    rtcSetGeometryBuildQuality(geometry, quality);
    rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, out, 0,
                               3 * sizeof(float), corner_width * (std::size_t(height) + 1));
    auto* grid = static_cast<RTCGrid*>(rtcSetNewGeometryBuffer(
        geometry, RTC_BUFFER_TYPE_GRID, 0, RTC_FORMAT_GRID, sizeof(RTCGrid), runs));
    errors_->throw_if_failed();
    for (const auto& b : band_grids)
      for (const SurfaceGridRun& run : b) {
        // Grid column 0 is the run's right end corner (x_end), mirrored: column W - x_end.
        grid->startVertexID = std::uint32_t(std::size_t(2 * run.band) * corner_width +
                                            std::size_t(width - run.x_end));
        grid->stride = std::uint32_t(corner_width);
        grid->width = std::uint16_t(run.x_end - run.x_begin + 1);
        grid->height = 3;
        ++grid;
      }
    rtcCommitGeometry(geometry);
    rtcAttachGeometry(scene_, geometry);
    rtcReleaseGeometry(geometry);
    errors_->throw_if_failed();
  }
  surface_quads_ = left + fan_pairs;
  if (surface_quads_ > 0)
    attach_indexed(scene_, RTC_GEOMETRY_TYPE_QUAD, quads, 0, 4 * sizeof(std::uint32_t),
                   surface_quads_, quality);
  grids_ = std::move(grids);
}

void OccluderScene::attach_indexed(RTCScene target, RTCGeometryType type,
                                   const std::uint32_t* indices, std::size_t offset_bytes,
                                   std::size_t stride_bytes, std::size_t count,
                                   RTCBuildQuality quality) {
  RTCGeometry geometry = rtcNewGeometry(device_, type);
  rtcSetGeometryBuildQuality(geometry, quality);
  // (positions carry one float of padding: vertex_count() is unchanged by it.)
  rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                             mesh_.positions.data(), 0, 3 * sizeof(float), mesh_.vertex_count());
  rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0,
                             type == RTC_GEOMETRY_TYPE_QUAD ? RTC_FORMAT_UINT4 : RTC_FORMAT_UINT3,
                             indices, offset_bytes, stride_bytes, count);
  rtcCommitGeometry(geometry);
  rtcAttachGeometry(target, geometry);
  rtcReleaseGeometry(geometry);  // the scene holds its own reference
  errors_->throw_if_failed();
}

bool OccluderScene::tracing_image() const {
  return image_surface_ && !surface_bvh_ready_->load(std::memory_order_acquire);
}

void OccluderScene::build_surface_bvh() const {
  if (!image_surface_ || surface_bvh_ready_->load(std::memory_order_acquire)) return;
  const std::lock_guard lock(*surface_bvh_mutex_);
  if (surface_bvh_ready_->load(std::memory_order_relaxed)) return;
  // scene_ is empty and no query reads it until the flag says it is built (tracing_image).
  const std::size_t surface = mesh_.surface_triangle_count;
  auto* self = const_cast<OccluderScene*>(this);
  if (surface_bvh_quads_)
    self->attach_indexed(scene_, RTC_GEOMETRY_TYPE_QUAD, mesh_.indices.data(),
                         quad_index_offset_bytes(0), kQuadIndexStrideBytes, surface / 2,
                         surface_bvh_quality_);
  else
    self->attach_indexed(scene_, RTC_GEOMETRY_TYPE_TRIANGLE, mesh_.indices.data(), 0,
                         3 * sizeof(std::uint32_t), surface, surface_bvh_quality_);
  rtcCommitScene(scene_);
  errors_->throw_if_failed();
  surface_bvh_ready_->store(true, std::memory_order_release);
}

std::size_t OccluderScene::grid_pixel_count() const {
  return grids_ ? grids_->grid_pixels : 0;
}

std::size_t OccluderScene::surface_quad_count() const {
  return surface_quads_;
}

OccluderScene::~OccluderScene() {
  release();
}

void OccluderScene::release() noexcept {
  if (extra_scene_) rtcReleaseScene(extra_scene_);
  if (scene_) rtcReleaseScene(scene_);
  extra_scene_ = nullptr;
  if (device_) rtcReleaseDevice(device_);
  scene_ = nullptr;
  device_ = nullptr;
}

OccluderScene::OccluderScene(OccluderScene&& other) noexcept
    : mesh_(std::move(other.mesh_)),  // moving a vector keeps its buffer: Embree's view stays valid
      errors_(std::move(other.errors_)),
      device_(std::exchange(other.device_, nullptr)),
      scene_(std::exchange(other.scene_, nullptr)),
      extra_scene_(std::exchange(other.extra_scene_, nullptr)),
      native_ray8_(other.native_ray8_),
      shadow_query_(std::move(other.shadow_query_)),
      grids_(std::move(other.grids_)),
      surface_quads_(other.surface_quads_),
      image_surface_(std::move(other.image_surface_)),
      surface_bvh_ready_(std::move(other.surface_bvh_ready_)),
      surface_bvh_mutex_(std::move(other.surface_bvh_mutex_)),
      surface_bvh_quads_(other.surface_bvh_quads_),
      surface_bvh_quality_(other.surface_bvh_quality_) {}

OccluderScene& OccluderScene::operator=(OccluderScene&& other) noexcept {
  if (this != &other) {
    release();  // before the mesh it shares goes away
    mesh_ = std::move(other.mesh_);
    errors_ = std::move(other.errors_);
    device_ = std::exchange(other.device_, nullptr);
    scene_ = std::exchange(other.scene_, nullptr);
    extra_scene_ = std::exchange(other.extra_scene_, nullptr);
    native_ray8_ = other.native_ray8_;
    shadow_query_ = std::move(other.shadow_query_);
    grids_ = std::move(other.grids_);
    surface_quads_ = other.surface_quads_;
    image_surface_ = std::move(other.image_surface_);
    surface_bvh_ready_ = std::move(other.surface_bvh_ready_);
    surface_bvh_mutex_ = std::move(other.surface_bvh_mutex_);
    surface_bvh_quads_ = other.surface_bvh_quads_;
    surface_bvh_quality_ = other.surface_bvh_quality_;
  }
  return *this;
}

bool OccluderScene::occluded(const std::array<float, 3>& origin,
                             const std::array<float, 3>& direction, float t_near,
                             float t_far) const {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRay ray;
  ray.org_x = origin[0];
  ray.org_y = origin[1];
  ray.org_z = origin[2];
  ray.tnear = t_near;
  ray.dir_x = direction[0];
  ray.dir_y = direction[1];
  ray.dir_z = direction[2];
  ray.time = 0.0f;
  ray.tfar = t_far;
  ray.mask = 0xFFFFFFFFu;
  ray.id = 0;
  ray.flags = 0;
  // The small BVH of extrusions and blockers first: a ray it stops skips the surface's.
  if (extra_scene_) {
    rtcOccluded1(extra_scene_, &context, &ray);
    if (ray.tfar < 0.0f) return true;
  }
  if (tracing_image()) return image_surface_->occluded(origin, direction, t_near, t_far);
  rtcOccluded1(scene_, &context, &ray);
  return ray.tfar < 0.0f;  // Embree sets tfar to -inf on a hit
}

void OccluderScene::occluded8(const RayPacket8& rays, bool occluded_out[8]) const {
  if (!native_ray8_) {
    for (int k = 0; k < 8; ++k)
      occluded_out[k] = rays.valid[k] != 0 &&
                        occluded({rays.origin_x[k], rays.origin_y[k], rays.origin_z[k]},
                                 {rays.direction_x[k], rays.direction_y[k], rays.direction_z[k]},
                                 rays.t_near[k], rays.t_far[k]);
    return;
  }
  const bool image = tracing_image();
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  alignas(32) int valid[8];
  alignas(32) RTCRay8 packet;
  for (int k = 0; k < 8; ++k) {
    valid[k] = rays.valid[k] ? -1 : 0;
    packet.org_x[k] = rays.origin_x[k];
    packet.org_y[k] = rays.origin_y[k];
    packet.org_z[k] = rays.origin_z[k];
    packet.tnear[k] = rays.t_near[k];
    packet.dir_x[k] = rays.direction_x[k];
    packet.dir_y[k] = rays.direction_y[k];
    packet.dir_z[k] = rays.direction_z[k];
    packet.time[k] = 0.0f;
    packet.tfar[k] = rays.t_far[k];
    packet.mask[k] = 0xFFFFFFFFu;
    packet.id[k] = unsigned(k);
    packet.flags[k] = 0;
  }
  if (extra_scene_) {
    rtcOccluded8(valid, extra_scene_, &context, &packet);
    bool any_open = false;
    for (int k = 0; k < 8; ++k) {
      if (packet.tfar[k] < 0.0f) valid[k] = 0;  // stopped by a blocker: done
      any_open = any_open || valid[k] != 0;
    }
    if (any_open && !image) rtcOccluded8(valid, scene_, &context, &packet);
  } else if (!image) {
    rtcOccluded8(valid, scene_, &context, &packet);
  }
  if (image) {
    RayPacket8 open = rays;
    for (int k = 0; k < 8; ++k) open.valid[k] = valid[k] != 0 && packet.tfar[k] >= 0.0f;
    bool surface_hit[8];
    image_surface_->occluded8(open, surface_hit);
    for (int k = 0; k < 8; ++k)
      occluded_out[k] = rays.valid[k] != 0 && (packet.tfar[k] < 0.0f || surface_hit[k]);
    return;
  }
  for (int k = 0; k < 8; ++k) occluded_out[k] = rays.valid[k] != 0 && packet.tfar[k] < 0.0f;
}

float OccluderScene::intersect_distance(const std::array<float, 3>& origin,
                                        const std::array<float, 3>& direction, float t_near,
                                        float t_far) const {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRayHit hit;
  hit.ray.org_x = origin[0];
  hit.ray.org_y = origin[1];
  hit.ray.org_z = origin[2];
  hit.ray.tnear = t_near;
  hit.ray.dir_x = direction[0];
  hit.ray.dir_y = direction[1];
  hit.ray.dir_z = direction[2];
  hit.ray.time = 0.0f;
  hit.ray.tfar = t_far;
  hit.ray.mask = 0xFFFFFFFFu;
  hit.ray.id = 0;
  hit.ray.flags = 0;
  hit.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  hit.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  // The surface's nearest hit from the image's walk whenever the scene has it, also once the
  // BVH is built (build_surface_bvh), so that a scene answers the same before and after, bit
  // for bit (and the render's output with it). Embree's quad test rounds t differently, and
  // misses rays that run exactly through the shared diagonal of a pixel's two triangles, as the
  // camera rays through the fine pixels' centres do on a mesh of half the resolution (a coarse
  // pixel's diagonal passes through two of its four fine pixels' centres); the watertight test
  // hits them. (intersect_distance serves camera rays: a single pixel of the walk.)
  bool surface_hit = false;
  if (image_surface_) {
    const float t = image_surface_->intersect_distance(origin, direction, t_near, t_far);
    surface_hit = t < kInfF;
    if (surface_hit) hit.ray.tfar = t;
  } else {
    rtcIntersect1(scene_, &context, &hit);
    surface_hit = hit.hit.geomID != RTC_INVALID_GEOMETRY_ID;
  }
  // Then the extrusions and blockers, no farther than the surface's hit (tfar is now its t).
  if (extra_scene_) rtcIntersect1(extra_scene_, &context, &hit);
  return surface_hit || hit.hit.geomID != RTC_INVALID_GEOMETRY_ID ? hit.ray.tfar : kInfF;
}

float ambient_occlusion(const OccluderScene& scene, const std::array<float, 3>& point,
                        const std::array<float, 3>& normal, int ray_count, float max_distance_m,
                        std::uint32_t seed, const std::array<float, 3>& pole, int partial_ray_count,
                        int* rays_traced) {
  if (ray_count < 1)
    throw Error(ErrorCode::invalid_argument,
                "ambient occlusion needs at least 1 ray, got " + std::to_string(ray_count));
  if (partial_ray_count > ray_count && partial_ray_count % ray_count != 0)
    throw Error(ErrorCode::invalid_argument,
                "ambient occlusion: " + std::to_string(partial_ray_count) +
                    " rays where occlusion is partial is not a multiple of " +
                    std::to_string(ray_count));
  if (!(max_distance_m > 0) || !std::isfinite(max_distance_m))
    throw Error(ErrorCode::invalid_argument, "ambient occlusion distance must be positive, got " +
                                                 std::to_string(max_distance_m) + " m");
  const double n_len = std::sqrt(double(normal[0]) * normal[0] + double(normal[1]) * normal[1] +
                                 double(normal[2]) * normal[2]);
  if (!(n_len > 0) || !std::isfinite(n_len))
    throw Error(ErrorCode::invalid_argument, "ambient occlusion normal is zero or not finite");
  const physics::Float3 n{normal[0] / n_len, normal[1] / n_len, normal[2] / n_len};
  physics::Float3 t1, t2;
  physics::ao_frame(n, physics::normalize(physics::Float3{pole[0], pole[1], pole[2]}), t1, t2);

  // Start just off the surface: float positions far from the world origin are coarser.
  const double point_norm = std::sqrt(double(point[0]) * point[0] + double(point[1]) * point[1] +
                                      double(point[2]) * point[2]);
  const float offset_m = float(std::max(1e-4, 1e-4 * point_norm));
  const float origin[3] = {float(point[0] + offset_m * n.x), float(point[1] + offset_m * n.y),
                           float(point[2] + offset_m * n.z)};

  // The first ray_count rays are every stride-th of the whole set (itself a low-discrepancy
  // set); where they disagree, the rest.
  const int total = std::max(ray_count, partial_ray_count);
  const int stride = total / ray_count;
  const std::uint32_t stream = physics::ao_stream(seed);
  // The set's local directions (a sincos each) are the same at every point: kept per thread for
  // the last (stream, total, stride) asked, so a render computes them once per thread.
  struct LocalSet {
    std::uint32_t stream = 0;
    int total = -1, stride = 0;
    std::vector<physics::Float3> local;
  };
  thread_local LocalSet set;
  if (set.stream != stream || set.total != total || set.stride != stride) {
    set.local.resize(std::size_t(total));
    for (int i = 0; i < total; ++i)
      set.local[std::size_t(i)] = physics::ao_local_direction(stream, i, total, stride);
    set.stream = stream;
    set.total = total;
    set.stride = stride;
  }
  int open = 0;
  auto trace = [&](int first, int count, int step) {
    occluded_rays(
        scene, std::size_t(count),
        [&](std::size_t k) {
          const int index = first + int(k) * step;
          const physics::Float3 dir =
              physics::ao_world_direction(set.local[std::size_t(index)], n, t1, t2);
          return ShadowRay{{origin[0], origin[1], origin[2]},
                           {float(dir.x), float(dir.y), float(dir.z)},
                           0.0f,
                           max_distance_m};
        },
        [&](std::size_t, bool blocked) { open += blocked ? 0 : 1; });
  };
  trace(0, ray_count, stride);
  if (stride == 1 || open == 0 || open == ray_count) {
    if (rays_traced) *rays_traced = ray_count;
    return float(open) / float(ray_count);
  }
  for (int first = 1; first < stride; ++first) trace(first, ray_count, stride);
  if (rays_traced) *rays_traced = ray_count * stride;
  return float(open) / float(ray_count * stride);
}

}  // namespace mr::render
