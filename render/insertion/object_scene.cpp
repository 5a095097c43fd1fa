// Inserted objects in world space and in an Embree scene (render/insertion/object_scene.h).
#include "render/insertion/object_scene.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "mr/error.h"
#include "render/huge_pages.h"

namespace mr::render::insertion {

namespace {

constexpr double kPi = 3.14159265358979323846;

[[noreturn]] void fail(const ObjectMesh& mesh, const std::string& what) {
  throw Error(
      ErrorCode::invalid_argument,
      "object '" + (mesh.source.empty() ? std::string("<unnamed>") : mesh.source) + "': " + what);
}

void embree_error(void*, RTCError code, const char* message) {
  // Embree reports through this callback; the calls below check rtcGetDeviceError as well.
  (void)code;
  (void)message;
}

// Bilinear lookup with repeat wrapping; returns the first `n` channels (missing ones = 1).
void sample_bilinear(const Image& image, float u, float v, int n, float* out) {
  const int w = image.width(), h = image.height();
  const float fx = (u - std::floor(u)) * float(w) - 0.5f,
              fy = (v - std::floor(v)) * float(h) - 0.5f;
  const int x0 = int(std::floor(fx)), y0 = int(std::floor(fy));
  const float ax = fx - float(x0), ay = fy - float(y0);
  auto wrap = [](int i, int size) { return ((i % size) + size) % size; };
  const int xs[2] = {wrap(x0, w), wrap(x0 + 1, w)}, ys[2] = {wrap(y0, h), wrap(y0 + 1, h)};
  for (int c = 0; c < n; ++c) {
    if (c >= image.channels()) {
      out[c] = 1;
      continue;
    }
    const float a = image.at(xs[0], ys[0], c), b = image.at(xs[1], ys[0], c),
                d = image.at(xs[0], ys[1], c), e = image.at(xs[1], ys[1], c);
    out[c] = (1 - ay) * ((1 - ax) * a + ax * b) + ay * ((1 - ax) * d + ax * e);
  }
}

void check_placement(const ObjectMesh& mesh, const ObjectPlacement& placement) {
  if (!(std::isfinite(placement.scale) && placement.scale > 0))
    fail(mesh, "placement scale must be finite and > 0, got " + std::to_string(placement.scale));
  if (!std::isfinite(placement.position_m.x) || !std::isfinite(placement.position_m.y) ||
      !std::isfinite(placement.position_m.z) || !std::isfinite(placement.yaw_deg))
    fail(mesh, "placement position and yaw must be finite");
}

// The tangents a normal texture is read with: the mesh's own (glTF's TANGENT, or the loader's),
// else generated from its UVs into `generated`; null for a mesh without UVs or normals (its
// normal texture is then not applied: there is no frame to read it in).
const std::vector<std::array<float, 4>>* tangents_of(const ObjectMesh& mesh,
                                                     std::vector<std::array<float, 4>>& generated) {
  const std::size_t nv = mesh.positions.size();
  if (mesh.tangents.size() == nv) return &mesh.tangents;
  if (mesh.uvs.size() != nv || mesh.normals.size() != nv) return nullptr;
  ObjectMesh frame_only;  // compute_tangents reads positions, normals, uvs and triangles
  frame_only.positions = mesh.positions;
  frame_only.normals = mesh.normals;
  frame_only.uvs = mesh.uvs;
  frame_only.triangles = mesh.triangles;
  compute_tangents(frame_only);
  generated = std::move(frame_only.tangents);
  return generated.size() == nv ? &generated : nullptr;
}

// Vertex i of `mesh` placed as world vertex `at` (the arrays already hold it): the one
// definition of the arithmetic, shared by append_object and move_objects so that both give the
// same floats. Grows lo, hi by the placed position.
void place_vertex(WorldObjects& world, std::size_t at, const ObjectMesh& mesh, std::size_t i,
                  const PlacementTransform& xf, const std::vector<std::array<float, 4>>* tangents,
                  Vec3d& lo, Vec3d& hi) {
  const auto& p = mesh.positions[i];
  if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]))
    fail(mesh, "vertex " + std::to_string(i) + " has a non-finite position");
  const Vec3d w = xf.apply({p[0], p[1], p[2]});
  float* q = &world.positions[3 * at];
  q[0] = float(w.x), q[1] = float(w.y), q[2] = float(w.z);
  lo = {std::min(lo.x, w.x), std::min(lo.y, w.y), std::min(lo.z, w.z)};
  hi = {std::max(hi.x, w.x), std::max(hi.y, w.y), std::max(hi.z, w.z)};
  Vec3d n{0, 0, 0};
  if (!mesh.normals.empty()) {
    const auto& m = mesh.normals[i];
    if (std::isfinite(m[0]) && std::isfinite(m[1]) && std::isfinite(m[2]))
      n = unit(xf.rotate({m[0], m[1], m[2]}));
  }
  float* nn = &world.normals[3 * at];
  nn[0] = float(n.x), nn[1] = float(n.y), nn[2] = float(n.z);
  float* uv = &world.uvs[2 * at];
  if (!mesh.uvs.empty() && std::isfinite(mesh.uvs[i][0]) && std::isfinite(mesh.uvs[i][1]))
    uv[0] = mesh.uvs[i][0], uv[1] = mesh.uvs[i][1];
  else
    uv[0] = uv[1] = 0.0f;
  if (tangents) {
    const auto& t = (*tangents)[i];
    Vec3d r{0, 0, 0};
    if (std::isfinite(t[0]) && std::isfinite(t[1]) && std::isfinite(t[2]) && std::isfinite(t[3]))
      r = unit(xf.rotate({t[0], t[1], t[2]}));
    float* out = &world.tangents[4 * at];
    out[0] = float(r.x), out[1] = float(r.y), out[2] = float(r.z);
    out[3] = t[3] < 0 ? -1.0f : 1.0f;
  }
}

