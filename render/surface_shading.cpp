// The microfacet BRDF of mr::Material and the shading of depth-map surfaces with it
// (render/surface_shading.h). Everything that evaluates the BRDF goes through the functions here.
#include "render/surface_shading.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "mr/error.h"
#include "render/depth_downsample.h"
#include "render/embree_scene.h"
#include "render/math.h"
#include "render/occluder_mesh.h"
#include "render/physics/medium.h"
#include "render/physics/scattering.h"

namespace mr::render {

namespace {

constexpr float kPi = 3.14159265358979323846f;
constexpr double kPiD = 3.14159265358979323846;
constexpr float kMinRoughness = 0.02f;  // mr::Material's range

float clamp_roughness(float r) {
  return std::clamp(r, kMinRoughness, 1.0f);
}

// G2 / (4 |n.l| |n.v|) for the height-correlated Smith term: finite as either cosine -> 0, so
// the BRDF never divides by a vanishing cosine.
float smith_visibility(float n_dot_l, float n_dot_v, float alpha2) {
  const float gl = n_dot_v * std::sqrt(alpha2 + (1 - alpha2) * n_dot_l * n_dot_l);
  const float gv = n_dot_l * std::sqrt(alpha2 + (1 - alpha2) * n_dot_v * n_dot_v);
  const float s = gl + gv;
  return s > 0 ? 0.5f / s : 0.0f;
}

float ggx_d_alpha2(float n_dot_h, float alpha2) {
  if (n_dot_h <= 0) return 0;
  const float t = n_dot_h * n_dot_h * (alpha2 - 1) + 1;
  return alpha2 / (kPi * t * t);
}

// The specular lobe without Fresnel, D V (n.l), and the Schlick weight w = (1 - v.h)^5, so that
// f_spec cos = coefficient * (F0 (1 - w) + w). Zero below either horizon.
struct LobeSample {
  float coefficient = 0, schlick_weight = 0;
};
LobeSample specular_lobe(const Vec3f& n, const Vec3f& l, const Vec3f& v, float roughness) {
  const float nl = dot(n, l), nv = dot(n, v);
  if (nl <= 0 || nv <= 0) return {};
  const Vec3f h = unit(Vec3f{l[0] + v[0], l[1] + v[1], l[2] + v[2]});
  const float r = clamp_roughness(roughness);
  const float alpha2 = r * r * r * r;
  const float vh = std::clamp(dot(v, h), 0.0f, 1.0f);
  const float m = 1 - vh;
  const float m2 = m * m;
  return {ggx_d_alpha2(dot(n, h), alpha2) * smith_visibility(nl, nv, alpha2) * nl, m2 * m2 * m};
}

// ---- The split-sum table E_spec(n.v, roughness) = F0 a + b --------------------------------

// Nodes in n.v are uniform in sqrt(n.v): E_spec has a boundary layer of width ~alpha at grazing
// view (it tends to 1 as n.v -> 0, by the Smith term's projected-area identity), which uniform
// nodes smear over their spacing for glossy surfaces.
constexpr int kTableMu = 96;
constexpr int kTableRoughness = 50;  // roughness nodes, uniform on [0.02, 1]
constexpr int kTableSamples = 1024;  // Hammersley points per node

double table_roughness(int j) {
  return kMinRoughness + (1.0 - kMinRoughness) * j / (kTableRoughness - 1);
}

// a and b at one node, by sampling GGX's distribution of visible normals (Heitz 2018) with a
// fixed Hammersley set. Then f cos / pdf(l) = G2(l, v) / G1(v) <= 1 for every sample, so the
// estimate has low variance and never exceeds 1 (energy conservation holds by construction).
SpecularAlbedo integrate_node(double mu, double roughness) {
  mu = std::max(mu, 1e-5);  // n.v = 0 is the limit; E_spec is continuous there
  const double alpha = roughness * roughness, alpha2 = alpha * alpha;
  const double vx = std::sqrt(1 - mu * mu), vz = mu;  // the view in the tangent frame, vy = 0
  // The view in the hemisphere configuration (stretched by alpha); its frame (t1, t2, ve).
  const double len = std::sqrt(alpha2 * vx * vx + vz * vz);
  const double ex = alpha * vx / len, ez = vz / len;
  // t1 = (0, 1, 0) (perpendicular to ve, which has no y part); t2 = cross(ve, t1).
  const double t2x = -ez, t2z = ex;
  const double s = 0.5 * (1 + ez);
  const double sv = std::sqrt(alpha2 + (1 - alpha2) * mu * mu);
  double a = 0, b = 0;
  for (int i = 0; i < kTableSamples; ++i) {
    const double u1 = (i + 0.5) / kTableSamples, u2 = radical_inverse_base2(std::uint32_t(i));
    const double r = std::sqrt(u1), phi = 2 * kPiD * u2;
    const double p1 = r * std::cos(phi);
    const double p2 = (1 - s) * std::sqrt(std::max(0.0, 1 - p1 * p1)) + s * r * std::sin(phi);
    const double p3 = std::sqrt(std::max(0.0, 1 - p1 * p1 - p2 * p2));
    // The sampled normal in the stretched frame, back to the ellipsoid (unstretched).
    const double nhx = p2 * t2x + p3 * ex, nhy = p1, nhz = p2 * t2z + p3 * ez;
    double hx = alpha * nhx, hy = alpha * nhy, hz = std::max(0.0, nhz);
    const double hn = std::sqrt(hx * hx + hy * hy + hz * hz);
    if (!(hn > 0)) continue;
    hx /= hn, hy /= hn, hz /= hn;
    const double vh = vx * hx + vz * hz;
    if (vh <= 0) continue;
    const double lz = 2 * vh * hz - vz;
    if (lz <= 0) continue;  // reflected below the horizon: no contribution
    const double sl = std::sqrt(alpha2 + (1 - alpha2) * lz * lz);
    // G2 / G1(v) for the height-correlated Smith term, written to stay finite as n.v -> 0.
    const double weight = (mu + sv) * lz / (lz * sv + mu * sl);
    const double w = std::pow(1 - vh, 5);
    a += weight * (1 - w);
    b += weight * w;
  }
  return {float(a / kTableSamples), float(b / kTableSamples)};
}

double table_mu(int i) {
  const double t = double(i) / (kTableMu - 1);
  return t * t;
}

struct AlbedoTable {
  std::vector<SpecularAlbedo> nodes;  // [roughness j][mu i]
  AlbedoTable() : nodes(std::size_t(kTableMu) * kTableRoughness) {
    // Serial on purpose: this runs inside a function-local static's initialiser, possibly on a
    // TBB worker; a nested parallel loop could let that worker steal a task that waits on this
    // very initialisation. It takes ~0.2 s once.
    for (int j = 0; j < kTableRoughness; ++j)
      for (int i = 0; i < kTableMu; ++i)
        nodes[std::size_t(j) * kTableMu + i] = integrate_node(table_mu(i), table_roughness(j));
  }
};

const AlbedoTable& albedo_table() {
  static const AlbedoTable table;  // thread-safe initialisation (C++11 magic statics)
  return table;
}

// Smoothstep between the outer and inner cone, as the scattering core's lamps.
float spot_factor(const Lamp& lamp, const Vec3f& from_lamp_unit) {
  if (lamp.outer_angle_deg >= 180.0) return 1.0f;
  const Vec3f axis = unit(to_f(lamp.spot_direction));
  return float(physics::spot_cone(dot(axis, from_lamp_unit),
                                  std::cos(lamp.inner_angle_deg * kPiD / 180),
                                  std::cos(lamp.outer_angle_deg * kPiD / 180)));
}

// A lamp's irradiance on a plane facing it at p (inverse square, spot cone) and the unit
// direction to it; false where it adds nothing (at the lamp, or outside its cone).
bool lamp_irradiance(const Lamp& lamp, const SurfacePoint& p, Vec3f& to_lamp_unit, Rgb& e) {
  const Vec3f to_lamp = {float(lamp.position_m.x) - p.position_m[0],
                         float(lamp.position_m.y) - p.position_m[1],
                         float(lamp.position_m.z) - p.position_m[2]};
  const float r2 = dot(to_lamp, to_lamp);
  if (!(r2 > 1e-12f)) return false;
  to_lamp_unit = unit(to_lamp);
  const float spot = spot_factor(lamp, {-to_lamp_unit[0], -to_lamp_unit[1], -to_lamp_unit[2]});
  if (spot <= 0) return false;
  for (int c = 0; c < 3; ++c) e[c] = lamp.intensity_per_sr[c] * spot / r2;
  return true;
}

void add_direct(ShadingTerms& terms, const SurfacePoint& p, const Vec3f& l, const Rgb& irradiance,
                float roughness) {
  const float nl = dot(p.normal, l);
  if (nl <= 0 || dot(p.normal, p.view) <= 0) return;
  const LobeSample lobe = specular_lobe(p.normal, l, p.view, roughness);
  for (int c = 0; c < 3; ++c) {
    terms.diffuse[c] += irradiance[c] * nl / kPi;
    terms.specular_f0[c] += irradiance[c] * lobe.coefficient * (1 - lobe.schlick_weight);
    terms.specular_bias[c] += irradiance[c] * lobe.coefficient * lobe.schlick_weight;
  }
}

// A deterministic per-pixel hash for decorrelating the rays of neighbouring pixels.
using physics::hash32;

// An orthonormal frame (t, b) around unit n.
void frame(const Vec3f& n, Vec3f& t, Vec3f& b) {
  const Vec3f helper = std::fabs(n[1]) < 0.9f ? Vec3f{0, 1, 0} : Vec3f{1, 0, 0};
  t = unit(cross(helper, n));
  b = cross(n, t);
}

// Traces `dirs` from `origin` to infinity; returns how many escape.
int count_escaping(const OccluderScene& scene, const Vec3f& origin, const Vec3f* dirs, int count) {
  int escaped = 0;
  occluded_rays(
      scene, std::size_t(std::max(count, 0)),
      [&](std::size_t i) { return ShadowRay{origin, dirs[i], 0.0f}; },
      [&](std::size_t, bool blocked) { escaped += !blocked; });
  return escaped;
}

void check_view(const std::string& what, const Image& image, int w, int h, int channels) {
  if (image.channels() != channels)
    throw Error(ErrorCode::invalid_argument, what + " must have " + std::to_string(channels) +
                                                 " channel(s), found " +
                                                 std::to_string(image.channels()));
  if (image.width() != w || image.height() != h)
    throw Error(ErrorCode::size_mismatch, what + " is " + std::to_string(image.width()) + "x" +
                                              std::to_string(image.height()) +
                                              ", the surface geometry is " + std::to_string(w) +
                                              "x" + std::to_string(h));
}

}  // namespace

float ggx_distribution(float n_dot_h, float roughness) {
  const float r = clamp_roughness(roughness);
  return ggx_d_alpha2(n_dot_h, r * r * r * r);
}

float smith_g2(float n_dot_l, float n_dot_v, float roughness) {
  if (n_dot_l <= 0 || n_dot_v <= 0) return 0;
  const float r = clamp_roughness(roughness);
  return 4 * n_dot_l * n_dot_v * smith_visibility(n_dot_l, n_dot_v, r * r * r * r);
}

float schlick_fresnel(float f0, float v_dot_h) {
  const float m = 1 - std::clamp(v_dot_h, 0.0f, 1.0f);
  const float m2 = m * m;
  return f0 + (1 - f0) * m2 * m2 * m;
}

Rgb brdf_cosine(const Material& material, const Vec3f& n, const Vec3f& l, const Vec3f& v) {
  const float nl = dot(n, l);
  if (nl <= 0 || dot(n, v) <= 0) return {0, 0, 0};
  const LobeSample lobe = specular_lobe(n, l, v, material.roughness);
  const float f0 = material.specular_albedo;
  const float spec = lobe.coefficient * (f0 * (1 - lobe.schlick_weight) + lobe.schlick_weight);
  Rgb out;
  for (int c = 0; c < 3; ++c) out[c] = material.diffuse_albedo[c] / kPi * nl + spec;
  return out;
}

SpecularAlbedo ggx_directional_albedo(float n_dot_v, float roughness) {
  const AlbedoTable& table = albedo_table();
  const float mu = std::sqrt(std::clamp(n_dot_v, 0.0f, 1.0f)) * (kTableMu - 1);
  const float rr =
      (clamp_roughness(roughness) - kMinRoughness) / (1 - kMinRoughness) * (kTableRoughness - 1);
  const int i0 = std::min(int(mu), kTableMu - 2), j0 = std::min(int(rr), kTableRoughness - 2);
  const float fi = mu - i0, fj = rr - j0;
  auto at = [&](int j, int i) { return table.nodes[std::size_t(j) * kTableMu + i]; };
  const SpecularAlbedo s00 = at(j0, i0), s01 = at(j0, i0 + 1), s10 = at(j0 + 1, i0),
                       s11 = at(j0 + 1, i0 + 1);
  // Bilinear in (sqrt(n.v), roughness).
  auto lerp2 = [&](float v00, float v01, float v10, float v11) {
    return (1 - fj) * ((1 - fi) * v00 + fi * v01) + fj * ((1 - fi) * v10 + fi * v11);
  };
  return {lerp2(s00.scale, s01.scale, s10.scale, s11.scale),
          lerp2(s00.bias, s01.bias, s10.bias, s11.bias)};
}

namespace {

// What one pixel's rays see: of the sun's `sun_rays` rays those above its tangent plane and
// those of them escaping the occluders; the sky's closed form (1 + n.y) / 2 and the share of its
// upward cosine-distributed rays escaping (traced false: none traced, the share is 1).
struct PixelRays {
  int sun_above = 0, sun_escaped = 0;
  float sky_closed = 0, sky_escape = 1;
  bool sky_traced = false;
};

class VisibilityRays {
 public:
  VisibilityRays(const Lighting& lighting, const SurfaceGeometryOptions& options)
      : sky_rays_(options.sky_rays) {
    if (lighting.sun) {
      sun_dir_ = unit(to_f(lighting.sun->direction_to_sun));
      if (dot(*sun_dir_, *sun_dir_) == 0)
        throw Error(ErrorCode::invalid_argument, "lighting.sun.direction_to_sun is zero");
      frame(*sun_dir_, sun_u_, sun_v_);
      sun_tan_radius_ = float(std::tan(lighting.sun->angular_radius_deg * kPiD / 180));
    }
    sun_rays_ = sun_tan_radius_ > 0 ? options.sun_rays : 1;
  }
  int sun_rays() const { return sun_rays_; }

