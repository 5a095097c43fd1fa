#include "photo/geometry.h"

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>

#include "core/cv_bridge.h"
#include "core/vec3.h"
#include "mr/error.h"
#include "photo/display.h"
#include "photo/opencv_contrib.h"

namespace mr::photo {

namespace {

using vec3::dot;  // core/vec3.h

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kMaxHorizonTiltDeg = 45;

std::string fmt(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4g", v);
  return buf;
}
std::string fmt(const PixelPoint& p) {
  return "(" + fmt(p[0]) + ", " + fmt(p[1]) + ")";
}

[[noreturn]] void fail(const std::string& pointer, const std::string& problem) {
  throw Error(ErrorCode::invalid_argument, pointer + ": " + problem);
}

// Normalised image coordinates of a pixel-centre point.
std::array<double, 2> normalised(const Camera& c, const PixelPoint& p) {
  return {(p[0] + 0.5 - c.cx) / c.focal_px, (p[1] + 0.5 - c.cy) / c.focal_px};
}

}  // namespace

PitchRoll pitch_roll_from_horizon(const Camera& camera, const std::array<PixelPoint, 2>& horizon) {
  for (int i = 0; i < 2; ++i) {
    const PixelPoint& p = horizon[i];
    const std::string ptr = "/horizon/" + std::to_string(i);
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]))
      fail(ptr, "expected finite coordinates, found " + fmt(p));
    if (p[0] < -camera.width || p[0] > 2.0 * camera.width || p[1] < -camera.height ||
        p[1] > 2.0 * camera.height)
      fail(ptr, fmt(p) + " is more than one image size outside the " +
                    std::to_string(camera.width) + "x" + std::to_string(camera.height) + " image");
  }
  if (std::hypot(horizon[1][0] - horizon[0][0], horizon[1][1] - horizon[0][1]) < 1.0)
    fail("/horizon", "the two points " + fmt(horizon[0]) + " and " + fmt(horizon[1]) +
                         " are less than 1 pixel apart");
  const auto p0 = normalised(camera, horizon[0]);
  const auto p1 = normalised(camera, horizon[1]);
  // Unit normal of the line, oriented down the image (b component >= 0).
  double na = -(p1[1] - p0[1]), nb = p1[0] - p0[0];
  const double len = std::hypot(na, nb);
  na /= len;
  nb /= len;
  if (nb < 0 || (nb == 0 && na < 0)) na = -na, nb = -nb;
  const double tilt = std::atan2(std::abs(na), nb) / kDeg;
  if (!(tilt < kMaxHorizonTiltDeg))
    fail("/horizon", "the line through " + fmt(horizon[0]) + " and " + fmt(horizon[1]) + " is " +
                         fmt(tilt) + " degrees from level; at most " + fmt(kMaxHorizonTiltDeg) +
                         " is accepted");
  PitchRoll out;
  out.roll_deg = std::atan2(na, nb) / kDeg + 0.0;  // + 0.0: no "-0" in documents
  out.pitch_deg = std::atan(na * p0[0] + nb * p0[1]) / kDeg + 0.0;
  return out;
}

std::array<PixelPoint, 2> horizon_of_pose(const Camera& camera, const CameraPose& pose) {
  const auto [f, r, u] = pose.axes();
  // Ray d = a r - b u + f is horizontal where a r.y - b u.y + f.y = 0.
  if (!(std::abs(u.y) > 1e-12))
    throw Error(ErrorCode::invalid_argument,
                "horizon_of_pose: the horizon is vertical in the image (roll " +
                    fmt(pose.roll_deg) + ", pitch " + fmt(pose.pitch_deg) + " degrees)");
  std::array<PixelPoint, 2> out;
  const double xs[2] = {0.0, double(camera.width - 1)};
  for (int i = 0; i < 2; ++i) {
    const double a = (xs[i] + 0.5 - camera.cx) / camera.focal_px;
    const double b = (a * r.y + f.y) / u.y;
    out[i] = {xs[i], b * camera.focal_px + camera.cy - 0.5};
  }
  return out;
}