// Whether a triangle (mesh indices, offset by base) has zero area once placed.
bool degenerate(const WorldObjects& world, std::uint32_t base,
                const std::array<std::uint32_t, 3>& tri) {
  auto pos = [&](std::uint32_t i) {
    const float* p = &world.positions[3 * std::size_t(base + i)];
    return Vec3d{p[0], p[1], p[2]};
  };
  const Vec3d a = pos(tri[0]), b = pos(tri[1]), c = pos(tri[2]);
  return !(length(cross(b - a, c - a)) > 1e-14);
}

// An object's bounding spheres about its box's centre: the box's half-diagonal, and the
// farthest vertex (WorldObjects::bounds, tight_bounds).
std::pair<std::array<float, 4>, std::array<float, 4>> spheres(const WorldObjects& world,
                                                              std::uint32_t first, std::size_t nv,
                                                              const Vec3d& lo, const Vec3d& hi) {
  const Vec3d centre = {(lo.x + hi.x) / 2, (lo.y + hi.y) / 2, (lo.z + hi.z) / 2};
  const std::array<float, 4> box = {float(centre.x), float(centre.y), float(centre.z),
                                    float(length(hi - centre) * 1.0001 + 1e-6)};
  double r2 = 0;
  for (std::size_t i = 0; i < nv; ++i) {
    const float* q = &world.positions[3 * (std::size_t(first) + i)];
    const double dx = q[0] - centre.x, dy = q[1] - centre.y, dz = q[2] - centre.z;
    r2 = std::max(r2, dx * dx + dy * dy + dz * dz);
  }
  return {
      box,
      {float(centre.x), float(centre.y), float(centre.z), float(std::sqrt(r2) * 1.0001 + 1e-6)}};
}

}  // namespace

Vec3d PlacementTransform::apply(const Vec3d& p) const {
  const Vec3d r = rotate(p);
  return {translation.x + scale * r.x, translation.y + scale * r.y, translation.z + scale * r.z};
}

