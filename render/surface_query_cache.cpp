#include "render/surface_query_cache.h"

#include <atomic>
#include <bit>
#include <new>

#include "mr/error.h"

namespace mr::render {

namespace {

template <typename T, typename Deleter>
void allocate_zeroed(std::unique_ptr<T[], Deleter>& array, std::size_t count) {
  array.reset(static_cast<T*>(std::calloc(count, sizeof(T))));
  if (!array) throw std::bad_alloc();
}

// At most this many sun-disk rays fit the one-byte count (seen + 1).
constexpr std::size_t kMaxSunDiskRays = 254;

bool same_ambient_occlusion(const SurfaceQuerySettings& a, const SurfaceQuerySettings& b) {
  return a.mesh_step == b.mesh_step && a.ao_rays == b.ao_rays &&
         a.ao_partial_rays == b.ao_partial_rays && a.seed == b.seed &&
         a.camera_forward == b.camera_forward;
}

}  // namespace

SurfaceQueryCache::SurfaceQueryCache(int width_px, int height_px)
    : width_(width_px), height_(height_px) {
  if (width_px <= 0 || height_px <= 0)
    throw Error(ErrorCode::invalid_argument, "SurfaceQueryCache: the image size must be positive");
  reset_ambient_occlusion();
  reset_sun_disk();
}

void SurfaceQueryCache::reset_ambient_occlusion() {
  allocate_zeroed(ao_, std::size_t(width_) * std::size_t(height_));
}

void SurfaceQueryCache::reset_sun_disk() {
  allocate_zeroed(sun_disk_, std::size_t(width_) * std::size_t(height_));
}

void SurfaceQueryCache::use(const SurfaceQuerySettings& settings) {
  if (settings_) {
    // The sun disk's rays start where shadow_origin puts them (mesh_step), like the AO's.
    const bool same_ao = same_ambient_occlusion(*settings_, settings);
    if (!same_ao) reset_ambient_occlusion();
    if (!same_ao || settings_->sun_disk_directions != settings.sun_disk_directions)
      reset_sun_disk();
  }
  settings_ = settings;
}

std::optional<float> SurfaceQueryCache::ambient_occlusion(int x, int y) const {
  if (!settings_) return std::nullopt;
  const std::uint32_t stored = std::atomic_ref(ao_[index(x, y)]).load(std::memory_order_relaxed);
  if (stored == 0) return std::nullopt;
  return std::bit_cast<float>(stored - 1);
}

void SurfaceQueryCache::set_ambient_occlusion(int x, int y, float ao) {
  if (!settings_) return;
  std::atomic_ref(ao_[index(x, y)])
      .store(std::bit_cast<std::uint32_t>(ao) + 1, std::memory_order_relaxed);
}

std::optional<int> SurfaceQueryCache::sun_disk_seen(int x, int y) const {
  if (!settings_ || settings_->sun_disk_directions.size() > kMaxSunDiskRays) return std::nullopt;
  const std::uint8_t stored =
      std::atomic_ref(sun_disk_[index(x, y)]).load(std::memory_order_relaxed);
  if (stored == 0) return std::nullopt;
  return int(stored) - 1;
}

void SurfaceQueryCache::set_sun_disk_seen(int x, int y, int seen) {
  if (!settings_ || settings_->sun_disk_directions.size() > kMaxSunDiskRays || seen < 0 ||
      std::size_t(seen) > settings_->sun_disk_directions.size())
    return;
  std::atomic_ref(sun_disk_[index(x, y)]).store(std::uint8_t(seen + 1), std::memory_order_relaxed);
}

std::unique_ptr<SurfaceQueryCache> SurfaceQuerySlot::take(int width_px, int height_px) const {
  std::unique_ptr<SurfaceQueryCache> cache;
  {
    const std::lock_guard lock(mutex_);
    cache = std::move(cache_);
  }
  if (cache && cache->width() == width_px && cache->height() == height_px) return cache;
  return std::make_unique<SurfaceQueryCache>(width_px, height_px);
}

void SurfaceQuerySlot::give_back(std::unique_ptr<SurfaceQueryCache> cache) const {
  const std::lock_guard lock(mutex_);
  cache_ = std::move(cache);
}

}  // namespace mr::render
