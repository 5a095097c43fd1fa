// Batch plumbing shared by the CLI's commands: input expansion, path patterns, value parsing.
#pragma once

#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace mr::cli {

/// Expands command-line inputs: files are kept (even if missing: they fail later with a clear
/// error), folders give their readable image files (sorted, not recursive, hidden files
/// skipped), patterns with * ? [ are globbed. Files found in folders or by globs whose stem ends
/// with one of `skip_stem_suffixes` (depth maps, AOV files) are left out; files named
/// explicitly never are. Duplicates are dropped; order is kept. A glob that matches nothing is
/// returned as is (it then fails as a missing file). Entries of a folder that cannot be photos
/// although named like images (a folder "x.jpg", a FIFO, a device) and every broken symbolic
/// link (dangling, or a loop) are skipped with one line each in `warnings` (when given).
std::vector<std::filesystem::path> expand_inputs(const std::vector<std::string>& args,
                                                 const std::vector<std::string>& skip_stem_suffixes = {},
                                                 std::vector<std::string>* warnings = nullptr);

/// Substitutes {dir}, {stem}, {name} and {ext} (with the dot) of `photo` into `pattern`.
std::filesystem::path expand_pattern(const std::string& pattern,
                                     const std::filesystem::path& photo);

/// True if `pattern` has any {placeholder} (otherwise it names one file for all photos).
bool is_pattern(const std::string& pattern);

/// "150", "150m", "150 m", "1.5km" -> metres. Throws std::invalid_argument.
double parse_distance_m(const std::string& text);
/// "0.8" -> grey, "0.8,0.85,0.9" -> RGB. Throws std::invalid_argument.
std::array<float, 3> parse_rgb(const std::string& text);

/// "1,2,3" -> exactly `count` numbers. Throws std::invalid_argument naming `what`.
std::vector<double> parse_numbers(const std::string& text, std::size_t count, const std::string& what);

/// True if a and b name the same file (resolving links and ., ..), whether or not b exists.
bool same_file(const std::filesystem::path& a, const std::filesystem::path& b);

}  // namespace mr::cli