Vec3d PlacementTransform::rotate(const Vec3d& v) const {
  return {rotation[0][0] * v.x + rotation[0][1] * v.y + rotation[0][2] * v.z,
          rotation[1][0] * v.x + rotation[1][1] * v.y + rotation[1][2] * v.z,
          rotation[2][0] * v.x + rotation[2][1] * v.y + rotation[2][2] * v.z};
}

PlacementTransform placement_transform(const ObjectPlacement& placement) {
  PlacementTransform t;
  t.scale = placement.scale;
  t.translation = vec(placement.position_m);
  // Yaw about +Y (positive turns +Z toward +X, as the camera's and the sun's azimuths do).
  const double yaw = placement.yaw_deg * kPi / 180;
  const double cy = std::cos(yaw), sy = std::sin(yaw);
  const double yaw_m[3][3] = {{cy, 0, sy}, {0, 1, 0}, {-sy, 0, cy}};
  // The shortest rotation taking +Y to `up` (Rodrigues about axis = Y x up).
  Vec3d up = unit(vec(placement.up));
  if (length(up) == 0) up = {0, 1, 0};
  double tilt[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  const Vec3d axis = cross(Vec3d{0, 1, 0}, up);
  const double s = length(axis), c = up.y;
  if (s > 1e-12) {
    const Vec3d k = {axis.x / s, axis.y / s, axis.z / s};
    const double K[3][3] = {{0, -k.z, k.y}, {k.z, 0, -k.x}, {-k.y, k.x, 0}};
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        double kk = 0;
        for (int m = 0; m < 3; ++m) kk += K[i][m] * K[m][j];
        tilt[i][j] = (i == j ? 1.0 : 0.0) + s * K[i][j] + (1 - c) * kk;
      }
  } else if (c < 0) {  // up = -Y: half a turn about X
    tilt[1][1] = -1;
    tilt[2][2] = -1;
  }
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      double v = 0;
      for (int m = 0; m < 3; ++m) v += tilt[i][m] * yaw_m[m][j];
      t.rotation[i][j] = v;
    }
  return t;
}

