// Private to libmr: the surface's shadow-query answers of one photo (each surface pixel's ambient
// occlusion and how many of its sun-disk rays pass), kept with the photo's cached occluder
// geometry (render/occluder_cache.h) for its next render (issue 12 item 4). mr-studio re-renders
// a photo for every fog or sun slider change; neither answer depends on the medium, and AO not on
// the sun either, so a fog slider's render traces only its march rays. A render's answers equal a
// fresh render's bit for bit (tests/occluder_cache_test.cpp): an answer is kept only under the
// settings it was computed with (SurfaceQuerySettings), and the geometry it was traced against
// is the cached geometry this cache belongs to.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <mutex>
#include <optional>
#include <vector>

#include "render/math.h"

namespace mr::render {

/// What a pixel's answers depend on besides the geometry (depth map, normals, camera, pose,
/// blockers, mesh: the occluder geometry cache's key).
struct SurfaceQuerySettings {
  // Ambient occlusion (render_scattering_cpu's Core::ambient_occlusion_at).
  int mesh_step = 1;  ///< MarchPlan::mesh_step: where shadow_origin puts a ray's start
  int ao_rays = 0, ao_partial_rays = 0;
  std::uint32_t seed = 0;
  Vec3d camera_forward{};
  // The sun-disk rays (Core::sun_disk_visibility): their directions, exactly.
  std::vector<Vec3d> sun_disk_directions;
};

/// Per-pixel answers for one image size. Unknown answers read as nullopt. Reads and writes of
/// different pixels may run concurrently (each is one relaxed atomic access, so two threads
/// answering the same pixel, with the same value, are not a data race). Memory: 5 bytes a pixel,
/// zero pages until written (only the pixels a render traced for are touched).
class SurfaceQueryCache {
 public:
  SurfaceQueryCache(int width_px, int height_px);

  int width() const { return width_; }
  int height() const { return height_; }

  /// Forgets the answers computed under other settings: the AO when any of its settings
  /// changed, the sun disk's when its settings or directions did (a sun slider keeps the AO).
  void use(const SurfaceQuerySettings& settings);

  std::optional<float> ambient_occlusion(int x, int y) const;
  void set_ambient_occlusion(int x, int y, float ao);
  /// How many of the pixel's sun-disk rays pass (0 .. sun_disk_directions.size()).
  std::optional<int> sun_disk_seen(int x, int y) const;
  void set_sun_disk_seen(int x, int y, int seen);

 private:
  struct Free {
    void operator()(void* p) const { std::free(p); }
  };
  std::size_t index(int x, int y) const { return std::size_t(y) * std::size_t(width_) + x; }
  void reset_ambient_occlusion();
  void reset_sun_disk();

  int width_ = 0, height_ = 0;
  std::optional<SurfaceQuerySettings> settings_;
  // AO: the float's bits + 1 (0: unknown); sun disk: rays seen + 1 (0: unknown). calloc'd, so
  // pages no render wrote to are never backed.
  std::unique_ptr<std::uint32_t[], Free> ao_;
  std::unique_ptr<std::uint8_t[], Free> sun_disk_;
};

/// The slot a cached geometry keeps its cache in: a render takes the cache for its run (no
/// locking while it renders) and gives it back afterwards. A render that finds the slot empty
/// (the first, or one running beside another) starts an empty cache; the last one given back
/// stays.
class SurfaceQuerySlot {
 public:
  /// The kept cache when it is for this image size, else a new empty one.
  std::unique_ptr<SurfaceQueryCache> take(int width_px, int height_px) const;
  void give_back(std::unique_ptr<SurfaceQueryCache> cache) const;

 private:
  mutable std::mutex mutex_;
  mutable std::unique_ptr<SurfaceQueryCache> cache_;
};

}  // namespace mr::render
