#include "json_reading.h"

#include "atomic_file.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <set>
#include <utility>
#include <vector>

namespace mr::json {

// A key as a JSON pointer reference token (RFC 6901): '~' -> "~0", '/' -> "~1". Control
// characters (a key may hold an escaped newline) are shown JSON-escaped to keep messages on
// one line.
std::string pointer_token(std::string_view key) {
  std::string t;
  for (char c : key) {
    if (c == '~') {
      t += "~0";
    } else if (c == '/') {
      t += "~1";
    } else if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\u%04x",
                    static_cast<unsigned>(static_cast<unsigned char>(c)));
      t += buf;
    } else {
      t += c;
    }
  }
  return t;
}

// Short, one-line text of a string value for messages; cut at a UTF-8 character boundary.
static std::string quoted_excerpt(const Json& j) {
  std::string s = j.dump();  // quoted, control characters escaped: always one line
  constexpr std::size_t kMax = 40;
  if (s.size() > kMax) {
    std::size_t n = kMax;
    while (n > 0 && (static_cast<unsigned char>(s[n]) & 0xC0) == 0x80) --n;
    s = s.substr(0, n) + "...";
  }
  return s;
}

// "found ..." part of a message: what the value is, with the value itself when it is short.
std::string describe(const Json& j) {
  switch (j.type()) {
    case Json::value_t::null:
      return "null";
    case Json::value_t::boolean:
      return std::string("a boolean (") + (j.get<bool>() ? "true" : "false") + ")";
    case Json::value_t::number_integer:
    case Json::value_t::number_unsigned:
    case Json::value_t::number_float:
      return "a number (" + j.dump() + ")";
    case Json::value_t::string:
      return "a string (" + quoted_excerpt(j) + ")";
    case Json::value_t::array:
      if (j.empty()) return "an empty array";
      return "an array of " + std::to_string(j.size()) + (j.size() == 1 ? " element" : " elements");
    case Json::value_t::object:
      return "an object";
    default:
      return "an unsupported value";
  }
}

// Levenshtein distance, case-insensitive: for "did you mean" on unknown keys.
std::size_t edit_distance(std::string_view a, std::string_view b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diag = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const bool same = std::tolower(static_cast<unsigned char>(a[i - 1])) ==
                        std::tolower(static_cast<unsigned char>(b[j - 1]));
      const std::size_t next = std::min({row[j] + 1, row[j - 1] + 1, diag + (same ? 0 : 1)});
      diag = row[j];
      row[j] = next;
    }
  }
  return row[b.size()];
}

// 1-based line and column (in characters, not bytes) of byte offset `offset` in `text`.
static std::pair<std::size_t, std::size_t> line_column(const std::string& text,
                                                       std::size_t offset) {
  offset = std::min(offset, text.size());
  std::size_t line = 1, column = 1;
  for (std::size_t i = 0; i < offset; ++i) {
    if (text[i] == '\n') {
      ++line;
      column = 1;
    } else if ((static_cast<unsigned char>(text[i]) & 0xC0) != 0x80) {  // skip UTF-8 tails
      ++column;
    }
  }
  return {line, column};
}

// nlohmann's message without its "[json.exception.parse_error.101] parse error at line 3,
// column 14: " prefix: we state the position ourselves, once.
static std::string parse_problem(const std::string& what) {
  std::string s = what;
  if (const auto b = s.find("] "); s.rfind("[json.exception.", 0) == 0 && b != std::string::npos)
    s = s.substr(b + 2);
  if (s.rfind("parse error", 0) == 0) {
    if (const auto colon = s.find(": "); colon != std::string::npos) s = s.substr(colon + 2);
  }
  return s;
}

// "line L, column C" of a syntax error. nlohmann's byte count ends at the last character it
// read, which is the end of the offending token ("0.5" in `"g" 0.5`): step back to the token's
// start, where a reader's eye looks for the mistake.
static std::string position_text(const std::string& text, std::size_t bytes_read,
                                 const std::string& problem) {
  std::size_t i = std::min(bytes_read > 0 ? bytes_read - 1 : 0, text.size());
  auto token_char = [&text](std::size_t k) {
    const unsigned char c = static_cast<unsigned char>(text[k]);
    return std::isalnum(c) || c == '.' || c == '+' || c == '-';
  };
  // "tru}": the lexer stops on the '}' that broke the literal; the literal starts before it.
  if (problem.find("invalid literal") != std::string::npos && i > 0 && i < text.size() &&
      !token_char(i) && token_char(i - 1))
    --i;
  if (i < text.size() && token_char(i))
    while (i > 0 && token_char(i - 1)) --i;
  const auto [line, column] = line_column(text, i);
  return "line " + std::to_string(line) + ", column " + std::to_string(column);
}