  // The rays of the surface point p (distance d from the eye, unit normal n) at pixel (x, y),
  // traced against `occluders` where given (else only counted).
  PixelRays trace(const Vec3f& n, const Vec3f& p, float d, int x, int y,
                  const OccluderScene* occluders) const {
    PixelRays out;
    Vec3f dirs[256];
    // Off the surface along its normal, as the scattering core does, so the pixel's own
    // (and its neighbours') triangles do not shadow it.
    const float offset = 1e-3f + 1e-3f * d;
    const Vec3f origin = {p[0] + offset * n[0], p[1] + offset * n[1], p[2] + offset * n[2]};
    const std::uint32_t seed = hash32(std::uint32_t(y) * 73856093u ^ std::uint32_t(x));
    const float rotation = float(seed >> 8) * (1.0f / 16777216.0f);
    if (sun_dir_ && dot(n, *sun_dir_) > 0) {
      int count = 0;
      for (int i = 0; i < sun_rays_; ++i) {
        Vec3f s = *sun_dir_;
        if (sun_rays_ > 1) {
          // Stratified in radius, golden-angle spiral in azimuth, rotated per pixel.
          const float r = sun_tan_radius_ * std::sqrt((i + 0.5f) / sun_rays_);
          const float phi = 2.39996323f * i + 2 * kPi * rotation;
          s = unit(Vec3f{s[0] + r * (std::cos(phi) * sun_u_[0] + std::sin(phi) * sun_v_[0]),
                         s[1] + r * (std::cos(phi) * sun_u_[1] + std::sin(phi) * sun_v_[1]),
                         s[2] + r * (std::cos(phi) * sun_u_[2] + std::sin(phi) * sun_v_[2])});
        }
        if (dot(n, s) > 0) dirs[count++] = s;
      }
      out.sun_above = count;
      out.sun_escaped = occluders ? count_escaping(*occluders, origin, dirs, count) : count;
    }
    out.sky_closed = 0.5f * (1 + n[1]);
    if (occluders && sky_rays_ > 0 && out.sky_closed > 0) {
      // Cosine-distributed directions around n (stratified: Hammersley with a per-pixel
      // Cranley-Patterson rotation); only the upward ones can reach the sky, and the
      // closed form already accounts for the downward share.
      Vec3f t, b;
      frame(n, t, b);
      int up = 0;
      for (int i = 0; i < sky_rays_; ++i) {
        const float u1 = (i + 0.5f) / sky_rays_;
        float u2 = float(radical_inverse_base2(std::uint32_t(i))) + rotation;
        u2 -= std::floor(u2);
        const float rad = std::sqrt(u1), phi = 2 * kPi * u2;
        const float a = rad * std::cos(phi), c = rad * std::sin(phi),
                    z = std::sqrt(std::max(0.0f, 1 - u1));
        const Vec3f dir = {a * t[0] + c * b[0] + z * n[0], a * t[1] + c * b[1] + z * n[1],
                           a * t[2] + c * b[2] + z * n[2]};
        if (dir[1] > 0) dirs[up++] = dir;
      }
      // One fixed count for every pixel: refining only where a first estimate came out
      // partial biases the result upward (open-looking pixels keep 1); a test caught it.
      if (up > 0) {
        out.sky_escape = float(count_escaping(*occluders, origin, dirs, up)) / float(up);
        out.sky_traced = true;
      }
    }
    return out;
  }

