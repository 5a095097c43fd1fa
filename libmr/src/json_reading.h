// Private to libmr: strict reading of the project's JSON documents (the scene, docs/scene.md; the
// annotations, docs/annotations.md): one-line errors "source: /json/pointer: problem" that say
// what was found, unknown keys rejected with a "did you mean", duplicate keys rejected, syntax
// errors with their line and column.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <filesystem>
#include <initializer_list>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>

#include "mr/error.h"
#include "mr/scene.h"

namespace mr::json {

// Ordered: documents are written in the structs' order, and errors about several bad keys
// report the first one in reading order.
using Json = nlohmann::ordered_json;
using Keys = std::initializer_list<std::string_view>;

/// A key as a JSON pointer reference token (RFC 6901), one line.
std::string pointer_token(std::string_view key);
/// "a number (0.5)", "an array of 2 elements", ...: what a value is, for "found ..." messages.
std::string describe(const Json& j);
/// Levenshtein distance, case-insensitive: for "did you mean" on unknown keys.
std::size_t edit_distance(std::string_view a, std::string_view b);

class JsonReader {
 public:
  explicit JsonReader(std::string source) : source_(std::move(source)) {}

  /// Throws "source: /json/pointer: problem" (or "source: problem" for the whole document).
  [[noreturn]] void fail(const std::string& pointer, const std::string& problem) const {
    throw Error(ErrorCode::invalid_argument,
                source_ + ": " + (pointer.empty() ? "" : pointer + ": ") + problem);
  }

  [[noreturn]] void expected(const std::string& pointer, const std::string& what,
                             const Json& found) const {
    fail(pointer, "expected " + what + ", found " + describe(found));
  }

  void object(const Json& j, const std::string& pointer) const {
    if (!j.is_object()) expected(pointer, "an object", j);
  }

  /// Unknown keys are errors: in a hand-edited file they are almost always typos, and a
  /// silently ignored "albdo" would render the wrong fog without a word.
  void check_keys(const Json& obj, const std::string& pointer, Keys known) const {
    for (const auto& [key, value] : obj.items()) {
      if (std::find(known.begin(), known.end(), key) != known.end()) continue;
      std::string_view best;
      std::size_t best_distance = std::numeric_limits<std::size_t>::max();
      for (std::string_view k : known) {
        const std::size_t d = edit_distance(key, k);
        if (d < best_distance) best_distance = d, best = k;
      }
      std::string hint;
      if (best_distance <= std::max<std::size_t>(2, key.size() / 4)) {
        hint = "; did you mean \"" + std::string(best) + "\"?";
      } else {
        hint = "; expected one of: ";
        for (std::string_view k : known) hint += (k == *known.begin() ? "" : ", ") + std::string(k);
      }
      fail(pointer + "/" + pointer_token(key), "unknown key" + hint);
    }
  }

  /// A finite number. (JSON has no NaN or infinity; numbers beyond a double fail to parse.)
  double number(const Json& j, const std::string& pointer) const {
    if (!j.is_number()) expected(pointer, "a number", j);
    return j.get<double>();
  }

  /// A number stored as float (colour channels): must fit, or it would become infinity.
  float single(const Json& j, const std::string& pointer) const {
    const double v = number(j, pointer);
    if (std::abs(v) > std::numeric_limits<float>::max())
      fail(pointer, j.dump() + " is too large for a single-precision value");
    return static_cast<float>(v);
  }

  /// An integer in [lo, hi] (the C++ type's range; the meaning's range is validate_scene's).
  /// 4.0 is accepted as 4: some JSON writers emit every number as a float.
  long long integer(const Json& j, const std::string& pointer, long long lo, long long hi) const {
    const std::string range = "an integer from " + std::to_string(lo) + " to " + std::to_string(hi);
    if (j.is_number_unsigned()) {
      const auto v = j.get<unsigned long long>();
      if (v > static_cast<unsigned long long>(hi)) expected(pointer, range, j);
      return static_cast<long long>(v);
    }
    if (j.is_number_integer()) {
      const auto v = j.get<long long>();
      if (v < lo || v > hi) expected(pointer, range, j);
      return v;
    }
    if (j.is_number_float()) {
      const double v = j.get<double>();
      if (std::floor(v) != v || v < static_cast<double>(lo) || v > static_cast<double>(hi))
        expected(pointer, range, j);
      return static_cast<long long>(v);
    }
    expected(pointer, range, j);
  }

  bool boolean(const Json& j, const std::string& pointer) const {
    if (!j.is_boolean()) expected(pointer, "true or false", j);
    return j.get<bool>();
  }

  Vec3 vec3(const Json& j, const std::string& pointer) const {
    if (!j.is_array() || j.size() != 3) expected(pointer, "an array of 3 numbers", j);
    return {number(j[0], pointer + "/0"), number(j[1], pointer + "/1"),
            number(j[2], pointer + "/2")};
  }

  /// A colour: [r, g, b], or one number for grey.
  Rgb rgb(const Json& j, const std::string& pointer) const {
    if (j.is_number()) {
      const float v = single(j, pointer);
      return {v, v, v};
    }
    if (!j.is_array() || j.size() != 3)
      expected(pointer, "a number or an array of 3 numbers [r, g, b]", j);
    return {single(j[0], pointer + "/0"), single(j[1], pointer + "/1"),
            single(j[2], pointer + "/2")};
  }

  /// A string that must be one of `choices`; returns its index.
  std::size_t choice(const Json& j, const std::string& pointer, Keys choices) const {
    std::string list;
    for (std::string_view c : choices)
      list += (list.empty() ? "\"" : ", \"") + std::string(c) + "\"";
    if (j.is_string()) {
      const auto& s = j.get_ref<const std::string&>();
      const auto it = std::find(choices.begin(), choices.end(), s);
      if (it != choices.end()) return static_cast<std::size_t>(it - choices.begin());
    }
    expected(pointer, "one of " + list, j);
  }

 private:
  std::string source_;
};

/// The member `key` of an object, or nullptr.
const Json* member(const Json& obj, const char* key);

/// Deepest nesting of arrays and objects parse_text accepts (the project's documents use 4).
inline constexpr std::size_t kMaxNesting = 256;

/// Parses the text, rejecting duplicate keys (the parser would silently keep one of them) and
/// turning syntax errors into "source: line L, column C: problem" (through `r`). Also rejected:
/// nesting deeper than kMaxNesting, NUL bytes, anything but white space after the document.
Json parse_text(const std::string& text, const JsonReader& r);

/// The whole content of a document file. Only regular files are read (a FIFO, a device such as
/// /dev/zero, a folder: mr::Error(io) naming the file and what it is), at most `max_bytes`
/// (documents are small; a larger file is an error, not a long wait).
std::string read_document_file(const std::filesystem::path& path, const std::string& what,
                               std::size_t max_bytes = std::size_t(64) << 20);

}  // namespace mr::json
