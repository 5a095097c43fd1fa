// Differential rendering of inserted objects (render/insertion/differential.h).
#include "render/insertion/differential.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "mr/error.h"
#include "render/math.h"
#include "render/physics/medium.h"
#include "render/surface_shading.h"

namespace mr::render::insertion {

namespace {

constexpr float kPi = 3.14159265358979323846f;
constexpr int kMaxRays = 256;
constexpr float kFixedRotation = 0.5f;  // the fixed pattern's rotation (any pixel's would do)

Vec3f add3(const Vec3f& a, const Vec3f& b, float s = 1) {
  return {a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]};
}
Vec3f sub3(const Vec3f& a, const Vec3f& b) {
  return {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
}

void frame(const Vec3f& n, Vec3f& t, Vec3f& b) {
  const Vec3f helper = std::fabs(n[1]) < 0.9f ? Vec3f{0, 1, 0} : Vec3f{1, 0, 0};
  t = unit(cross(helper, n));
  b = cross(n, t);
}

// The light the renderer samples, prepared once.
struct Lights {
  bool sun = false;
  Vec3f sun_dir{}, sun_u{}, sun_v{};
  float sun_tan_radius = 0;
  int sun_rays = 1;
  Lighting sun_sky;                   // sun and sky only (lamps shadowed separately)
  std::vector<Lighting> single_lamp;  // one lamp each
  std::vector<Vec3f> lamp_position;
  // With a fixed pattern (every pixel the same rotation) the directions are computed once: the
  // sun's, and the sky's in the local frame (tangent, bitangent, normal coefficients).
  float fixed_rotation = -1;  // < 0: none
  std::vector<Vec3f> fixed_sun;
  std::vector<Vec3f> fixed_sky;
  int fixed_sky_total = 0;
};

// Direction i of `count` over the sun's disk: stratified in radius, golden-angle spiral in
// azimuth, rotated per pixel (as render/surface_shading.cpp samples it).
Vec3f sun_direction(const Lights& L, int i, int count, float rotation) {
  if (count <= 1 || L.sun_tan_radius <= 0) return L.sun_dir;
  const float r = L.sun_tan_radius * std::sqrt((float(i) + 0.5f) / float(count));
  const float phi = 2.39996323f * float(i) + 2 * kPi * rotation;
  const float c = std::cos(phi), s = std::sin(phi);
  return unit(Vec3f{L.sun_dir[0] + r * (c * L.sun_u[0] + s * L.sun_v[0]),
                    L.sun_dir[1] + r * (c * L.sun_u[1] + s * L.sun_v[1]),
                    L.sun_dir[2] + r * (c * L.sun_u[2] + s * L.sun_v[2])});
}

// Cosine-weighted direction i of `count` about n (Hammersley, Cranley-Patterson rotated): its
// coefficients along the tangent, bitangent and normal, then the direction.
Vec3f sky_local(int i, int count, float rotation) {
  const float u1 = (float(i) + 0.5f) / float(count);
  float u2 = float(radical_inverse_base2(std::uint32_t(i))) + rotation;
  u2 -= std::floor(u2);
  const float rad = std::sqrt(u1), phi = 2 * kPi * u2;
  return {rad * std::cos(phi), rad * std::sin(phi), std::sqrt(std::max(0.0f, 1 - u1))};
}
Vec3f sky_world(const Vec3f& n, const Vec3f& t, const Vec3f& b, const Vec3f& k) {
  const float a = k[0], c = k[1], z = k[2];
  return {a * t[0] + c * b[0] + z * n[0], a * t[1] + c * b[1] + z * n[1],
          a * t[2] + c * b[2] + z * n[2]};
}
Vec3f sky_direction(const Vec3f& n, const Vec3f& t, const Vec3f& b, int i, int count,
                    float rotation) {
  return sky_world(n, t, b, sky_local(i, count, rotation));
}

// The rays of one shading point: sun directions, upward sky directions, lamp segments.
struct RaySet {
  ShadowRay rays[kMaxRays];
  int sun_first = 0, sun_count = 0, sun_total = 0;  // sun_total: directions drawn (incl. below n)
  int sky_first = 0, sky_count = 0;                 // upward ones traced
  int lamp_first = 0, lamp_count = 0;
  int size = 0;
};

// Fills `set` for a point at `origin` with normal n: the sun directions with index
// first, first + stride, ... < total (`count` of them), the sky's likewise, every lamp.
// With several origins (points spread over the pixel's footprint), ray j of each kind starts at
// origins[j % origin_count], so the shadow is anti-aliased like the camera's samples; lamps start
// at origins[0].
void build_rays(RaySet& set, const Lights& L, const Vec3f* origins, int origin_count,
                const Vec3f& n, float rotation, int sun_start, int sun_stride, int sun_n,
                int sky_start, int sky_stride, int sky_n, int sky_total) {
  const Vec3f& origin = origins[0];
  set.size = 0;
  set.sun_first = 0;
  set.sun_count = 0;
  set.sun_total = 0;
  if (L.sun) {
    for (int j = 0; j < sun_n; ++j) {
      const int i = (sun_start + j * sun_stride) % L.sun_rays;
      const Vec3f s = rotation == L.fixed_rotation ? L.fixed_sun[std::size_t(i)]
                                                   : sun_direction(L, i, L.sun_rays, rotation);
      ++set.sun_total;
      if (dot(n, s) > 0) set.rays[set.size++] = ShadowRay{origins[j % origin_count], s, 0.0f};
    }
  }
  set.sun_count = set.size;
  set.sky_first = set.size;
  if (sky_n > 0 && L.sun_sky.sky_radiance) {
    Vec3f t, b;
    frame(n, t, b);
    for (int j = 0; j < sky_n; ++j) {
      const int i = (sky_start + j * sky_stride) % sky_total;
      const Vec3f d = rotation == L.fixed_rotation && sky_total == L.fixed_sky_total
                          ? sky_world(n, t, b, L.fixed_sky[std::size_t(i)])
                          : sky_direction(n, t, b, i, sky_total, rotation);
      if (d[1] > 0) set.rays[set.size++] = ShadowRay{origins[j % origin_count], d, 0.0f};
    }
  }
  set.sky_count = set.size - set.sky_first;
  set.lamp_first = set.size;
  for (const Vec3f& lamp : L.lamp_position) {
    const Vec3f to = sub3(lamp, origin);
    set.rays[set.size++] = ShadowRay{origin, to, 0.0f, 1.0f - 1e-4f};
  }
  set.lamp_count = set.size - set.lamp_first;
}

// Visibility shares of a ray set given which rays are blocked.
struct Visibility {
  float sun = 0, sky_share = 1;
  float lamp[16]{};
};
Visibility visibility_of(const RaySet& set, const bool* blocked) {
  Visibility v;
  if (set.sun_total > 0) {
    int seen = 0;
    for (int i = 0; i < set.sun_count; ++i) seen += !blocked[set.sun_first + i];
    v.sun = float(seen) / float(set.sun_total);
  }
  if (set.sky_count > 0) {
    int seen = 0;
    for (int i = 0; i < set.sky_count; ++i) seen += !blocked[set.sky_first + i];
    v.sky_share = float(seen) / float(set.sky_count);
  }
  for (int i = 0; i < set.lamp_count && i < 16; ++i)
    v.lamp[i] = blocked[set.lamp_first + i] ? 0.0f : 1.0f;
  return v;
}

// The shading terms of a point under the lights with the given visibilities (the one call into
// the shared BRDF code; an alternative shading path replaces this function).
ShadingTerms terms_at(const Lights& L, const SurfacePoint& base, const Visibility& vis,
                      float roughness) {
  SurfacePoint p = base;
  p.sun_visibility = vis.sun;
  p.sky_visibility = 0.5f * (1 + p.normal[1]) * vis.sky_share;
  ShadingTerms t = shading_terms(p, L.sun_sky, roughness);
  for (std::size_t k = 0; k < L.single_lamp.size() && k < 16; ++k) {
    if (vis.lamp[k] <= 0) continue;
    const ShadingTerms l = shading_terms(p, L.single_lamp[k], roughness);
    for (int c = 0; c < 3; ++c) {
      t.diffuse[c] += l.diffuse[c];
      t.specular_f0[c] += l.specular_f0[c];
      t.specular_bias[c] += l.specular_bias[c];
    }
  }
  return t;
}

// terms_at(...).diffuse alone (the same floats): the photo's side needs only the Lambertian
// ratio, and the specular lobes cost as much as the rest of its shading.
Rgb diffuse_at(const Lights& L, const SurfacePoint& base, const Visibility& vis) {
  SurfacePoint p = base;
  p.sun_visibility = vis.sun;
  p.sky_visibility = 0.5f * (1 + p.normal[1]) * vis.sky_share;
  Rgb d = diffuse_term(p, L.sun_sky);
  for (std::size_t k = 0; k < L.single_lamp.size() && k < 16; ++k) {
    if (vis.lamp[k] <= 0) continue;
    const Rgb l = diffuse_term(p, L.single_lamp[k]);
    for (int c = 0; c < 3; ++c) d[c] += l[c];
  }
  return d;
}

// Whether a ray from `origin` along unit `dir` (spreading by tan_spread per metre) can pass
// within the bounding sphere (centre c, radius r) at t > 0, before t_max.
bool may_hit_sphere(const Vec3f& origin, const Vec3f& dir, float tan_spread,
                    const std::array<float, 4>& s,
                    float t_max = std::numeric_limits<float>::infinity()) {
  const Vec3f q = {s[0] - origin[0], s[1] - origin[1], s[2] - origin[2]};
  const float along = dot(q, dir);
  const float r = s[3];
  if (along < -r) return false;
  if (along - r > t_max) return false;
  const float a = std::clamp(along, 0.0f, t_max);
  const Vec3f closest = {q[0] - a * dir[0], q[1] - a * dir[1], q[2] - a * dir[2]};
  const float spread = r + std::max(a, 0.0f) * tan_spread + 1e-4f;
  return dot(closest, closest) < spread * spread;
}

}  // namespace

void EmbreeVisibility::occluded(Geometry which, std::span<const ShadowRay> rays,
                                bool* blocked) const {
  if (which == Geometry::objects) {
    objects_.occluded(rays, blocked);
    return;
  }
  if (!photo_) {
    std::fill(blocked, blocked + rays.size(), false);
    return;
  }
  occluded_rays(
      *photo_, rays.size(), [&](std::size_t i) { return rays[i]; },
      [&](std::size_t i, bool b) { blocked[i] = b; });
}

namespace {

const WorldObjects& check_objects(const InsertionInputs& in) {
  if (!in.objects || !in.visibility)
    throw Error(ErrorCode::invalid_argument, "insert objects: no object scene or visibility path");
  return in.objects->world();
}

// A pixel rectangle, inclusive.
struct Rect {
  int x0, y0, x1, y1;
};

// Whether a shadow ray (origin + t direction, t in [t_near, t_far]) can meet any of the spheres.
bool ray_may_hit(const ShadowRay& ray, const std::vector<std::array<float, 4>>& spheres) {
  const Vec3f o = {ray.origin[0], ray.origin[1], ray.origin[2]};
  Vec3f d = {ray.direction[0], ray.direction[1], ray.direction[2]};
  const float len = std::sqrt(dot(d, d));
  if (!(len > 0)) return true;
  d = {d[0] / len, d[1] / len, d[2] / len};
  const float t_max =
      std::isfinite(ray.t_far) ? ray.t_far * len : std::numeric_limits<float>::infinity();
  for (const auto& s : spheres)
    if (may_hit_sphere(o, d, 0, s, t_max)) return true;
  return false;
}

// Point-to-segment distance (the lamps' tile test).
float segment_distance(const Vec3f& s, const Vec3f& a, const Vec3f& b) {
  const Vec3f ab = sub3(b, a), as = sub3(s, a);
  const float len2 = dot(ab, ab);
  const float t = len2 > 0 ? std::clamp(dot(as, ab) / len2, 0.0f, 1.0f) : 0.0f;
  const Vec3f c = sub3(as, Vec3f{t * ab[0], t * ab[1], t * ab[2]});
  return std::sqrt(dot(c, c));
}

// Everything one pixel's shading needs, checked and prepared once per frame: the lights, the
// screen rectangles that may show an object, the camera. shade() renders one pixel; clean()
// writes what a pixel no object can change holds (the photo itself).
class Renderer {
 public:
  struct Scratch {
    RaySet set;
    bool blocked_objects[kMaxRays], blocked_photo[kMaxRays], blocked_any[kMaxRays];
    ShadowRay compact[kMaxRays];  // the rays traced against the objects
    int index[kMaxRays];
    bool blocked_compact[kMaxRays];
    std::size_t shadow_rays = 0, camera_rays = 0;