std::optional<Vec3> ground_point(const Camera& camera, const CameraPose& pose,
                                 const PixelPoint& p) {
  const Vec3 d = pose.ray_direction(camera, p[0], p[1]);
  if (!(d.y < -1e-12)) return std::nullopt;
  const double t = pose.position_m.y / -d.y;
  const Vec3& o = pose.position_m;
  return Vec3{o.x + t * d.x, 0.0, o.z + t * d.z};
}

double camera_height_from_known_length(const Camera& camera, const CameraPose& pose,
                                       const Annotations::KnownLength& known) {
  CameraPose unit = pose;
  unit.position_m = {0, 1, 0};
  const auto a = ground_point(camera, unit, known.a);
  if (!a)
    fail("/known_length/a",
         fmt(known.a) + " is on or above the horizon; it must be a ground point");
  const auto b = ground_point(camera, unit, known.b);
  if (!b)
    fail("/known_length/b",
         fmt(known.b) + " is on or above the horizon; it must be a ground point");
  const double d = std::hypot(a->x - b->x, a->z - b->z);
  if (!(d > 1e-9)) fail("/known_length", "the two points are the same point on the ground");
  return known.length_m / d;
}

VerticalPlane plane_of_polygon(const Camera& camera, const CameraPose& pose,
                               const Annotations::Plane& plane, const std::string& pointer) {
  VerticalPlane out;
  if (plane.base) {
    std::optional<Vec3> g[2];
    for (int i = 0; i < 2; ++i) {
      g[i] = ground_point(camera, pose, (*plane.base)[i]);
      if (!g[i])
        fail(pointer + "/base/" + std::to_string(i),
             fmt((*plane.base)[i]) + " is on or above the horizon; it must be on the ground");
    }
    // Normal: horizontal, perpendicular to the base: cross(g1 - g0, +Y) = (-dz, 0, dx).
    const double dx = g[1]->x - g[0]->x, dz = g[1]->z - g[0]->z;
    const double len = std::hypot(dx, dz);
    if (!(len > 1e-6)) fail(pointer + "/base", "the two points meet the ground at the same place");
    out.normal = {-dz / len, 0, dx / len};
    out.offset = dot(out.normal, *g[0]);
    return out;
  }
  // The lowest vertex, the one farthest below the horizon line: lines on the ground across the
  // camera's horizontal viewing direction image parallel to the horizon, so that is the vertex
  // whose ground point has the smallest horizontal forward distance.
  const Vec3 fwd = pose.axes()[0];
  const double len = std::hypot(fwd.x, fwd.z);
  out.normal = {fwd.x / len, 0, fwd.z / len};
  std::optional<Vec3> g;
  for (const PixelPoint& p : plane.polygon) {
    const auto gp = ground_point(camera, pose, p);
    if (gp && (!g || dot(out.normal, *gp) < dot(out.normal, *g))) g = gp;
  }
  if (!g)
    fail(pointer + "/polygon",
         "lies entirely on or above the horizon; a plane standing on the ground must reach below "
         "it");
  out.offset = dot(out.normal, *g);
  return out;
}

double Room::distance(const Vec3& o, const Vec3& d) const {
  double t = kInf;
  if (d.y < 0) t = o.y / -d.y;
  if (ceiling_height_m && d.y > 0) t = std::min(t, (*ceiling_height_m - o.y) / d.y);
  for (const VerticalPlane& w : walls) {
    const double nd = dot(w.normal, d);
    if (nd < 0) t = std::min(t, std::max(0.0, (w.offset - dot(w.normal, o)) / nd));
  }
  return t;
}