 private:
  int sky_rays_ = 0, sun_rays_ = 1;
  std::optional<Vec3f> sun_dir_;
  Vec3f sun_u_{}, sun_v_{};
  float sun_tan_radius_ = 0;
};

std::optional<OccluderScene> occluder_scene(const Image& distance_m, const Camera& camera,
                                            const CameraPose& pose) {
  TriangleMesh mesh = reconstruct_occluder_mesh(distance_m.view(), camera, pose);
  // Robust traversal: a shadow ray slipping through the shared edge of two triangles would
  // light one pixel inside a shadow (seen in tests), and here every pixel's visibility is
  // one sample that nothing averages out. It measured no slower (embree_scene.h).
  OccluderSceneOptions scene_options;
  scene_options.robust = true;
  std::optional<OccluderScene> scene;
  if (mesh.triangle_count() > 0) scene.emplace(std::move(mesh), scene_options);
  return scene;
}

// The unit ray through pixel (x, y) and the point `d` metres along it: one place, so that
// surface_point gives the floats the geometry was made with.
void ray_and_point(const Camera& camera, const CameraPose& pose, int x, int y, float d, Vec3f& ray,
                   Vec3f& p) {
  ray = to_f(pose.ray_direction(camera, x, y));
  const Vec3f eye = to_f(pose.position_m);
  p = {eye[0] + d * ray[0], eye[1] + d * ray[1], eye[2] + d * ray[2]};
}

// The surface point of pixel (x, y): false where there is none (sky, or no usable normal).
bool surface_at(const Image& distance_m, const Image& normal, const Camera& camera,
                const CameraPose& pose, int x, int y, Vec3f& n, Vec3f& p, Vec3f& ray, float& d) {
  d = distance_m.at(x, y, 0);
  n = {normal.at(x, y, 0), normal.at(x, y, 1), normal.at(x, y, 2)};
  if (!(std::isfinite(d) && d > 0) || dot(n, n) < 0.5f) return false;
  ray_and_point(camera, pose, x, y, d, ray, p);
  return true;
}

// The escape shares of a coarser trace (SurfaceGeometryOptions::traced_pixel_budget): per coarse
// pixel, the share of the sun's rays above its tangent plane and of the sky's upward rays that
// escape the occluders, -1 where it has none (sky, facing away).
struct CoarseEscapes {
  int factor = 1;
  Image distance_m, sun, sky;
};

// A coarse pixel's weight for a pixel falls with the difference of their distances, to 0 at this
// share of the pixel's (a biweight): a depth edge of the photo is far more, a slanted ground's
// step between coarse pixels less. Compact, so another surface adds nothing.
constexpr float kCoarseDepthTolerance = 0.1f;

// A fine pixel's escape share from the coarse grid: the bilinear neighbours of its centre,
// weighted by how near their distance is to its own `d`, those without a share left out; else
// the share of the coarse pixel nearest in distance among the 3 x 3 around it; else 1.
float coarse_share(const CoarseEscapes& coarse, const Image& share, int x, int y, float d) {
  const int cw = share.width(), ch = share.height(), f = coarse.factor;
  const float cx = (x + 0.5f) / f - 0.5f, cy = (y + 0.5f) / f - 0.5f;
  const int x0 = int(std::floor(cx)), y0 = int(std::floor(cy));
  const float fx = cx - x0, fy = cy - y0;
  double sum = 0, weight = 0;
  for (int j = 0; j < 2; ++j)
    for (int i = 0; i < 2; ++i) {
      const int xi = std::clamp(x0 + i, 0, cw - 1), yj = std::clamp(y0 + j, 0, ch - 1);
      const float v = share.at(xi, yj, 0);
      if (v < 0) continue;
      const float relative = (coarse.distance_m.at(xi, yj, 0) - d) / (kCoarseDepthTolerance * d);
      if (!(std::fabs(relative) < 1)) continue;
      const float biweight = (1 - relative * relative) * (1 - relative * relative);
      const double w = double(i ? fx : 1 - fx) * (j ? fy : 1 - fy) * biweight;
      sum += w * v;
      weight += w;
    }
  if (weight > 1e-6) return float(sum / weight);
  const int nx = std::clamp(int(std::lround(cx)), 0, cw - 1),
            ny = std::clamp(int(std::lround(cy)), 0, ch - 1);
  float best = 1, nearest = std::numeric_limits<float>::infinity();
  for (int j = std::max(ny - 1, 0); j <= std::min(ny + 1, ch - 1); ++j)
    for (int i = std::max(nx - 1, 0); i <= std::min(nx + 1, cw - 1); ++i) {
      const float v = share.at(i, j, 0);
      const float gap = std::fabs(coarse.distance_m.at(i, j, 0) - d);
      if (v >= 0 && gap < nearest) {
        nearest = gap;
        best = v;
      }
    }
  return best;
}

CoarseEscapes trace_coarse(const Image& distance_m, const Camera& camera, const CameraPose& pose,
                           const VisibilityRays& rays, int factor) {
  CoarseEscapes out;
  out.factor = factor;
  DownsampledDistance coarse = downsample_distance_nearest(distance_m.view(), camera, factor);
  const int w = coarse.camera.width, h = coarse.camera.height;
  const Image normal = estimate_normals(coarse.distance_m.view(), coarse.camera, pose);
  const std::optional<OccluderScene> occluders =
      occluder_scene(coarse.distance_m, coarse.camera, pose);
  out.sun = Image(w, h, 1);
  out.sky = Image(w, h, 1);
  tbb::parallel_for(tbb::blocked_range<int>(0, h), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y != rows.end(); ++y)
      for (int x = 0; x < w; ++x) {
        Vec3f n, p, ray;
        float d;
        out.sun.at(x, y, 0) = out.sky.at(x, y, 0) = -1;
        if (!surface_at(coarse.distance_m, normal, coarse.camera, pose, x, y, n, p, ray, d))
          continue;
        const PixelRays r = rays.trace(n, p, d, x, y, occluders ? &*occluders : nullptr);
        if (r.sun_above > 0) out.sun.at(x, y, 0) = float(r.sun_escaped) / float(r.sun_above);
        if (r.sky_traced) out.sky.at(x, y, 0) = r.sky_escape;
      }
  });
  out.distance_m = std::move(coarse.distance_m);
  return out;
}

}  // namespace

