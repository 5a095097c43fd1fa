// The surface under a clicked pixel (photo/object_placement.h): a robust local plane fit to the
// depth map's world points, intersected with the click's ray.
#include "photo/object_placement.h"

#include <opencv2/core.hpp>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "mr/error.h"

namespace mr::photo {

namespace {

struct P3 {
  double x, y, z;
};
P3 operator-(P3 a, P3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
P3 operator+(P3 a, P3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
P3 operator*(double s, P3 a) { return {s * a.x, s * a.y, s * a.z}; }
double dot(P3 a, P3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
P3 p3(const Vec3& v) { return {v.x, v.y, v.z}; }

struct Plane {
  P3 centroid{0, 0, 0};
  P3 normal{0, 1, 0};
  bool valid = false;
};

// Least squares plane through the points (PCA): the normal is the covariance's eigenvector of
// the smallest eigenvalue. Invalid for fewer than 3 points or (nearly) collinear ones.
Plane fit_plane(const std::vector<P3>& pts, const std::vector<char>& use) {
  Plane plane;
  std::size_t n = 0;
  P3 c{0, 0, 0};
  for (std::size_t i = 0; i < pts.size(); ++i)
    if (use[i]) c = c + pts[i], ++n;
  if (n < 3) return plane;
  c = (1.0 / double(n)) * c;
  cv::Matx33d cov = cv::Matx33d::zeros();
  for (std::size_t i = 0; i < pts.size(); ++i) {
    if (!use[i]) continue;
    const P3 d = pts[i] - c;
    const double v[3] = {d.x, d.y, d.z};
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) cov(a, b) += v[a] * v[b];
  }
  cv::Mat values, vectors;
  cv::eigen(cv::Mat(cov), values, vectors);  // descending eigenvalues, vectors as rows
  const double l0 = values.at<double>(0), l1 = values.at<double>(1);
  // Collinear (a single row or column of pixels, or a thin strip): the plane is undetermined.
  if (!(l1 > 1e-6 * l0) || !(l0 > 0)) return plane;
  plane.centroid = c;
  plane.normal = {vectors.at<double>(2, 0), vectors.at<double>(2, 1), vectors.at<double>(2, 2)};
  const double len = std::sqrt(dot(plane.normal, plane.normal));
  if (!(len > 0) || !std::isfinite(len)) return plane;
  plane.normal = (1.0 / len) * plane.normal;
  plane.valid = true;
  return plane;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  const auto mid = v.begin() + std::ptrdiff_t(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

}  // namespace

SurfaceAtPixel surface_at_pixel(const Camera& camera, const CameraPose& pose,
                                ConstImageView distance_m, double x, double y, int radius_px) {
  const std::string where = "place at pixel (" + std::to_string(x) + ", " + std::to_string(y) + ")";
  if (distance_m.width != camera.width || distance_m.height != camera.height)
    throw Error(ErrorCode::size_mismatch,
                where + ": the distance image is " + std::to_string(distance_m.width) + "x" +
                    std::to_string(distance_m.height) + ", the camera's image " +
                    std::to_string(camera.width) + "x" + std::to_string(camera.height));
  if (distance_m.channels < 1 || !distance_m.data)
    throw Error(ErrorCode::invalid_argument, where + ": the distance image is empty");
  if (!(x >= 0 && y >= 0 && x < camera.width && y < camera.height))
    throw Error(ErrorCode::invalid_argument,
                where + ": outside the " + std::to_string(camera.width) + "x" +
                    std::to_string(camera.height) + " image");
  if (radius_px < 1 || radius_px > 64)
    throw Error(ErrorCode::invalid_argument,
                where + ": window radius " + std::to_string(radius_px) + " must be in 1..64");

  const int px = static_cast<int>(x), py = static_cast<int>(y);
  const double d0 = distance_m.at(px, py, 0);
  if (!(std::isfinite(d0) && d0 > 0))
    throw Error(ErrorCode::invalid_argument,
                where + ": no surface there (distance " + std::to_string(d0) +
                    ": sky or unknown depth); click on the ground or another surface");
  const P3 origin = p3(pose.position_m);
  // ray_direction takes pixel-index coordinates (its pixel centre at integer values).
  const P3 click_ray = p3(pose.ray_direction(camera, x - 0.5, y - 0.5));

  std::vector<P3> pts;
  std::vector<char> near_centre;  // within one pixel of the clicked one
  for (int j = std::max(0, py - radius_px); j <= std::min(camera.height - 1, py + radius_px); ++j)
    for (int i = std::max(0, px - radius_px); i <= std::min(camera.width - 1, px + radius_px);
         ++i) {
      const double d = distance_m.at(i, j, 0);
      if (!(std::isfinite(d) && d > 0)) continue;
      pts.push_back(origin + d * p3(pose.ray_direction(camera, i, j)));
      near_centre.push_back(std::abs(i - px) <= 1 && std::abs(j - py) <= 1);
    }
  const P3 centre_point = origin + d0 * p3(pose.ray_direction(camera, px, py));

  // Robust fit: start from the clicked pixel's 3x3 neighbourhood (across a depth edge mostly
  // its own surface), then grow to the window's points on the fitted plane, and refit.
  std::vector<char> use = near_centre;
  Plane plane = fit_plane(pts, use);
  for (int iteration = 0; iteration < 4 && plane.valid; ++iteration) {
    // Distances of every window point from the plane through the clicked point. Their median
    // measures the noise plus how wrong the plane still is (a 3x3 fit to noisy depth can be
    // tilted): points within 3 times it are kept, so the set grows while the plane is poor and
    // settles on the clicked surface, the window's majority, when it is good.
    const double offset = dot(centre_point - plane.centroid, plane.normal);
    std::vector<double> residuals(pts.size());
    for (std::size_t i = 0; i < pts.size(); ++i)
      residuals[i] = std::abs(dot(pts[i] - plane.centroid, plane.normal) - offset);
    // Noise-free depth leaves residuals of rounding only: then a point counts as on the plane
    // within half a pixel's footprint, so the first row of a crossing surface stays out.
    const double tolerance = std::max(3.0 * median(residuals), 1e-3 + 0.5 * d0 / camera.focal_px);
    for (std::size_t i = 0; i < pts.size(); ++i) use[i] = residuals[i] < tolerance;
    plane = fit_plane(pts, use);
  }
  SurfaceAtPixel out;
  out.inliers = static_cast<int>(std::count(use.begin(), use.end(), char(1)));
  out.position_m = {origin.x + d0 * click_ray.x, origin.y + d0 * click_ray.y,
                    origin.z + d0 * click_ray.z};
  if (!plane.valid || out.inliers < 6) return out;
  P3 n = plane.normal;
  if (dot(n, origin - plane.centroid) < 0) n = -1.0 * n;  // the side the camera sees
  const double denom = dot(n, click_ray);
  if (!(std::abs(denom) > 1e-9)) return out;  // the ray grazes the plane
  const double t = dot(n, plane.centroid - origin) / denom;
  if (!(std::isfinite(t) && t > 0 && std::abs(t - d0) < 0.5 * d0)) return out;
  out.position_m = {origin.x + t * click_ray.x, origin.y + t * click_ray.y,
                    origin.z + t * click_ray.z};
  out.normal = {n.x, n.y, n.z};
  out.normal_valid = true;
  return out;
}

}  // namespace mr::photo
