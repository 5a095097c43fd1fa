#include "cv_bridge.h"

#include "mr/error.h"

namespace mr::detail {

cv::Mat as_mat(ImageView view) {
  if (view.channels > CV_CN_MAX)
    throw Error(ErrorCode::invalid_argument,
                "cv::Mat supports at most " + std::to_string(CV_CN_MAX) + " channels");
  return cv::Mat(view.height, view.width, CV_32FC(view.channels), view.data,
                 std::size_t(view.row_stride) * sizeof(float));
}

cv::Mat as_mat(ConstImageView view) {
  return as_mat(ImageView{const_cast<float*>(view.data), view.width, view.height, view.channels,
                          view.row_stride});
}

ImageView as_view(cv::Mat& mat) {
  if (mat.depth() != CV_32F || mat.dims != 2)
    throw Error(ErrorCode::invalid_argument, "as_view: cv::Mat must be 2-D float32");
  return {mat.ptr<float>(), mat.cols, mat.rows, mat.channels(),
          std::ptrdiff_t(mat.step1())};
}

}  // namespace mr::detail
