#include "render/huge_pages.h"

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <new>
#include <vector>

#if defined(__linux__)
#include <sys/mman.h>
#include <sys/prctl.h>
#endif

namespace mr::render {

namespace {

constexpr std::size_t kHuge = std::size_t(2) << 20;
// The least the pool maps at once (acquire_huge_block).
constexpr std::size_t kChunk = std::size_t(128) << 20;

std::size_t whole_pages(std::size_t bytes) {
  return (std::max<std::size_t>(bytes, 1) + kHuge - 1) / kHuge * kHuge;
}

#if defined(__linux__)
// Fresh, 2 MiB-aligned anonymous memory (mapped 2 MiB more, then trimmed to the alignment), so
// that any 2 MiB-aligned piece of it can later be unmapped on its own.
void* map_block(std::size_t bytes) {
  void* raw =
      mmap(nullptr, bytes + kHuge, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (raw == MAP_FAILED) throw std::bad_alloc();
  const auto start = reinterpret_cast<std::uintptr_t>(raw);
  const auto aligned = (start + kHuge - 1) & ~std::uintptr_t(kHuge - 1);
  if (aligned > start) munmap(raw, aligned - start);
  const std::uintptr_t end = aligned + bytes, raw_end = start + bytes + kHuge;
  if (raw_end > end) munmap(reinterpret_cast<void*>(end), raw_end - end);
  void* block = reinterpret_cast<void*>(aligned);
  advise_huge_pages(block, bytes);
  return block;
}

void unmap_block(void* block, std::size_t bytes) noexcept {
  munmap(block, bytes);
}

// The released blocks (never destroyed: arrays may be released during static destruction).
struct Pool {
  std::mutex mutex;
  struct Block {
    char* data;
    std::size_t bytes;
  };
  std::vector<Block> blocks;
  std::size_t held = 0;
};

Pool& pool() {
  static Pool* const p = new Pool;
  return *p;
}
#endif

}  // namespace

bool balloon_reports_free_pages(const std::string& virtio_balloon_driver) {
  constexpr std::size_t kReportingBit = 5;  // VIRTIO_BALLOON_F_REPORTING
  std::error_code error;
  for (std::filesystem::directory_iterator it(virtio_balloon_driver, error), end;
       !error && it != end; it.increment(error)) {
    // The driver's directory lists its bound devices as links named virtio<N>.
    if (it->path().filename().string().rfind("virtio", 0) != 0) continue;
    std::ifstream features(it->path() / "features");
    std::string bits;
    if (features >> bits && bits.size() > kReportingBit && bits[kReportingBit] == '1') return true;
  }
  return false;
}

bool huge_pages_wanted() {
  static const bool wanted = [] {
#if defined(__linux__)
    bool want = !balloon_reports_free_pages("/sys/bus/virtio/drivers/virtio_balloon");
    if (const char* v = std::getenv("MR_HUGE_PAGES")) {
      const std::string value = v;
      if (value == "on") want = true;
      if (value == "off") want = false;
    }
    // Embree advises huge pages for its own blocks whatever its configuration says (its
    // os_malloc), and its BVH is most of a fresh render's new memory: only the process-wide
    // switch keeps those on 4 KiB pages too.
    if (!want) prctl(PR_SET_THP_DISABLE, 1, 0, 0, 0);
    return want;
#else
    return false;
#endif
  }();
  return wanted;
}

const char* embree_device_config() {
  return huge_pages_wanted() ? nullptr : "hugepages=0";
}

void advise_huge_pages(const void* data, std::size_t bytes) {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  if (!data || bytes < 2 * kHuge || !huge_pages_wanted()) return;
  // The whole huge pages inside the range only: the ends may share a page with other
  // allocations, whose backing this must not change.
  const auto begin = (reinterpret_cast<std::uintptr_t>(data) + kHuge - 1) & ~(kHuge - 1);
  const auto end = (reinterpret_cast<std::uintptr_t>(data) + bytes) & ~(kHuge - 1);
  if (end > begin) madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);
#else
  (void)data;
  (void)bytes;
#endif
}

#if defined(__linux__)

void* acquire_huge_block(std::size_t bytes) {
  bytes = whole_pages(bytes);
  {
    Pool& p = pool();
    const std::lock_guard lock(p.mutex);
    // The smallest block that is large enough; the rest of it stays in the pool.
    std::size_t best = p.blocks.size();
    for (std::size_t i = 0; i < p.blocks.size(); ++i)
      if (p.blocks[i].bytes >= bytes &&
          (best == p.blocks.size() || p.blocks[i].bytes < p.blocks[best].bytes))
        best = i;
    if (best < p.blocks.size()) {
      Pool::Block& b = p.blocks[best];
      char* block = b.data;
      b.data += bytes;
      b.bytes -= bytes;
      if (b.bytes == 0) p.blocks.erase(p.blocks.begin() + std::ptrdiff_t(best));
      p.held -= bytes;
      return block;
    }
  }
  // A fresh mapping of at least kChunk: the rest goes to the pool, so that the next requests
  // are carved from the same range and later releases join into large blocks again (pages
  // never touched cost nothing).
  const std::size_t mapped = std::max(bytes, kChunk);
  char* block = static_cast<char*>(map_block(mapped));
  if (mapped > bytes) release_huge_block(block + bytes, mapped - bytes);
  return block;
}

void release_huge_block(void* block, std::size_t bytes) noexcept {
  if (!block) return;
  bytes = whole_pages(bytes);
  Pool& p = pool();
  {
    const std::lock_guard lock(p.mutex);
    bool noted = p.held + bytes <= kHugePagePoolBytes;
    if (noted) {
      try {
        p.blocks.reserve(p.blocks.size() + 1);
      } catch (...) {  // no room to note it: unmap it below
        noted = false;
      }
    }
    if (noted) {
      // Joined with the pieces next to it (split from the same mapping earlier), so that
      // repeated renders find their large blocks whole again.
      char* data = static_cast<char*>(block);
      std::size_t size = bytes;
      for (std::size_t i = 0; i < p.blocks.size();) {
        const Pool::Block b = p.blocks[i];
        if (b.data + b.bytes == data || data + size == b.data) {
          data = std::min(data, b.data);
          size += b.bytes;
          p.blocks[i] = p.blocks.back();
          p.blocks.pop_back();
        } else {
          ++i;
        }
      }
      p.blocks.push_back({data, size});
      p.held += bytes;
      return;
    }
  }
  unmap_block(block, bytes);
}

std::size_t trim_huge_page_pool() noexcept {
  Pool& p = pool();
  std::vector<Pool::Block> blocks;
  std::size_t held = 0;
  {
    const std::lock_guard lock(p.mutex);
    blocks.swap(p.blocks);
    held = std::exchange(p.held, 0);
  }
  for (const Pool::Block& b : blocks) unmap_block(b.data, b.bytes);
  return held;
}

std::size_t huge_page_pool_bytes() noexcept {
  Pool& p = pool();
  const std::lock_guard lock(p.mutex);
  return p.held;
}

#else  // no pool: aligned heap blocks

void* acquire_huge_block(std::size_t bytes) {
  void* p = std::aligned_alloc(kHuge, whole_pages(bytes));
  if (!p) throw std::bad_alloc();
  return p;
}

void release_huge_block(void* block, std::size_t) noexcept {
  std::free(block);
}

std::size_t trim_huge_page_pool() noexcept {
  return 0;
}

std::size_t huge_page_pool_bytes() noexcept {
  return 0;
}

#endif

}  // namespace mr::render
