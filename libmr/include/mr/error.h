// mr::Error: the one exception type libmr throws.
#pragma once

#include <stdexcept>
#include <string>

#include "mr/export.h"

namespace mr {

/// What kind of failure an mr::Error reports; front ends map these to messages and exit codes.
enum class ErrorCode {
  invalid_argument,  ///< a parameter is out of range or malformed (the message names it)
  io,                ///< a file could not be read or written (the message names the file)
  corrupt_input,     ///< a file was read but its content is unusable (truncated, NaN pixels, ...)
  size_mismatch,     ///< two inputs that must have the same size do not
  color,             ///< OpenColorIO could not load a config or convert between colour spaces
  internal,          ///< a bug: an invariant of libmr itself was broken
  cancelled,         ///< the caller asked the call to stop (mr::CancelToken); nothing was output
};

/// Human-readable name of a code ("io", "invalid_argument", ...).
MR_API const char* to_string(ErrorCode code) noexcept;

/// Thrown by every libmr function that fails. what() is a one-line message that names the
/// file or parameter concerned and says what was found, e.g.
/// "photo.jpg: depth map is 640x480, photo is 1280x960".
class MR_API Error : public std::runtime_error {
 public:
  Error(ErrorCode code, const std::string& message) : std::runtime_error(message), code_(code) {}
  ErrorCode code() const noexcept { return code_; }

 private:
  ErrorCode code_;
};

}  // namespace mr
