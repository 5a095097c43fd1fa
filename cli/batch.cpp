#include "batch.h"

#include <glob.h>

#include <algorithm>
#include <cstdlib>
#include <set>
#include <stdexcept>

#include "mr/io.h"

namespace fs = std::filesystem;

namespace mr::cli {

namespace {

// What a folder entry that cannot be a photo is, for the warning that names it ("" for regular
// files).
std::string unusable_entry(const fs::path& p) {
  std::error_code ec;
  const fs::file_status link = fs::symlink_status(p, ec);
  const fs::file_status target = fs::status(p, ec);
  if (fs::is_symlink(link) && (ec || target.type() == fs::file_type::not_found)) {
    if (ec == std::errc::too_many_symbolic_link_levels) return "a symbolic link loop";
    std::error_code e2;
    return "a dangling symbolic link (to " + fs::read_symlink(p, e2).string() + ")";
  }
  if (ec) return "unreadable (" + ec.message() + ")";
  if (fs::is_regular_file(target)) return "";
  if (fs::is_directory(target)) return "a folder";
  if (fs::is_fifo(target)) return "a FIFO (named pipe)";
  if (fs::is_character_file(target) || fs::is_block_file(target)) return "a device";
  return "not a regular file";
}

std::vector<fs::path> folder_images(const fs::path& folder, std::vector<std::string>* warnings) {
  std::vector<fs::path> out;
  std::vector<std::pair<fs::path, std::string>> skipped;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(folder, ec)) {
    const fs::path& p = entry.path();
    if (p.filename().string().starts_with(".")) continue;  // hidden (our temporaries too)
    const std::string problem = unusable_entry(p);
    const bool image_name = is_readable_image_extension(p);
    if (problem.empty()) {
      if (image_name) out.push_back(p);
    } else if (image_name || problem.find("symbolic link") != std::string::npos) {
      // Named, not silently dropped: a photo the user expects may be behind it.
      skipped.emplace_back(p, problem);
    }
  }
  if (ec && warnings) warnings->push_back(folder.string() + ": cannot list: " + ec.message());
  std::sort(out.begin(), out.end());
  std::sort(skipped.begin(), skipped.end());
  if (warnings)
    for (const auto& [p, problem] : skipped)
      warnings->push_back(p.string() + ": " + problem + ", not a photo; skipped");
  return out;
}

std::vector<fs::path> glob_paths(const std::string& pattern) {
  glob_t g{};
  std::vector<fs::path> out;
  if (::glob(pattern.c_str(), 0, nullptr, &g) == 0)
    for (std::size_t i = 0; i < g.gl_pathc; ++i) out.emplace_back(g.gl_pathv[i]);
  ::globfree(&g);
  return out;  // glob sorts its matches
}

void replace_all(std::string& s, const std::string& from, const std::string& to) {
  for (std::size_t pos = 0; (pos = s.find(from, pos)) != std::string::npos; pos += to.size())
    s.replace(pos, from.size(), to);
}

}  // namespace

std::vector<fs::path> expand_inputs(const std::vector<std::string>& args,
                                    const std::vector<std::string>& skip_stem_suffixes,
                                    std::vector<std::string>* warnings) {
  std::vector<fs::path> out;
  std::set<fs::path> seen;
  auto add = [&](const fs::path& p) {
    if (seen.insert(p.lexically_normal()).second) out.push_back(p);
  };
  auto add_found = [&](const fs::path& p) {
    const std::string stem = p.stem().string();
    for (const auto& suffix : skip_stem_suffixes)
      if (stem.ends_with(suffix)) return;
    add(p);
  };
  for (const std::string& arg : args) {
    std::error_code ec;
    if (fs::is_directory(arg, ec)) {
      for (const auto& p : folder_images(arg, warnings)) add_found(p);
    } else if (arg.find_first_of("*?[") != std::string::npos && !fs::exists(arg, ec)) {
      auto matches = glob_paths(arg);
      if (matches.empty()) add(arg);
      for (const auto& p : matches) {
        if (fs::is_directory(p, ec)) {
          if (warnings && is_readable_image_extension(p))
            warnings->push_back(p.string() + ": a folder, not a photo; skipped");
          continue;
        }
        add_found(p);
      }
    } else {
      add(arg);
    }
  }
  return out;
}

bool is_pattern(const std::string& pattern) {
  for (const char* key : {"{dir}", "{stem}", "{name}", "{ext}"})
    if (pattern.find(key) != std::string::npos) return true;
  return false;
}

fs::path expand_pattern(const std::string& pattern, const fs::path& photo) {
  std::string s = pattern;
  const std::string dir = photo.parent_path().empty() ? "." : photo.parent_path().string();
  replace_all(s, "{dir}", dir);
  replace_all(s, "{stem}", photo.stem().string());
  replace_all(s, "{name}", photo.filename().string());
  replace_all(s, "{ext}", photo.extension().string());
  return s;
}

double parse_distance_m(const std::string& text) {
  std::size_t used = 0;
  double value = 0;
  try {
    value = std::stod(text, &used);
  } catch (const std::exception&) {
    throw std::invalid_argument("'" + text + "' is not a distance (e.g. 150m, 1.5km)");
  }
  std::string unit = text.substr(used);
  unit.erase(std::remove(unit.begin(), unit.end(), ' '), unit.end());
  if (unit == "km") value *= 1000.0;
  else if (!unit.empty() && unit != "m")
    throw std::invalid_argument("'" + text + "': unknown unit '" + unit + "' (use m or km)");
  return value;
}

std::array<float, 3> parse_rgb(const std::string& text) {
  std::array<float, 3> out{};
  std::vector<float> values;
  std::size_t pos = 0;
  while (pos <= text.size()) {
    std::size_t comma = text.find(',', pos);
    if (comma == std::string::npos) comma = text.size();
    const std::string item = text.substr(pos, comma - pos);
    std::size_t used = 0;
    try {
      values.push_back(std::stof(item, &used));
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != item.size())
      throw std::invalid_argument("'" + text + "' is not a value or R,G,B triple");
    pos = comma + 1;
  }
  if (values.size() == 1) out = {values[0], values[0], values[0]};
  else if (values.size() == 3) out = {values[0], values[1], values[2]};
  else throw std::invalid_argument("'" + text + "' must be one value or three (R,G,B)");
  return out;
}

std::vector<double> parse_numbers(const std::string& text, std::size_t count, const std::string& what) {
  std::vector<double> out;
  std::size_t pos = 0;
  while (pos <= text.size()) {
    std::size_t comma = text.find(',', pos);
    if (comma == std::string::npos) comma = text.size();
    const std::string item = text.substr(pos, comma - pos);
    std::size_t used = 0;
    double v = 0;
    try {
      v = std::stod(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != item.size())
      throw std::invalid_argument(what + ": '" + text + "' is not a list of numbers");
    out.push_back(v);
    pos = comma + 1;
  }
  if (out.size() != count)
    throw std::invalid_argument(what + ": '" + text + "' must have " + std::to_string(count) +
                                " numbers, has " + std::to_string(out.size()));
  return out;
}

bool same_file(const fs::path& a, const fs::path& b) {
  std::error_code ec;
  if (fs::exists(a, ec) && fs::exists(b, ec)) return fs::equivalent(a, b, ec);
  return fs::weakly_canonical(a, ec) == fs::weakly_canonical(b, ec);
}

}  // namespace mr::cli
