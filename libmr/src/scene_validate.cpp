// mr::validate_scene: every field of a FogScene checked against the ranges documented in
// mr/scene.h and docs/scene.md, so that the scattering core can trust its input and a bad value
// is reported where it was set rather than as NaN pixels far downstream.
//
// Message shape (one line): "<C++ field path> = <value found>: <rule>", e.g.
// "lighting.lamps[2].position_m.y = nan: must be finite". scene_json.cpp relies on this shape:
// it maps the path before " = " to a JSON pointer, so keep paths free of " = ".
#include <algorithm>
#include <charconv>
#include <cmath>
#include <numbers>
#include <string>
#include <vector>

#include "mr/error.h"
#include "mr/scattering.h"
#include "mr/scene.h"

namespace mr {

namespace {

constexpr int kMaxLamps = 64;       // the core's per-pixel light loop is sized for this
constexpr double kMaxSigmaT = 1e4;  // 1/m; beyond this the fog is a wall within a millimetre
constexpr int kMaxMarchSteps = 4096;
constexpr int kMaxGridStep = 3;  // DESIGN.md section 3: M, N <= 3
constexpr double kMaxSunRadiusDeg = 5;

// Shortest text that reads back as the same value, so the message shows what the user wrote
// ("1.2", not "1.200000"); to_chars spells non-finite values "nan", "inf", "-inf".
template <typename T>
std::string show(T v) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, r.ptr);
}

[[noreturn]] void fail(const std::string& path, const std::string& value, const std::string& rule) {
  throw Error(ErrorCode::invalid_argument, path + " = " + value + ": " + rule);
}

// Comparisons are written so that NaN fails them (every comparison with NaN is false).
void finite(const std::string& path, double v) {
  if (!std::isfinite(v)) fail(path, show(v), "must be finite");
}

// T is float for colour channels, double otherwise: the message shows the value as stored.
template <typename T>
void closed(const std::string& path, T v, double lo, double hi) {
  if (!(v >= lo && v <= hi)) fail(path, show(v), "must be in [" + show(lo) + ", " + show(hi) + "]");
}

void positive(const std::string& path, double v) {
  if (!(std::isfinite(v) && v > 0)) fail(path, show(v), "must be finite and > 0");
}

void int_range(const std::string& path, int v, int lo, int hi, const std::string& note = "") {
  if (v < lo || v > hi)
    fail(path, std::to_string(v),
         "must be in " + std::to_string(lo) + ".." + std::to_string(hi) + note);
}

void finite_vec(const std::string& path, const Vec3& v) {
  finite(path + ".x", v.x);
  finite(path + ".y", v.y);
  finite(path + ".z", v.z);
}

// Directions are normalised by the core: the squared length must be a usable positive number.
void direction(const std::string& path, const Vec3& v) {
  finite_vec(path, v);
  const double len2 = v.x * v.x + v.y * v.y + v.z * v.z;
  const std::string value = "(" + show(v.x) + ", " + show(v.y) + ", " + show(v.z) + ")";
  if (!(len2 > 0)) fail(path, value, "must have a non-zero length");
  if (!std::isfinite(len2)) fail(path, value, "is too long to normalise; use a unit vector");
}

// Radiometric quantities: non-negative and finite per channel.
void non_negative_rgb(const std::string& path, const Rgb& c) {
  for (int i = 0; i < 3; ++i) {
    const std::string p = path + "[" + std::to_string(i) + "]";
    if (!(std::isfinite(c[i]) && c[i] >= 0)) fail(p, show(c[i]), "must be finite and >= 0");
  }
}

void validate_pose(const CameraPose& pose) {
  finite_vec("pose.position_m", pose.position_m);
  finite("pose.yaw_deg", pose.yaw_deg);
  closed("pose.pitch_deg", pose.pitch_deg, -90, 90);
  closed("pose.roll_deg", pose.roll_deg, -180, 180);
}