    /// Traces the first `traced` compacted rays against the objects and scatters the answers
    /// back to their indices in `blocked` (which holds false for the rays not traced).
    void trace_compacted_objects(const VisibilityPath& visibility, int traced, bool* blocked) {
      if (traced > 0) {
        visibility.occluded(Geometry::objects,
                            std::span<const ShadowRay>(compact, std::size_t(traced)),
                            blocked_compact);
        for (int k = 0; k < traced; ++k) blocked[index[k]] = blocked_compact[k];
      }
      shadow_rays += std::size_t(traced);
    }
  };

  Renderer(const InsertionInputs& in, const InsertionSettings& settings);
  void shade(int x, int y, InsertionLayers& out, Scratch& scratch) const;
  void clean(int x, int y, InsertionLayers& out) const;
  /// Whether any pixel of the tile may differ from the photo: conservative with respect to the
  /// per-pixel tests in shade() (see PhotoTiles).
  bool tile_influenced(const std::array<float, 5>& bound, const Rect& tile) const;

  const InsertionInputs& in;
  const InsertionSettings& settings;

 private:
  Vec3f ray_direction(double x, double y) const {
    const double u = (x + 0.5 - in.camera.cx) / in.camera.focal_px,
                 v = (y + 0.5 - in.camera.cy) / in.camera.focal_px;
    const Vec3& f = cam_axes_[0];
    const Vec3& r = cam_axes_[1];
    const Vec3& up = cam_axes_[2];
    const double dx = u * r.x - v * up.x + f.x, dy = u * r.y - v * up.y + f.y,
                 dz = u * r.z - v * up.z + f.z;
    const double len = std::sqrt(dx * dx + dy * dy + dz * dz);
    return Vec3f{float(dx / len), float(dy / len), float(dz / len)};
  }
  // The per-pixel occlusion test, bilinearly filtered (see the header).
  float depth_visibility(float sx, float sy, float t) const {
    const float fx = sx - 0.5f, fy = sy - 0.5f;
    const int x0 = int(std::floor(fx)), y0 = int(std::floor(fy));
    const float ax = fx - float(x0), ay = fy - float(y0);
    float vis = 0;
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i < 2; ++i) {
        const int x = std::clamp(x0 + i, 0, w_ - 1), y = std::clamp(y0 + j, 0, h_ - 1);
        const float d = in.distance_m.at(x, y, 0);
        const bool front = !(std::isfinite(d) && d > 0) || t < d * (1 + tol_);
        vis += front ? (i ? ax : 1 - ax) * (j ? ay : 1 - ay) : 0.0f;
      }
    return vis;
  }

