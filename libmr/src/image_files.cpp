#include "image_files.h"

#include <algorithm>
#include <cctype>
#include <set>
#include <string>

#include "core/oiio_module.h"
#include "direct_codecs.h"

namespace mr::detail {

namespace {

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

}  // namespace

std::unique_ptr<ImageReader> open_direct_reader(const std::filesystem::path& path) {
  if (auto jpeg = open_jpeg_reader(path)) return jpeg;
  if (auto png = open_png_reader(path)) return png;
  return open_exr_reader(path);
}

std::unique_ptr<ImageWriter> create_direct_writer(const std::filesystem::path& path) {
  const std::string ext = lower(path.extension().string());
  if (ext == ".jpg" || ext == ".jpeg") return create_jpeg_writer(path);
  return nullptr;
}

std::unique_ptr<ImageReader> open_image_reader(const std::filesystem::path& path) {
  if (auto direct = open_direct_reader(path)) return direct;
  return std::unique_ptr<ImageReader>(oiio_module().open_reader(path.string()));
}

std::unique_ptr<ImageWriter> create_image_writer(const std::filesystem::path& path) {
  if (auto direct = create_direct_writer(path)) return direct;
  return std::unique_ptr<ImageWriter>(oiio_module().create_writer(path.string()));
}

bool is_readable_extension(const std::filesystem::path& path) {
  // The batch formats without loading OIIO (all four are in its list).
  static const std::set<std::string> batch = {".jpg", ".jpeg", ".png", ".exr"};
  if (batch.count(lower(path.extension().string()))) return true;
  static const std::set<std::string> extensions = [] {
    std::set<std::string> out;
    // "tiff:tif,tiff;jpeg:jpg,jpeg;..."
    const std::string list = oiio_module().extension_list();
    std::size_t pos = 0;
    while (pos < list.size()) {
      std::size_t end = list.find(';', pos);
      if (end == std::string::npos) end = list.size();
      std::string entry = list.substr(pos, end - pos);
      std::size_t colon = entry.find(':');
      std::string exts = colon == std::string::npos ? entry : entry.substr(colon + 1);
      std::size_t p = 0;
      while (p <= exts.size()) {
        std::size_t comma = exts.find(',', p);
        if (comma == std::string::npos) comma = exts.size();
        if (comma > p) out.insert(lower(exts.substr(p, comma - p)));
        p = comma + 1;
      }
      pos = end + 1;
    }
    return out;
  }();
  std::string ext = lower(path.extension().string());
  return ext.size() > 1 && extensions.count(ext.substr(1)) > 0;
}

}  // namespace mr::detail