void validate_medium(const Medium& m) {
  for (int i = 0; i < 3; ++i)
    closed("medium.sigma_t_per_m[" + std::to_string(i) + "]", m.sigma_t_per_m[i], 0, kMaxSigmaT);
  for (int i = 0; i < 3; ++i) closed("medium.albedo[" + std::to_string(i) + "]", m.albedo[i], 0, 1);
  // Open interval: |g| = 1 is a delta-function phase (HG's normalisation divides by zero).
  if (!(m.g > -1 && m.g < 1)) fail("medium.g", show(m.g), "must be in (-1, 1)");
  if (m.height_fog) {
    finite("medium.height_fog.base_height_m", m.height_fog->base_height_m);
    positive("medium.height_fog.scale_height_m", m.height_fog->scale_height_m);
  }
  // The layer bounds may be infinite (unbounded), never NaN, and must leave a non-empty layer.
  if (std::isnan(m.layer_bottom_m))
    fail("medium.layer_bottom_m", "nan", "must be a number or -inf");
  if (std::isnan(m.layer_top_m)) fail("medium.layer_top_m", "nan", "must be a number or +inf");
  if (!(m.layer_bottom_m < m.layer_top_m))
    fail("medium.layer_bottom_m", show(m.layer_bottom_m),
         "must be < medium.layer_top_m = " + show(m.layer_top_m));
  closed("medium.noise.amplitude", m.noise.amplitude, 0, 1);
  positive("medium.noise.scale_m", m.noise.scale_m);
  int_range("medium.noise.octaves", m.noise.octaves, 1, 8);
}

void validate_lighting(const Lighting& l) {
  if (l.sun) {
    direction("lighting.sun.direction_to_sun", l.sun->direction_to_sun);
    non_negative_rgb("lighting.sun.irradiance", l.sun->irradiance);
    closed("lighting.sun.angular_radius_deg", l.sun->angular_radius_deg, 0, kMaxSunRadiusDeg);
  }
  if (l.sky_radiance) non_negative_rgb("lighting.sky_radiance", *l.sky_radiance);
  if (l.lamps.size() > static_cast<std::size_t>(kMaxLamps))
    fail("lighting.lamps", std::to_string(l.lamps.size()) + " lamps",
         "at most " + std::to_string(kMaxLamps) + " are supported");
  for (std::size_t i = 0; i < l.lamps.size(); ++i) {
    const Lamp& lamp = l.lamps[i];
    const std::string p = "lighting.lamps[" + std::to_string(i) + "]";
    finite_vec(p + ".position_m", lamp.position_m);
    non_negative_rgb(p + ".intensity_per_sr", lamp.intensity_per_sr);
    direction(p + ".spot_direction", lamp.spot_direction);
    if (!(lamp.outer_angle_deg > 0 && lamp.outer_angle_deg <= 180))
      fail(p + ".outer_angle_deg", show(lamp.outer_angle_deg), "must be in (0, 180]");
    if (!(lamp.inner_angle_deg >= 0 && lamp.inner_angle_deg <= lamp.outer_angle_deg))
      fail(p + ".inner_angle_deg", show(lamp.inner_angle_deg),
           "must be in [0, outer_angle_deg = " + show(lamp.outer_angle_deg) + "]");
  }
}

void validate_render(const RenderSettings& r) {
  // Enums can hold any int after a cast (or a stray memcpy); the core switches on them.
  const int q = static_cast<int>(r.quality);
  if (q < static_cast<int>(Quality::draft) || q > static_cast<int>(Quality::final))
    fail("render.quality", std::to_string(q), "not a valid mr::Quality");
  const int b = static_cast<int>(r.backend);
  if (b < static_cast<int>(Backend::automatic) || b > static_cast<int>(Backend::vulkan))
    fail("render.backend", std::to_string(b), "not a valid mr::Backend");
  int_range("render.march_steps", r.march_steps, 0, kMaxMarchSteps,
            " (0: from the quality preset)");
  int_range("render.grid_step", r.grid_step, 0, kMaxGridStep, " (0: from the quality preset)");
  if (!(std::isfinite(r.max_distance_m) && r.max_distance_m >= 0))
    fail("render.max_distance_m", show(r.max_distance_m), "must be finite and >= 0 (0: automatic)");
  if (r.threads < 0)
    fail("render.threads", std::to_string(r.threads), "must be >= 0 (0: all cores)");
}

