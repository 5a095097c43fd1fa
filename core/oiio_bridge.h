// Private to libmr: mr::Image views as OpenImageIO ImageBufs, for code that links OIIO itself
// (the OIIO module, tests). Header-only, so libmr.so does not need libOpenImageIO.
#pragma once

#include <OpenImageIO/imagebuf.h>

#include "core/metadata_impl.h"
#include "core/oiio_attributes.h"
#include "mr/image.h"

namespace mr::detail {

/// An ImageBuf that wraps the view's pixels without copying (the view must stay alive).
/// Works for any row stride.
inline OIIO::ImageBuf wrap(ImageView view) {
  OIIO::ImageSpec spec(view.width, view.height, view.channels, OIIO::TypeDesc::FLOAT);
  return OIIO::ImageBuf(spec, view.data, OIIO::stride_t(view.channels * sizeof(float)),
                        OIIO::stride_t(view.row_stride * sizeof(float)));
}

inline OIIO::ImageBuf wrap(ConstImageView view) {
  // ImageBuf has no const-wrapping constructor; callers only read from the result.
  return wrap(ImageView{const_cast<float*>(view.data), view.width, view.height, view.channels,
                        view.row_stride});
}

}  // namespace mr::detail