namespace {

// The walls of the box's floor points at `pose`, without the ceiling.
Room walls_of_box(const Camera& camera, const CameraPose& pose,
                  const Annotations::InteriorBox& box) {
  Room room;
  const std::string ptr = "/interior_box/floor";
  for (std::size_t i = 0; i < box.floor.size(); ++i) {
    const auto g = ground_point(camera, pose, box.floor[i]);
    if (!g)
      fail(ptr + "/" + std::to_string(i),
           fmt(box.floor[i]) + " is on or above the horizon; floor points must be below it");
    room.floor_m.push_back(*g);
  }
  const Vec3 cam{pose.position_m.x, 0, pose.position_m.z};
  // Lengths below this (relative to the floor's extent) count as zero: the tolerance of the
  // collinearity and convexity tests.
  double extent = 0;
  for (const Vec3& g : room.floor_m)
    extent = std::max(extent, std::hypot(g.x - cam.x, g.z - cam.z));
  const double eps = 1e-6 * extent;
  for (std::size_t i = 0; i + 1 < room.floor_m.size(); ++i) {
    const Vec3 &a = room.floor_m[i], &b = room.floor_m[i + 1];
    const double dx = b.x - a.x, dz = b.z - a.z, len = std::hypot(dx, dz);
    if (!(len > eps))
      fail(ptr + "/" + std::to_string(i + 1), "points " + std::to_string(i) + " and " +
                                                  std::to_string(i + 1) +
                                                  " meet the floor at the same place");
    VerticalPlane w{{-dz / len, 0, dx / len}, 0};
    w.offset = dot(w.normal, a);
    const double side = dot(w.normal, cam) - w.offset;
    if (std::abs(side) <= eps)
      fail(ptr, "the camera stands on the line of wall " + std::to_string(i) + " (points " +
                    std::to_string(i) + " and " + std::to_string(i + 1) + ")");
    if (side < 0) w.normal = {-w.normal.x, 0, -w.normal.z}, w.offset = -w.offset;
    room.walls.push_back(w);
  }
  for (std::size_t i = 0; i + 2 < room.floor_m.size(); ++i) {
    const VerticalPlane& w = room.walls[i];
    if (std::abs(dot(w.normal, room.floor_m[i + 2]) - w.offset) <= 1e-4 * extent)
      fail(ptr + "/" + std::to_string(i + 1),
           "points " + std::to_string(i) + ", " + std::to_string(i + 1) + " and " +
               std::to_string(i + 2) +
               " meet the floor on one line (collinear): they span one wall; drop the middle one");
  }
  for (std::size_t i = 0; i < room.walls.size(); ++i)
    for (std::size_t j = 0; j < room.floor_m.size(); ++j)
      if (dot(room.walls[i].normal, room.floor_m[j]) - room.walls[i].offset < -eps)
        fail(ptr, "the points do not bound a convex room around the camera: point " +
                      std::to_string(j) + " lies outside wall " + std::to_string(i) +
                      " (through points " + std::to_string(i) + " and " + std::to_string(i + 1) +
                      ")");
  return room;
}

// The height above the floor where the ceiling point's ray meets the nearest wall.
double ceiling_hit_height(const Camera& camera, const CameraPose& pose, const Room& walls,
                          const PixelPoint& p) {
  const std::string ptr = "/interior_box/ceiling_point";
  const Vec3 d = pose.ray_direction(camera, p[0], p[1]);
  if (!(d.y > 1e-12))
    fail(ptr, fmt(p) + " is on or below the horizon; the ceiling meets the walls above it");
  const Vec3 o = pose.position_m;
  double t = kInf;
  for (const VerticalPlane& w : walls.walls) {
    const double nd = dot(w.normal, d);
    if (nd < 0) t = std::min(t, (w.offset - dot(w.normal, o)) / nd);
  }
  if (!std::isfinite(t))
    fail(ptr, fmt(p) + " looks past every wall; it must be on a wall's top edge");
  return o.y + t * d.y;
}

}  // namespace

Room room_of_box(const Camera& camera, const CameraPose& pose,
                 const Annotations::InteriorBox& box) {
  Room room = walls_of_box(camera, pose, box);
  const double h = pose.position_m.y;
  if (box.ceiling_height_m) {
    room.ceiling_height_m = *box.ceiling_height_m;
    if (!(*room.ceiling_height_m > h))
      fail("/interior_box/ceiling_height_m",
           fmt(*room.ceiling_height_m) + " m is not above the camera (" + fmt(h) + " m)");
  } else if (box.ceiling_point) {
    room.ceiling_height_m = ceiling_hit_height(camera, pose, room, *box.ceiling_point);
  }
  return room;
}

