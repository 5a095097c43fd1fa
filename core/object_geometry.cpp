// Geometry of inserted objects (mr/objects.h): placement transforms, bounds, mesh invariants,
// normals and tangents, area and volume.
#include <algorithm>
#include <charconv>
#include <cmath>
#include <numbers>
#include <string>

#include "mr/error.h"
#include "mr/objects.h"

namespace mr {

namespace {

// Shortest text that reads back as the same value ("nan", "inf" for non-finite ones), as
// scene_validate.cpp writes them: the scene JSON maps "<path> = <value>: <rule>" to a pointer.
std::string show(double v) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, r.ptr);
}

[[noreturn]] void fail(const std::string& path, const std::string& value, const std::string& rule) {
  throw Error(ErrorCode::invalid_argument, path + " = " + value + ": " + rule);
}

struct D3 {
  double x, y, z;
};
D3 operator+(D3 a, D3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
D3 operator-(D3 a, D3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
D3 operator*(double s, D3 a) { return {s * a.x, s * a.y, s * a.z}; }
double dot(D3 a, D3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
D3 cross(D3 a, D3 b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
D3 d3(const std::array<float, 3>& p) { return {p[0], p[1], p[2]}; }
std::array<float, 3> f3(D3 p) { return {float(p.x), float(p.y), float(p.z)}; }
D3 normalized(D3 v) {
  const double len = std::sqrt(dot(v, v));
  return len > 0 ? (1.0 / len) * v : D3{0, 0, 0};
}

// The 3x3 rotation R_tilt(+Y -> up) R_y(yaw), row-major, and the matrix applied to points.
struct Affine {
  double r[9];  // rotation, row-major
  double s;     // uniform scale
  D3 t;         // translation
  D3 rotate(D3 v) const {
    return {r[0] * v.x + r[1] * v.y + r[2] * v.z, r[3] * v.x + r[4] * v.y + r[5] * v.z,
            r[6] * v.x + r[7] * v.y + r[8] * v.z};
  }
  D3 point(D3 p) const { return t + s * rotate(p); }
};

Affine placement_affine(const ObjectPlacement& placement) {
  validate_placement(placement);
  const D3 up = normalized({placement.up.x, placement.up.y, placement.up.z});
  // R_y(yaw): +Z -> (sin, 0, cos), +X -> (cos, 0, -sin), as the camera's yaw turns.
  const double yaw = placement.yaw_deg * std::numbers::pi / 180.0;
  const double cy = std::cos(yaw), sy = std::sin(yaw);
  const double ry[9] = {cy, 0, sy, 0, 1, 0, -sy, 0, cy};
  // R_tilt: Rodrigues' rotation about axis k = Y x up by the angle between them,
  // R = I + [k]x + [k]x^2 / (1 + c) with k unnormalised (|k| = sin), c = Y . up.
  double rt[9];
  const double c = up.y;
  if (c < -1 + 1e-12) {
    // up = -Y: 180 degrees about +X.
    const double flip[9] = {1, 0, 0, 0, -1, 0, 0, 0, -1};
    std::copy(flip, flip + 9, rt);
  } else {
    const D3 k = cross({0, 1, 0}, up);  // (up.z, 0, -up.x)
    const double kx[9] = {0, -k.z, k.y, k.z, 0, -k.x, -k.y, k.x, 0};
    double kx2[9];
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        double sum = 0;
        for (int m = 0; m < 3; ++m) sum += kx[i * 3 + m] * kx[m * 3 + j];
        kx2[i * 3 + j] = sum;
      }
    for (int i = 0; i < 9; ++i) rt[i] = (i % 4 == 0 ? 1.0 : 0.0) + kx[i] + kx2[i] / (1 + c);
  }
  Affine a{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      double sum = 0;
      for (int m = 0; m < 3; ++m) sum += rt[i * 3 + m] * ry[m * 3 + j];
      a.r[i * 3 + j] = sum;
    }
  a.s = placement.scale;
  a.t = {placement.position_m.x, placement.position_m.y, placement.position_m.z};
  return a;
}

[[noreturn]] void mesh_fail(const ObjectMesh& mesh, const std::string& problem) {
  throw Error(ErrorCode::corrupt_input,
              (mesh.source.empty() ? std::string("<mesh>") : mesh.source) + ": " + problem);
}

bool finite3(const std::array<float, 3>& v) {
  return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
}

}  // namespace

void validate_placement(const ObjectPlacement& p, const std::string& what) {
  const Vec3& pos = p.position_m;
  if (!std::isfinite(pos.x)) fail(what + ".position_m.x", show(pos.x), "must be finite");
  if (!std::isfinite(pos.y)) fail(what + ".position_m.y", show(pos.y), "must be finite");
  if (!std::isfinite(pos.z)) fail(what + ".position_m.z", show(pos.z), "must be finite");
  const Vec3& u = p.up;
  const std::string up_value = "[" + show(u.x) + ", " + show(u.y) + ", " + show(u.z) + "]";
  if (!(std::isfinite(u.x) && std::isfinite(u.y) && std::isfinite(u.z)))
    fail(what + ".up", up_value, "must be finite");
  const double len2 = u.x * u.x + u.y * u.y + u.z * u.z;
  if (!(len2 > 0)) fail(what + ".up", up_value, "must have a non-zero length");
  if (!std::isfinite(len2)) fail(what + ".up", up_value, "is too long to normalise; use a unit vector");
  if (!std::isfinite(p.yaw_deg)) fail(what + ".yaw_deg", show(p.yaw_deg), "must be finite");
  if (!(std::isfinite(p.scale) && p.scale > 0))
    fail(what + ".scale", show(p.scale), "must be finite and > 0");
}

void validate_scene_object(const SceneObject& object, const std::string& what) {
  if (object.mesh.empty())
    fail(what + ".mesh", "\"\"", "must name a model file or \"primitive:NAME\"");
  const std::string prefix = kPrimitivePrefix;
  if (object.mesh.compare(0, prefix.size(), prefix) == 0) {
    const std::string name = object.mesh.substr(prefix.size());
    const auto names = primitive_names();
    if (std::find(names.begin(), names.end(), name) == names.end()) {
      std::string known;
      for (const std::string& n : names) known += (known.empty() ? "" : ", ") + prefix + n;
      fail(what + ".mesh", "\"" + object.mesh + "\"", "unknown primitive; known: " + known);
    }
  }
  validate_placement(object.placement, what + ".placement");
  if (object.material) validate_material(*object.material, what + ".material");
}

Mat4 placement_matrix(const ObjectPlacement& placement) {
  const Affine a = placement_affine(placement);
  return {a.s * a.r[0], a.s * a.r[1], a.s * a.r[2], a.t.x,  //
          a.s * a.r[3], a.s * a.r[4], a.s * a.r[5], a.t.y,  //
          a.s * a.r[6], a.s * a.r[7], a.s * a.r[8], a.t.z,  //
          0,            0,            0,            1};
}

ObjectMesh apply_placement(const ObjectMesh& mesh, const ObjectPlacement& placement) {
  const Affine a = placement_affine(placement);
  ObjectMesh out = mesh;
  for (auto& p : out.positions) p = f3(a.point(d3(p)));
  for (auto& n : out.normals) n = f3(normalized(a.rotate(d3(n))));
  for (auto& t : out.tangents) {
    const D3 r = normalized(a.rotate({t[0], t[1], t[2]}));
    t = {float(r.x), float(r.y), float(r.z), t[3]};
  }
  return out;
}

Bounds3 mesh_bounds(const ObjectMesh& mesh) {
  Bounds3 b;
  if (mesh.positions.empty()) return b;
  b.min = b.max = {mesh.positions[0][0], mesh.positions[0][1], mesh.positions[0][2]};
  for (const auto& p : mesh.positions) {
    b.min = {std::min(b.min.x, double(p[0])), std::min(b.min.y, double(p[1])),
             std::min(b.min.z, double(p[2]))};
    b.max = {std::max(b.max.x, double(p[0])), std::max(b.max.y, double(p[1])),
             std::max(b.max.z, double(p[2]))};
  }
  return b;
}

Bounds3 world_bounds(const ObjectMesh& mesh, const ObjectPlacement& placement) {
  const Affine a = placement_affine(placement);
  Bounds3 b;
  bool first = true;
  for (const auto& p : mesh.positions) {
    const D3 w = a.point(d3(p));
    if (first) {
      b.min = b.max = {w.x, w.y, w.z};
      first = false;
    }
    b.min = {std::min(b.min.x, w.x), std::min(b.min.y, w.y), std::min(b.min.z, w.z)};
    b.max = {std::max(b.max.x, w.x), std::max(b.max.y, w.y), std::max(b.max.z, w.z)};
  }
  return b;
}

void validate_object_mesh(const ObjectMesh& mesh) {
  const std::size_t nv = mesh.positions.size();
  if (nv == 0) mesh_fail(mesh, "the mesh has no vertices");
  if (mesh.triangles.empty()) mesh_fail(mesh, "the mesh has no triangles");
  for (std::size_t i = 0; i < nv; ++i)
    if (!finite3(mesh.positions[i]))
      mesh_fail(mesh, "vertex " + std::to_string(i) + " has a non-finite position");
  auto per_vertex = [&](std::size_t n, const char* what) {
    if (n != 0 && n != nv)
      mesh_fail(mesh, std::to_string(n) + " " + what + " for " + std::to_string(nv) +
                          " vertices (must be one per vertex, or none)");
  };
  per_vertex(mesh.normals.size(), "normals");
  per_vertex(mesh.uvs.size(), "uvs");
  per_vertex(mesh.tangents.size(), "tangents");
  for (std::size_t i = 0; i < mesh.normals.size(); ++i)
    if (!finite3(mesh.normals[i]))
      mesh_fail(mesh, "vertex " + std::to_string(i) + " has a non-finite normal");
  for (std::size_t i = 0; i < mesh.uvs.size(); ++i)
    if (!std::isfinite(mesh.uvs[i][0]) || !std::isfinite(mesh.uvs[i][1]))
      mesh_fail(mesh, "vertex " + std::to_string(i) + " has a non-finite uv");
  for (std::size_t i = 0; i < mesh.tangents.size(); ++i)
    for (float v : mesh.tangents[i])
      if (!std::isfinite(v))
        mesh_fail(mesh, "vertex " + std::to_string(i) + " has a non-finite tangent");
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t)
    for (std::uint32_t i : mesh.triangles[t])
      if (i >= nv)
        mesh_fail(mesh, "triangle " + std::to_string(t) + " uses vertex " + std::to_string(i) +
                            " of " + std::to_string(nv));
  if (mesh.materials.empty()) mesh_fail(mesh, "the mesh has no material");
  if (!mesh.triangle_material.empty() && mesh.triangle_material.size() != mesh.triangles.size())
    mesh_fail(mesh, std::to_string(mesh.triangle_material.size()) + " triangle materials for " +
                        std::to_string(mesh.triangles.size()) + " triangles");
  for (std::size_t t = 0; t < mesh.triangle_material.size(); ++t)
    if (mesh.triangle_material[t] >= mesh.materials.size())
      mesh_fail(mesh, "triangle " + std::to_string(t) + " uses material " +
                          std::to_string(mesh.triangle_material[t]) + " of " +
                          std::to_string(mesh.materials.size()));
  const int nt = static_cast<int>(mesh.textures.size());
  for (std::size_t m = 0; m < mesh.materials.size(); ++m) {
    const ObjectMaterial& mat = mesh.materials[m];
    const std::string what = "material " + std::to_string(m) + " (" + mat.name + ")";
    for (float c : mat.base_color)
      if (!(c >= 0 && c <= 1)) mesh_fail(mesh, what + ": base colour outside [0, 1]");
    if (!(mat.metallic >= 0 && mat.metallic <= 1))
      mesh_fail(mesh, what + ": metallic outside [0, 1]");
    if (!(mat.roughness >= 0 && mat.roughness <= 1))
      mesh_fail(mesh, what + ": roughness outside [0, 1]");
    for (int tex : {mat.base_color_texture, mat.metallic_roughness_texture, mat.normal_texture})
      if (tex < -1 || tex >= nt)
        mesh_fail(mesh, what + ": texture index " + std::to_string(tex) + " of " +
                            std::to_string(nt));
    if (mat.material) {
      try {
        validate_material(*mat.material, what);
      } catch (const Error& e) {
        mesh_fail(mesh, e.what());
      }
    }
  }
  for (const ObjectTexture& t : mesh.textures)
    if (t.image.empty() || (t.image.channels() != 3 && t.image.channels() != 4))
      mesh_fail(mesh, "texture " + t.source + " is empty or not RGB / RGBA");
}

void compute_vertex_normals(ObjectMesh& mesh) {
  std::vector<D3> sum(mesh.positions.size(), D3{0, 0, 0});
  for (const auto& t : mesh.triangles) {
    if (t[0] >= sum.size() || t[1] >= sum.size() || t[2] >= sum.size()) continue;
    const D3 p0 = d3(mesh.positions[t[0]]);
    // Twice the area times the unit normal: area weighting for free.
    const D3 n = cross(d3(mesh.positions[t[1]]) - p0, d3(mesh.positions[t[2]]) - p0);
    for (std::uint32_t i : t) sum[i] = sum[i] + n;
  }
  mesh.normals.resize(mesh.positions.size());
  for (std::size_t i = 0; i < sum.size(); ++i) {
    const D3 n = normalized(sum[i]);
    mesh.normals[i] = dot(n, n) > 0.5 && std::isfinite(n.x + n.y + n.z) ? f3(n)
                                                                        : std::array{0.f, 1.f, 0.f};
  }
}

void compute_tangents(ObjectMesh& mesh) {
  const std::size_t nv = mesh.positions.size();
  if (mesh.normals.size() != nv || mesh.uvs.size() != nv || nv == 0) {
    mesh.tangents.clear();
    return;
  }
  std::vector<D3> tan(nv, D3{0, 0, 0}), bitan(nv, D3{0, 0, 0});
  for (const auto& t : mesh.triangles) {
    if (t[0] >= nv || t[1] >= nv || t[2] >= nv) continue;
    const D3 p0 = d3(mesh.positions[t[0]]);
    const D3 e1 = d3(mesh.positions[t[1]]) - p0, e2 = d3(mesh.positions[t[2]]) - p0;
    const auto& w0 = mesh.uvs[t[0]];
    const double du1 = mesh.uvs[t[1]][0] - w0[0], dv1 = mesh.uvs[t[1]][1] - w0[1];
    const double du2 = mesh.uvs[t[2]][0] - w0[0], dv2 = mesh.uvs[t[2]][1] - w0[1];
    const double det = du1 * dv2 - du2 * dv1;
    if (!(std::abs(det) > 1e-20)) continue;  // degenerate UVs: no direction to give
    // dP/du and dP/dv, weighted by the triangle's area in UV space through 1/det's sign only.
    const double s = det > 0 ? 1.0 : -1.0;
    const D3 sdir = s * (dv2 * e1 - dv1 * e2);
    const D3 tdir = s * (du1 * e2 - du2 * e1);
    for (std::uint32_t i : t) {
      tan[i] = tan[i] + sdir;
      bitan[i] = bitan[i] + tdir;
    }
  }
  mesh.tangents.resize(nv);
  for (std::size_t i = 0; i < nv; ++i) {
    const D3 n = d3(mesh.normals[i]);
    D3 t = normalized(tan[i] - dot(n, tan[i]) * n);  // Gram-Schmidt against the normal
    if (!(dot(t, t) > 0.5)) {
      // No UV direction here: any unit vector orthogonal to n keeps the frame valid.
      const D3 a = std::abs(n.x) < 0.9 ? D3{1, 0, 0} : D3{0, 1, 0};
      t = normalized(cross(a, n));
    }
    // glTF: bitangent = w cross(n, t). Our uv's v grows downward in the texture while a
    // normal map's +Y (green) points up the texture, so the bitangent is -dP/dv's direction.
    const double w = dot(cross(n, t), -1.0 * bitan[i]) < 0 ? -1.0 : 1.0;
    mesh.tangents[i] = {float(t.x), float(t.y), float(t.z), float(w)};
  }
}

double mesh_area(const ObjectMesh& mesh) {
  double area = 0;
  for (const auto& t : mesh.triangles) {
    const D3 p0 = d3(mesh.positions.at(t[0]));
    area += 0.5 * std::sqrt(dot(cross(d3(mesh.positions.at(t[1])) - p0,
                                      d3(mesh.positions.at(t[2])) - p0),
                                cross(d3(mesh.positions.at(t[1])) - p0,
                                      d3(mesh.positions.at(t[2])) - p0)));
  }
  return area;
}

double mesh_volume(const ObjectMesh& mesh) {
  // Divergence theorem: V = 1/6 sum p0 . (p1 x p2) over outward-facing triangles.
  double six_v = 0;
  for (const auto& t : mesh.triangles)
    six_v += dot(d3(mesh.positions.at(t[0])),
                 cross(d3(mesh.positions.at(t[1])), d3(mesh.positions.at(t[2]))));
  return six_v / 6.0;
}

}  // namespace mr