int traced_visibility_factor(int width, int height, std::size_t traced_pixel_budget) {
  const double pixels = double(width) * height;
  if (traced_pixel_budget == 0 || !(pixels > double(traced_pixel_budget))) return 1;
  // At most the map's narrower side, so the coarse map keeps a pixel across.
  return std::min({int(std::ceil(std::sqrt(pixels / double(traced_pixel_budget)))), width, height});
}

SurfaceGeometry surface_geometry_from_depth(const Image& distance_m, const Camera& camera,
                                            const CameraPose& pose, const Lighting& lighting,
                                            const SurfaceGeometryOptions& options) {
  if (options.sky_rays < 0 || options.sky_rays > 256)
    throw Error(ErrorCode::invalid_argument, "surface geometry: sky_rays must be in 0..256, got " +
                                                 std::to_string(options.sky_rays));
  if (options.sun_rays < 1 || options.sun_rays > 64)
    throw Error(ErrorCode::invalid_argument, "surface geometry: sun_rays must be in 1..64, got " +
                                                 std::to_string(options.sun_rays));
  if (options.threads < 0)
    throw Error(ErrorCode::invalid_argument,
                "surface geometry: threads must be >= 0, got " + std::to_string(options.threads));
  tbb::task_arena arena(options.threads > 0 ? options.threads : tbb::task_arena::automatic);
  SurfaceGeometry g;
  arena.execute([&] {
    // Throws for a wrong channel count or size (the message names both sizes).
    g.normal = estimate_normals(distance_m.view(), camera, pose);
    const int w = camera.width, h = camera.height;
    g.distance_m = distance_m;
    g.camera = camera;
    g.pose = pose;
    g.sun_visibility = Image(w, h, 1);
    g.sky_visibility = Image(w, h, 1);
    g.surface = Image(w, h, 1);
    const VisibilityRays rays(lighting, options);
    const int factor =
        options.shadows ? traced_visibility_factor(w, h, options.traced_pixel_budget) : 1;
    std::optional<OccluderScene> occluders;
    CoarseEscapes coarse;
    if (factor > 1)
      coarse = trace_coarse(distance_m, camera, pose, rays, factor);
    else if (options.shadows)
      occluders = occluder_scene(distance_m, camera, pose);

    tbb::parallel_for(tbb::blocked_range<int>(0, h), [&](const tbb::blocked_range<int>& rows) {
      for (int y = rows.begin(); y != rows.end(); ++y)
        for (int x = 0; x < w; ++x) {
          Vec3f n, p, ray;
          float d;
          if (!surface_at(distance_m, g.normal, camera, pose, x, y, n, p, ray, d)) {
            for (int c = 0; c < 3; ++c) g.normal.at(x, y, c) = 0;
            continue;
          }
          g.surface.at(x, y, 0) = 1;
          const PixelRays r = rays.trace(n, p, d, x, y, occluders ? &*occluders : nullptr);
          if (factor > 1) {
            // The tangent plane per pixel, the occluders from the coarse trace.
            g.sun_visibility.at(x, y, 0) = r.sun_above > 0
                                               ? float(r.sun_above) / float(rays.sun_rays()) *
                                                     coarse_share(coarse, coarse.sun, x, y, d)
                                               : 0.0f;
            g.sky_visibility.at(x, y, 0) =
                r.sky_closed > 0 ? r.sky_closed * coarse_share(coarse, coarse.sky, x, y, d) : 0.0f;
          } else {
            g.sun_visibility.at(x, y, 0) = float(r.sun_escaped) / float(rays.sun_rays());
            g.sky_visibility.at(x, y, 0) = r.sky_closed * r.sky_escape;
          }
        }
    });
  });
  return g;
}