double ceiling_over_camera_height(const Camera& camera, const CameraPose& pose,
                                  const Annotations::InteriorBox& box) {
  if (!box.ceiling_point) fail("/interior_box/ceiling_point", "missing");
  CameraPose unit = pose;
  unit.position_m = {pose.position_m.x, 1, pose.position_m.z};
  return ceiling_hit_height(camera, unit, walls_of_box(camera, unit, box), *box.ceiling_point);
}

std::optional<PixelPoint> project(const Camera& camera, const CameraPose& pose, const Vec3& p) {
  const auto [f, r, u] = pose.axes();
  const Vec3 v{p.x - pose.position_m.x, p.y - pose.position_m.y, p.z - pose.position_m.z};
  const double z = dot(v, f);
  if (!(z > 1e-3)) return std::nullopt;
  return PixelPoint{camera.focal_px * dot(v, r) / z + camera.cx - 0.5,
                    camera.focal_px * -dot(v, u) / z + camera.cy - 0.5};
}

bool inside_polygon(const std::vector<PixelPoint>& poly, double x, double y) {
  bool in = false;
  const std::size_t n = poly.size();
  for (std::size_t i = 0, j = n - 1; i < n; j = i++) {
    const double xi = poly[i][0], yi = poly[i][1], xj = poly[j][0], yj = poly[j][1];
    if ((yi > y) != (yj > y) && x < (xj - xi) * (y - yi) / (yj - yi) + xi) in = !in;
  }
  return in;
}

DistanceMap distance_map(const Camera& camera, const CameraPose& pose,
                         const Annotations& annotations) {
  const int w = camera.width, h = camera.height;
  const double height = pose.position_m.y;
  if (!(height > 0) || !std::isfinite(height))
    fail("/camera_height_m", "the camera must be above the ground, found " + fmt(height) + " m");
  std::vector<VerticalPlane> planes;
  for (std::size_t i = 0; i < annotations.planes.size(); ++i)
    planes.push_back(
        plane_of_polygon(camera, pose, annotations.planes[i], "/planes/" + std::to_string(i)));

  // Integer pixel bounding boxes of the polygons, so each is tested only where it can be.
  struct Box {
    int x0, y0, x1, y1;
  };
  auto box_of = [w, h](const std::vector<PixelPoint>& poly) {
    double x0 = kInf, y0 = kInf, x1 = -kInf, y1 = -kInf;
    for (const auto& p : poly) {
      x0 = std::min(x0, p[0]), x1 = std::max(x1, p[0]);
      y0 = std::min(y0, p[1]), y1 = std::max(y1, p[1]);
    }
    return Box{std::max(0, int(std::floor(x0))), std::max(0, int(std::floor(y0))),
               std::min(w - 1, int(std::ceil(x1))), std::min(h - 1, int(std::ceil(y1)))};
  };
  std::vector<Box> plane_boxes, hint_boxes;
  for (const auto& p : annotations.planes) plane_boxes.push_back(box_of(p.polygon));
  for (const auto& hnt : annotations.distance_hints) hint_boxes.push_back(box_of(hnt.polygon));

  DistanceMap out;
  if (annotations.interior_box) out.room = room_of_box(camera, pose, *annotations.interior_box);
  out.distance_m = Image(w, h, 1, {"Z"});
  out.coverage.assign(std::size_t(w) * h, Coverage::sky);
  const Vec3 o = pose.position_m;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const Vec3 d = pose.ray_direction(camera, x, y);
      double dist = kInf;
      Coverage cov = Coverage::sky;
      if (d.y < 0) dist = height / -d.y, cov = Coverage::ground;
      if (out.room) {
        const double t = out.room->distance(o, d);
        if (std::isfinite(t)) dist = t, cov = Coverage::room;
      }
      double best_plane = kInf;
      for (std::size_t i = 0; i < planes.size(); ++i) {
        const Box& b = plane_boxes[i];
        if (x < b.x0 || x > b.x1 || y < b.y0 || y > b.y1) continue;
        if (!inside_polygon(annotations.planes[i].polygon, x, y)) continue;
        const double nd = dot(planes[i].normal, d);
        if (nd == 0) continue;
        const double t = (planes[i].offset - dot(planes[i].normal, o)) / nd;
        if (!(t > 0) || !std::isfinite(t)) continue;
        if (o.y + t * d.y < 0) continue;  // below the plane's base: the ground is in front
        best_plane = std::min(best_plane, t);
      }
      if (best_plane < kInf) dist = best_plane, cov = Coverage::plane;
      for (std::size_t i = 0; i < annotations.distance_hints.size(); ++i) {
        const Box& b = hint_boxes[i];
        if (x < b.x0 || x > b.x1 || y < b.y0 || y > b.y1) continue;
        if (!inside_polygon(annotations.distance_hints[i].polygon, x, y)) continue;
        dist = annotations.distance_hints[i].distance_m;
        cov = Coverage::hint;
      }
      out.distance_m.at(x, y, 0) = float(dist);
      out.coverage[std::size_t(y) * w + x] = cov;
      ++out.counts[int(cov)];
    }
  }
  return out;
}

