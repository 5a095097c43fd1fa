#include "output_safety.h"

#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cctype>
#include <cerrno>
#include <chrono>
#include <map>
#include <regex>
#include <set>

#include "mr/error.h"
#include "mr/io.h"

namespace fs = std::filesystem;

namespace mr::cli {

namespace {

// A key that names one file whatever the path that leads to it: device and inode for files that
// exist (hard and symbolic links, "a/../b"), else the normalised absolute path.
std::string file_key(const fs::path& p) {
  struct stat st {};
  if (::stat(p.c_str(), &st) == 0)
    return "inode:" + std::to_string(st.st_dev) + ":" + std::to_string(st.st_ino);
  std::error_code ec;
  return "path:" + fs::weakly_canonical(p, ec).lexically_normal().string();
}

}  // namespace

bool written_by_mr_fog(const fs::path& path) {
  try {
    return probe_image(path).software == kOutputSoftware;
  } catch (const Error&) {
    return false;  // unreadable: not one of ours (it fails as a photo, with its reason)
  }
}

std::vector<std::string> check_planned_outputs(
    const std::vector<fs::path>& inputs, const std::vector<std::vector<PlannedOutput>>& outputs) {
  std::map<std::string, fs::path> input_keys;
  for (const fs::path& in : inputs) input_keys.emplace(file_key(in), in);
  std::map<std::string, std::vector<std::size_t>> writers;  // output file -> jobs writing it
  std::vector<std::string> errors(outputs.size());
  for (std::size_t j = 0; j < outputs.size(); ++j) {
    std::set<std::string> own;  // one job may not write one file twice either
    for (const PlannedOutput& out : outputs[j]) {
      const std::string key = file_key(out.path);
      if (const auto it = input_keys.find(key); it != input_keys.end()) {
        const bool same_name = it->second.lexically_normal() == out.path.lexically_normal();
        errors[j] = out.owner + ": output " + out.path.string() + " is an input of this run" +
                    (same_name ? "" : " (" + it->second.string() + ")") +
                    "; refusing to overwrite it (choose another --out-dir or --suffix)";
        break;
      }
      try {
        check_output_path(out.path);
      } catch (const Error& e) {
        errors[j] = out.owner + ": output " + e.what();
        break;
      }
      if (own.insert(key).second) writers[key].push_back(j);
    }
  }
  for (const auto& [key, jobs] : writers) {
    if (jobs.size() < 2) continue;
    for (std::size_t j : jobs) {
      if (!errors[j].empty()) continue;
      std::string others;
      for (std::size_t k : jobs)
        if (k != j) others += (others.empty() ? "" : ", ") + outputs[k].front().owner;
      const fs::path* shared = nullptr;
      for (const PlannedOutput& out : outputs[j])
        if (file_key(out.path) == key) shared = &out.path;
      errors[j] = outputs[j].front().owner + ": output " + shared->string() +
                  " would also be written for " + others +
                  "; none of them is rendered (rename one, or use another --out-dir or --format)";
    }
  }
  return errors;
}

std::vector<fs::path> remove_stale_temporaries(const fs::path& folder) {
  // The names of libmr's atomic writes (libmr/src/atomic_file.cpp) and of the CLI's own.
  static const std::regex kTemporary(R"(^\..+\.mr-tmp-([0-9]{1,9})-[0-9]+(\.[A-Za-z0-9]+)?$)");
  std::vector<fs::path> removed;
  std::error_code ec;
  const auto now = fs::file_time_type::clock::now();
  for (const auto& entry : fs::directory_iterator(folder.empty() ? "." : folder, ec)) {
    const std::string name = entry.path().filename().string();
    std::smatch m;
    if (!std::regex_match(name, m, kTemporary)) continue;
    std::error_code e2;
    if (!entry.is_regular_file(e2) || entry.is_symlink(e2)) continue;
    const pid_t pid = pid_t(std::stol(m[1].str()));
    if (pid == ::getpid()) continue;
    const bool dead = pid > 0 && ::kill(pid, 0) != 0 && errno == ESRCH;
    const auto age = now - fs::last_write_time(entry.path(), e2);
    const bool old = !e2 && age > std::chrono::hours(24);
    if ((dead || old) && fs::remove(entry.path(), e2)) removed.push_back(entry.path());
  }
  return removed;
}

PhotoOutputEncoding photo_output_encoding(const std::filesystem::path& output,
                                          const std::filesystem::path& photo) {
  std::string ext = output.extension().string();
  for (char& ch : ext) ch = char(std::tolower(static_cast<unsigned char>(ch)));
  PhotoOutputEncoding e;
  e.display_referred = ext != ".exr" && ext != ".hdr" && ext != ".pfm";
  if ((ext == ".png" || ext == ".tif" || ext == ".tiff") && !photo.empty() &&
      probe_image(photo).pixel_type == PixelType::uint16)
    e.pixel_type = PixelType::uint16;
  return e;
}

}  // namespace mr::cli
