// Private to libmr: write-to-temporary-then-rename, so no reader ever sees a partial file.
#pragma once

#include <filesystem>

namespace mr::detail {

/// A temporary path beside `final_path` (same folder, so rename is atomic; same extension, so
/// format-sniffing writers agree). The temporary file is removed on destruction unless commit()
/// renamed it into place.
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
};

}  // namespace mr::detail
