// The built-in primitives of inserted objects (mr/objects.h): sphere, box, plane, cylinder, for
// tests and quick use. Every one stands on y = 0, centred on the Y axis, in metres.
//
// Seams: vertices are duplicated where the UVs jump (the sphere's and cylinder's u = 0 / 1 seam,
// the poles, the box's and cylinder's creases), but a duplicate's position is computed from the
// same integer index as its twin (angle of j % segments), so the copies are bit-identical and the
// mesh welded by position is watertight.
#include <cmath>
#include <numbers>
#include <string>
#include <vector>

#include "mr/error.h"
#include "mr/objects.h"

namespace mr {

namespace {

constexpr int kDefaultSegments = 64;
constexpr int kMaxSegments = 4096;  // 16 M triangles for the sphere; more is a mistake

using V3 = std::array<float, 3>;
using V2 = std::array<float, 2>;

struct Builder {
  ObjectMesh& mesh;
  std::uint32_t vertex(V3 p, V3 n, V2 uv) {
    mesh.positions.push_back(p);
    mesh.normals.push_back(n);
    mesh.uvs.push_back(uv);
    return static_cast<std::uint32_t>(mesh.positions.size() - 1);
  }
  void triangle(std::uint32_t a, std::uint32_t b, std::uint32_t c) {
    mesh.triangles.push_back({a, b, c});
  }
  // Quad a-b-c-d, counter-clockwise seen from the front.
  void quad(std::uint32_t a, std::uint32_t b, std::uint32_t c, std::uint32_t d) {
    triangle(a, b, c);
    triangle(a, c, d);
  }
};

// Angle of segment j of n around +Y; j % n so that the seam's copy equals the first exactly.
// The angle grows from +Z toward +X (as yaw does): p(j) = (r sin a, y, r cos a).
double ring_angle(int j, int n) {
  return 2.0 * std::numbers::pi * double(j % n) / double(n);
}

void make_sphere(Builder& b, int segments) {
  const int rings = std::max(2, segments / 2);
  const double r = 0.5;
  // Rows k = 0 (north pole, y = 1) .. rings (south pole, y = 0); v = k / rings.
  std::vector<std::vector<std::uint32_t>> row(static_cast<std::size_t>(rings) + 1);
  for (int k = 0; k <= rings; ++k) {
    const double theta = std::numbers::pi * double(k) / double(rings);  // from +Y
    const double st = (k == 0 || k == rings) ? 0.0 : std::sin(theta);
    const double ct = k == 0 ? 1.0 : k == rings ? -1.0 : std::cos(theta);
    const int count = (k == 0 || k == rings) ? segments : segments + 1;
    for (int j = 0; j < count; ++j) {
      const double a = ring_angle(j, segments);
      const double nx = st * std::sin(a), ny = ct, nz = st * std::cos(a);
      // Poles: one vertex per segment, u at the segment's middle (the texture's pinch point).
      const double u = (k == 0 || k == rings) ? (j + 0.5) / segments : double(j) / segments;
      row[std::size_t(k)].push_back(
          b.vertex({float(r * nx), float(r + r * ny), float(r * nz)},
                   {float(nx), float(ny), float(nz)}, {float(u), float(double(k) / rings)}));
    }
  }
  // Orientation: at a = 0 on the equator, (k, j) -> (k+1, j) -> (k+1, j+1) has edges (0, -h, 0)
  // and (d, -h, 0), whose cross product is (0, 0, h d): +Z, outward. Quads run top j, bottom j,
  // bottom j+1, top j+1; at the poles the pole's row stands for both of its corners.
  for (int k = 0; k < rings; ++k) {
    const auto& top = row[std::size_t(k)];
    const auto& bottom = row[std::size_t(k) + 1];
    for (std::size_t j = 0; j < std::size_t(segments); ++j) {
      if (k == 0) {
        b.triangle(top[j], bottom[j], bottom[j + 1]);
      } else if (k == rings - 1) {
        b.triangle(top[j], bottom[j], top[j + 1]);
      } else {
        b.quad(top[j], bottom[j], bottom[j + 1], top[j + 1]);
      }
    }
  }
}

void make_box(Builder& b) {
  // Each face: its outward normal n and two in-plane axes s, t with cross(s, t) = n, so that
  // corners c + (-s - t), (+s - t), (+s + t), (-s + t) run counter-clockwise seen from outside.
  struct Face {
    V3 n, s, t;
  };
  const Face faces[6] = {
      {{1, 0, 0}, {0, 0, -1}, {0, 1, 0}},  {{-1, 0, 0}, {0, 0, 1}, {0, 1, 0}},
      {{0, 1, 0}, {1, 0, 0}, {0, 0, -1}},  {{0, -1, 0}, {1, 0, 0}, {0, 0, 1}},
      {{0, 0, 1}, {1, 0, 0}, {0, 1, 0}},   {{0, 0, -1}, {-1, 0, 0}, {0, 1, 0}},
  };
  for (const Face& f : faces) {
    std::uint32_t idx[4];
    const float ss[4] = {-1, 1, 1, -1}, ts[4] = {-1, -1, 1, 1};
    for (int c = 0; c < 4; ++c) {
      V3 p;
      for (int i = 0; i < 3; ++i) p[i] = 0.5f * (f.n[i] + ss[c] * f.s[i] + ts[c] * f.t[i]);
      p[1] += 0.5f;  // the cube stands on y = 0
      // u along s, v along -t (v down, glTF).
      idx[c] = b.vertex(p, f.n, {0.5f * (ss[c] + 1), 0.5f * (1 - ts[c])});
    }
    b.quad(idx[0], idx[1], idx[2], idx[3]);
  }
}

void make_plane(Builder& b) {
  // Seen from +Y with +X right and -Z up, corners counter-clockwise: (-,+) (+,+) (+,-) (-,-).
  const V3 n{0, 1, 0};
  const std::uint32_t a = b.vertex({-0.5f, 0, 0.5f}, n, {0, 1});
  const std::uint32_t c = b.vertex({0.5f, 0, 0.5f}, n, {1, 1});
  const std::uint32_t d = b.vertex({0.5f, 0, -0.5f}, n, {1, 0});
  const std::uint32_t e = b.vertex({-0.5f, 0, -0.5f}, n, {0, 0});
  b.quad(a, c, d, e);
}

void make_cylinder(Builder& b, int segments) {
  const double r = 0.5;
  std::vector<std::uint32_t> side_top, side_bottom;
  for (int j = 0; j <= segments; ++j) {
    const double a = ring_angle(j, segments);
    const float x = float(r * std::sin(a)), z = float(r * std::cos(a));
    const V3 n{float(std::sin(a)), 0, float(std::cos(a))};
    const float u = float(double(j) / segments);
    side_top.push_back(b.vertex({x, 1, z}, n, {u, 0}));
    side_bottom.push_back(b.vertex({x, 0, z}, n, {u, 1}));
  }
  // As for the sphere: top j, bottom j, bottom j+1, top j+1 faces outward.
  for (std::size_t j = 0; j < std::size_t(segments); ++j)
    b.quad(side_top[j], side_bottom[j], side_bottom[j + 1], side_top[j + 1]);
  // Caps: a centre and a ring each, with flat normals; UVs map the disk into the unit square.
  for (int cap = 0; cap < 2; ++cap) {
    const float y = cap == 0 ? 1.0f : 0.0f;
    const V3 n{0, cap == 0 ? 1.0f : -1.0f, 0};
    const std::uint32_t centre = b.vertex({0, y, 0}, n, {0.5f, 0.5f});
    std::vector<std::uint32_t> ring;
    for (int j = 0; j < segments; ++j) {
      const double a = ring_angle(j, segments);
      const float x = float(r * std::sin(a)), z = float(r * std::cos(a));
      ring.push_back(b.vertex({x, y, z}, n, {0.5f + x, 0.5f - z}));
    }
    for (std::size_t j = 0; j < std::size_t(segments); ++j) {
      const std::uint32_t p = ring[j], q = ring[(j + 1) % std::size_t(segments)];
      // cross(p - centre, q - centre) at a = 0 is (0, r^2 sin(da), 0): +Y, so the top cap takes
      // (centre, p, q) and the bottom cap the reverse.
      if (cap == 0)
        b.triangle(centre, p, q);
      else
        b.triangle(centre, q, p);
    }
  }
}

}  // namespace

std::vector<std::string> primitive_names() {
  return {"sphere", "box", "plane", "cylinder"};
}

ObjectMesh make_primitive(const std::string& name, int segments) {
  if (segments == 0) segments = kDefaultSegments;
  if (segments < 3 || segments > kMaxSegments)
    throw Error(ErrorCode::invalid_argument,
                "primitive " + name + ": segments = " + std::to_string(segments) +
                    ": must be in 3.." + std::to_string(kMaxSegments) + " (0: 64)");
  ObjectMesh mesh;
  mesh.source = std::string(kPrimitivePrefix) + name;
  Builder b{mesh};
  if (name == "sphere") {
    make_sphere(b, segments);
  } else if (name == "box") {
    make_box(b);
  } else if (name == "plane") {
    make_plane(b);
  } else if (name == "cylinder") {
    make_cylinder(b, segments);
  } else {
    std::string known;
    for (const std::string& n : primitive_names()) known += (known.empty() ? "" : ", ") + n;
    throw Error(ErrorCode::invalid_argument,
                "unknown primitive \"" + name + "\"; the built-in primitives are: " + known);
  }
  ObjectMaterial material;
  material.name = "default";
  mesh.materials.push_back(material);
  mesh.triangle_material.assign(mesh.triangles.size(), 0);
  compute_tangents(mesh);
  return mesh;
}

}  // namespace mr