SurfacePoint surface_point(const SurfaceGeometry& geometry, int x, int y) {
  SurfacePoint p;
  p.surface = geometry.surface.at(x, y, 0) > 0;
  if (!p.surface) return p;
  Vec3f ray;
  ray_and_point(geometry.camera, geometry.pose, x, y, geometry.distance_m.at(x, y, 0), ray,
                p.position_m);
  for (int c = 0; c < 3; ++c) {
    p.normal[c] = geometry.normal.at(x, y, c);
    p.view[c] = -ray[c];
  }
  p.sun_visibility = geometry.sun_visibility.at(x, y, 0);
  p.sky_visibility = geometry.sky_visibility.at(x, y, 0);
  return p;
}

ShadingTerms shading_terms(const SurfacePoint& p, const Lighting& lighting, float roughness) {
  ShadingTerms terms;
  if (!p.surface) return terms;
  if (lighting.sun && p.sun_visibility > 0) {
    const Sun& sun = *lighting.sun;
    const Rgb e = {sun.irradiance[0] * p.sun_visibility, sun.irradiance[1] * p.sun_visibility,
                   sun.irradiance[2] * p.sun_visibility};
    add_direct(terms, p, unit(to_f(sun.direction_to_sun)), e, roughness);
  }
  if (lighting.sky_radiance && p.sky_visibility > 0) {
    const float nv = dot(p.normal, p.view);
    if (nv > 0) {
      const SpecularAlbedo ab = ggx_directional_albedo(nv, roughness);
      for (int c = 0; c < 3; ++c) {
        const float l = (*lighting.sky_radiance)[c] * p.sky_visibility;
        terms.diffuse[c] += l;
        terms.specular_f0[c] += l * ab.scale;
        terms.specular_bias[c] += l * ab.bias;
      }
    }
  }
  for (const Lamp& lamp : lighting.lamps) {
    Vec3f l;
    Rgb e;
    if (lamp_irradiance(lamp, p, l, e)) add_direct(terms, p, l, e, roughness);
  }
  return terms;
}