void append_object(WorldObjects& world, const ObjectMesh& mesh, const ObjectPlacement& placement,
                   const std::optional<Material>& material_override) {
  check_placement(mesh, placement);
  const std::size_t nv = mesh.positions.size();
  if (!mesh.normals.empty() && mesh.normals.size() != nv)
    fail(mesh,
         std::to_string(mesh.normals.size()) + " normals for " + std::to_string(nv) + " vertices");
  if (!mesh.uvs.empty() && mesh.uvs.size() != nv)
    fail(mesh, std::to_string(mesh.uvs.size()) + " uvs for " + std::to_string(nv) + " vertices");
  if (mesh.materials.empty()) fail(mesh, "has no material");
  if (!mesh.triangle_material.empty() && mesh.triangle_material.size() != mesh.triangles.size())
    fail(mesh, "triangle_material has " + std::to_string(mesh.triangle_material.size()) +
                   " entries for " + std::to_string(mesh.triangles.size()) + " triangles");
  if (world.vertex_count() + nv > 0xFFFFFFF0u) fail(mesh, "too many vertices");

  // Textures: copied once, shared by the materials that use them.
  const std::size_t texture_base = world.textures.size();
  for (const ObjectTexture& t : mesh.textures) {
    if (t.image.empty()) fail(mesh, "texture '" + t.source + "' is empty");
    world.textures.push_back(std::make_shared<const Image>(t.image));
  }
  const std::size_t material_base = world.materials.size();
  for (std::size_t k = 0; k < mesh.materials.size(); ++k) {
    const ObjectMaterial& m = mesh.materials[k];
    ShadingMaterial s;
    s.base_color = m.base_color;
    s.metallic = std::clamp(m.metallic, 0.0f, 1.0f);
    s.roughness = std::clamp(m.roughness, 0.0f, 1.0f);
    auto texture = [&](int index, const char* what) -> const Image* {
      if (index < 0) return nullptr;
      if (std::size_t(index) >= mesh.textures.size())
        fail(mesh, "material " + std::to_string(k) + "'s " + what + " texture index " +
                       std::to_string(index) + " is out of range");
      return world.textures[texture_base + std::size_t(index)].get();
    };
    s.base_color_texture = texture(m.base_color_texture, "base colour");
    s.metallic_roughness_texture = texture(m.metallic_roughness_texture, "metallic-roughness");
    s.normal_texture = texture(m.normal_texture, "normal");
    if (s.normal_texture && s.normal_texture->channels() < 3)
      fail(mesh, "normal texture '" + mesh.textures[std::size_t(m.normal_texture)].source +
                     "' has " + std::to_string(s.normal_texture->channels()) +
                     " channel(s); a tangent-space normal map needs 3 (R, G, B = x, y, z)");
    s.material = material_override ? material_override : m.material;
    if (s.material) validate_material(*s.material, "object '" + mesh.source + "' material");
    world.materials.push_back(s);
  }

  // Tangents, only where a normal texture needs them: the mesh's own (glTF's TANGENT, or the
  // loader's), else generated from the UVs. A mesh without UVs or normals has none (its normal
  // texture is then not applied: there is no frame to read it in).
  bool wants_tangents = false;
  for (std::size_t k = material_base; k < world.materials.size(); ++k)
    wants_tangents = wants_tangents || world.materials[k].normal_texture != nullptr;
  std::vector<std::array<float, 4>> generated;
  const std::vector<std::array<float, 4>>* tangents =
      wants_tangents ? tangents_of(mesh, generated) : nullptr;
  // Once one object has tangents the array is per vertex of all (zero: no frame).
  if (wants_tangents || !world.tangents.empty())
    world.tangents.resize(4 * (world.vertex_count() + nv), 0.0f);

  const PlacementTransform xf = placement_transform(placement);
  if (!world.positions.empty()) world.positions.pop_back();  // the padding float
  const std::uint32_t vertex_base = std::uint32_t(world.vertex_count());
  world.positions.resize(3 * (std::size_t(vertex_base) + nv));
  world.normals.resize(3 * (std::size_t(vertex_base) + nv));
  world.uvs.resize(2 * (std::size_t(vertex_base) + nv));
  Vec3d lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  for (std::size_t i = 0; i < nv; ++i)
    place_vertex(world, vertex_base + i, mesh, i, xf, tangents, lo, hi);
  world.positions.push_back(0.0f);  // Embree reads 16 bytes for the last float3
  const std::size_t first_triangle = world.triangle_count();
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    const auto& tri = mesh.triangles[t];
    for (int k = 0; k < 3; ++k)
      if (tri[k] >= nv)
        fail(mesh, "triangle " + std::to_string(t) + " uses vertex " + std::to_string(tri[k]) +
                       " of " + std::to_string(nv));
    const std::uint32_t material = mesh.triangle_material.empty() ? 0 : mesh.triangle_material[t];
    if (material >= mesh.materials.size())
      fail(mesh, "triangle " + std::to_string(t) + " uses material " + std::to_string(material) +
                     " of " + std::to_string(mesh.materials.size()));
    if (degenerate(world, vertex_base, tri)) continue;  // hits nothing, and casts nothing
    world.indices.insert(world.indices.end(),
                         {vertex_base + tri[0], vertex_base + tri[1], vertex_base + tri[2]});
    world.triangle_material.push_back(std::uint32_t(material_base + material));
    bool smooth = !mesh.normals.empty();
    for (int k = 0; k < 3 && smooth; ++k) {
      const float* n = &world.normals[3 * std::size_t(vertex_base + tri[k])];
      smooth = n[0] * n[0] + n[1] * n[1] + n[2] * n[2] > 0.5f;
    }
    world.smooth.push_back(smooth ? 1 : 0);
  }
  if (nv > 0) {
    const auto [box, tight] = spheres(world, vertex_base, nv, lo, hi);
    world.bounds.push_back(box);
    world.tight_bounds.push_back(tight);
  }
  world.objects.push_back({vertex_base, std::uint32_t(nv), std::uint32_t(first_triangle),
                           std::uint32_t(world.triangle_count() - first_triangle),
                           tangents != nullptr});
}

