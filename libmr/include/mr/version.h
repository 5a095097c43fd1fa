// libmr version.
#pragma once

namespace mr {
/// "major.minor.patch" of the libmr this program runs against.
const char* version() noexcept;
}  // namespace mr
