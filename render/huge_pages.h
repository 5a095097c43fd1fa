// Private to libmr: the occluder geometry's large buffers on transparent huge pages (issue 12
// item 4).
//
// Building the 1080p occluder geometry touches ~200 MB of fresh memory (per-pixel samples,
// planes, corner tables, the mesh's vertex and index buffers). Every 4 KiB page of it costs a
// page fault on first touch, and on the 2-core development VM one fault cost ~12 us: 64 MB took
// 195 ms of CPU to fault in, against 4 ms when the kernel could back it with 2 MiB pages
// (madvise(MADV_HUGEPAGE); the kernel's transparent huge pages are commonly in "madvise" mode,
// as there). Faulting, not arithmetic, was then most of the mesh and normals stages.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdlib>
#include <memory>
#include <new>
#include <type_traits>

namespace mr::render {

/// Asks the kernel to back the whole 2 MiB pages inside [data, data + bytes) with transparent
/// huge pages when they are first touched (Linux madvise(MADV_HUGEPAGE); elsewhere, or for
/// ranges under 4 MiB, nothing). Call it before the range is first written: pages already
/// present stay as they are. Changes no contents and no addresses; failures are ignored (the
/// memory then stays on ordinary pages).
void advise_huge_pages(const void* data, std::size_t bytes);

/// An uninitialized array of n trivially copyable T, 2 MiB-aligned and advised for huge pages
/// (advise_huge_pages), for scratch buffers that a parallel loop fills entirely: no zeroing
/// pass (std::vector value-initializes its elements serially, touching every page from one
/// thread first).
template <class T>
class HugePageArray {
  static_assert(std::is_trivially_copyable_v<T> && std::is_trivially_destructible_v<T>);

 public:
  explicit HugePageArray(std::size_t n) : size_(n) {
    constexpr std::size_t kAlign = std::size_t(2) << 20;
    const std::size_t bytes =
        (std::max<std::size_t>(n * sizeof(T), 1) + kAlign - 1) / kAlign * kAlign;
    void* p = std::aligned_alloc(kAlign, bytes);
    if (!p) throw std::bad_alloc();
    data_.reset(static_cast<T*>(p));
    advise_huge_pages(p, bytes);
  }
  T* data() { return data_.get(); }
  const T* data() const { return data_.get(); }
  std::size_t size() const { return size_; }
  T& operator[](std::size_t i) { return data_[i]; }
  const T& operator[](std::size_t i) const { return data_[i]; }

 private:
  struct Free {
    void operator()(T* p) const { std::free(p); }
  };
  std::unique_ptr<T[], Free> data_;
  std::size_t size_ = 0;
};

}  // namespace mr::render