Rgb diffuse_term(const SurfacePoint& p, const Lighting& lighting) {
  Rgb d{0, 0, 0};
  if (!p.surface) return d;
  const float nv = dot(p.normal, p.view);
  if (nv <= 0) return d;  // add_direct and the sky term add nothing then
  if (lighting.sun && p.sun_visibility > 0) {
    const Sun& sun = *lighting.sun;
    const float nl = dot(p.normal, unit(to_f(sun.direction_to_sun)));
    if (nl > 0)
      for (int c = 0; c < 3; ++c) d[c] += sun.irradiance[c] * p.sun_visibility * nl / kPi;
  }
  if (lighting.sky_radiance && p.sky_visibility > 0)
    for (int c = 0; c < 3; ++c) d[c] += (*lighting.sky_radiance)[c] * p.sky_visibility;
  for (const Lamp& lamp : lighting.lamps) {
    Vec3f l;
    Rgb e;
    if (!lamp_irradiance(lamp, p, l, e)) continue;
    const float nl = dot(p.normal, l);
    if (nl <= 0) continue;
    for (int c = 0; c < 3; ++c) d[c] += e[c] * nl / kPi;
  }
  return d;
}

Rgb shade(const Material& m, const ShadingTerms& t) {
  Rgb out;
  for (int c = 0; c < 3; ++c)
    out[c] = m.diffuse_albedo[c] * t.diffuse[c] + m.specular_albedo * t.specular_f0[c] +
             t.specular_bias[c];
  return out;
}

