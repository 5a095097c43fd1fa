#include "progress.h"

#include <unistd.h>

#include <cstdio>

namespace mr::cli {

Reporter::Reporter(std::size_t total, bool quiet)
    : total_(total), quiet_(quiet), tty_(::isatty(STDERR_FILENO) == 1) {}

void Reporter::clear_bar_locked() {
  if (bar_visible_) std::fputs("\r\033[K", stderr);
  bar_visible_ = false;
}

void Reporter::draw_bar_locked() {
  if (quiet_ || !tty_ || total_ == 0) return;
  constexpr int kWidth = 30;
  const int filled = int(kWidth * done_ / total_);
  std::string bar(std::size_t(filled), '=');
  bar.resize(kWidth, ' ');
  std::string name = last_name_.size() > 40 ? "..." + last_name_.substr(last_name_.size() - 37) : last_name_;
  std::fprintf(stderr, "\r\033[K[%s] %zu/%zu %s", bar.c_str(), done_, total_, name.c_str());
  std::fflush(stderr);
  bar_visible_ = true;
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

}  // namespace mr::cli