bool move_objects(WorldObjects& world, std::span<const ObjectMesh* const> meshes,
                  std::span<const ObjectPlacement> placements) {
  if (meshes.size() != world.objects.size() || placements.size() != meshes.size()) return false;
  std::size_t sphere = 0;
  for (std::size_t k = 0; k < meshes.size(); ++k) {
    const ObjectMesh& mesh = *meshes[k];
    const WorldObjects::Range& range = world.objects[k];
    const std::size_t nv = mesh.positions.size();
    if (nv != range.vertex_count) return false;
    check_placement(mesh, placements[k]);
    const PlacementTransform xf = placement_transform(placements[k]);
    std::vector<std::array<float, 4>> generated;
    const std::vector<std::array<float, 4>>* tangents =
        range.tangents ? tangents_of(mesh, generated) : nullptr;
    if (range.tangents && !tangents) return false;
    Vec3d lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
    for (std::size_t i = 0; i < nv; ++i)
      place_vertex(world, range.first_vertex + i, mesh, i, xf, tangents, lo, hi);
    // The same triangles must survive the degenerate test as when appended.
    std::size_t kept = range.first_triangle;
    const std::size_t end = std::size_t(range.first_triangle) + range.triangle_count;
    for (const auto& tri : mesh.triangles) {
      if (tri[0] >= nv || tri[1] >= nv || tri[2] >= nv) return false;
      if (degenerate(world, range.first_vertex, tri)) continue;
      if (kept >= end) return false;
      const std::uint32_t* w = &world.indices[3 * kept++];
      if (w[0] != range.first_vertex + tri[0] || w[1] != range.first_vertex + tri[1] ||
          w[2] != range.first_vertex + tri[2])
        return false;
    }
    if (kept != end) return false;
    if (nv > 0) {
      const auto [box, tight] = spheres(world, range.first_vertex, nv, lo, hi);
      world.bounds[sphere] = box;
      world.tight_bounds[sphere] = tight;
      ++sphere;
    }
  }
  return true;
}

SurfaceReflectance reflectance_at(const WorldObjects& world, std::uint32_t prim, float u, float v) {
  const ShadingMaterial& m = world.materials[world.triangle_material[prim]];
  SurfaceReflectance r;
  if (m.material) {
    r.diffuse_albedo = m.material->diffuse_albedo;
    r.f0 = {m.material->specular_albedo, m.material->specular_albedo, m.material->specular_albedo};
    r.roughness = m.material->roughness;
    return r;
  }
  Rgb base = m.base_color;
  float metallic = m.metallic, roughness = m.roughness;
  if (m.base_color_texture || m.metallic_roughness_texture) {
    const std::uint32_t* tri = &world.indices[3 * std::size_t(prim)];
    float uv[2];
    for (int k = 0; k < 2; ++k)
      uv[k] = (1 - u - v) * world.uvs[2 * std::size_t(tri[0]) + k] +
              u * world.uvs[2 * std::size_t(tri[1]) + k] +
              v * world.uvs[2 * std::size_t(tri[2]) + k];
    if (m.base_color_texture) {
      float t[3];
      sample_bilinear(*m.base_color_texture, uv[0], uv[1], 3, t);
      for (int c = 0; c < 3; ++c) base[c] *= std::clamp(t[c], 0.0f, 1.0f);
    }
    if (m.metallic_roughness_texture) {
      float t[3];
      sample_bilinear(*m.metallic_roughness_texture, uv[0], uv[1], 3, t);
      roughness *= std::clamp(t[1], 0.0f, 1.0f);
      metallic *= std::clamp(t[2], 0.0f, 1.0f);
    }
  }
  // glTF 2.0's metallic-roughness model: dielectrics reflect 4 % at normal incidence and the
  // rest diffusely with the base colour; metals reflect specularly with the base colour as F0.
  for (int c = 0; c < 3; ++c) {
    r.diffuse_albedo[c] = base[c] * (1 - metallic);
    r.f0[c] = 0.04f * (1 - metallic) + base[c] * metallic;
  }
  r.roughness = roughness;
  return r;
}

