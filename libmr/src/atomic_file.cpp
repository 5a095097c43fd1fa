#include "atomic_file.h"

#include <fcntl.h>
#include <sys/stat.h>
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
std::string kind_of(mode_t mode) {
  if (S_ISDIR(mode)) return "a folder";
  if (S_ISFIFO(mode)) return "a FIFO (named pipe)";
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISBLK(mode)) return "a block device";
  if (S_ISSOCK(mode)) return "a socket";
  if (S_ISLNK(mode)) return "a symbolic link";
  return "not a regular file";
}

}  // namespace

void check_regular_input(const std::filesystem::path& path, const std::string& what) {
  const std::string name = path.string();
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    const int err = errno;
    struct stat link {};
    if (err == ENOENT && ::lstat(path.c_str(), &link) == 0 && S_ISLNK(link.st_mode)) {
      std::error_code ec;
      const auto target = std::filesystem::read_symlink(path, ec);
      throw Error(ErrorCode::io, name + ": a dangling symbolic link (to " +
                                     (ec ? std::string("?") : target.string()) + ")");
    }
    if (err == ENOENT) throw Error(ErrorCode::io, name + ": no such file");
    if (err == ELOOP)
      throw Error(ErrorCode::io, name + ": a symbolic link loop (too many levels of links)");
    throw Error(ErrorCode::io, name + ": cannot open: " + std::strerror(err));
  }
  if (!S_ISREG(st.st_mode))
    throw Error(ErrorCode::io, name + ": is " + kind_of(st.st_mode) + ", not " + what +
                                   " (only regular files are read)");
  // Permission problems as such, not as the decoder's "not an OpenEXR file".
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) throw Error(ErrorCode::io, name + ": cannot open: " + std::strerror(errno));
  ::close(fd);
}

void check_output_target(const std::filesystem::path& path) {
  struct stat st {};
  if (::lstat(path.c_str(), &st) != 0) return;  // nothing there (or unreachable: rename says)
  if (!S_ISREG(st.st_mode))
    throw Error(ErrorCode::io, path.string() + ": is " + kind_of(st.st_mode) +
                                   "; outputs are only written as regular files (remove it or "
                                   "choose another name)");
}

AtomicFile::AtomicFile(std::filesystem::path final_path) : final_(std::move(final_path)) {
  check_output_target(final_);
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
  check_output_target(final_);  // it may have appeared while the file was written
  sync_file(temp_);
  std::filesystem::rename(temp_, final_, ec);
  if (ec)
    throw Error(ErrorCode::io, final_.string() + ": cannot move the finished file into place: " +
                                   ec.message());
  committed_ = true;
}

}  // namespace mr::detail
