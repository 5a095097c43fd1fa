// Private to libmr: what is behind mr::Metadata. OIIO's ParamValueList, from
// libOpenImageIO_Util (light: not libOpenImageIO, see core/oiio_module.h).
#pragma once

#include <OpenImageIO/paramlist.h>

#include "mr/metadata.h"

namespace mr {

struct Metadata::Impl {
  OIIO::ParamValueList attributes;
};

}  // namespace mr
