// Issue 16: the built-in primitives (area and volume against closed forms, watertight, unit
// outward normals) and the placement transform of inserted objects (mr/objects.h).
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <numbers>
#include <set>
#include <tuple>

#include "mr/error.h"
#include "mr/objects.h"

namespace mr {
namespace {

constexpr double kPi = std::numbers::pi;

using Key = std::tuple<float, float, float>;

// Every directed edge, with vertices welded by exact position: a closed, consistently oriented
// mesh has each edge once in each direction. Returns the number of edges that break this.
int unpaired_edges(const ObjectMesh& m) {
  std::map<Key, int> id;
  std::vector<int> weld(m.positions.size());
  for (std::size_t i = 0; i < m.positions.size(); ++i) {
    const Key k{m.positions[i][0], m.positions[i][1], m.positions[i][2]};
    weld[i] = id.emplace(k, int(id.size())).first->second;
  }
  std::map<std::pair<int, int>, int> directed;
  for (const auto& t : m.triangles)
    for (int e = 0; e < 3; ++e) ++directed[{weld[t[e]], weld[t[(e + 1) % 3]]}];
  int bad = 0;
  for (const auto& [edge, count] : directed) {
    const auto back = directed.find({edge.second, edge.first});
    if (count != 1 || back == directed.end() || back->second != 1) ++bad;
  }
  return bad;
}

struct D3 {
  double x, y, z;
};
D3 sub(const std::array<float, 3>& a, const std::array<float, 3>& b) {
  return {double(a[0]) - b[0], double(a[1]) - b[1], double(a[2]) - b[2]};
}
D3 cross(D3 a, D3 b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
double dot(D3 a, D3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
D3 v(const std::array<float, 3>& a) { return {a[0], a[1], a[2]}; }

// Normals unit; every triangle's geometric normal agrees with its vertex normals and points away
// from the (convex) primitive's centre (0, 0.5, 0); tangents unit and orthogonal to the normal.
void check_normals(const ObjectMesh& m, bool convex_closed) {
  ASSERT_EQ(m.normals.size(), m.positions.size());
  for (const auto& n : m.normals) EXPECT_NEAR(std::sqrt(dot(v(n), v(n))), 1.0, 1e-6);
  for (const auto& t : m.triangles) {
    const D3 face = cross(sub(m.positions[t[1]], m.positions[t[0]]),
                          sub(m.positions[t[2]], m.positions[t[0]]));
    for (std::uint32_t i : t) EXPECT_GT(dot(face, v(m.normals[i])), 0) << m.source;
    if (convex_closed) {
      D3 c{0, 0, 0};
      for (std::uint32_t i : t)
        c = {c.x + m.positions[i][0] / 3.0, c.y + m.positions[i][1] / 3.0 - 0.5 / 3.0,
             c.z + m.positions[i][2] / 3.0};
      EXPECT_GT(dot(face, c), 0) << m.source;
    }
  }
  ASSERT_EQ(m.tangents.size(), m.positions.size());
  for (std::size_t i = 0; i < m.tangents.size(); ++i) {
    const D3 t{m.tangents[i][0], m.tangents[i][1], m.tangents[i][2]};
    EXPECT_NEAR(std::sqrt(dot(t, t)), 1.0, 1e-5);
    EXPECT_NEAR(dot(t, v(m.normals[i])), 0.0, 1e-5);
    EXPECT_EQ(std::abs(m.tangents[i][3]), 1.0f);
  }
  for (const auto& uv : m.uvs) {
    EXPECT_GE(uv[0], 0.0f);
    EXPECT_LE(uv[0], 1.0f);
    EXPECT_GE(uv[1], 0.0f);
    EXPECT_LE(uv[1], 1.0f);
  }
}

TEST(Primitives, BoxIsTheUnitCubeOnTheGround) {
  const ObjectMesh box = make_primitive("box");
  EXPECT_NO_THROW(validate_object_mesh(box));
  EXPECT_EQ(box.triangles.size(), 12u);
  EXPECT_NEAR(mesh_area(box), 6.0, 1e-6);    // exact up to float rounding of the corners
  EXPECT_NEAR(mesh_volume(box), 1.0, 1e-6);  // positive: outward
  EXPECT_EQ(unpaired_edges(box), 0);
  check_normals(box, true);
  const Bounds3 b = mesh_bounds(box);
  EXPECT_EQ(b.min.x, -0.5);
  EXPECT_EQ(b.min.y, 0.0);
  EXPECT_EQ(b.max.y, 1.0);
  EXPECT_EQ(b.max.z, 0.5);
}

TEST(Primitives, PlaneIsOneSquareMetreFacingUp) {
  const ObjectMesh plane = make_primitive("plane");
  EXPECT_NO_THROW(validate_object_mesh(plane));
  EXPECT_NEAR(mesh_area(plane), 1.0, 1e-7);
  check_normals(plane, false);
  for (const auto& n : plane.normals) EXPECT_EQ(n, (std::array<float, 3>{0, 1, 0}));
  for (const auto& p : plane.positions) EXPECT_EQ(p[1], 0.0f);
  // Open: its 4 border edges are unpaired, its diagonal is paired.
  EXPECT_EQ(unpaired_edges(plane), 4);
}

// The n-gon prism exactly (closed form of the polygonal cylinder), and the true cylinder
// (radius 0.5, height 1: area 1.5 pi, volume pi / 4) within the polygon's O(1/n^2) error.
TEST(Primitives, CylinderMatchesItsPolygonExactlyAndTheCylinderClosely) {
  for (int n : {8, 64}) {
    const ObjectMesh cyl = make_primitive("cylinder", n);
    EXPECT_NO_THROW(validate_object_mesh(cyl));
    const double r = 0.5, h = 1.0;
    const double polygon_area = 0.5 * n * r * r * std::sin(2 * kPi / n);
    const double side = n * 2 * r * std::sin(kPi / n) * h;
    EXPECT_NEAR(mesh_area(cyl), side + 2 * polygon_area, 1e-5) << n;
    EXPECT_NEAR(mesh_volume(cyl), polygon_area * h, 1e-5) << n;
    EXPECT_EQ(unpaired_edges(cyl), 0) << n;
    check_normals(cyl, true);
    // Side normals are radial: (x, 0, z) / r.
    for (std::size_t i = 0; i < cyl.positions.size(); ++i) {
      const auto& p = cyl.positions[i];
      const auto& nn = cyl.normals[i];
      if (nn[1] != 0) continue;
      EXPECT_NEAR(nn[0], p[0] / r, 1e-6);
      EXPECT_NEAR(nn[2], p[2] / r, 1e-6);
    }
  }
  // n = 64: the polygon misses the circle by (2 pi^2 / 3) / n^2 = 0.16 % in volume.
  const ObjectMesh cyl = make_primitive("cylinder");
  EXPECT_NEAR(mesh_volume(cyl) / (kPi / 4) - 1, 0.0, 2e-3);
  EXPECT_NEAR(mesh_area(cyl) / (1.5 * kPi) - 1, 0.0, 2e-3);
}

// The UV sphere (64 segments, 32 rings) against 4 pi r^2 and 4/3 pi r^3: inscribed, so below
// them, by a second-order error; doubling the segments divides the error by 4 (+-12 %).
TEST(Primitives, SphereConvergesToTheSphereAtSecondOrder) {
  const double r = 0.5;
  const double area = 4 * kPi * r * r, volume = 4.0 / 3.0 * kPi * r * r * r;
  const ObjectMesh s64 = make_primitive("sphere");
  const ObjectMesh s128 = make_primitive("sphere", 128);
  for (const ObjectMesh* s : {&s64, &s128}) {
    EXPECT_NO_THROW(validate_object_mesh(*s));
    EXPECT_EQ(unpaired_edges(*s), 0);
    check_normals(*s, true);
    // Vertex normals are radial and vertices lie on the sphere.
    for (std::size_t i = 0; i < s->positions.size(); ++i) {
      const D3 d{s->positions[i][0], s->positions[i][1] - r, s->positions[i][2]};
      EXPECT_NEAR(std::sqrt(dot(d, d)), r, 1e-6);
      EXPECT_NEAR(d.x / r, s->normals[i][0], 1e-6);
      EXPECT_NEAR(d.y / r, s->normals[i][1], 1e-6);
      EXPECT_NEAR(d.z / r, s->normals[i][2], 1e-6);
    }
  }
  const double area_err64 = 1 - mesh_area(s64) / area, area_err128 = 1 - mesh_area(s128) / area;
  const double vol_err64 = 1 - mesh_volume(s64) / volume;
  const double vol_err128 = 1 - mesh_volume(s128) / volume;
  EXPECT_GT(area_err64, 0);
  EXPECT_LT(area_err64, 4e-3);  // 0.0020 (64 segments; 0.00050 at 128)
  EXPECT_GT(vol_err64, 0);
  EXPECT_LT(vol_err64, 6e-3);  // 0.0040 (0.0010 at 128)
  EXPECT_NEAR(area_err64 / area_err128, 4.0, 0.5);
  EXPECT_NEAR(vol_err64 / vol_err128, 4.0, 0.5);
  const Bounds3 b = mesh_bounds(s64);
  EXPECT_EQ(b.min.y, 0.0);
  EXPECT_EQ(b.max.y, 1.0);
}

TEST(Primitives, UnknownNamesAndBadSegmentsAreClearErrors) {
  try {
    make_primitive("teapot");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::invalid_argument);
    EXPECT_NE(std::string(e.what()).find("teapot"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("sphere, box, plane, cylinder"), std::string::npos);
  }
  EXPECT_THROW(make_primitive("sphere", 2), Error);
  EXPECT_THROW(make_primitive("sphere", 100000), Error);
}

// The placement: scale, yaw (+Z toward +X), tilt (+Y -> up), then the position.
TEST(Placement, MatrixFollowsTheDocumentedOrder) {
  ObjectPlacement p;
  p.position_m = {1, 2, 3};
  p.yaw_deg = 90;
  p.scale = 2;
  Mat4 m = placement_matrix(p);
  auto apply = [](const Mat4& m, double x, double y, double z) {
    return D3{m[0] * x + m[1] * y + m[2] * z + m[3], m[4] * x + m[5] * y + m[6] * z + m[7],
              m[8] * x + m[9] * y + m[10] * z + m[11]};
  };
  D3 q = apply(m, 0, 0, 1);  // +Z turned to +X, doubled, moved
  EXPECT_NEAR(q.x, 3, 1e-12);
  EXPECT_NEAR(q.y, 2, 1e-12);
  EXPECT_NEAR(q.z, 3, 1e-12);
  EXPECT_EQ(m[12], 0);
  EXPECT_EQ(m[15], 1);

  // Tilt: up = +X takes the object's +Y to +X; up = -Y turns it upside down.
  ObjectPlacement t;
  t.position_m = {0, 0, 0};
  t.up = {2, 0, 0};  // normalised
  m = placement_matrix(t);
  q = apply(m, 0, 1, 0);
  EXPECT_NEAR(q.x, 1, 1e-12);
  EXPECT_NEAR(q.y, 0, 1e-12);
  EXPECT_NEAR(q.z, 0, 1e-12);
  t.up = {0, -1, 0};
  m = placement_matrix(t);
  q = apply(m, 0, 1, 0);
  EXPECT_NEAR(q.y, -1, 1e-12);
  // Any tilt: the rotation part is orthonormal with determinant +1.
  t.up = {0.3, 0.8, -0.5};
  t.yaw_deg = 37;
  m = placement_matrix(t);
  const double det = m[0] * (m[5] * m[10] - m[6] * m[9]) - m[1] * (m[4] * m[10] - m[6] * m[8]) +
                     m[2] * (m[4] * m[9] - m[5] * m[8]);
  EXPECT_NEAR(det, 1.0, 1e-12);
  const double len = std::sqrt(0.09 + 0.64 + 0.25);
  q = apply(m, 0, 1, 0);
  EXPECT_NEAR(q.x, 0.3 / len, 1e-12);
  EXPECT_NEAR(q.y, 0.8 / len, 1e-12);
  EXPECT_NEAR(q.z, -0.5 / len, 1e-12);
}

TEST(Placement, PlacedBoxHasScaledVolumeAndExactWorldBounds) {
  const ObjectMesh box = make_primitive("box");
  ObjectPlacement p;
  p.position_m = {1, 0, 5};
  p.scale = 2;
  p.yaw_deg = 45;
  const ObjectMesh placed = apply_placement(box, p);
  EXPECT_NEAR(mesh_volume(placed), 8.0, 1e-4);  // scale^3, orientation kept (positive)
  check_normals(apply_placement(box, ObjectPlacement{{0, 0, 0}, {0, 1, 0}, 30, 1}), true);
  const Bounds3 b = world_bounds(box, p);
  // A 2 m cube turned by 45 degrees spans 2 sqrt(2) m across x and z.
  EXPECT_NEAR(b.min.x, 1 - std::sqrt(2.0), 1e-6);
  EXPECT_NEAR(b.max.x, 1 + std::sqrt(2.0), 1e-6);
  EXPECT_NEAR(b.min.z, 5 - std::sqrt(2.0), 1e-6);
  EXPECT_NEAR(b.min.y, 0, 1e-6);
  EXPECT_NEAR(b.max.y, 2, 1e-6);
  const Bounds3 pb = mesh_bounds(placed);
  EXPECT_NEAR(pb.max.x, b.max.x, 1e-6);
  // Normals of the placed mesh stay unit and outward from the moved centre.
  for (std::size_t i = 0; i < placed.normals.size(); ++i)
    EXPECT_NEAR(std::sqrt(dot(v(placed.normals[i]), v(placed.normals[i]))), 1.0, 1e-6);
}

TEST(Placement, BadValuesNameTheField) {
  ObjectPlacement p;
  p.scale = std::nan("");
  try {
    validate_placement(p, "objects[0].placement");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(std::string(e.what()), "objects[0].placement.scale = nan: must be finite and > 0");
  }
  p.scale = 1;
  p.up = {0, 0, 0};
  EXPECT_THROW(placement_matrix(p), Error);
  p.up = {0, 1, 0};
  p.position_m.y = INFINITY;
  EXPECT_THROW(world_bounds(make_primitive("box"), p), Error);
}

TEST(SceneObjects, ValidationNamesUnknownPrimitivesAndEmptyMeshes) {
  SceneObject o;
  o.mesh = "primitive:teapot";
  try {
    validate_scene_object(o, "objects[2]");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("objects[2].mesh = \"primitive:teapot\""),
              std::string::npos)
        << e.what();
  }
  o.mesh = "";
  EXPECT_THROW(validate_scene_object(o), Error);
  o.mesh = "primitive:cylinder";
  EXPECT_NO_THROW(validate_scene_object(o));
  o.material = Material{{2, 0, 0}, 0.04f, 0.5f};
  EXPECT_THROW(validate_scene_object(o), Error);
}

}  // namespace
}  // namespace mr
