#include "grabcut_assist.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "mr/error.h"

namespace mrstudio {

std::vector<mr::PixelPoint> snap_polygon_grabcut(const QImage& photo,
                                                 const std::vector<mr::PixelPoint>& rough,
                                                 double tolerance_px, int iterations) {
  if (rough.size() < 3)
    throw mr::Error(mr::ErrorCode::invalid_argument, "GrabCut: the polygon needs >= 3 points");
  if (photo.isNull()) throw mr::Error(mr::ErrorCode::invalid_argument, "GrabCut: no photo");
  const QImage rgb = photo.convertToFormat(QImage::Format_RGB888);
  // GrabCut works on a crop around the polygon: the polygon's box and a margin of background.
  std::vector<cv::Point> poly;
  for (const auto& p : rough) poly.emplace_back(int(std::lround(p[0])), int(std::lround(p[1])));
  const cv::Rect box = cv::boundingRect(poly);
  const int margin = std::max(8, int(0.15 * std::max(box.width, box.height)));
  const cv::Rect crop =
      cv::Rect(box.x - margin, box.y - margin, box.width + 2 * margin, box.height + 2 * margin) &
      cv::Rect(0, 0, rgb.width(), rgb.height());
  if (crop.width < 4 || crop.height < 4 || box.area() < 9)
    throw mr::Error(mr::ErrorCode::invalid_argument,
                    "GrabCut: the polygon is too small or outside the photo");
  cv::Mat image(crop.height, crop.width, CV_8UC3);
  for (int y = 0; y < crop.height; ++y) {
    const uchar* line = rgb.constScanLine(crop.y + y) + 3 * crop.x;
    std::copy_n(line, 3 * crop.width, image.ptr<uchar>(y));
  }
  cv::cvtColor(image, image, cv::COLOR_RGB2BGR);
  // Outside the polygon: probably background; far outside (beyond a band): background.
  cv::Mat mask(crop.size(), CV_8U, cv::Scalar(cv::GC_PR_BGD));
  std::vector<cv::Point> local;
  for (const cv::Point& p : poly) local.push_back(p - crop.tl());
  cv::Mat inside(crop.size(), CV_8U, cv::Scalar(0));
  cv::fillPoly(inside, std::vector<std::vector<cv::Point>>{local}, cv::Scalar(1));
  cv::Mat near;
  cv::dilate(inside, near,
             cv::getStructuringElement(cv::MORPH_ELLIPSE,
                                       cv::Size(2 * margin / 3 + 1, 2 * margin / 3 + 1)));
  mask.setTo(cv::GC_BGD, near == 0);
  mask.setTo(cv::GC_PR_FGD, inside != 0);
  if (cv::countNonZero(mask == cv::GC_BGD) == 0)  // the crop hit the photo's edges all round
    mask.row(0).setTo(cv::GC_BGD);
  cv::Mat bgd, fgd;
  cv::grabCut(image, mask, cv::Rect(), bgd, fgd, iterations, cv::GC_INIT_WITH_MASK);
  cv::Mat object = (mask == cv::GC_FGD) | (mask == cv::GC_PR_FGD);
  // Small specks and holes are not the outline.
  cv::morphologyEx(object, object, cv::MORPH_OPEN,
                   cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(3, 3)));
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(object, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_SIMPLE);
  if (contours.empty())
    throw mr::Error(mr::ErrorCode::invalid_argument, "GrabCut: no object found inside the polygon");
  const auto largest = std::max_element(
      contours.begin(), contours.end(),
      [](const auto& a, const auto& b) { return cv::contourArea(a) < cv::contourArea(b); });
  std::vector<cv::Point> simple;
  cv::approxPolyDP(*largest, simple, tolerance_px, true);
  if (simple.size() < 3)
    throw mr::Error(mr::ErrorCode::invalid_argument, "GrabCut: the object is too small");
  // Contour points are the centres of the outermost object pixels; the outline runs along their
  // outer edges: each edge moves out by half a pixel (vertices along the miter).
  const std::size_t n = simple.size();
  double area2 = 0;
  for (std::size_t i = 0; i < n; ++i)
    area2 +=
        double(simple[i].x) * simple[(i + 1) % n].y - double(simple[(i + 1) % n].x) * simple[i].y;
  const double out_sign = area2 > 0 ? 1.0 : -1.0;  // image y points down
  auto normal = [&](const cv::Point& a, const cv::Point& b) {
    const double dx = b.x - a.x, dy = b.y - a.y, l = std::max(1e-9, std::hypot(dx, dy));
    return cv::Point2d(out_sign * dy / l, -out_sign * dx / l);
  };
  std::vector<mr::PixelPoint> out;
  for (std::size_t i = 0; i < n; ++i) {
    const cv::Point2d n1 = normal(simple[(i + n - 1) % n], simple[i]),
                      n2 = normal(simple[i], simple[(i + 1) % n]);
    const double k = 0.5 / std::max(0.2, 1.0 + n1.dot(n2));  // miter, bounded at sharp corners
    out.push_back(
        {simple[i].x + crop.x + k * (n1.x + n2.x), simple[i].y + crop.y + k * (n1.y + n2.y)});
  }
  return out;
}

}  // namespace mrstudio
