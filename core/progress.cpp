// mr::CancelToken's progress reports (mr/cancel.h): throttled, forward-only, serialised.
#include <algorithm>
#include <chrono>
#include <functional>

#include "mr/cancel.h"

namespace mr {
namespace {

std::int64_t now_ns() noexcept {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace

void CancelToken::set_progress(ProgressCallback callback, std::chrono::milliseconds min_interval) {
  std::lock_guard lock(mutex_);
  callback_ = std::move(callback);
  interval_ns_ = std::max<std::int64_t>(0, std::chrono::nanoseconds(min_interval).count());
  next_report_ns_.store(0, std::memory_order_relaxed);
  last_stage_.clear();
  last_done_ = 0;
  reported_any_ = false;
  last_stage_hash_.store(0, std::memory_order_relaxed);
  has_progress_.store(bool(callback_), std::memory_order_relaxed);
}

void CancelToken::report(std::string_view stage, std::size_t done,
                         std::size_t total) const noexcept {
  if (!has_progress_.load(std::memory_order_relaxed) || total == 0) return;
  if (done > total) done = total;
  // The start and end of a stage always come through (a stage change is only known under the
  // lock: a middle report of a new stage may be throttled, its end never is).
  const std::size_t hash = std::hash<std::string_view>{}(stage);
  const bool milestone =
      done == 0 || done == total || hash != last_stage_hash_.load(std::memory_order_relaxed);
  const std::int64_t now = interval_ns_ > 0 && !milestone ? now_ns() : 0;
  if (!milestone && now < next_report_ns_.load(std::memory_order_relaxed)) return;
  std::unique_lock lock(mutex_, std::defer_lock);
  if (milestone) {
    lock.lock();
  } else if (!lock.try_lock()) {
    return;  // another thread is reporting: this one's news is about as fresh
  }
  const bool same_stage = reported_any_ && last_stage_ == stage;
  if (same_stage && done <= last_done_ && done != 0) return;  // late or repeated: not news
  if (!milestone && same_stage && now < next_report_ns_.load(std::memory_order_relaxed)) return;
  if (!same_stage) {
    last_stage_.assign(stage);
    last_stage_hash_.store(hash, std::memory_order_relaxed);
  }
  last_done_ = done;
  reported_any_ = true;
  if (interval_ns_ > 0)
    next_report_ns_.store((now ? now : now_ns()) + interval_ns_, std::memory_order_relaxed);
  try {
    callback_(Progress{stage, done, total});
  } catch (...) {
    requested_.store(true, std::memory_order_relaxed);
  }
}

}  // namespace mr