std::string read_document_file(const std::filesystem::path& path, const std::string& what,
                               std::size_t max_bytes) {
  const std::string name = path.string();
  detail::check_regular_input(path, what);
  std::error_code ec;
  const auto size = std::filesystem::file_size(path, ec);
  if (!ec && size > max_bytes)
    throw Error(ErrorCode::io, name + ": " + std::to_string(size) + " bytes; " + what +
                                   " is at most " + std::to_string(max_bytes) + " bytes");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(ErrorCode::io, name + ": cannot open: " + std::strerror(errno));
  std::string text;
  char buffer[1 << 16];
  while (in.read(buffer, sizeof buffer) || in.gcount() > 0) {
    text.append(buffer, std::size_t(in.gcount()));
    if (text.size() > max_bytes)  // grew while being read
      throw Error(ErrorCode::io, name + ": more than " + std::to_string(max_bytes) + " bytes; " +
                                     what + " is smaller");
  }
  if (in.bad()) throw Error(ErrorCode::io, name + ": cannot read: " + std::strerror(errno));
  return text;
}

const Json* member(const Json& obj, const char* key) {
  const auto it = obj.find(key);
  return it == obj.end() ? nullptr : &*it;
}

// Parses the text, rejecting duplicate keys (the parser would silently keep one of them) and
// turning syntax errors into "source: line L, column C: problem".
Json parse_text(const std::string& text, const JsonReader& r) {
  // nlohmann's lexer takes a NUL byte for the end of the input, so "{...}\0garbage" would read
  // as "{...}". JSON text never holds a raw NUL (inside strings it must be escaped as \u0000).
  if (const std::size_t nul = text.find('\0'); nul != std::string::npos) {
    const auto [line, column] = line_column(text, nul);
    r.fail("", "line " + std::to_string(line) + ", column " + std::to_string(column) +
                   ": a NUL byte (JSON text has none; the file is truncated, padded or binary)");
  }
  struct Frame {
    bool is_array = false;
    std::size_t index = 0;       // arrays: the element being read
    std::string key;             // objects: the member being read
    std::set<std::string> keys;  // a set: documents with huge objects must not cost n^2
  };
  std::vector<Frame> stack;
  auto pointer = [&stack](std::size_t depth) {
    std::string p;
    for (std::size_t i = 0; i < depth; ++i)
      p += "/" + (stack[i].is_array ? std::to_string(stack[i].index) : pointer_token(stack[i].key));
    return p;
  };
  auto element_done = [&stack] {
    if (!stack.empty() && stack.back().is_array) ++stack.back().index;
  };
  using Event = Json::parse_event_t;
  auto callback = [&](int, Event event, Json& parsed) {
    switch (event) {
      case Event::object_start:
      case Event::array_start:
        // Nesting is bounded: every reader of the value (copies, dumps, our own walkers)
        // recurses once per level, and 100,000 levels overflow the stack.
        if (stack.size() >= kMaxNesting)
          r.fail(pointer(std::min<std::size_t>(stack.size(), 8)) + (stack.size() > 8 ? "/..." : ""),
                 "arrays and objects nested more than " + std::to_string(kMaxNesting) +
                     " levels deep");
        stack.push_back({event == Event::array_start, 0, {}, {}});
        break;
      case Event::key: {
        Frame& f = stack.back();
        f.key = parsed.get<std::string>();
        if (!f.keys.insert(f.key).second) r.fail(pointer(stack.size()), "duplicate key");
        break;
      }
      case Event::object_end:
      case Event::array_end:
        stack.pop_back();
        element_done();
        break;
      case Event::value:
        element_done();
        break;
    }
    return true;
  };
  try {
    return Json::parse(text, callback);
  } catch (const Json::parse_error& e) {
    const std::string problem = parse_problem(e.what());
    r.fail("", position_text(text, e.byte, problem) + ": " + problem);
  } catch (const Json::exception& e) {
    // Number overflow (1e400) carries no position: name the JSON path being read instead.
    r.fail(pointer(stack.size()), parse_problem(e.what()));
  }
}

}  // namespace mr::json