  int w_, h_;
  Lights L_;
  const WorldObjects& world_;
  int S_, S2_, sky_total_;
  Vec3f eye_;
  int channels_;
  std::vector<Rect> rects_;
  std::array<Vec3, 3> cam_axes_;
  float tol_;
};

Renderer::Renderer(const InsertionInputs& in_, const InsertionSettings& settings_)
    : in(in_),
      settings(settings_),
      w_(in_.camera.width),
      h_(in_.camera.height),
      world_(check_objects(in_)) {
  const int w = w_, h = h_;
  auto check = [&](ConstImageView v, int channels_min, int channels_max, const char* what) {
    if (v.width != w || v.height != h)
      throw Error(ErrorCode::size_mismatch, std::string("insert objects: the ") + what + " is " +
                                                std::to_string(v.width) + "x" +
                                                std::to_string(v.height) + ", the camera " +
                                                std::to_string(w) + "x" + std::to_string(h));
    if (v.channels < channels_min || v.channels > channels_max)
      throw Error(ErrorCode::invalid_argument, std::string("insert objects: the ") + what +
                                                   " has " + std::to_string(v.channels) +
                                                   " channels");
  };
  check(in.photo, 3, 64, "photo");
  check(in.distance_m, 1, 1, "distance map");
  check(in.normals, 3, 3, "normal map");
  if (settings.samples_per_axis < 1 || settings.samples_per_axis > 8)
    throw Error(ErrorCode::invalid_argument,
                "insert objects: samples_per_axis must be in 1..8, got " +
                    std::to_string(settings.samples_per_axis));
  if (settings.sun_rays < 1 || settings.sun_rays > 64 || settings.sky_rays < 0 ||
      settings.sky_rays > 128)
    throw Error(ErrorCode::invalid_argument,
                "insert objects: sun_rays must be in 1..64 and sky_rays in 0..128");
  if (in.lighting.lamps.size() > 16)
    throw Error(ErrorCode::invalid_argument, "insert objects: at most 16 lamps");
  if (!in.lighting.sky_radiance)
    throw Error(ErrorCode::invalid_argument, "insert objects: the sky radiance must be resolved");

  L_.sun_sky.sky_radiance = in.lighting.sky_radiance;
  if (in.lighting.sun) {
    L_.sun = true;
    L_.sun_sky.sun = in.lighting.sun;
    L_.sun_dir = unit(to_f(in.lighting.sun->direction_to_sun));
    if (dot(L_.sun_dir, L_.sun_dir) == 0)
      throw Error(ErrorCode::invalid_argument, "lighting.sun.direction_to_sun is zero");
    frame(L_.sun_dir, L_.sun_u, L_.sun_v);
    L_.sun_tan_radius = float(std::tan(in.lighting.sun->angular_radius_deg * kPi / 180));
    L_.sun_rays = L_.sun_tan_radius > 0 ? settings.sun_rays : 1;
  }
  for (const Lamp& lamp : in.lighting.lamps) {
    Lighting one;
    one.lamps.push_back(lamp);
    L_.single_lamp.push_back(one);
    L_.lamp_position.push_back(to_f(lamp.position_m));
  }
  if (settings.fixed_pattern) {
    L_.fixed_rotation = kFixedRotation;
    for (int i = 0; i < L_.sun_rays; ++i)
      L_.fixed_sun.push_back(sun_direction(L_, i, L_.sun_rays, kFixedRotation));
    L_.fixed_sky_total = std::max(settings.sky_rays, 1);
    for (int i = 0; i < L_.fixed_sky_total; ++i)
      L_.fixed_sky.push_back(sky_local(i, L_.fixed_sky_total, kFixedRotation));
  }

  S_ = settings.samples_per_axis;
  S2_ = S_ * S_;
  sky_total_ = settings.sky_rays;
  eye_ = to_f(in.pose.position_m);
  channels_ = in.photo.channels;
  tol_ = float(settings.depth_tolerance);
  cam_axes_ = in.pose.axes();

  // Screen rectangles that may show an object (its bounding sphere's box projected), so pixels
  // elsewhere trace no camera rays.
  const auto [forward, right, up] = in.pose.axes();
  for (const auto& s : world_.tight_bounds) {
    double xmin = 1e30, xmax = -1e30, ymin = 1e30, ymax = -1e30;
    bool behind = false;
    for (int k = 0; k < 8; ++k) {
      const Vec3 c = {s[0] + ((k & 1) ? s[3] : -s[3]) - in.pose.position_m.x,
                      s[1] + ((k & 2) ? s[3] : -s[3]) - in.pose.position_m.y,
                      s[2] + ((k & 4) ? s[3] : -s[3]) - in.pose.position_m.z};
      const double z = c.x * forward.x + c.y * forward.y + c.z * forward.z;
      if (z <= 1e-6) {
        behind = true;
        break;
      }
      const double u = (c.x * right.x + c.y * right.y + c.z * right.z) / z;
      const double v = -(c.x * up.x + c.y * up.y + c.z * up.z) / z;
      const double px = in.camera.cx + u * in.camera.focal_px,
                   py = in.camera.cy + v * in.camera.focal_px;
      xmin = std::min(xmin, px), xmax = std::max(xmax, px), ymin = std::min(ymin, py),
      ymax = std::max(ymax, py);
    }
    if (behind)
      rects_.push_back({0, 0, w - 1, h - 1});
    else
      rects_.push_back({int(std::max(0.0, std::floor(xmin) - 1)),
                        int(std::max(0.0, std::floor(ymin) - 1)),
                        int(std::min(double(w - 1), std::ceil(xmax) + 1)),
                        int(std::min(double(h - 1), std::ceil(ymax) + 1))});
  }
}

void Renderer::clean(int x, int y, InsertionLayers& out) const {
  const float* I = in.photo.pixel(x, y);
  float* C = out.composite.view().pixel(x, y);
  for (int c = 0; c < channels_; ++c) C[c] = I[c];
  for (int c = 0; c < 3; ++c) {
    out.shadow.view().at(x, y, c) = 1.0f;
    out.difference.view().at(x, y, c) = 0.0f;
    out.object_radiance.view().at(x, y, c) = 0.0f;
  }
  out.matte.view().at(x, y, 0) = 0.0f;
  out.distance_m.view().at(x, y, 0) = in.distance_m.at(x, y, 0);
}

bool Renderer::tile_influenced(const std::array<float, 5>& bound, const Rect& tile) const {
  for (const Rect& r : rects_)
    if (tile.x0 <= r.x1 && r.x0 <= tile.x1 && tile.y0 <= r.y1 && r.y0 <= tile.y1) return true;
  const float rt = bound[3];
  if (rt < 0) return false;  // no pixel of the tile has a surface the renderer shades
  const Vec3f c = {bound[0], bound[1], bound[2]};
  // shade() tests each pixel's shadow-ray origin o against each object's sphere; every o of the
  // tile lies within rt of c, so these tests, widened by rt (twice where the ray's closest
  // approach moves with o) and a millimetre for rounding, pass whenever one of the pixel's does.
  for (std::size_t k = 0; k < world_.tight_bounds.size(); ++k) {
    const auto& s = world_.tight_bounds[k];
    const float sky_radius =
        (settings.sky_influence_tight ? world_.tight_bounds : world_.bounds)[k][3];
    if (L_.sun) {
      const float spread = L_.sun_tan_radius * 1.01f;
      if (may_hit_sphere(c, L_.sun_dir, spread,
                         {s[0], s[1], s[2], s[3] + bound[4] + rt * (2 + spread) + 1e-3f}))
        return true;
    }
    const Vec3f q = {s[0] - c[0], s[1] - c[1], s[2] - c[2]};
    const float sky_r = float(settings.sky_influence_radii) * sky_radius + rt + 1e-3f;
    if (dot(q, q) < sky_r * sky_r) return true;
    for (const Vec3f& lp : L_.lamp_position)
      if (segment_distance({s[0], s[1], s[2]}, c, lp) < s[3] + rt + 1e-3f) return true;
  }
  return false;
}

void Renderer::shade(int x, int y, InsertionLayers& out, Scratch& scratch) const {
  const InsertionSettings& st = settings;
  const Lights& L = L_;
  const WorldObjects& world = world_;
  const int S = S_, S2 = S2_, sky_total = sky_total_;
  const Vec3f& eye = eye_;
  RaySet& set = scratch.set;
  bool* blocked_objects = scratch.blocked_objects;
  bool* blocked_photo = scratch.blocked_photo;
  bool* blocked_any = scratch.blocked_any;

  const std::uint32_t seed = physics::hash32(std::uint32_t(y) * 73856093u ^ std::uint32_t(x));
  // A fixed pattern (the preview): every pixel draws the same directions, so neighbours agree
  // (no salt-and-pepper speckle) and nothing shimmers between frames.
  const float rotation =
      st.fixed_pattern ? kFixedRotation : float(seed >> 8) * (1.0f / 16777216.0f);
  const float d = in.distance_m.at(x, y, 0);
  const float* I = in.photo.pixel(x, y);

  // ---- The photo's surface: shading with / without the objects -----------------
  Rgb ratio = {1, 1, 1};
  const Vec3f n = {in.normals.at(x, y, 0), in.normals.at(x, y, 1), in.normals.at(x, y, 2)};
  if (std::isfinite(d) && d > 0 && dot(n, n) > 0.5f && !world.bounds.empty()) {
    const Vec3f ray = ray_direction(x, y);
    const Vec3f p = add3(eye, ray, d);
    const float lift = 1e-3f + 1e-3f * d;
    const Vec3f origin = add3(p, n, lift);
    const float footprint = 2.0f * d / float(in.camera.focal_px);
    bool sun_maybe = false, sky_maybe = false, lamp_maybe = false;
    for (std::size_t k = 0; k < world.tight_bounds.size(); ++k) {
      const auto& s = world.tight_bounds[k];
      const float sky_radius = (st.sky_influence_tight ? world.tight_bounds : world.bounds)[k][3];
      if (L.sun && dot(n, L.sun_dir) > -L.sun_tan_radius)
        sun_maybe = sun_maybe || may_hit_sphere(origin, L.sun_dir, L.sun_tan_radius * 1.01f,
                                                {s[0], s[1], s[2], s[3] + footprint});
      const Vec3f q = {s[0] - origin[0], s[1] - origin[1], s[2] - origin[2]};
      sky_maybe = sky_maybe || dot(q, q) < float(st.sky_influence_radii * st.sky_influence_radii) *
                                               sky_radius * sky_radius;
      for (const Vec3f& lp : L.lamp_position) {
        const Vec3f to = sub3(lp, origin);
        const float len = std::sqrt(dot(to, to));
        if (len > 0)
          lamp_maybe = lamp_maybe ||
                       may_hit_sphere(origin, {to[0] / len, to[1] / len, to[2] / len}, 0, s, len);
      }
    }
    if (sun_maybe || sky_maybe || lamp_maybe) {
      // The pixel's footprint on its tangent plane: one origin per camera sample position,
      // so shadow edges crossing the pixel are anti-aliased (as the photo's own are).
      Vec3f origins[64];
      int origin_count = 0;
      for (int k = 0; k < S2; ++k) {
        const float sx = float(x) + (float(k % S) + 0.5f) / float(S),
                    sy = float(y) + (float(k / S) + 0.5f) / float(S);
        const Vec3f r = ray_direction(double(sx) - 0.5, double(sy) - 0.5);
        const float denom = dot(r, n);
        const float t = denom < -1e-3f ? dot(sub3(p, eye), n) / denom : -1.0f;
        origins[origin_count++] =
            (t > 0.9f * d && t < 1.1f * d) ? add3(add3(eye, r, t), n, lift) : origin;
      }
      build_rays(set, L, origins, origin_count, n, rotation, 0, 1, L.sun ? L.sun_rays : 0, 0, 1,
                 sky_total, std::max(sky_total, 1));
      const std::span<const ShadowRay> rays(set.rays, std::size_t(set.size));
      // Against the objects, only the rays that can meet one's bounding sphere are traced: the
      // others cannot be blocked by them (an exact cull, far cheaper than the BVH's traversal).
      // Sky rays beyond the sky influence count as unblocked (see sky_influence_radii).
      int traced = 0;
      for (int i = 0; i < set.size; ++i) {
        blocked_objects[i] = false;
        const bool sky_ray = i >= set.sky_first && i < set.sky_first + set.sky_count;
        if (sky_ray && !sky_maybe) continue;
        if (!ray_may_hit(set.rays[i], world.tight_bounds)) continue;
        scratch.index[traced] = i;
        scratch.compact[traced++] = set.rays[i];
      }
      scratch.trace_compacted_objects(*in.visibility, traced, blocked_objects);
      bool any = false;
      for (int i = 0; i < set.size; ++i) any = any || blocked_objects[i];
      if (any) {
        in.visibility->occluded(Geometry::photo, rays, blocked_photo);
        scratch.shadow_rays += std::size_t(set.size);
        for (int i = 0; i < set.size; ++i) blocked_any[i] = blocked_photo[i] || blocked_objects[i];
        SurfacePoint sp;
        sp.surface = true;
        sp.normal = n;
        sp.view = {-ray[0], -ray[1], -ray[2]};
        sp.position_m = p;
        const Rgb without = diffuse_at(L, sp, visibility_of(set, blocked_photo));
        const Rgb with = diffuse_at(L, sp, visibility_of(set, blocked_any));
        for (int c = 0; c < 3; ++c) ratio[c] = without[c] > 1e-12f ? with[c] / without[c] : 1.0f;
      }
    }
  }

  // ---- The objects: sub-pixel camera rays, occlusion, shading --------------------
  bool in_rect = false;
  for (const Rect& r : rects_)
    in_rect = in_rect || (x >= r.x0 && x <= r.x1 && y >= r.y0 && y <= r.y1);
  float coverage = 0;
  Rgb radiance = {0, 0, 0};
  float new_distance = d;
  if (in_rect) {
    const Vec3f centre_ray = ray_direction(x, y);
    const ObjectHit centre = in.objects->intersect(eye, centre_ray, 0.0f);
    ++scratch.camera_rays;
    if (centre.hit() && depth_visibility(float(x) + 0.5f, float(y) + 0.5f, centre.t) >= 0.5f)
      new_distance = centre.t;
    const int sun_n = L.sun ? std::max(1, (L.sun_rays + S2 - 1) / S2) : 0;
    const int sky_n = sky_total > 0 ? std::max(1, (sky_total + S2 - 1) / S2) : 0;
    for (int k = 0; k < S2; ++k) {
      const int si = k % S, sj = k / S;
      // Stratified jitter from the pixel's hash (the stratum's centre in a fixed pattern).
      const std::uint32_t hk = physics::hash32(seed ^ (0x9E3779B9u * std::uint32_t(k + 1)));
      const float jx = st.fixed_pattern ? 0.5f : float(hk & 0xFFFF) / 65536.0f;
      const float jy = st.fixed_pattern ? 0.5f : float(hk >> 16) / 65536.0f;
      const float sx = float(x) + (float(si) + jx) / float(S),
                  sy = float(y) + (float(sj) + jy) / float(S);
      // One sample at the pixel's centre is the centre ray itself.
      const Vec3f dir = S == 1 && st.fixed_pattern
                            ? centre_ray
                            : ray_direction(double(sx) - 0.5, double(sy) - 0.5);
      const ObjectHit hit =
          S == 1 && st.fixed_pattern ? centre : in.objects->intersect(eye, dir, 0.0f);
      if (!(S == 1 && st.fixed_pattern)) ++scratch.camera_rays;
      if (!hit.hit()) continue;
      const float vis = depth_visibility(sx, sy, hit.t);
      if (vis <= 0) continue;
      // The hit's geometry: the geometric normal toward the camera, the shading normal
      // (interpolated) on the same side, bent toward the viewer where interpolation
      // turned it away (silhouettes of coarse meshes).
      const std::uint32_t* tri = &world.indices[3 * std::size_t(hit.prim)];
      auto P = [&](int k2) {
        const float* q = &world.positions[3 * std::size_t(tri[k2])];
        return Vec3f{q[0], q[1], q[2]};
      };
      const Vec3f a = P(0), b = P(1), c = P(2);
      const Vec3f ng_mesh = unit(cross(sub3(b, a), sub3(c, a)));  // the mesh's outside
      const bool back = dot(ng_mesh, dir) > 0;
      const Vec3f ng = back ? Vec3f{-ng_mesh[0], -ng_mesh[1], -ng_mesh[2]} : ng_mesh;
      Vec3f ns = ng;
      Vec3f m = ng_mesh;  // the shading normal on the mesh's normals' side
      bool flip = back;
      if (world.smooth[hit.prim]) {
        m = {0, 0, 0};
        const float bw[3] = {1 - hit.u - hit.v, hit.u, hit.v};
        for (int k2 = 0; k2 < 3; ++k2)
          for (int cc = 0; cc < 3; ++cc)
            m[cc] += bw[k2] * world.normals[3 * std::size_t(tri[k2]) + cc];
        m = unit(m);
        flip = dot(m, ng) < 0;
        ns = flip ? Vec3f{-m[0], -m[1], -m[2]} : m;
      }
      if (world.materials[world.triangle_material[hit.prim]].normal_texture) {
        // The normal map perturbs the normal on the side the mesh's frame describes; seen from
        // behind, the same bump faces the other way.
        const Vec3f mapped = normal_mapped(world, hit.prim, hit.u, hit.v, m);
        ns = flip ? Vec3f{-mapped[0], -mapped[1], -mapped[2]} : mapped;
      }
      const Vec3f view = {-dir[0], -dir[1], -dir[2]};
      const float nv = dot(ns, view);
      if (nv < 0.02f) ns = unit(add3(ns, view, 0.02f - nv));
      const Vec3f hp = add3(eye, dir, hit.t);
      const Vec3f origin = add3(hp, ng, 1e-4f + 2e-5f * hit.t);
      build_rays(set, L, &origin, 1, ns, rotation, k % std::max(L.sun_rays, 1), S2, sun_n,
                 k % std::max(sky_total, 1), S2, sky_n, std::max(sky_total, 1));
      const std::span<const ShadowRay> rays(set.rays, std::size_t(set.size));
      if (st.fixed_pattern) {
        // A fixed pattern would turn the facets' self-shadowing (directions above the smooth
        // shading normal's horizon but below the flat triangle's, which meet the neighbouring
        // triangles) into facet-shaped patches on curved objects: those directions count as
        // open to the objects, as on the smooth surface the normals describe. (The hashed
        // pattern averages them into the smooth result over many rays.)
        int traced = 0;
        for (int i = 0; i < set.size; ++i) {
          blocked_objects[i] = false;
          const ShadowRay& r = set.rays[i];
          if (i < set.lamp_first &&
              r.direction[0] * ng[0] + r.direction[1] * ng[1] + r.direction[2] * ng[2] <= 0)
            continue;
          scratch.index[traced] = i;
          scratch.compact[traced++] = r;
        }
        scratch.trace_compacted_objects(*in.visibility, traced, blocked_objects);
      } else {
        in.visibility->occluded(Geometry::objects, rays, blocked_objects);
        scratch.shadow_rays += std::size_t(set.size);
      }
      in.visibility->occluded(Geometry::photo, rays, blocked_photo);
      scratch.shadow_rays += std::size_t(set.size);
      for (int i = 0; i < set.size; ++i) blocked_any[i] = blocked_photo[i] || blocked_objects[i];
      const SurfaceReflectance refl = reflectance_at(world, hit.prim, hit.u, hit.v);
      SurfacePoint sp;
      sp.surface = true;
      sp.normal = ns;
      sp.view = view;
      sp.position_m = hp;
      const ShadingTerms t = terms_at(L, sp, visibility_of(set, blocked_any), refl.roughness);
      for (int cc = 0; cc < 3; ++cc)
        radiance[cc] += vis * (refl.diffuse_albedo[cc] * t.diffuse[cc] +
                               refl.f0[cc] * t.specular_f0[cc] + t.specular_bias[cc]);
      coverage += vis;
    }
    coverage /= float(S2);
    for (float& v : radiance) v /= float(S2);
  }

  float* C = out.composite.view().pixel(x, y);
  for (int c = 0; c < 3; ++c) {
    const float shadowed = I[c] * ratio[c];
    C[c] = radiance[c] + (1 - coverage) * shadowed;
    out.shadow.view().at(x, y, c) = ratio[c];
    out.difference.view().at(x, y, c) = C[c] - I[c];
    out.object_radiance.view().at(x, y, c) = radiance[c];
  }
  for (int c = 3; c < channels_; ++c)
    C[c] = c == 3 ? I[c] * (1 - coverage) + coverage : I[c];  // alpha: the object is opaque
  out.matte.view().at(x, y, 0) = coverage;
  out.distance_m.view().at(x, y, 0) = new_distance;
}

InsertionLayers allocate_layers(int w, int h, int channels) {
  InsertionLayers out;
  out.composite = Image::uninitialized(w, h, channels);
  out.matte = Image(w, h, 1, {"A"});
  out.shadow = Image::uninitialized(w, h, 3);
  out.difference = Image::uninitialized(w, h, 3);
  out.distance_m = Image::uninitialized(w, h, 1, {"Z"});
  out.object_radiance = Image(w, h, 3);
  return out;
}

}  // namespace

