#include "mr/error.h"

#include <string>

#include "mr/cancel.h"
#include "mr/version.h"

namespace mr {

const char* to_string(ErrorCode code) noexcept {
  switch (code) {
    case ErrorCode::invalid_argument: return "invalid_argument";
    case ErrorCode::io: return "io";
    case ErrorCode::corrupt_input: return "corrupt_input";
    case ErrorCode::size_mismatch: return "size_mismatch";
    case ErrorCode::color: return "color";
    case ErrorCode::internal: return "internal";
    case ErrorCode::cancelled: return "cancelled";
  }
  return "unknown";
}

void throw_if_cancelled(const CancelToken* token, const char* what) {
  if (token && token->requested())
    throw Error(ErrorCode::cancelled, std::string(what) + ": cancelled");
}

const char* version() noexcept { return MR_VERSION_STRING; }

}  // namespace mr
