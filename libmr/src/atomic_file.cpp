#include "atomic_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <system_error>

#include "mr/error.h"

namespace mr::detail {

namespace {
std::atomic<unsigned> g_counter{0};

// fsync so that a crash after rename cannot leave a renamed-but-empty file.
void sync_file(const std::filesystem::path& p) {
  int fd = ::open(p.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return;
  ::fsync(fd);
  ::close(fd);
}
}  // namespace

AtomicFile::AtomicFile(std::filesystem::path final_path) : final_(std::move(final_path)) {
  // ".<name>.mr-tmp-<pid>-<n><ext>": hidden, unique per process and call, same extension.
  const std::string name = "." + final_.stem().string() + ".mr-tmp-" + std::to_string(::getpid()) +
                           "-" + std::to_string(g_counter++) + final_.extension().string();
  temp_ = final_.parent_path() / name;
}

AtomicFile::~AtomicFile() {
  if (!committed_) {
    std::error_code ec;
    std::filesystem::remove(temp_, ec);
  }
}

void AtomicFile::commit(bool overwrite) {
  std::error_code ec;
  if (!overwrite && std::filesystem::exists(final_, ec))
    throw Error(ErrorCode::io, final_.string() + ": exists already (not overwriting)");
  sync_file(temp_);
  std::filesystem::rename(temp_, final_, ec);
  if (ec)
    throw Error(ErrorCode::io, final_.string() + ": cannot move the finished file into place: " +
                                   ec.message());
  committed_ = true;
}

}  // namespace mr::detail
