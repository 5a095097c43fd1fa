// Terminal output for batch commands: errors, warnings and a progress bar that never interleave.
#pragma once

#include <cstddef>
#include <mutex>
#include <string>

namespace mr::cli {

class Reporter {
 public:
  /// `quiet`: only errors. The bar is drawn only when stderr is a terminal.
  Reporter(std::size_t total, bool quiet);
  /// "ERROR: <message>" on stderr (oiiotool's convention).
  void error(const std::string& message);
  void warning(const std::string& message);
  void info(const std::string& message);
  /// One more job finished; redraws the bar.
  void advance(const std::string& name);
  /// Erases the bar (before the summary).
  void finish();

 private:
  void clear_bar_locked();
  void draw_bar_locked();

  std::mutex mutex_;
  std::size_t total_, done_ = 0;
  bool quiet_, tty_, bar_visible_ = false;
  std::string last_name_;
};

}  // namespace mr::cli
