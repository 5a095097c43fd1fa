// Private to libmr: mr::Image views as cv::Mat headers. Heavy header: include only in .cpp.
#pragma once

#include <opencv2/core/mat.hpp>

#include "mr/image.h"

namespace mr::detail {

/// A cv::Mat header of type CV_32FC(channels) over the view's pixels (no copy; the view must
/// outlive the Mat). Throws mr::Error(invalid_argument) for more than CV_CN_MAX channels.
cv::Mat as_mat(ImageView view);
/// Read-only variant; the Mat must not be written to.
cv::Mat as_mat(ConstImageView view);
/// A view onto a continuous or row-strided CV_32FC(n) Mat (no copy).
ImageView as_view(cv::Mat& mat);

}  // namespace mr::detail
