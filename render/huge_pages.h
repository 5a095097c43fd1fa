// Private to libmr: the occluder geometry's large buffers on transparent huge pages where they
// pay (issue 12 item 4; huge_pages_wanted below).
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
#include <string>
#include <type_traits>
#include <utility>

namespace mr::render {

/// Whether this process asks for transparent huge pages (decided once, on first use).
///
/// Not on a virtual machine whose balloon device takes back free memory (virtio's free page
/// reporting, as Firecracker and cloud sandboxes run): the guest reports free blocks of 2 MiB
/// and more to the hypervisor, which drops their backing, and a huge page is exactly such a
/// block, so its first touch faults in the host as well. On the 2-core development VM of
/// 2026-12-07 (Linux 6.18, Firecracker, reporting on) touching 640 MB of fresh memory took
/// 2.1-2.3 s on huge pages after a few idle seconds and 0.26-0.33 s on 4 KiB pages; a fresh
/// 1080p normal render (BM_Stages) took 2.0-2.45 s with them and 1.66-1.85 s without (system
/// CPU 0.76-0.93 s against 0.19-0.29 s; render CPU unchanged). Elsewhere huge pages stay: on
/// the VM of earlier sessions a 4 KiB fault cost ~12 us and huge pages made the geometry's
/// faults ~50x cheaper (the note at the top of this file).
///
/// Where the answer is no, the process's transparent huge pages are switched off as a whole
/// (Linux prctl(PR_SET_THP_DISABLE); children and exec'd programs inherit it), because Embree
/// advises them for its BVH whatever its configuration says. The environment variable
/// MR_HUGE_PAGES=on|off overrides the decision (benchmarks, machines this rule misjudges).
bool huge_pages_wanted();
/// Whether a virtio balloon device bound to its driver under `virtio_balloon_driver` (normally
/// /sys/bus/virtio/drivers/virtio_balloon) negotiated free page reporting (feature bit 5 of
/// its `features` file, which lists bits 0, 1, ... as '0' / '1'). False when nothing is there
/// or readable.
bool balloon_reports_free_pages(const std::string& virtio_balloon_driver);
/// The configuration for rtcNewDevice matching huge_pages_wanted(): Embree's defaults (huge
/// pages on Linux) or "hugepages=0".
const char* embree_device_config();

/// Asks the kernel to back the whole 2 MiB pages inside [data, data + bytes) with transparent
/// huge pages when they are first touched (Linux madvise(MADV_HUGEPAGE); elsewhere, for
/// ranges under 4 MiB, or where huge_pages_wanted() says no, nothing). Call it before the range is
/// first written: pages already present stay as they are. Changes no contents and no addresses;
/// failures are ignored (the memory then stays on ordinary pages).
void advise_huge_pages(const void* data, std::size_t bytes);

/// A block of `bytes` (rounded up to whole 2 MiB pages), 2 MiB-aligned, advised for huge pages
/// (advise_huge_pages), uninitialized: from the process's pool of released blocks when one is
/// large enough, else freshly mapped. Throws std::bad_alloc. Thread-safe.
///
/// Why a pool (issue 12 item 4): on the development VM the first touch of fresh memory costs
/// ~1-5 ms per MB even on huge pages (the kernel zeroes it, and the hypervisor maps it), ~30x a
/// memset of memory already mapped. A 1080p render's geometry and passes allocate ~280 MB of
/// scratch one after another (the normals' and the mesh's samples, the mesh's planes and corner
/// tables, the render's per-pixel AO, sun visibility, grid samples, gradients and the photo
/// fallback's points): released blocks serve the next stage's requests instead of being
/// unmapped and mapped afresh (a larger block is split at 2 MiB boundaries, and released
/// neighbours are joined). Fresh memory is mapped 128 MiB at least, the rest going to the pool,
/// so that consecutive requests lie side by side and join into large blocks when released
/// (pages never touched cost nothing). The pool keeps at most kHugePagePoolBytes; what a
/// release would put beyond that is unmapped.
void* acquire_huge_block(std::size_t bytes);
/// Returns a block of acquire_huge_block (the same `bytes`) to the pool (or unmaps it).
void release_huge_block(void* block, std::size_t bytes) noexcept;
/// Unmaps every block the pool holds (e.g. when a long-running process goes idle); returns the
/// bytes it held.
std::size_t trim_huge_page_pool() noexcept;
/// The bytes the pool holds now (for tests and reports).
std::size_t huge_page_pool_bytes() noexcept;
/// The most the pool keeps: a 4K render's scratch is about four times the 1080p figure above.
inline constexpr std::size_t kHugePagePoolBytes = std::size_t(1) << 30;

/// An uninitialized array of n trivially copyable T, 2 MiB-aligned and advised for huge pages
/// (acquire_huge_block), for scratch buffers that a parallel loop fills entirely: no zeroing
/// pass (std::vector value-initializes its elements serially, touching every page from one
/// thread first). Its memory comes from and goes back to the pool of acquire_huge_block, so
/// its contents start as whatever the block last held: every element must be written before
/// it is read.
template <class T>
class HugePageArray {
  static_assert(std::is_trivially_copyable_v<T> && std::is_trivially_destructible_v<T>);

 public:
  explicit HugePageArray(std::size_t n)
      : data_(static_cast<T*>(acquire_huge_block(std::max<std::size_t>(n * sizeof(T), 1)))),
        size_(n) {}
  ~HugePageArray() {
    if (data_) release_huge_block(data_, std::max<std::size_t>(size_ * sizeof(T), 1));
  }
  HugePageArray(HugePageArray&& other) noexcept
      : data_(std::exchange(other.data_, nullptr)), size_(std::exchange(other.size_, 0)) {}
  HugePageArray& operator=(HugePageArray&& other) noexcept {
    if (this != &other) {
      if (data_) release_huge_block(data_, std::max<std::size_t>(size_ * sizeof(T), 1));
      data_ = std::exchange(other.data_, nullptr);
      size_ = std::exchange(other.size_, 0);
    }
    return *this;
  }
  HugePageArray(const HugePageArray&) = delete;
  HugePageArray& operator=(const HugePageArray&) = delete;
  T* data() { return data_; }
  const T* data() const { return data_; }
  std::size_t size() const { return size_; }
  T& operator[](std::size_t i) { return data_[i]; }
  const T& operator[](std::size_t i) const { return data_[i]; }

 private:
  T* data_ = nullptr;  // null only when moved from
  std::size_t size_ = 0;
};

}  // namespace mr::render
