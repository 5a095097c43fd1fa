// Private to libmr: write-to-temporary-then-rename, so no reader ever sees a partial file; and
// the checks that keep reads to regular files and writes to regular files.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

namespace mr::detail {

/// Throws mr::Error(io) "<path>: <why>" unless `path` names (possibly through symbolic links) a
/// regular file this process can open for reading: no such file, a dangling symbolic link, a
/// symbolic link loop, permission denied, a folder, a FIFO, a device (/dev/zero), a socket.
/// Reading any of the latter could block for ever or never end. `what` names the kind of file
/// for messages ("an image", "a scene file").
void check_regular_input(const std::filesystem::path& path, const std::string& what);

/// Throws mr::Error(io) "<path>: is a <kind>; ..." when `path` exists and is not a regular file
/// (checked without following symbolic links: a symbolic link, a FIFO, a device, a folder).
/// Outputs are only ever regular files created or replaced by a rename in their folder.
void check_output_target(const std::filesystem::path& path);

/// A temporary path beside `final_path` (same folder, so rename is atomic; same extension, so
/// format-sniffing writers agree): ".<stem>.mr-tmp-<pid>-<n><ext>", the name `mr` recognises to
/// remove the leftovers of a killed run. `final_path` must not be anything but a regular file
/// (check_output_target, here and again before the rename). The temporary file is removed on
/// destruction unless commit() renamed it into place.
class AtomicFile {
 public:
  explicit AtomicFile(std::filesystem::path final_path);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  const std::filesystem::path& temp_path() const { return temp_; }
  const std::filesystem::path& final_path() const { return final_; }
  /// Flushes the temporary file to disk and renames it over the final path.
  /// Throws mr::Error(io) naming the final path; with overwrite == false an existing final
  /// file is an error and is left alone.
  void commit(bool overwrite = true);

 private:
  std::filesystem::path final_, temp_;
  bool committed_ = false;
  int slot_ = -1;  // in the registry remove_temporaries_now() reads
};

/// Writes `text` to `path` through an AtomicFile (temporary beside it, fsync, rename).
/// Throws mr::Error(io) naming `path` (a missing folder is said as such); nothing is left
/// behind on failure.
void write_text_atomically(const std::filesystem::path& path, std::string_view text,
                           bool overwrite = true);

/// Unlinks the temporary files of every AtomicFile alive now (uncommitted outputs being
/// written). Async-signal-safe: for a handler that ends the process at once.
void remove_temporaries_now() noexcept;

}  // namespace mr::detail
