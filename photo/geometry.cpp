#include "photo/geometry.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>

#include "mr/error.h"

namespace mr::photo {

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kMaxHorizonTiltDeg = 45;

std::string fmt(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4g", v);
  return buf;
}
std::string fmt(const PixelPoint& p) { return "(" + fmt(p[0]) + ", " + fmt(p[1]) + ")"; }

[[noreturn]] void fail(const std::string& pointer, const std::string& problem) {
  throw Error(ErrorCode::invalid_argument, pointer + ": " + problem);
}

double dot(const Vec3& a, const Vec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }

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

std::optional<Vec3> ground_point(const Camera& camera, const CameraPose& pose, const PixelPoint& p) {
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
  if (!a) fail("/known_length/a", fmt(known.a) + " is on or above the horizon; it must be a ground point");
  const auto b = ground_point(camera, unit, known.b);
  if (!b) fail("/known_length/b", fmt(known.b) + " is on or above the horizon; it must be a ground point");
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
         "lies entirely on or above the horizon; a plane standing on the ground must reach below it");
  out.offset = dot(out.normal, *g);
  return out;
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

DistanceMap distance_map(const Camera& camera, const CameraPose& pose, const Annotations& annotations) {
  const int w = camera.width, h = camera.height;
  const double height = pose.position_m.y;
  if (!(height > 0) || !std::isfinite(height))
    fail("/camera_height_m", "the camera must be above the ground, found " + fmt(height) + " m");
  std::vector<VerticalPlane> planes;
  for (std::size_t i = 0; i < annotations.planes.size(); ++i)
    planes.push_back(plane_of_polygon(camera, pose, annotations.planes[i], "/planes/" + std::to_string(i)));

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
  out.distance_m = Image(w, h, 1, {"Z"});
  out.coverage.assign(std::size_t(w) * h, Coverage::sky);
  const Vec3 o = pose.position_m;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const Vec3 d = pose.ray_direction(camera, x, y);
      double dist = kInf;
      Coverage cov = Coverage::sky;
      if (d.y < 0) dist = height / -d.y, cov = Coverage::ground;
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

}  // namespace mr::photo
