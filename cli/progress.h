// Terminal output for the commands: errors, warnings, notes and a progress bar that never
// interleave. The bar (stderr a terminal, not --quiet) shows the photos done and, inside the
// photos in flight, their current stage and fraction (mr::Progress, reported by libmr through a
// CancelToken each photo's work carries: PhotoProgress). Where stderr is not a terminal nothing
// is drawn; with -v the progress comes as occasional note lines instead.
#pragma once

#include <chrono>
#include <cstddef>
#include <list>
#include <mutex>
#include <string>
#include <vector>

#include "mr/cancel.h"

namespace mr::cli {

class PhotoProgress;

class Reporter {
 public:
  /// `total`: photos. `quiet`: only errors. `verbose`: also progress notes when stderr is not a
  /// terminal. `tty`: whether stderr is a terminal (default: asked of the system).
  Reporter(std::size_t total, bool quiet, bool verbose = false, int tty = -1);
  /// "ERROR: <message>" on stderr (oiiotool's convention).
  void error(const std::string& message);
  void warning(const std::string& message);
  void info(const std::string& message);
  /// One more job finished; redraws the bar.
  void advance(const std::string& name);
  /// Erases the bar (before the summary, or before a report on stdout).
  void finish();
  /// Whether progress inside photos is shown (a bar, or -v notes): only then do photos' calls
  /// get a token (PhotoProgress::token), so that a pipe's run is exactly as without progress.
  bool shows_progress() const { return !quiet_ && (tty_ || verbose_); }

  /// Seconds between -v progress notes of one stage (its start is always noted).
  static constexpr double kNoteIntervalS = 5.0;

 private:
  friend class PhotoProgress;
  struct InFlight {
    std::string name, stage;
    double fraction = 0;  ///< of the photo's whole work
    double stage_fraction = 0;
    std::chrono::steady_clock::time_point last_note{};
  };
  void clear_bar_locked();
  void draw_bar_locked();
  void update(InFlight& photo, const Progress& p, double fraction);

  std::mutex mutex_;
  std::size_t total_, done_ = 0;
  bool quiet_, verbose_, tty_, bar_visible_ = false;
  std::string last_name_;
  std::list<InFlight> in_flight_;  // stable addresses: PhotoProgress keeps an iterator
  std::chrono::steady_clock::time_point last_draw_{};
};

/// The stages of a photo's work in the order they run, with their shares of its time (relative
/// weights). A stage not listed keeps the photo's fraction where it was.
struct Phase {
  std::vector<std::string> stages;
  double weight = 1;
};
/// mr::estimate_scene's steps (EstimateOptions::cancel).
std::vector<std::string> estimate_stages();

/// One photo's work in a Reporter, while it lives: a token for the libmr calls (nullptr when
/// the reporter shows no progress) whose reports move the bar or make -v notes.
class PhotoProgress {
 public:
  PhotoProgress(Reporter& reporter, const std::string& name, std::vector<Phase> phases);
  ~PhotoProgress();
  PhotoProgress(const PhotoProgress&) = delete;
  PhotoProgress& operator=(const PhotoProgress&) = delete;
  const CancelToken* token() const { return reporter_.shows_progress() ? &token_ : nullptr; }

 private:
  void on_progress(const Progress& p);

  Reporter& reporter_;
  std::vector<Phase> phases_;
  double weight_sum_ = 0;
  std::list<Reporter::InFlight>::iterator entry_;
  CancelToken token_;
};

}  // namespace mr::cli