namespace {

// `map` (the photo's size, float channels) smoothed edge-aware against the photo: the fast
// global smoother guided by the photo in display-referred 8-bit (its guide must be 8-bit), both
// area-averaged down to at most o.working_pixels and the result brought back up linearly.
template <typename Options>  // DepthRefineOptions, SkyProximityOptions
cv::Mat smooth_against_photo(ConstImageView photo, const cv::Mat& map, const Options& o,
                             double texture_px = 0) {
  const int w = photo.width, h = photo.height;
  const double s = std::min(1.0, std::sqrt(o.working_pixels / (double(w) * h)));
  const int ww = std::max(4, int(std::lround(w * s))), wh = std::max(4, int(std::lround(h * s)));
  const cv::Mat display = display_rgb8(photo);
  cv::Mat guide = display, small = map;
  if (s < 1) {
    cv::resize(display, guide, cv::Size(ww, wh), 0, 0, cv::INTER_AREA);
    cv::resize(map, small, cv::Size(ww, wh), 0, 0, cv::INTER_AREA);
  }
  if (texture_px > 0) {
    // Fine texture (snow crust, grass, foliage, bark) out of the guide, its outlines kept
    // (rolling guidance, Zhang et al. 2014): with every grain of texture an edge, the smoother
    // leaves each pixel with its own unrefined value, a speckled, jagged depth in exactly
    // the low-confidence band it should smooth (a seam in dense fog).
    cv::Mat plain;
    contrib::rolling_guidance_filter(guide, plain, -1, 25, texture_px, 4);
    guide = plain;
  }
  cv::Mat smoothed;
  contrib::fast_global_smoother_filter(guide, small, smoothed, o.lambda, o.sigma_color);
  if (s < 1) cv::resize(smoothed, smoothed, cv::Size(w, h), 0, 0, cv::INTER_LINEAR);
  return smoothed;
}

}  // namespace

float refine_keep_weight(float confidence) {
  const float t = std::clamp((confidence - 0.5f) / 0.5f, 0.0f, 1.0f);
  return t * t * (3 - 2 * t);
}