// Bounds that keep the added geometry to a size the BVH builds in well under a second.
constexpr double kMaxBlockerExtentM = 10e3;
constexpr double kMaxCanopyCells = 4e6;  // (radius / cell)^2 * 4
constexpr std::size_t kMaxSkylineSamples = 100000;
constexpr std::size_t kMaxPolygonCorners = 100000;

// A blocker polygon is drawn as a fan from its first corner (render/blockers.cpp), which covers
// the polygon exactly only when it is planar and convex; a polygon of no area casts no shadow
// and is almost surely a mistake (a wall drawn as a click, its top at its bottom). Tolerances
// are relative to the polygon's size: 1 mm per metre off its plane, turns that go back by
// less than 1e-9 of its size squared (collinear corners) pass.
void check_convex_planar(const std::string& path, const std::vector<Vec3>& c) {
  const std::size_t n = c.size();
  auto sub = [](const Vec3& a, const Vec3& b) { return Vec3{a.x - b.x, a.y - b.y, a.z - b.z}; };
  auto cross = [](const Vec3& a, const Vec3& b) {
    return Vec3{a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
  };
  auto dot = [](const Vec3& a, const Vec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; };
  double extent = 0;
  Vec3 normal{0, 0, 0}, centre{0, 0, 0};  // Newell's normal: twice the area, along the normal
  for (std::size_t k = 0; k < n; ++k) {
    const Vec3& a = c[k];
    const Vec3& b = c[(k + 1) % n];
    const Vec3 ab = cross(a, b);
    normal = {normal.x + ab.x, normal.y + ab.y, normal.z + ab.z};
    centre = {centre.x + a.x / double(n), centre.y + a.y / double(n), centre.z + a.z / double(n)};
    extent = std::max(extent, std::sqrt(dot(sub(b, c[0]), sub(b, c[0]))));
  }
  const double twice_area = std::sqrt(dot(normal, normal));
  if (!(twice_area > 1e-9 * extent * extent) || !(extent > 0))
    fail(path, "area " + show(0.5 * twice_area) + " m^2",
         "the polygon has no area (its corners are on one point or one line)");
  const Vec3 u{normal.x / twice_area, normal.y / twice_area, normal.z / twice_area};
  for (std::size_t k = 0; k < n; ++k) {
    const double off = std::fabs(dot(sub(c[k], centre), u));
    if (off > 1e-3 * extent)
      fail(path + "[" + std::to_string(k) + "]", show(off) + " m off the polygon's plane",
           "the corners must lie in one plane (within 1 mm per metre of the polygon's size)");
  }
  // Convex and simple: every turn goes the same way around the normal, and they add up to one
  // full turn (a star polygon turns the same way but more than once).
  double turning = 0;
  for (std::size_t k = 0; k < n; ++k) {
    const Vec3 e0 = sub(c[(k + 1) % n], c[k]);
    const Vec3 e1 = sub(c[(k + 2) % n], c[(k + 1) % n]);
    const double s = dot(cross(e0, e1), u);
    if (s < -1e-9 * extent * extent)
      fail(path + "[" + std::to_string((k + 1) % n) + "]", "a reflex corner",
           "the polygon must be convex, its corners in order around it");
    if (dot(e0, e0) > 0 && dot(e1, e1) > 0) turning += std::atan2(std::max(s, 0.0), dot(e0, e1));
  }
  if (turning > 2 * std::numbers::pi * 1.001)
    fail(path, "turns " + show(turning * 180 / std::numbers::pi) + " degrees",
         "the polygon must be simple and convex (its edges turn once around, 360 degrees)");
}

void validate_blockers(const Blockers& b) {
  const Blockers::Completion& c = b.completion;
  if (!(std::isfinite(c.max_height_m) && c.max_height_m > 0 && c.max_height_m <= kMaxBlockerExtentM))
    fail("blockers.completion.max_height_m", show(c.max_height_m),
         "must be in (0, " + show(kMaxBlockerExtentM) + "] metres");
  if (!(std::isfinite(c.max_extent_m) && c.max_extent_m > 0 && c.max_extent_m <= kMaxBlockerExtentM))
    fail("blockers.completion.max_extent_m", show(c.max_extent_m),
         "must be in (0, " + show(kMaxBlockerExtentM) + "] metres");
  closed("blockers.completion.prism_max_width_m", c.prism_max_width_m, 0, kMaxBlockerExtentM);
  if (b.skyline) {
    const Blockers::Skyline& k = *b.skyline;
    if (!(std::isfinite(k.distance_m) && k.distance_m > 0 && k.distance_m <= kMaxBlockerExtentM))
      fail("blockers.skyline.distance_m", show(k.distance_m),
           "must be in (0, " + show(kMaxBlockerExtentM) + "] metres");
    if (k.samples.size() < 2 || k.samples.size() > kMaxSkylineSamples)
      fail("blockers.skyline.samples", std::to_string(k.samples.size()) + " samples",
           "need 2 to " + std::to_string(kMaxSkylineSamples));
    for (std::size_t i = 0; i < k.samples.size(); ++i) {
      const std::string p = "blockers.skyline.samples[" + std::to_string(i) + "]";
      closed(p + ".azimuth_deg", k.samples[i].azimuth_deg, -720, 720);
      closed(p + ".height_m", k.samples[i].height_m, 0, kMaxBlockerExtentM);
    }
  }
  for (std::size_t i = 0; i < b.polygons.size(); ++i) {
    const std::string p = "blockers.polygons[" + std::to_string(i) + "].corners_m";
    const auto& corners = b.polygons[i].corners_m;
    if (corners.size() < 3 || corners.size() > kMaxPolygonCorners)
      fail(p, std::to_string(corners.size()) + " corners",
           "need 3 to " + std::to_string(kMaxPolygonCorners));
    for (std::size_t k = 0; k < corners.size(); ++k)
      finite_vec(p + "[" + std::to_string(k) + "]", corners[k]);
    check_convex_planar(p, corners);
  }
  if (b.canopy) {
    const Blockers::Canopy& c2 = *b.canopy;
    if (!(std::isfinite(c2.height_m) && c2.height_m > 0 && c2.height_m <= kMaxBlockerExtentM))
      fail("blockers.canopy.height_m", show(c2.height_m),
           "must be in (0, " + show(kMaxBlockerExtentM) + "] metres");
    closed("blockers.canopy.gap_fraction", c2.gap_fraction, 0, 1);
    positive("blockers.canopy.radius_m", c2.radius_m);
    positive("blockers.canopy.cell_m", c2.cell_m);
    const double cells = 4 * (c2.radius_m / c2.cell_m) * (c2.radius_m / c2.cell_m);
    if (!(cells <= kMaxCanopyCells))
      fail("blockers.canopy.cell_m", show(c2.cell_m),
           "too small for radius_m = " + show(c2.radius_m) + ": at most " +
               show(kMaxCanopyCells) + " cells (4 (radius / cell)^2)");
  }
}

}  // namespace

void validate_scene(const FogScene& scene) {
  validate_pose(scene.pose);
  validate_medium(scene.medium);
  validate_lighting(scene.lighting);
  validate_render(scene.render);
  validate_blockers(scene.blockers);
  // Inserted objects (issue 16): each entry's mesh name, placement and material.
  constexpr std::size_t kMaxObjects = 4096;
  if (scene.objects.size() > kMaxObjects)
    fail("objects", std::to_string(scene.objects.size()) + " objects",
         "at most " + std::to_string(kMaxObjects));
  for (std::size_t i = 0; i < scene.objects.size(); ++i)
    validate_scene_object(scene.objects[i], "objects[" + std::to_string(i) + "]");
}

}  // namespace mr
