// Placing inserted objects on the photo's reconstructed surfaces (issue 16): the point and the
// surface normal under a clicked pixel, from the metric depth (distance along the ray) and the
// camera. The public entry point is mr::place_at_pixel (mr/object_placement.h).
#pragma once

#include "mr/camera.h"
#include "mr/image.h"
#include "mr/scene.h"

namespace mr::photo {

/// The surface under image position (x, y) (continuous image coordinates: pixel (i, j) covers
/// [i, i+1) x [j, j+1)).
struct SurfaceAtPixel {
  Vec3 position_m;      ///< world frame
  Vec3 normal{0, 1, 0};  ///< unit, facing the camera; valid only when normal_valid
  bool normal_valid = false;
  int inliers = 0;  ///< pixels of the neighbourhood on the fitted plane
};

/// Fits a plane to the world points of the pixels within `radius_px` of the clicked one (finite,
/// positive distances only), robustly: first to the clicked pixel's 3x3 neighbourhood, then,
/// four times, to the window's points within max(3 x their median distance, 1 mm + half a
/// pixel's footprint d / (2 f)) of the plane through the clicked point, so that a window
/// straddling a depth edge keeps its majority surface; and intersects the ray through (x, y)
/// with it. Where no plane fits (fewer than 6 inliers, or collinear points)
/// or the intersection is implausible, the position is the clicked pixel's own distance along
/// the ray and normal_valid is false.
/// Throws mr::Error(invalid_argument) when (x, y) is outside the image, the image does not
/// match the camera's size, or the clicked pixel has no surface (sky: infinite distance, or 0 /
/// NaN).
SurfaceAtPixel surface_at_pixel(const Camera& camera, const CameraPose& pose,
                                ConstImageView distance_m, double x, double y, int radius_px);

}  // namespace mr::photo