std::vector<float> refine_inverse_distance(ConstImageView photo,
                                           const std::vector<float>& inverse_distance,
                                           const std::vector<float>& confidence,
                                           const DepthRefineOptions& o) {
  const int w = photo.width, h = photo.height;
  const std::size_t n = std::size_t(w) * h;
  if (inverse_distance.size() != n || confidence.size() != n)
    throw Error(ErrorCode::size_mismatch, "refine_inverse_distance: the photo is " +
                                              std::to_string(w) + "x" + std::to_string(h) +
                                              " but the maps hold " +
                                              std::to_string(inverse_distance.size()) + " and " +
                                              std::to_string(confidence.size()) + " values");
  std::vector<float> out = inverse_distance;
  if (w < 4 || h < 4 || photo.channels < 1) return out;
  bool all_kept = true;
  for (const float c : confidence) all_kept &= refine_keep_weight(c) >= 1.0f;
  if (all_kept) return out;

  // The maps as (c q, c), smoothed against the photo.
  cv::Mat weighted(h, w, CV_32FC2);
  for (int y = 0; y < h; ++y) {
    cv::Vec2f* m = weighted.ptr<cv::Vec2f>(y);
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      // A little confidence everywhere, so that every pixel has a defined average.
      const float c = std::max(1e-3f, std::clamp(confidence[i], 0.0f, 1.0f));
      m[x] = {c * inverse_distance[i], c};
    }
  }
  const cv::Mat smoothed = smooth_against_photo(photo, weighted, o, o.texture_px);
  for (int y = 0; y < h; ++y) {
    const cv::Vec2f* m = smoothed.ptr<cv::Vec2f>(y);
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      const float keep = refine_keep_weight(confidence[i]);
      if (keep >= 1.0f) continue;
      const float q = m[x][1] > 1e-6f ? m[x][0] / m[x][1] : inverse_distance[i];
      if (!std::isfinite(q)) continue;
      out[i] = std::max(0.0f, keep * inverse_distance[i] + (1 - keep) * q);
    }
  }
  return out;
}

std::vector<double> robust_inverse_line(const double* forward, int count, int reach) {
  std::vector<double> out(std::size_t(std::max(0, count)), kInf);
  std::vector<double> xs, qs;
  for (int k = 0; k < count; ++k)
    if (forward[k] > 0 && std::isfinite(forward[k])) xs.push_back(k), qs.push_back(1 / forward[k]);
  if (xs.empty()) return out;
  auto median = [](std::vector<double> v) {
    auto mid = v.begin() + std::ptrdiff_t(v.size() / 2);
    std::nth_element(v.begin(), mid, v.end());
    return *mid;
  };
  double a = median(qs), b = 0;
  if (xs.front() != xs.back()) {
    std::vector<double> weight(xs.size(), 1.0), residual(xs.size());
    for (int round = 0; round < 20; ++round) {
      double sw = 0, sx = 0, sq = 0;
      for (std::size_t i = 0; i < xs.size(); ++i)
        sw += weight[i], sx += weight[i] * xs[i], sq += weight[i] * qs[i];
      const double mx = sx / sw, mq = sq / sw;
      double sxx = 0, sxq = 0;
      for (std::size_t i = 0; i < xs.size(); ++i) {
        sxx += weight[i] * (xs[i] - mx) * (xs[i] - mx);
        sxq += weight[i] * (xs[i] - mx) * (qs[i] - mq);
      }
      b = sxx > 0 ? sxq / sxx : 0;
      a = mq - b * mx;
      for (std::size_t i = 0; i < xs.size(); ++i) residual[i] = std::abs(qs[i] - a - b * xs[i]);
      const double scale = 1.4826 * median(residual);
      if (!(scale > 1e-12 * std::abs(mq))) break;  // the measured columns lie on the line
      const double c = 1.345 * scale;
      for (std::size_t i = 0; i < xs.size(); ++i)
        weight[i] = residual[i] <= c ? 1.0 : c / residual[i];
    }
  }
  if (!(reach > 0) || xs.size() < 3) {
    for (int k = 0; k < count; ++k) {
      const double q = a + b * k;
      out[std::size_t(k)] = q > 0 ? 1 / q : kInf;
    }
    return out;
  }
  // Local lines (tricube kernel of `reach` columns, the global fit's robust weights), blended
  // with the global line by their kernel mass so the result stays continuous where the
  // measured columns thin out.
  std::vector<double> robust(xs.size(), 1.0);
  {
    std::vector<double> residual(xs.size());
    for (std::size_t i = 0; i < xs.size(); ++i) residual[i] = std::abs(qs[i] - a - b * xs[i]);
    const double c = 1.345 * 1.4826 * median(residual);
    if (c > 0)
      for (std::size_t i = 0; i < xs.size(); ++i)
        robust[i] = residual[i] <= c ? 1.0 : c / residual[i];
  }
  for (int k = 0; k < count; ++k) {
    double sw = 0, sx = 0, sq = 0, sxx = 0, sxq = 0;
    const auto lo = std::lower_bound(xs.begin(), xs.end(), k - reach);
    for (auto it = lo; it != xs.end() && *it <= k + reach; ++it) {
      const std::size_t i = std::size_t(it - xs.begin());
      const double u = std::abs(xs[i] - k) / (reach + 1);
      const double t = 1 - u * u * u;
      const double wt = robust[i] * t * t * t;
      sw += wt, sx += wt * xs[i], sq += wt * qs[i];
    }
    double q = a + b * k;
    if (sw > 0) {
      const double mx = sx / sw, mq = sq / sw;
      for (auto it = lo; it != xs.end() && *it <= k + reach; ++it) {
        const std::size_t i = std::size_t(it - xs.begin());
        const double u = std::abs(xs[i] - k) / (reach + 1);
        const double t = 1 - u * u * u;
        const double wt = robust[i] * t * t * t;
        sxx += wt * (xs[i] - mx) * (xs[i] - mx), sxq += wt * (xs[i] - mx) * (qs[i] - mq);
      }
      // The local slope only where the kernel spans enough columns, else the local mean.
      const double local = sxx > 1e-9 * sw * reach * reach ? mq + sxq / sxx * (k - mx) : mq;
      // Kernel mass of about a third of the reach's columns: mostly local.
      const double mass = sw / (0.3 * reach + 1);
      const double f = mass / (1 + mass);
      q = f * local + (1 - f) * q;
    }
    out[std::size_t(k)] = q > 0 ? 1 / q : kInf;
  }
  return out;
}

