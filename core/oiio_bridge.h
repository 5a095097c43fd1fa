// Private to libmr: OpenImageIO <-> mr::Image / mr::Metadata. Heavy header: include only in .cpp.
#pragma once

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/paramlist.h>

#include "mr/image.h"
#include "mr/metadata.h"

namespace mr {

struct Metadata::Impl {
  OIIO::ParamValueList attributes;
};

namespace detail {

/// An ImageBuf that wraps the view's pixels without copying (the view must stay alive).
/// Works for any row stride.
OIIO::ImageBuf wrap(ImageView view);
OIIO::ImageBuf wrap(ConstImageView view);
/// A spec for the view's size with float pixels and the image's channel names.
OIIO::ImageSpec float_spec(int width, int height, int channels,
                           const std::vector<std::string>& channel_names);

}  // namespace detail
}  // namespace mr
