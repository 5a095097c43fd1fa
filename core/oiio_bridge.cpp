#include "oiio_bridge.h"

namespace mr::detail {

OIIO::ImageSpec float_spec(int width, int height, int channels,
                           const std::vector<std::string>& channel_names) {
  OIIO::ImageSpec spec(width, height, channels, OIIO::TypeDesc::FLOAT);
  if (int(channel_names.size()) == channels) spec.channelnames = channel_names;
  return spec;
}

OIIO::ImageBuf wrap(ImageView view) {
  OIIO::ImageSpec spec(view.width, view.height, view.channels, OIIO::TypeDesc::FLOAT);
  return OIIO::ImageBuf(spec, view.data, OIIO::stride_t(view.channels * sizeof(float)),
                        OIIO::stride_t(view.row_stride * sizeof(float)));
}

OIIO::ImageBuf wrap(ConstImageView view) {
  // ImageBuf has no const-wrapping constructor; callers only read from the result.
  return wrap(ImageView{const_cast<float*>(view.data), view.width, view.height, view.channels,
                        view.row_stride});
}

}  // namespace mr::detail
