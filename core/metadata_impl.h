// Private to libmr: what is behind mr::Metadata, an attribute list as OIIO keeps them
// (core/attributes.h; converted to OIIO's ParamValueList only in its module and tests).
#pragma once

#include "core/attributes.h"
#include "mr/metadata.h"

namespace mr {

struct Metadata::Impl {
  detail::AttributeList attributes;
};

}  // namespace mr