InsertionLayers render_insertion(const InsertionInputs& in, const InsertionSettings& settings) {
  const Renderer renderer(in, settings);
  const int w = in.camera.width, h = in.camera.height;
  InsertionLayers out = allocate_layers(w, h, in.photo.channels);
  std::atomic<std::size_t> shadow_rays{0}, camera_rays{0};
  tbb::task_arena arena(settings.threads > 0 ? settings.threads : tbb::task_arena::automatic);
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<int>(0, h), [&](const tbb::blocked_range<int>& rows) {
      Renderer::Scratch scratch;
      for (int y = rows.begin(); y != rows.end(); ++y) {
        throw_if_cancelled(in.cancel, "insert objects");
        for (int x = 0; x < w; ++x) renderer.shade(x, y, out, scratch);
      }
      shadow_rays += scratch.shadow_rays;
      camera_rays += scratch.camera_rays;
    });
  });
  out.shadow_rays = shadow_rays;
  out.camera_rays = camera_rays;
  return out;
}

PhotoTiles photo_tiles(const InsertionInputs& in, int tile_px) {
  if (tile_px < 1)
    throw Error(ErrorCode::invalid_argument, "insert objects: tile size must be >= 1");
  const int w = in.camera.width, h = in.camera.height;
  if (in.distance_m.width != w || in.distance_m.height != h || in.normals.width != w ||
      in.normals.height != h)
    throw Error(ErrorCode::size_mismatch,
                "insert objects: the distance and normal maps must be the camera's size");
  PhotoTiles tiles;
  tiles.tile_px = tile_px;
  tiles.tiles_x = (w + tile_px - 1) / tile_px;
  tiles.tiles_y = (h + tile_px - 1) / tile_px;
  tiles.bounds.assign(std::size_t(tiles.tiles_x) * std::size_t(tiles.tiles_y), {0, 0, 0, -1, 0});
  const Vec3f eye = to_f(in.pose.position_m);
  const auto axes = in.pose.axes();
  tbb::parallel_for(0, tiles.tiles_y, [&](int ty) {
    for (int tx = 0; tx < tiles.tiles_x; ++tx) {
      Vec3f lo{1e30f, 1e30f, 1e30f}, hi{-1e30f, -1e30f, -1e30f};
      float max_d = 0;
      bool any = false;
      for (int y = ty * tile_px; y < std::min(h, (ty + 1) * tile_px); ++y)
        for (int x = tx * tile_px; x < std::min(w, (tx + 1) * tile_px); ++x) {
          const float d = in.distance_m.at(x, y, 0);
          const Vec3f n = {in.normals.at(x, y, 0), in.normals.at(x, y, 1), in.normals.at(x, y, 2)};
          if (!(std::isfinite(d) && d > 0 && dot(n, n) > 0.5f)) continue;
          // The shadow rays' origin exactly as Renderer::shade computes it.
          const double u = (x + 0.5 - in.camera.cx) / in.camera.focal_px,
                       v = (y + 0.5 - in.camera.cy) / in.camera.focal_px;
          const double dx = u * axes[1].x - v * axes[2].x + axes[0].x,
                       dy = u * axes[1].y - v * axes[2].y + axes[0].y,
                       dz = u * axes[1].z - v * axes[2].z + axes[0].z;
          const double len = std::sqrt(dx * dx + dy * dy + dz * dz);
          const Vec3f ray{float(dx / len), float(dy / len), float(dz / len)};
          const Vec3f o = add3(add3(eye, ray, d), n, 1e-3f + 1e-3f * d);
          for (int c = 0; c < 3; ++c) lo[c] = std::min(lo[c], o[c]), hi[c] = std::max(hi[c], o[c]);
          max_d = std::max(max_d, d);
          any = true;
        }
      if (!any) continue;
      const Vec3f centre = {(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2};
      const Vec3f half = sub3(hi, centre);
      tiles.bounds[std::size_t(ty) * std::size_t(tiles.tiles_x) + std::size_t(tx)] = {
          centre[0], centre[1], centre[2], std::sqrt(dot(half, half)) * 1.0001f + 1e-4f,
          2.0f * max_d / float(in.camera.focal_px)};
    }
  });
  return tiles;
}

std::vector<std::uint8_t> influenced_tiles(const InsertionInputs& in,
                                           const InsertionSettings& settings,
                                           const PhotoTiles& tiles) {
  const Renderer renderer(in, settings);
  std::vector<std::uint8_t> mask(tiles.bounds.size(), 0);
  const int w = in.camera.width, h = in.camera.height;
  for (int ty = 0; ty < tiles.tiles_y; ++ty)
    for (int tx = 0; tx < tiles.tiles_x; ++tx) {
      const Rect r = {tx * tiles.tile_px, ty * tiles.tile_px,
                      std::min(w, (tx + 1) * tiles.tile_px) - 1,
                      std::min(h, (ty + 1) * tiles.tile_px) - 1};
      const std::size_t i = std::size_t(ty) * std::size_t(tiles.tiles_x) + std::size_t(tx);
      mask[i] = renderer.tile_influenced(tiles.bounds[i], r) ? 1 : 0;
    }
  return mask;
}

void render_insertion_tiles(const InsertionInputs& in, const InsertionSettings& settings,
                            const PhotoTiles& tiles, std::span<const std::uint8_t> render_mask,
                            std::span<const std::uint8_t> clean_mask, InsertionLayers& out) {
  const Renderer renderer(in, settings);
  const int w = in.camera.width, h = in.camera.height;
  if (out.composite.width() != w || out.composite.height() != h ||
      out.composite.channels() != in.photo.channels)
    out = allocate_layers(w, h, in.photo.channels);
  if (render_mask.size() != tiles.bounds.size() ||
      (!clean_mask.empty() && clean_mask.size() != tiles.bounds.size()))
    throw Error(ErrorCode::invalid_argument, "insert objects: a tile mask of the wrong size");
  std::vector<int> todo;
  for (std::size_t i = 0; i < tiles.bounds.size(); ++i)
    if (render_mask[i] || (!clean_mask.empty() && clean_mask[i])) todo.push_back(int(i));
  std::atomic<std::size_t> shadow_rays{0}, camera_rays{0};
  tbb::task_arena arena(settings.threads > 0 ? settings.threads : tbb::task_arena::automatic);
  arena.execute([&] {
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, todo.size()),
        [&](const tbb::blocked_range<std::size_t>& r) {
          Renderer::Scratch scratch;
          for (std::size_t k = r.begin(); k != r.end(); ++k) {
            throw_if_cancelled(in.cancel, "insert objects");
            const int i = todo[k];
            const int tx = i % tiles.tiles_x, ty = i / tiles.tiles_x;
            const bool render = render_mask[std::size_t(i)] != 0;
            for (int y = ty * tiles.tile_px; y < std::min(h, (ty + 1) * tiles.tile_px); ++y)
              for (int x = tx * tiles.tile_px; x < std::min(w, (tx + 1) * tiles.tile_px); ++x)
                render ? renderer.shade(x, y, out, scratch) : renderer.clean(x, y, out);
          }
          shadow_rays += scratch.shadow_rays;
          camera_rays += scratch.camera_rays;
        });
  });
  out.shadow_rays = shadow_rays;
  out.camera_rays = camera_rays;
}

}  // namespace mr::render::insertion
