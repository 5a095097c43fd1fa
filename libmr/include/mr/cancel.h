// mr::CancelToken: cooperative cancellation of a long libmr call (a render) from another thread,
// and the progress that call reports on its way (mr::Progress).
#pragma once

#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string>
#include <string_view>

#include "mr/export.h"

namespace mr {

/// Where a long call stands: the stage it is in and how much of that stage is done, in the
/// stage's own units (image rows of a render, tiles on the GPU, strips of a streamed photo,
/// estimation steps, fitted segments). Within a stage `done` only grows, up to `total`.
struct MR_API Progress {
  std::string_view stage;  ///< "render", "stream", "horizon", "sky mask", ... (valid in the call)
  std::size_t done = 0;
  std::size_t total = 0;  ///< > 0
  /// done / total in [0, 1].
  double fraction() const noexcept { return total ? double(done) / double(total) : 0.0; }
};

/// Called with the progress of a call using the token (see CancelToken::set_progress).
using ProgressCallback = std::function<void(const Progress&)>;

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
///
/// Progress: a token may also carry a callback that the calls using it report their progress to
/// (the CPU core: rows of its passes; Vulkan: tiles; mr::FogStreamer: rows written; estimation:
/// its steps; material transfer: segments fitted). The callback
///  * runs on whichever thread made the progress (a TBB worker), never on two threads at once;
///  * is throttled: at most one call per `min_interval`, except that the start of a stage
///    (done == 0), its end (done == total) and the first report of a new stage always come
///    through; reports that would go backwards (threads finishing rows out of order) are dropped,
///    so within a stage `done` only grows;
///  * must be quick and must not throw (an exception from it is swallowed and requests the
///    cancellation); to stop the call it calls request() on the token.
/// Reporting costs the call a relaxed atomic load per row without a callback, and a clock read
/// per row with one: a render's result never depends on it.
class MR_API CancelToken {
 public:
  CancelToken() = default;
  CancelToken(const CancelToken&) = delete;
  CancelToken& operator=(const CancelToken&) = delete;

  /// Asks every call using this token to stop. Never blocks.
  void request() noexcept { requested_.store(true, std::memory_order_relaxed); }
  bool requested() const noexcept { return requested_.load(std::memory_order_relaxed); }
  void reset() noexcept { requested_.store(false, std::memory_order_relaxed); }

  /// Sets (or, with an empty function, removes) the progress callback and its throttle
  /// interval (0: every report that moves forward). Only while no call is using the token.
  void set_progress(ProgressCallback callback,
                    std::chrono::milliseconds min_interval = std::chrono::milliseconds(100));
  bool has_progress() const noexcept { return has_progress_.load(std::memory_order_relaxed); }

  /// For libmr's calls (and front ends' own long work): `done` of `total` units of `stage`
  /// are finished. Thread-safe; see the class comment for what reaches the callback.
  void report(std::string_view stage, std::size_t done, std::size_t total) const noexcept;

 private:
  mutable std::atomic<bool> requested_{false};  // mutable: a throwing callback requests it
  std::atomic<bool> has_progress_{false};
  ProgressCallback callback_;
  std::int64_t interval_ns_ = 100'000'000;
  mutable std::atomic<std::int64_t> next_report_ns_{0};
  mutable std::atomic<std::size_t> last_stage_hash_{0};  // a new stage skips the throttle
  mutable std::mutex mutex_;  // serialises the callback and guards the two below
  mutable std::string last_stage_;
  mutable std::size_t last_done_ = 0;
  mutable bool reported_any_ = false;
};

/// Throws mr::Error(ErrorCode::cancelled, "<what>: cancelled") when `token` is non-null and
/// requested; else does nothing.
MR_API void throw_if_cancelled(const CancelToken* token, const char* what);

/// token->report(...) when `token` is non-null and carries a progress callback.
inline void report_progress(const CancelToken* token, std::string_view stage, std::size_t done,
                            std::size_t total) noexcept {
  if (token && token->has_progress()) token->report(stage, done, total);
}

/// A stage's shared counter for parallel loops: each worker add()s the units it finished and
/// the new total is reported (throttled by the token). Without a token or callback add() is
/// a branch.
class MR_API ProgressCounter {
 public:
  /// Reports (stage, 0, total) at once.
  ProgressCounter(const CancelToken* token, std::string_view stage, std::size_t total) noexcept
      : token_(token && token->has_progress() ? token : nullptr), stage_(stage), total_(total) {
    if (token_) token_->report(stage_, 0, total_);
  }
  void add(std::size_t units) noexcept {
    if (!token_) return;
    const std::size_t now = done_.fetch_add(units, std::memory_order_relaxed) + units;
    token_->report(stage_, now < total_ ? now : total_, total_);
  }
  /// Reports the stage as complete (e.g. after a loop whose units were not all counted).
  void finish() noexcept {
    if (token_) token_->report(stage_, total_, total_);
  }

 private:
  const CancelToken* token_;
  std::string_view stage_;
  std::size_t total_;
  std::atomic<std::size_t> done_{0};
};

}  // namespace mr
