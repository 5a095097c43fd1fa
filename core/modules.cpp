#include "core/modules.h"

#include <dlfcn.h>

#include <filesystem>
#include <string>
#include <vector>

#include "core/oiio_module.h"
#include "mr/error.h"

namespace mr::detail {

namespace {

// The folders to look in: the one of the object holding this code (libmr.so, or the program
// for libmr's static library), then ../libmr/ from it (tests and benchmarks in the build tree).
std::vector<std::filesystem::path> module_folders() {
  std::vector<std::filesystem::path> folders;
  Dl_info info{};
  std::filesystem::path self;
  if (dladdr(reinterpret_cast<const void*>(&load_module), &info) && info.dli_fname &&
      *info.dli_fname)
    self = info.dli_fname;
  std::error_code ec;
  // The main program's name is argv[0]-like: /proc/self/exe names it whatever the working folder.
  if (self.empty() ||
      self.filename() == std::filesystem::canonical("/proc/self/exe", ec).filename())
    self = std::filesystem::canonical("/proc/self/exe", ec);
  const std::filesystem::path folder = self.parent_path();
  folders.push_back(folder);
  folders.push_back(folder.parent_path() / "libmr");
  return folders;
}

}  // namespace

const void* load_module(const char* file, const char* entry) {
  std::string reason;
  std::filesystem::path first;
  for (const std::filesystem::path& folder : module_folders()) {
    const std::filesystem::path path = folder / file;
    if (first.empty()) first = path;
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) continue;
    // RTLD_LOCAL: the module's libraries stay out of the global namespace; never closed.
    void* handle = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (!handle) {
      const char* why = dlerror();
      throw Error(ErrorCode::io, path.string() + ": cannot load libmr's module (" +
                                     (why ? why : "unknown reason") + ")");
    }
    using Entry = const void* (*)();
    auto get = reinterpret_cast<Entry>(dlsym(handle, entry));
    if (!get) throw Error(ErrorCode::io, path.string() + ": not libmr's module (no " + entry + ")");
    return get();
  }
  throw Error(ErrorCode::io, first.string() +
                                 ": libmr's module is missing (installed beside "
                                 "libmr.so; needed for this file or operation)");
}

const OiioModule& oiio_module() {
  static const auto* module =
      static_cast<const OiioModule*>(load_module("libmr_oiio.so", "mr_oiio_module"));
  return *module;
}

}  // namespace mr::detail
