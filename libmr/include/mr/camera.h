// mr::Camera: the pinhole camera of a photo.
#pragma once

#include <array>

#include "mr/export.h"
#include "mr/metadata.h"

namespace mr {

/// A pinhole camera looking down +z (x right, y down in the image), in pixel units.
/// Pixel (x, y) covers [x, x+1) x [y, y+1); its centre ray passes through (x+0.5, y+0.5).
struct MR_API Camera {
  int width = 0, height = 0;
  double focal_px = 0;  ///< focal length in pixels
  double cx = 0, cy = 0;  ///< principal point in pixels

  /// Camera with a horizontal field of view in degrees, principal point at the centre.
  /// Throws mr::Error(invalid_argument) unless 0 < fov < 180 and the size is positive.
  static Camera from_horizontal_fov(int width, int height, double fov_deg);
  /// Camera with a focal length in pixels, principal point at the centre.
  static Camera from_focal_px(int width, int height, double focal_px);
  /// Camera from EXIF FocalLengthIn35mmFormat (OIIO: "Exif:FocalLengthIn35mmFilm"; 36 mm across
  /// the long side), else `fallback_fov_deg` horizontally (60 degrees, DESIGN.md section 4).
  static Camera from_metadata(int width, int height, const Metadata& metadata,
                              double fallback_fov_deg = 60.0);

  double horizontal_fov_deg() const;
  /// |ray(x,y)| / z: converts planar z-depth of the pixel centre to distance along its ray.
  double z_to_distance(int x, int y) const;
  /// Unit ray direction through the centre of pixel (x, y).
  std::array<double, 3> ray_direction(int x, int y) const;
};

}  // namespace mr
