// Helpers shared by the tests: scratch folders, checksums, running the CLI.
#pragma once

#include <sys/resource.h>

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "mr/image.h"

namespace mr::test {

/// A fresh folder under the system temp dir, removed (with its contents) on destruction.
class ScratchDir {
 public:
  ScratchDir();
  ~ScratchDir();
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::string& name) const { return path_ / name; }
  /// Names of all entries (recursively, relative), sorted.
  std::vector<std::string> list() const;

 private:
  std::filesystem::path path_;
};

/// 64-bit FNV-1a of a file's bytes.
std::uint64_t file_checksum(const std::filesystem::path& path);
void write_bytes(const std::filesystem::path& path, const std::string& bytes);
std::string read_bytes(const std::filesystem::path& path);

struct CommandResult {
  int exit_code = -1;
  std::string output;  ///< stdout and stderr together
};
/// Runs a shell command line, capturing its output.
CommandResult run(const std::string& command_line);
/// Runs `program` with `args` in a child process (no shell) and waits for it; `usage` gets the
/// child's resource usage as the OS counted it (wait4: peak RSS, page faults). Returns its exit
/// code, or -1 when it could not be started or did not exit normally.
int run_measured(const std::string& program, const std::vector<std::string>& args,
                 rusage* usage);

/// A smooth synthetic RGB test image in scene-linear [0, 1]: gradients plus a hue sweep.
Image make_test_photo(int width, int height);
/// Largest |a - b| over all values; images must have equal shapes.
double max_abs_diff(const Image& a, const Image& b);

/// Every third pixel (nearest neighbour keeps depth edges sharp) of a photo and its depth map,
/// written as an 8-bit PNG and a float EXR (raw: the depth's values as stored).
void write_every_third_pixel(const std::filesystem::path& photo, const std::filesystem::path& depth,
                             const std::filesystem::path& photo_out,
                             const std::filesystem::path& depth_out);

/// write_every_third_pixel of the sample `<samples>/<stem>.jpg` and its `<stem>_depth.exr`, as
/// `<dir>/<stem>.png` and `<dir>/<stem>_depth.exr` (where `mr fog` finds a photo's depth).
void write_reduced_sample(const std::filesystem::path& samples, const std::string& stem,
                          const std::filesystem::path& dir);

/// `p` in single quotes, for the command lines the CLI tests run through the shell.
std::string shell_quoted(const std::filesystem::path& p);

}  // namespace mr::test