Vec3f normal_mapped(const WorldObjects& world, std::uint32_t prim, float u, float v,
                    const Vec3f& n) {
  const ShadingMaterial& m = world.materials[world.triangle_material[prim]];
  if (!m.normal_texture || world.tangents.empty()) return n;
  const std::uint32_t* tri = &world.indices[3 * std::size_t(prim)];
  const float bw[3] = {1 - u - v, u, v};
  float uv[2] = {0, 0};
  Vec3f t{0, 0, 0};
  for (int k = 0; k < 3; ++k) {
    for (int c = 0; c < 2; ++c) uv[c] += bw[k] * world.uvs[2 * std::size_t(tri[k]) + c];
    for (int c = 0; c < 3; ++c) t[c] += bw[k] * world.tangents[4 * std::size_t(tri[k]) + c];
  }
  // Gram-Schmidt against n: interpolated tangents are neither unit nor orthogonal to the
  // interpolated normal.
  const float tn = dot(t, n);
  t = unit(Vec3f{t[0] - tn * n[0], t[1] - tn * n[1], t[2] - tn * n[2]});
  if (dot(t, t) < 0.5f) return n;  // no tangent here (a vertex without a frame)
  const float w = world.tangents[4 * std::size_t(tri[0]) + 3];
  const Vec3f b0 = cross(n, t);
  const Vec3f b = {w * b0[0], w * b0[1], w * b0[2]};
  float s[3];
  sample_bilinear(*m.normal_texture, uv[0], uv[1], 3, s);
  const float x = 2 * s[0] - 1, y = 2 * s[1] - 1, z = 2 * s[2] - 1;
  const Vec3f mapped = unit(Vec3f{x * t[0] + y * b[0] + z * n[0], x * t[1] + y * b[1] + z * n[1],
                                  x * t[2] + y * b[2] + z * n[2]});
  if (!(dot(mapped, mapped) > 0.5f)) return n;  // a zero or non-finite texel
  return mapped;
}

ObjectScene::ObjectScene(const WorldObjects& world, bool fast_build, bool refittable)
    : world_(world) {
  if (world.triangle_count() == 0) return;
  device_ = rtcNewDevice(embree_device_config());
  if (!device_) throw Error(ErrorCode::internal, "Embree: cannot create a device for the objects");
  rtcSetDeviceErrorFunction(device_, &embree_error, nullptr);
  scene_ = rtcNewScene(device_);
  // Embree honours a geometry's REFIT quality only in its two-level scenes (scene quality LOW),
  // and only refits (instead of building again) in a DYNAMIC scene: measured on the bench's
  // 100k-triangle sphere, 24 ms CPU per move without the flag, 1 ms with it.
  rtcSetSceneBuildQuality(
      scene_, fast_build || refittable ? RTC_BUILD_QUALITY_LOW : RTC_BUILD_QUALITY_MEDIUM);
  rtcSetSceneFlags(
      scene_, refittable ? RTC_SCENE_FLAG_ROBUST | RTC_SCENE_FLAG_DYNAMIC : RTC_SCENE_FLAG_ROBUST);
  RTCGeometry geometry = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_TRIANGLE);
  if (refittable) rtcSetGeometryBuildQuality(geometry, RTC_BUILD_QUALITY_REFIT);
  rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                             world.positions.data(), 0, 3 * sizeof(float), world.vertex_count());
  rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                             world.indices.data(), 0, 3 * sizeof(std::uint32_t),
                             world.triangle_count());
  rtcCommitGeometry(geometry);
  rtcAttachGeometry(scene_, geometry);
  if (refittable) {
    geometry_ = geometry;  // the scene holds it too; released in the destructor
    positions_ = world.positions.data();
    vertex_count_ = world.vertex_count();
  } else {
    rtcReleaseGeometry(geometry);
  }
  rtcCommitScene(scene_);
  const RTCError error = rtcGetDeviceError(device_);
  if (error != RTC_ERROR_NONE) {
    if (geometry_) rtcReleaseGeometry(geometry_);
    rtcReleaseScene(scene_);
    rtcReleaseDevice(device_);
    throw Error(ErrorCode::internal, "Embree: building the objects' scene failed (error " +
                                         std::to_string(int(error)) + ")");
  }
}

