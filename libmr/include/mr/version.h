// libmr version.
#pragma once

#include "mr/export.h"


namespace mr {
/// "major.minor.patch" of the libmr this program runs against.
MR_API const char* version() noexcept;
}  // namespace mr