Rgb shade_pixel(const Material& material, const SurfaceGeometry& geometry, const Lighting& lighting,
                int x, int y) {
  const SurfacePoint p = surface_point(geometry, x, y);
  if (!p.surface) return {0, 0, 0};
  return shade(material, shading_terms(p, lighting, material.roughness));
}

void shade_regions(const SurfaceGeometry& geometry, const Lighting& lighting, const Image& labels,
                   std::span<const Material> materials, Image& out) {
  const int w = geometry.surface.width(), h = geometry.surface.height();
  check_view("shade_regions: labels", labels, w, h, 1);
  check_view("shade_regions: output", out, w, h, 3);
  for (std::size_t k = 0; k < materials.size(); ++k)
    validate_material(materials[k], "shade_regions: materials[" + std::to_string(k) + "]");
  tbb::parallel_for(tbb::blocked_range<int>(0, h), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y != rows.end(); ++y)
      for (int x = 0; x < w; ++x) {
        const float label = labels.at(x, y, 0);
        if (!(label >= 1 && label <= float(materials.size())) || std::floor(label) != label)
          continue;
        const Rgb c = shade_pixel(materials[std::size_t(label) - 1], geometry, lighting, x, y);
        float* o = out.pixel(x, y);
        if (geometry.surface.at(x, y, 0) > 0) {
          o[0] = c[0];
          o[1] = c[1];
          o[2] = c[2];
        }
      }
  });
}

}  // namespace mr::render
