#include "mr/camera.h"

#include <cmath>
#include <numbers>
#include <string>

#include "mr/error.h"

namespace mr {

namespace {
void check_size(int width, int height) {
  if (width <= 0 || height <= 0)
    throw Error(ErrorCode::invalid_argument, "camera: image size " + std::to_string(width) + "x" +
                                                 std::to_string(height) + " is not positive");
}
}  // namespace

Camera Camera::from_focal_px(int width, int height, double focal_px) {
  check_size(width, height);
  if (!(focal_px > 0) || !std::isfinite(focal_px))
    throw Error(ErrorCode::invalid_argument,
                "camera: focal length " + std::to_string(focal_px) + " px must be positive");
  return {width, height, focal_px, 0.5 * width, 0.5 * height};
}

Camera Camera::from_horizontal_fov(int width, int height, double fov_deg) {
  if (!(fov_deg > 0 && fov_deg < 180))
    throw Error(ErrorCode::invalid_argument,
                "camera: field of view " + std::to_string(fov_deg) + " deg is not in (0, 180)");
  const double half = 0.5 * fov_deg * std::numbers::pi / 180.0;
  return from_focal_px(width, height, 0.5 * width / std::tan(half));
}

Camera Camera::from_metadata(int width, int height, const Metadata& metadata,
                             double fallback_fov_deg) {
  // 35 mm equivalent focal length refers to a 36 mm wide frame along the long side.
  // OIIO names EXIF tag 0xA405 "Exif:FocalLengthIn35mmFilm"; accept the EXIF spec's name too.
  auto f35 = metadata.get_number("Exif:FocalLengthIn35mmFilm");
  if (!f35) f35 = metadata.get_number("Exif:FocalLengthIn35mmFormat");
  if (f35 && *f35 > 0) {
    const double long_side = std::max(width, height);
    const double focal_px = *f35 / 36.0 * long_side;
    return from_focal_px(width, height, focal_px);
  }
  return from_horizontal_fov(width, height, fallback_fov_deg);
}

double Camera::horizontal_fov_deg() const {
  return 2.0 * std::atan(0.5 * width / focal_px) * 180.0 / std::numbers::pi;
}

double Camera::z_to_distance(int x, int y) const {
  const double u = (x + 0.5 - cx) / focal_px, v = (y + 0.5 - cy) / focal_px;
  return std::sqrt(u * u + v * v + 1.0);
}

std::array<double, 3> Camera::ray_direction(int x, int y) const {
  const double u = (x + 0.5 - cx) / focal_px, v = (y + 0.5 - cy) / focal_px;
  const double n = std::sqrt(u * u + v * v + 1.0);
  return {u / n, v / n, 1.0 / n};
}

}  // namespace mr
