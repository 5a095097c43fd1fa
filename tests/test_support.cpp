#include "test_support.h"

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <random>
#include <sstream>
#include <stdexcept>

#include "mr/io.h"

namespace fs = std::filesystem;

namespace mr::test {

ScratchDir::ScratchDir() {
  std::random_device rd;
  path_ = fs::temp_directory_path() /
          ("mr-test-" + std::to_string(::getpid()) + "-" + std::to_string(rd()));
  fs::create_directories(path_);
}

ScratchDir::~ScratchDir() {
  std::error_code ec;
  // Read-only subfolders made by tests must be writable again to be removed.
  for (auto it = fs::recursive_directory_iterator(path_, ec);
       it != fs::recursive_directory_iterator(); ++it)
    if (it->is_directory(ec))
      fs::permissions(it->path(), fs::perms::owner_all, fs::perm_options::add, ec);
  fs::remove_all(path_, ec);
}

std::vector<std::string> ScratchDir::list() const {
  std::vector<std::string> names;
  for (const auto& e : fs::recursive_directory_iterator(path_))
    names.push_back(fs::relative(e.path(), path_).string());
  std::sort(names.begin(), names.end());
  return names;
}

std::uint64_t file_checksum(const fs::path& path) {
  const std::string bytes = read_bytes(path);
  std::uint64_t h = 1469598103934665603ull;
  for (unsigned char c : bytes) h = (h ^ c) * 1099511628211ull;
  return h;
}

void write_bytes(const fs::path& path, const std::string& bytes) {
  std::ofstream f(path, std::ios::binary);
  f << bytes;
}

std::string read_bytes(const fs::path& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

CommandResult run(const std::string& command_line) {
  CommandResult result;
  FILE* pipe = ::popen((command_line + " 2>&1").c_str(), "r");
  if (!pipe) throw std::runtime_error("popen failed: " + command_line);
  std::array<char, 4096> buf;
  while (std::size_t n = std::fread(buf.data(), 1, buf.size(), pipe))
    result.output.append(buf.data(), n);
  const int status = ::pclose(pipe);
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return result;
}

Image make_test_photo(int width, int height) {
  Image im(width, height, 3);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const float u = (x + 0.5f) / width, v = (y + 0.5f) / height;
      float* p = im.pixel(x, y);
      p[0] = u;
      p[1] = v;
      p[2] = 0.5f + 0.5f * std::sin(6.2831853f * (u + v));
    }
  return im;
}

double max_abs_diff(const Image& a, const Image& b) {
  if (a.width() != b.width() || a.height() != b.height() || a.channels() != b.channels())
    throw std::runtime_error("max_abs_diff: shapes differ");
  double m = 0;
  for (std::size_t i = 0; i < a.pixels().size(); ++i)
    m = std::max(m, double(std::fabs(a.pixels()[i] - b.pixels()[i])));
  return m;
}

void write_every_third_pixel(const std::filesystem::path& photo_in,
                             const std::filesystem::path& depth_in,
                             const std::filesystem::path& photo_out,
                             const std::filesystem::path& depth_out) {
  const Image photo = read_image(photo_in);
  ReadOptions raw;
  raw.to_scene_linear = false;
  raw.reject_non_finite = false;
  const Image depth = read_image(depth_in, raw);
  const int w = photo.width() / 3, h = photo.height() / 3;
  Image p(w, h, 3), d(w, h, 1, {"Z"});
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      for (int c = 0; c < 3; ++c) p.at(x, y, c) = photo.at(3 * x + 1, 3 * y + 1, c);
      d.at(x, y, 0) = depth.at(3 * x + 1, 3 * y + 1, 0);
    }
  write_image(photo_out, p);
  WriteOptions wd;
  wd.pixel_type = PixelType::float32;
  wd.colorspace = colorspace::raw;
  write_image(depth_out, d, wd);
}

void write_reduced_sample(const std::filesystem::path& samples, const std::string& stem,
                          const std::filesystem::path& dir) {
  write_every_third_pixel(samples / (stem + ".jpg"), samples / (stem + "_depth.exr"),
                          dir / (stem + ".png"), dir / (stem + "_depth.exr"));
}

std::string shell_quoted(const std::filesystem::path& p) {
  return "'" + p.string() + "'";
}

int run_measured(const std::string& program, const std::vector<std::string>& args,
                 rusage* usage) {
  std::vector<char*> argv{const_cast<char*>(program.c_str())};
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  const pid_t pid = fork();
  if (pid < 0) return -1;
  if (pid == 0) {
    execv(program.c_str(), argv.data());
    _exit(127);
  }
  int status = 0;
  if (wait4(pid, &status, 0, usage) != pid || !WIFEXITED(status)) return -1;
  return WEXITSTATUS(status);
}

}  // namespace mr::test
