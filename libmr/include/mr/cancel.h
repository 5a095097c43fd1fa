// mr::CancelToken: cooperative cancellation of a long libmr call (a render) from another thread.
#pragma once

#include <atomic>

namespace mr {

/// A flag one thread raises to ask a running libmr call, which was handed a pointer to it, to
/// stop early. The call checks it at its natural boundaries (the CPU core between image rows,
/// the Vulkan backend between tiles and stages, the dispatcher between mesh, BVH and marching),
/// so it returns within about one row's or one tile's work of the request, by throwing
/// mr::Error(ErrorCode::cancelled); it then leaves nothing behind (its outputs are dropped).
/// A call that is never cancelled returns exactly what it returns without a token.
///
/// The token is owned by the caller and must outlive the call. request() and requested() are
/// safe from any thread at any time; a token stays requested until reset() (call reset() only
/// when no call is using it). Not copyable: share it by pointer.
class CancelToken {
 public:
  CancelToken() = default;
  CancelToken(const CancelToken&) = delete;
  CancelToken& operator=(const CancelToken&) = delete;

  /// Asks every call using this token to stop. Never blocks.
  void request() noexcept { requested_.store(true, std::memory_order_relaxed); }
  bool requested() const noexcept { return requested_.load(std::memory_order_relaxed); }
  void reset() noexcept { requested_.store(false, std::memory_order_relaxed); }

 private:
  std::atomic<bool> requested_{false};
};

/// Throws mr::Error(ErrorCode::cancelled, "<what>: cancelled") when `token` is non-null and
/// requested; else does nothing.
void throw_if_cancelled(const CancelToken* token, const char* what);

}  // namespace mr
