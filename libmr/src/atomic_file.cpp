#include "atomic_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <cerrno>
#include <climits>
#include <cstring>
#include <fstream>
#include <system_error>

#include "mr/error.h"
#include "mr/io.h"

namespace mr::detail {

namespace {
std::atomic<unsigned> g_counter{0};

// The temporary files being written now, readable from a signal handler: a slot is claimed
// (free -> claimed) by one writer, filled, then published (ready); the handler only reads
// ready slots. A path too long for a slot is simply not registered (the next run's stale-file
// sweep still removes it).
enum SlotState : int { kFree = 0, kClaimed = 1, kReady = 2 };
struct TemporarySlot {
  std::atomic<int> state{kFree};
  char path[PATH_MAX];
};
constexpr std::size_t kSlots = 256;  // photos in flight are at most 4 per core (mr fog -j)
std::array<TemporarySlot, kSlots> g_temporaries;
static_assert(std::atomic<int>::is_always_lock_free, "read from a signal handler");

int register_temporary(const std::filesystem::path& p) {
  const std::string& s = p.native();
  if (s.size() >= PATH_MAX) return -1;
  for (std::size_t i = 0; i < kSlots; ++i) {
    int expected = kFree;
    if (g_temporaries[i].state.compare_exchange_strong(expected, kClaimed,
                                                       std::memory_order_acquire)) {
      std::memcpy(g_temporaries[i].path, s.c_str(), s.size() + 1);
      g_temporaries[i].state.store(kReady, std::memory_order_release);
      return int(i);
    }
  }
  return -1;
}

void unregister_temporary(int slot) {
  if (slot >= 0) g_temporaries[std::size_t(slot)].state.store(kFree, std::memory_order_release);
}

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
  slot_ = register_temporary(temp_);
}

AtomicFile::~AtomicFile() {
  if (!committed_) {
    std::error_code ec;
    std::filesystem::remove(temp_, ec);
  }
  unregister_temporary(slot_);
}

void remove_temporaries_now() noexcept {
  for (TemporarySlot& slot : g_temporaries)
    if (slot.state.load(std::memory_order_acquire) == kReady &&
        std::strstr(slot.path, ".mr-tmp-") != nullptr)  // a slot being reused is left alone
      ::unlink(slot.path);
}

void AtomicFile::commit(bool overwrite) {
  std::error_code ec;
  if (!overwrite && std::filesystem::exists(final_, ec))
    throw Error(ErrorCode::io, final_.string() + ": exists already (not overwriting)");
  check_output_target(final_);  // it may have appeared while the file was written
  sync_file(temp_);
  std::filesystem::rename(temp_, final_, ec);
  if (ec)
    throw Error(ErrorCode::io,
                final_.string() + ": cannot move the finished file into place: " + ec.message());
  committed_ = true;
  unregister_temporary(slot_);
  slot_ = -1;
}

void write_text_atomically(const std::filesystem::path& path, std::string_view text,
                           bool overwrite) {
  const std::string name = path.string();
  AtomicFile file(path);  // removes its temporary file unless committed
  {
    std::ofstream out(file.temp_path(), std::ios::binary | std::ios::trunc);
    if (!out) {
      const int err = errno;
      std::error_code ec;
      const std::filesystem::path folder =
          path.parent_path().empty() ? std::filesystem::path(".") : path.parent_path();
      if (!std::filesystem::is_directory(folder, ec))
        throw Error(ErrorCode::io,
                    name + ": cannot write: folder " + folder.string() + " does not exist");
      throw Error(ErrorCode::io, name + ": cannot write: " + std::strerror(err));
    }
    out.write(text.data(), static_cast<std::streamsize>(text.size()));
    out.close();
    if (!out) throw Error(ErrorCode::io, name + ": cannot write: " + std::strerror(errno));
  }
  file.commit(overwrite);
}

}  // namespace mr::detail

namespace mr {

void write_text_file(const std::filesystem::path& path, std::string_view text, bool overwrite) {
  detail::write_text_atomically(path, text, overwrite);
}

}  // namespace mr
