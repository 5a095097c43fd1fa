#include "progress.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace mr::cli {
namespace {

std::string shortened(const std::string& name, std::size_t max) {
  return name.size() > max ? "..." + name.substr(name.size() - (max - 3)) : name;
}

// Bar redraws from progress reports at most this often (finished photos and messages redraw
// at once).
constexpr auto kRedrawInterval = std::chrono::milliseconds(100);

}  // namespace

Reporter::Reporter(std::size_t total, bool quiet, bool verbose, int tty)
    : total_(total),
      quiet_(quiet),
      verbose_(verbose),
      tty_(tty < 0 ? ::isatty(STDERR_FILENO) == 1 : tty != 0) {}

void Reporter::clear_bar_locked() {
  if (bar_visible_) std::fputs("\r\033[K", stderr);
  bar_visible_ = false;
}

void Reporter::draw_bar_locked() {
  if (quiet_ || !tty_ || total_ == 0) return;
  constexpr int kWidth = 30;
  // Photos done plus the fractions of those in flight.
  double progress = double(done_);
  for (const InFlight& p : in_flight_) progress += p.fraction;
  const int filled = std::clamp(int(kWidth * progress / double(total_)), 0, kWidth);
  std::string bar(std::size_t(filled), '=');
  bar.resize(kWidth, ' ');
  std::string text;
  if (!in_flight_.empty()) {
    // The photo that has gone least far: the one the batch waits for.
    const InFlight* slowest = &in_flight_.front();
    for (const InFlight& p : in_flight_)
      if (p.fraction < slowest->fraction) slowest = &p;
    text = shortened(slowest->name, 40);
    if (!slowest->stage.empty()) {
      char pct[32];
      std::snprintf(pct, sizeof pct, " %d%%", int(std::floor(100 * slowest->stage_fraction)));
      text += ": " + slowest->stage + pct;
    }
    if (in_flight_.size() > 1) text += " (+" + std::to_string(in_flight_.size() - 1) + ")";
  } else {
    text = shortened(last_name_, 40);
  }
  if (total_ > 1)
    std::fprintf(stderr, "\r\033[K[%s] %zu/%zu %s", bar.c_str(), done_, total_, text.c_str());
  else
    std::fprintf(stderr, "\r\033[K[%s] %s", bar.c_str(), text.c_str());
  std::fflush(stderr);
  bar_visible_ = true;
  last_draw_ = std::chrono::steady_clock::now();
}

void Reporter::error(const std::string& message) {
  std::lock_guard lock(mutex_);
  clear_bar_locked();
  std::fprintf(stderr, "ERROR: %s\n", message.c_str());
  draw_bar_locked();
}

void Reporter::warning(const std::string& message) {
  std::lock_guard lock(mutex_);
  if (quiet_) return;
  clear_bar_locked();
  std::fprintf(stderr, "WARNING: %s\n", message.c_str());
  draw_bar_locked();
}

void Reporter::info(const std::string& message) {
  std::lock_guard lock(mutex_);
  if (quiet_) return;
  clear_bar_locked();
  std::fprintf(stderr, "%s\n", message.c_str());
  draw_bar_locked();
}

void Reporter::advance(const std::string& name) {
  std::lock_guard lock(mutex_);
  ++done_;
  last_name_ = name;
  draw_bar_locked();
}

void Reporter::finish() {
  std::lock_guard lock(mutex_);
  clear_bar_locked();
  std::fflush(stderr);
}

void Reporter::update(InFlight& photo, const Progress& p, double fraction) {
  std::lock_guard lock(mutex_);
  const bool new_stage = photo.stage != p.stage;
  photo.stage.assign(p.stage);
  photo.stage_fraction = p.fraction();
  photo.fraction = std::max(photo.fraction, fraction);
  const auto now = std::chrono::steady_clock::now();
  if (tty_) {
    if (new_stage || now - last_draw_ >= kRedrawInterval) draw_bar_locked();
    return;
  }
  // A pipe: lines, and only with -v: a stage's start, then at most one per kNoteIntervalS.
  if (!verbose_ || quiet_) return;
  if (!new_stage && std::chrono::duration<double>(now - photo.last_note).count() < kNoteIntervalS)
    return;
  photo.last_note = now;
  if (new_stage)
    std::fprintf(stderr, "note: %s: %s\n", photo.name.c_str(), photo.stage.c_str());
  else
    std::fprintf(stderr, "note: %s: %s %d%%\n", photo.name.c_str(), photo.stage.c_str(),
                 int(std::floor(100 * photo.stage_fraction)));
  std::fflush(stderr);
}

std::vector<std::string> estimate_stages() {
  return {"horizon", "sky mask", "depth", "refine", "light"};
}

PhotoProgress::PhotoProgress(Reporter& reporter, const std::string& name, std::vector<Phase> phases)
    : reporter_(reporter), phases_(std::move(phases)) {
  for (const Phase& p : phases_) weight_sum_ += p.weight;
  {
    std::lock_guard lock(reporter_.mutex_);
    reporter_.in_flight_.push_back({name, "", 0, 0, {}});
    entry_ = std::prev(reporter_.in_flight_.end());
  }
  if (reporter_.shows_progress())
    token_.set_progress([this](const Progress& p) { on_progress(p); });
}

PhotoProgress::~PhotoProgress() {
  std::lock_guard lock(reporter_.mutex_);
  reporter_.in_flight_.erase(entry_);
}

void PhotoProgress::on_progress(const Progress& p) {
  // The photo's fraction: the phases before this stage's done, plus its share of this one.
  double before = 0, fraction = -1;
  for (const Phase& phase : phases_) {
    if (std::find(phase.stages.begin(), phase.stages.end(), p.stage) != phase.stages.end()) {
      fraction = (before + phase.weight * p.fraction()) / weight_sum_;
      break;
    }
    before += phase.weight;
  }
  reporter_.update(*entry_, p, fraction);
}

}  // namespace mr::cli