Defocus estimate_defocus(ConstImageView photo, const std::vector<std::uint8_t>& sky,
                         const DefocusOptions& o) {
  Defocus out;
  const int w = photo.width, h = photo.height;
  if (w < 16 || h < 16 || photo.channels < 1) return out;
  const bool with_sky = sky.size() == std::size_t(w) * h;
  const cv::Mat src = detail::as_mat(photo);
  const int ch = photo.channels;
  cv::Mat luma(h, w, CV_32F), sky_f(h, w, CV_32F, cv::Scalar(0));
  for (int y = 0; y < h; ++y) {
    const float* row = src.ptr<float>(y);
    for (int x = 0; x < w; ++x) {
      const float* p = row + std::ptrdiff_t(x) * ch;
      float v = ch >= 3 ? 0.2126f * p[0] + 0.7152f * p[1] + 0.0722f * p[2] : p[0];
      if (!std::isfinite(v)) v = 0;
      luma.at<float>(y, x) = std::pow(std::clamp(v, 0.0f, 1.0f), 1 / 2.2f);
      if (with_sky) sky_f.at<float>(y, x) = sky[std::size_t(y) * w + x] ? 1.0f : 0.0f;
    }
  }
  const double s = std::min(1.0, double(o.working_long_side) / std::max(w, h));
  if (s < 1) {
    const cv::Size size(std::max(16, int(std::lround(w * s))), std::max(16, int(std::lround(h * s))));
    cv::resize(luma, luma, size, 0, 0, cv::INTER_AREA);
    cv::resize(sky_f, sky_f, size, 0, 0, cv::INTER_AREA);
  }
  cv::Mat reblurred;
  cv::GaussianBlur(luma, reblurred, cv::Size(0, 0), o.reblur_sigma_px);
  auto squared_gradient = [](const cv::Mat& m) {
    cv::Mat gx, gy;
    cv::Sobel(m, gx, CV_32F, 1, 0, 3, 1.0 / 8);
    cv::Sobel(m, gy, CV_32F, 0, 1, 3, 1.0 / 8);
    return cv::Mat(gx.mul(gx) + gy.mul(gy));
  };
  const cv::Mat e1 = squared_gradient(luma), e2 = squared_gradient(reblurred);
  const int bw = o.block_px, ww = luma.cols, wh = luma.rows;
  for (int by = 0; by + bw / 2 <= wh; by += bw)
    for (int bx = 0; bx + bw / 2 <= ww; bx += bw) {
      const cv::Rect r(bx, by, std::min(bw, ww - bx), std::min(bw, wh - by));
      if (cv::mean(sky_f(r))[0] > 0.5) continue;
      ++out.blocks;
      const double s1 = cv::mean(e1(r))[0], s2 = cv::mean(e2(r))[0];
      // Too little structure to tell (a plain wall, JPEG noise): neither.
      if (!(std::sqrt(s2) >= o.min_structure)) continue;
      const double ratio = s1 / s2;
      const double blur = ratio > 1.0001 ? o.reblur_sigma_px / std::sqrt(ratio * ratio - 1) : 1e3;
      out.sharp_blocks += blur <= o.sharp_px;
      out.blurred_blocks += blur >= o.blurred_px;
    }
  return out;
}