void ObjectScene::refit() {
  if (!scene_) return;  // an empty world: nothing to move
  if (!geometry_)
    throw Error(ErrorCode::internal, "Embree: the objects' scene was not built refittable");
  if (world_.positions.data() != positions_ || world_.vertex_count() != vertex_count_)
    throw Error(ErrorCode::internal, "Embree: the objects' vertex buffer changed under a refit");
  rtcUpdateGeometryBuffer(geometry_, RTC_BUFFER_TYPE_VERTEX, 0);
  rtcCommitGeometry(geometry_);
  rtcCommitScene(scene_);
  const RTCError error = rtcGetDeviceError(device_);
  if (error != RTC_ERROR_NONE)
    throw Error(ErrorCode::internal, "Embree: refitting the objects' scene failed (error " +
                                         std::to_string(int(error)) + ")");
}

ObjectScene::~ObjectScene() {
  if (geometry_) rtcReleaseGeometry(geometry_);
  if (scene_) rtcReleaseScene(scene_);
  if (device_) rtcReleaseDevice(device_);
}

ObjectHit ObjectScene::intersect(const Vec3f& origin, const Vec3f& direction, float t_near,
                                 float t_far) const {
  ObjectHit hit;
  if (!scene_) return hit;
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRayHit rh{};
  rh.ray.org_x = origin[0];
  rh.ray.org_y = origin[1];
  rh.ray.org_z = origin[2];
  rh.ray.dir_x = direction[0];
  rh.ray.dir_y = direction[1];
  rh.ray.dir_z = direction[2];
  rh.ray.tnear = t_near;
  rh.ray.tfar = t_far;
  rh.ray.mask = 0xFFFFFFFFu;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(scene_, &context, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return hit;
  hit.t = rh.ray.tfar;
  hit.prim = rh.hit.primID;
  hit.u = rh.hit.u;
  hit.v = rh.hit.v;
  return hit;
}

void ObjectScene::occluded(std::span<const ShadowRay> rays, bool* blocked) const {
  if (!scene_) {
    std::fill(blocked, blocked + rays.size(), false);
    return;
  }
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  for (std::size_t i = 0; i < rays.size(); ++i) {
    RTCRay r{};
    r.org_x = rays[i].origin[0];
    r.org_y = rays[i].origin[1];
    r.org_z = rays[i].origin[2];
    r.dir_x = rays[i].direction[0];
    r.dir_y = rays[i].direction[1];
    r.dir_z = rays[i].direction[2];
    r.tnear = rays[i].t_near;
    r.tfar = rays[i].t_far;
    r.mask = 0xFFFFFFFFu;
    rtcOccluded1(scene_, &context, &r);
    blocked[i] = r.tfar < 0;  // Embree sets tfar = -inf for an occluded ray
  }
}

}  // namespace mr::render::insertion