double smooth_max(double a, double b, double softness) {
  const double m = std::max(a, b);
  if (!(softness > 0) || !std::isfinite(softness)) return m;
  return m + softness * std::log1p(std::exp(-std::abs(a - b) / softness));
}

double bounded_inverse_distance(double ray_up, double ray_forward, double camera_height_m,
                                double far_forward_m, double focal_px, double soft_rows) {
  // Rays nearly sideways meet the billboard at 20 x its forward distance at most (as the
  // estimate's billboards).
  const double billboard = std::max(ray_forward, 0.05) / far_forward_m;
  const double ground = -ray_up / camera_height_m;
  return smooth_max(ground, billboard, soft_rows / (focal_px * camera_height_m));
}

float sky_fold(float proximity) {
  if (!(proximity > 0)) return 1.0f;  // NaN too: apart from the sky
  const float t = std::clamp(1.0f - 2.0f * proximity, 0.0f, 1.0f);
  return t * t;
}

std::vector<float> sky_proximity(ConstImageView photo, const std::vector<std::uint8_t>& sky,
                                 const SkyProximityOptions& o) {
  const int w = photo.width, h = photo.height;
  const std::size_t n = std::size_t(w) * h;
  if (sky.size() != n)
    throw Error(ErrorCode::size_mismatch, "sky_proximity: the photo is " + std::to_string(w) +
                                              "x" + std::to_string(h) + " but the sky mask holds " +
                                              std::to_string(sky.size()) + " values");
  std::vector<float> out(n, 0.0f);
  bool any = false;
  for (std::size_t i = 0; i < n; ++i) out[i] = sky[i] ? 1.0f : 0.0f, any |= sky[i] != 0;
  if (!any || w < 4 || h < 4 || photo.channels < 1) return out;
  // Only the open sky spreads: components that reach the frame's border. An enclosed piece
  // (sky seen through foliage, or a pale patch misjudged as sky: a highlight on a cheek) would
  // otherwise pull the smooth surface around it to the sky's distance too.
  cv::Mat open_sky(h, w, CV_8U);
  {
    cv::Mat binary(h, w, CV_8U);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) binary.at<std::uint8_t>(y, x) = sky[std::size_t(y) * w + x] != 0;
    cv::Mat labels;
    const int count = cv::connectedComponents(binary, labels, 8, CV_32S);
    std::vector<std::uint8_t> border(std::size_t(count), 0);
    for (int x = 0; x < w; ++x) border[labels.at<int>(0, x)] = border[labels.at<int>(h - 1, x)] = 1;
    for (int y = 0; y < h; ++y) border[labels.at<int>(y, 0)] = border[labels.at<int>(y, w - 1)] = 1;
    border[0] = 0;  // the background (not sky)
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) open_sky.at<std::uint8_t>(y, x) = border[labels.at<int>(y, x)];
  }
  cv::Mat indicator(h, w, CV_32F);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      indicator.at<float>(y, x) = open_sky.at<std::uint8_t>(y, x) ? 1.0f : 0.0f;
  const cv::Mat smoothed = smooth_against_photo(photo, indicator, o);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      if (sky[i]) continue;
      const float v = smoothed.at<float>(y, x);
      out[i] = std::isfinite(v) ? std::clamp(v, 0.0f, 1.0f) : 0.0f;
    }
  return out;
}

}  // namespace mr::photo
