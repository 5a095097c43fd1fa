// The occluder mesh (render/occluder_mesh.*) and its Embree scene (render/embree_scene.*),
// checked against a synthetic depth map computed analytically: a ground plane with two boxes
// standing on it, seen from eye height, sky above the horizon.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

#include "mr/camera.h"
#include "mr/error.h"
#include "mr/image.h"
#include "mr/scene.h"
#include "render/embree_scene.h"
#include "render/math.h"
#include "render/occluder_mesh.h"

namespace mr::render {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr float kInfF = std::numeric_limits<float>::infinity();

struct Box {
  Vec3 min_m, max_m;
};

/// What a pixel's centre ray hits: distance (inf = sky), object (-1 sky, 0 ground, 1.. boxes)
/// and face (box faces 0..5 = -x, +x, -y, +y, -z, +z; ground 0), and the face's outward normal.
struct Hit {
  double distance_m = kInf;
  int object = -1;
  int face = -1;
  Vec3 normal;
  bool sky() const { return object < 0; }
};

/// The analytic scene: ground y = 0 and axis-aligned boxes standing on it.
struct Scene {
  std::vector<Box> boxes;

  Hit trace(const Vec3& o, const Vec3& w) const {
    Hit best;
    if (w.y < 0) {
      best.distance_m = -o.y / w.y;
      best.object = 0;
      best.face = 0;
      best.normal = {0, 1, 0};
    }
    for (std::size_t b = 0; b < boxes.size(); ++b) {
      const double lo[3] = {boxes[b].min_m.x, boxes[b].min_m.y, boxes[b].min_m.z};
      const double hi[3] = {boxes[b].max_m.x, boxes[b].max_m.y, boxes[b].max_m.z};
      const double oo[3] = {o.x, o.y, o.z}, ww[3] = {w.x, w.y, w.z};
      double t_enter = -kInf, t_exit = kInf;
      int enter_face = -1;
      for (int a = 0; a < 3; ++a) {
        if (ww[a] == 0) {
          if (oo[a] < lo[a] || oo[a] > hi[a]) t_enter = kInf;
          continue;
        }
        double t0 = (lo[a] - oo[a]) / ww[a], t1 = (hi[a] - oo[a]) / ww[a];
        int f0 = 2 * a, f1 = 2 * a + 1;
        if (t0 > t1) std::swap(t0, t1), std::swap(f0, f1);
        if (t0 > t_enter) t_enter = t0, enter_face = f0;
        t_exit = std::min(t_exit, t1);
      }
      if (t_enter <= t_exit && t_enter > 0 && t_enter < best.distance_m) {
        best.distance_m = t_enter;
        best.object = int(b) + 1;
        best.face = enter_face;
        const double s = (enter_face % 2) ? 1.0 : -1.0;
        best.normal = {enter_face / 2 == 0 ? s : 0, enter_face / 2 == 1 ? s : 0,
                       enter_face / 2 == 2 ? s : 0};
      }
    }
    return best;
  }
};

/// A depth map rendered from the analytic scene, with what each pixel hit.
struct Rendered {
  Camera camera;
  CameraPose pose;
  Image distance_m;
  std::vector<Hit> hits;
  const Hit& hit(int x, int y) const { return hits[std::size_t(y) * camera.width + x]; }
};

Rendered render(const Scene& scene, const Camera& camera, const CameraPose& pose) {
  Rendered r{camera, pose, Image(camera.width, camera.height, 1), {}};
  r.hits.resize(std::size_t(camera.width) * camera.height);
  for (int y = 0; y < camera.height; ++y)
    for (int x = 0; x < camera.width; ++x) {
      const Hit h = scene.trace(pose.position_m, pose.ray_direction(camera, x, y));
      r.hits[std::size_t(y) * camera.width + x] = h;
      r.distance_m.at(x, y, 0) = float(h.distance_m);
    }
  return r;
}

/// 160x120, 60 degrees across, eye height 1.6 m pitched down 10 degrees: a low box (roof seen
/// from above) at 4-5.5 m on the left, a tall pillar (top against the sky) at 7-8 m on the right.
Rendered make_box_scene() {
  Scene scene;
  scene.boxes.push_back({{-2.0, 0.0, 4.0}, {-0.8, 1.0, 5.5}});
  scene.boxes.push_back({{0.8, 0.0, 7.0}, {1.6, 2.5, 8.0}});
  CameraPose pose;
  pose.position_m = {0, 1.6, 0};
  pose.pitch_deg = -10;
  return render(scene, Camera::from_horizontal_fov(160, 120, 60), pose);
}

constexpr double kRatio = MeshOptions{}.discontinuity_ratio;

double relative_gap(double a, double b) {
  return std::abs(a - b) / std::min(a, b);
}

bool same_face(const Hit& p, const Hit& q) {
  return !p.sky() && p.object == q.object && p.face == q.face;
}

/// Whether the mesh must join neighbours p = (x, y) and q = (x + dx, y + dy): whenever their
/// distances are within the ratio (MeshOptions: one surface, e.g. a box's crease or its foot on
/// the ground); and on one face seen at any angle, provided the face is at least 4 pixels across
/// there (p's and q's far neighbours on it too). A face only 2-3 pixels across, seen so nearly
/// edge-on that neighbours differ by more than the ratio, cannot be told from a step in depth
/// with local information; either is allowed there. Every other pair is a discontinuity.
bool must_join(const Rendered& r, int x, int y, int dx, int dy) {
  const Hit &p = r.hit(x, y), &q = r.hit(x + dx, y + dy);
  if (p.sky() || q.sky()) return false;
  if (relative_gap(p.distance_m, q.distance_m) <= kRatio) return true;
  const int bx = x - dx, by = y - dy, fx = x + 2 * dx, fy = y + 2 * dy;
  return same_face(p, q) && bx >= 0 && by >= 0 && bx < r.camera.width && by < r.camera.height &&
         fx >= 0 && fy >= 0 && fx < r.camera.width && fy < r.camera.height &&
         same_face(p, r.hit(bx, by)) && same_face(p, r.hit(fx, fy));
}
/// Neighbours that the mesh must keep apart: different objects whose distances differ by more
/// than twice the ratio (silhouettes). Pairs in between (a box's foot on the ground) may go
/// either way.
bool must_split(const Hit& p, const Hit& q) {
  return !p.sky() && !q.sky() && p.object != q.object &&
         relative_gap(p.distance_m, q.distance_m) > 2 * kRatio;
}

std::uint64_t edge_key(std::uint32_t a, std::uint32_t b) {
  return a < b ? (std::uint64_t(a) << 32 | b) : (std::uint64_t(b) << 32 | a);
}

/// The four corner vertices of each surface pixel, and its own vertex m if it is fanned (else
/// ~0u), from the documented triangle layout: for the k-th of the N surface pixels, triangle
/// 2k = (a, c11, c01), 2k+1 = (a, c10, c11) with a = c00, or a = m for the f-th fanned pixel,
/// whose other triangles are 2N + 2f = (m, c00, c10) and 2N + 2f + 1 = (m, c01, c00).
struct PixelCorners {
  std::uint32_t c00, c10, c01, c11;
  std::uint32_t m = ~0u;
  /// The pixel's triangles, 2 or 4 (fanned), as vertex triples.
  std::vector<std::array<std::uint32_t, 3>> triangles() const {
    if (m == ~0u) return {{c00, c11, c01}, {c00, c10, c11}};
    return {{m, c11, c01}, {m, c10, c11}, {m, c00, c10}, {m, c01, c00}};
  }
};
std::size_t surface_pixel_count(const Rendered& r) {
  std::size_t n = 0;
  for (const Hit& h : r.hits) n += h.sky() ? 0 : 1;
  return n;
}
/// F, the number of fanned pixels (2 extra surface triangles each).
std::size_t fanned_pixel_count(const TriangleMesh& mesh, const Rendered& r) {
  const std::size_t n = surface_pixel_count(r);
  EXPECT_GE(mesh.surface_triangle_count, 2 * n);
  EXPECT_EQ(mesh.surface_triangle_count % 2, 0u);
  return (mesh.surface_triangle_count - 2 * n) / 2;
}
std::vector<PixelCorners> corners_by_pixel(const TriangleMesh& mesh, const Rendered& r) {
  std::vector<PixelCorners> corners(r.hits.size(), PixelCorners{~0u, ~0u, ~0u, ~0u});
  const std::size_t n = surface_pixel_count(r), fans = fanned_pixel_count(mesh, r);
  // A fanned pixel's vertex m comes after all corner vertices (indices >= the first fan
  // triangle's m), and is used by no other pixel.
  const std::uint32_t first_m = fans ? mesh.indices[3 * 2 * n] : ~0u;
  std::size_t k = 0, f = 0;
  for (std::size_t i = 0; i < r.hits.size(); ++i) {
    if (r.hits[i].sky()) continue;
    const std::uint32_t* t = &mesh.indices[6 * k];
    EXPECT_EQ(t[3], t[0]);
    EXPECT_EQ(t[5], t[1]);
    if (t[0] >= first_m && f < fans) {
      const std::uint32_t* e = &mesh.indices[3 * (2 * n + 2 * f)];
      EXPECT_EQ(e[0], t[0]);
      EXPECT_EQ(e[3], t[0]);
      EXPECT_EQ(e[2], t[4]);         // c10
      EXPECT_EQ(e[4], t[2]);         // c01
      EXPECT_EQ(e[5], e[1]);         // c00
      EXPECT_EQ(t[0], first_m + f);  // fanned pixels' vertices in pixel order
      corners[i] = {e[1], t[4], t[2], t[1], t[0]};
      ++f;
    } else {
      corners[i] = {t[0], t[4], t[2], t[1]};
    }
    ++k;
  }
  EXPECT_EQ(k, n);
  EXPECT_EQ(f, fans);
  return corners;
}

std::unordered_map<std::uint64_t, int> edge_uses(const TriangleMesh& mesh, std::size_t triangles) {
  std::unordered_map<std::uint64_t, int> uses;
  for (std::size_t t = 0; t < triangles; ++t) {
    const std::uint32_t* v = &mesh.indices[3 * t];
    ++uses[edge_key(v[0], v[1])];
    ++uses[edge_key(v[1], v[2])];
    ++uses[edge_key(v[2], v[0])];
  }
  return uses;
}

Vec3 vertex(const TriangleMesh& mesh, std::uint32_t v) {
  return {mesh.positions[3 * v], mesh.positions[3 * v + 1], mesh.positions[3 * v + 2]};
}
double distance_between(const Vec3& a, const Vec3& b) {
  return std::sqrt((a.x - b.x) * (a.x - b.x) + (a.y - b.y) * (a.y - b.y) +
                   (a.z - b.z) * (a.z - b.z));
}

/// Sides of a pixel: the neighbour's offset and the corner pair on that side.
struct Side {
  int dx, dy;
  std::uint32_t PixelCorners::*a;
  std::uint32_t PixelCorners::*b;
};
constexpr Side kSides[4] = {{0, -1, &PixelCorners::c00, &PixelCorners::c10},
                            {0, 1, &PixelCorners::c01, &PixelCorners::c11},
                            {-1, 0, &PixelCorners::c00, &PixelCorners::c01},
                            {1, 0, &PixelCorners::c10, &PixelCorners::c11}};
// The same edge seen from the neighbour across it (its opposite side).
constexpr int kOpposite[4] = {1, 0, 3, 2};

/// Checks watertightness of a mesh of `r`: every edge is used at most twice, and every pair of
/// neighbours that must be joined shares its common edge (both vertices), so edges used once lie
/// only on the image border, next to the sky, or on a discontinuity. Returns the number of
/// joined neighbour pairs checked.
int check_watertight(const TriangleMesh& mesh, const Rendered& r) {
  const auto corners = corners_by_pixel(mesh, r);
  const auto uses = edge_uses(mesh, mesh.surface_triangle_count);
  for (const auto& [key, count] : uses) EXPECT_LE(count, 2) << "non-manifold edge " << key;
  const int w = r.camera.width, h = r.camera.height;
  int joined = 0, bad_unshared = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const Hit& p = r.hit(x, y);
      if (p.sky()) continue;
      const PixelCorners& c = corners[std::size_t(y) * w + x];
      for (int s = 0; s < 4; ++s) {
        const int qx = x + kSides[s].dx, qy = y + kSides[s].dy;
        const std::uint32_t a = c.*kSides[s].a, b = c.*kSides[s].b;
        const int count = uses.at(edge_key(a, b));
        if (qx < 0 || qy < 0 || qx >= w || qy >= h) continue;  // image border
        const Hit& q = r.hit(qx, qy);
        if (must_join(r, x, y, kSides[s].dx, kSides[s].dy)) {
          ++joined;
          const PixelCorners& cq = corners[std::size_t(qy) * w + qx];
          const Side& o = kSides[kOpposite[s]];
          if (!(count == 2 && cq.*o.a == a && cq.*o.b == b)) {
            ++bad_unshared;
            ADD_FAILURE() << "pixels (" << x << "," << y << ") and (" << qx << "," << qy
                          << ") on object " << p.object << " at " << p.distance_m << " / "
                          << q.distance_m << " m do not share their edge";
          }
        }
        // Otherwise (sky, a discontinuity) the edge may be open: nothing to check.
      }
    }
  EXPECT_EQ(bad_unshared, 0);
  return joined;
}

// Watertight within continuous regions: every interior edge of a continuous region is used by
// exactly two triangles (exact integer check, no tolerance).
TEST(OccluderMesh, WatertightWithinContinuousRegions) {
  const Rendered r = make_box_scene();
  const TriangleMesh mesh = reconstruct_occluder_mesh(r.distance_m.view(), r.camera, r.pose);
  const std::size_t surface_pixels = surface_pixel_count(r);
  const std::size_t fans = fanned_pixel_count(mesh, r);
  ASSERT_EQ(mesh.surface_triangle_count, 2 * (surface_pixels + fans));
  ASSERT_EQ(mesh.triangle_count(), mesh.surface_triangle_count);  // no extrusions
  // Fans only at creases: a small fraction of the pixels (the mesh stays as cheap to build and
  // trace as with 2 triangles per pixel).
  EXPECT_LT(fans, surface_pixels / 20);
  RecordProperty("fanned_pixels", std::to_string(fans));
  const int joined = check_watertight(mesh, r);
  EXPECT_GT(joined, 4 * int(surface_pixels) * 9 / 10);  // the test did look at most edges
  // Continuous regions share vertices: far fewer vertices than 4 per pixel.
  EXPECT_LT(mesh.vertex_count(), surface_pixels * 11 / 10);
}

// No triangle bridges a depth discontinuity, and none lies in the sky.
TEST(OccluderMesh, NoTriangleAcrossDiscontinuityOrInSky) {
  const Rendered r = make_box_scene();
  const TriangleMesh mesh = reconstruct_occluder_mesh(r.distance_m.view(), r.camera, r.pose);
  const auto corners = corners_by_pixel(mesh, r);
  const auto uses = edge_uses(mesh, mesh.triangle_count());
  const int w = r.camera.width, h = r.camera.height;
  const Vec3 o = r.pose.position_m;
  const auto [forward, right, up] = r.pose.axes();
  int splits = 0, centroid_elsewhere = 0;
  double worst_vertex_gap = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const Hit& p = r.hit(x, y);
      if (p.sky()) continue;
      const PixelCorners& c = corners[std::size_t(y) * w + x];
      // (a) Silhouette pairs never share their common edge.
      for (int s = 0; s < 4; ++s) {
        const int qx = x + kSides[s].dx, qy = y + kSides[s].dy;
        if (qx < 0 || qy < 0 || qx >= w || qy >= h || !must_split(p, r.hit(qx, qy))) continue;
        ++splits;
        const PixelCorners& cq = corners[std::size_t(qy) * w + qx];
        const Side& op = kSides[kOpposite[s]];
        EXPECT_FALSE(cq.*op.a == c.*kSides[s].a && cq.*op.b == c.*kSides[s].b)
            << "edge shared across the discontinuity between (" << x << "," << y << ") and (" << qx
            << "," << qy << ")";
      }
      // (b) Each corner vertex lies on the pixel's own analytic face within twice the ratio:
      // shared corners average the planes of continuous neighbours only (tolerance 2 * 5 %;
      // a vertex pulled towards a background 10 % or more away would fail).
      for (const std::uint32_t v : {c.c00, c.c10, c.c01, c.c11}) {
        const Vec3 pv = vertex(mesh, v);
        const double t = distance_between(pv, o);
        const Vec3 wv{(pv.x - o.x) / t, (pv.y - o.y) / t, (pv.z - o.z) / t};
        // The pixel's face plane: n . X = n . X_p.
        const Vec3 wp = r.pose.ray_direction(r.camera, x, y);
        const Vec3 xp{o.x + p.distance_m * wp.x, o.y + p.distance_m * wp.y,
                      o.z + p.distance_m * wp.z};
        const Vec3& n = p.normal;
        const double t_face = ((xp.x - o.x) * n.x + (xp.y - o.y) * n.y + (xp.z - o.z) * n.z) /
                              (wv.x * n.x + wv.y * n.y + wv.z * n.z);
        if (!(t_face > 0)) continue;  // the corner ray misses the face's plane
        worst_vertex_gap = std::max(worst_vertex_gap, relative_gap(t, t_face));
        EXPECT_LE(relative_gap(t, t_face), 2 * kRatio)
            << "pixel (" << x << "," << y << ") object " << p.object << " face " << p.face;
      }
      // (c) All its triangles' centroids project onto this (non-sky) pixel.
      for (const auto& tri : c.triangles()) {
        Vec3 g{0, 0, 0};
        for (const std::uint32_t v : tri) {
          const Vec3 pv = vertex(mesh, v);
          g = {g.x + (pv.x - o.x) / 3, g.y + (pv.y - o.y) / 3, g.z + (pv.z - o.z) / 3};
        }
        const double z = g.x * forward.x + g.y * forward.y + g.z * forward.z;
        const double u = (g.x * right.x + g.y * right.y + g.z * right.z) / z;
        const double v = -(g.x * up.x + g.y * up.y + g.z * up.z) / z;
        const int px = int(std::floor(u * r.camera.focal_px + r.camera.cx));
        const int py = int(std::floor(v * r.camera.focal_px + r.camera.cy));
        ASSERT_TRUE(px >= 0 && py >= 0 && px < w && py < h);
        EXPECT_FALSE(r.hit(px, py).sky()) << "triangle of pixel (" << x << "," << y << ")";
        centroid_elsewhere += (px != x || py != y);
      }
    }
  EXPECT_GT(splits, 100);  // the scene does have silhouettes
  EXPECT_EQ(centroid_elsewhere, 0);
  RecordProperty("worst_vertex_gap", std::to_string(worst_vertex_gap));
  (void)uses;
}

// Tracing the mesh through every pixel centre gives back the input distance within 0.5 % of it
// (the acceptance bar) on every pixel that is not within one pixel of a real
// discontinuity (another object, or the sky), where the mesh deliberately breaks. Pixels next to
// a crease (another face joined to this one) are held to the same 0.5 %: there a pixel's two
// triangles, which follow its corners only, would miss by up to 2.2 % on faces seen nearly
// edge-on, so the mesh fans those pixels around a vertex of their own
// (MeshOptions::centre_tolerance). Creases and other pixels are reported separately.
TEST(OccluderMesh, RerenderedDepthMatchesInput) {
  const Rendered r = make_box_scene();
  const OccluderScene scene(reconstruct_occluder_mesh(r.distance_m.view(), r.camera, r.pose));
  const int w = r.camera.width, h = r.camera.height;
  const std::array<float, 3> origin{float(r.pose.position_m.x), float(r.pose.position_m.y),
                                    float(r.pose.position_m.z)};
  int checked = 0, creases = 0;
  double worst = 0, worst_crease = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const Hit& p = r.hit(x, y);
      if (p.sky()) continue;
      bool near_break = false, near_crease = false;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int qx = x + dx, qy = y + dy;
          if (qx < 0 || qy < 0 || qx >= w || qy >= h) continue;
          const Hit& q = r.hit(qx, qy);
          near_break |= q.sky() || relative_gap(p.distance_m, q.distance_m) > kRatio;
          near_crease |= !same_face(p, q);
        }
      // Steps within one face seen nearly edge-on count as breaks only across objects.
      if (near_break) {
        bool real_break = false;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int qx = x + dx, qy = y + dy;
            if (qx < 0 || qy < 0 || qx >= w || qy >= h) continue;
            const Hit& q = r.hit(qx, qy);
            real_break |= q.sky() || (q.object != p.object &&
                                      relative_gap(p.distance_m, q.distance_m) > kRatio);
          }
        if (real_break) continue;
      }
      const Vec3 wp = r.pose.ray_direction(r.camera, x, y);
      const float t = scene.intersect_distance(origin, {float(wp.x), float(wp.y), float(wp.z)},
                                               0.0f, std::numeric_limits<float>::infinity());
      const double error = std::abs(t - p.distance_m) / p.distance_m;
      (near_crease ? worst_crease : worst) = std::max(near_crease ? worst_crease : worst, error);
      ++(near_crease ? creases : checked);
      EXPECT_LE(error, 0.005) << "pixel (" << x << "," << y << ") object " << p.object << " face "
                              << p.face << ": mesh " << t << " m, input " << p.distance_m << " m";
    }
  EXPECT_GT(checked, w * h / 2);
  EXPECT_GT(creases, 100);
  RecordProperty("worst_relative_error", std::to_string(worst));
  RecordProperty("worst_relative_error_at_creases", std::to_string(worst_crease));
}

// Fanning changes nothing but the fanned pixels: with centre_tolerance = +inf no pixel is fanned
// (2 triangles per pixel), the corner vertices are bit-identical with and without fans, and the
// default fans exactly the pixels whose two triangles miss the centre by more than 0.1 % (up to
// float rounding of the traced distances: 1e-5 either side) -- next to creases, where the
// unfanned mesh misses by up to ~2 %.
TEST(OccluderMesh, FansExactlyWhereTwoTrianglesMissTheCentre) {
  const Rendered r = make_box_scene();
  MeshOptions no_fans;
  no_fans.centre_tolerance = kInf;
  const TriangleMesh plain =
      reconstruct_occluder_mesh(r.distance_m.view(), r.camera, r.pose, no_fans);
  const TriangleMesh fanned = reconstruct_occluder_mesh(r.distance_m.view(), r.camera, r.pose);
  const std::size_t n = surface_pixel_count(r);
  ASSERT_EQ(plain.surface_triangle_count, 2 * n);
  ASSERT_EQ(plain.triangle_count(), 2 * n);
  const std::size_t fans = fanned_pixel_count(fanned, r);
  ASSERT_GT(fans, 0u);
  ASSERT_EQ(fanned.vertex_count(), plain.vertex_count() + fans);
  EXPECT_TRUE(std::equal(plain.positions.begin(), plain.positions.end(), fanned.positions.begin()));
  const auto corners = corners_by_pixel(fanned, r);
  const auto plain_corners = corners_by_pixel(plain, r);
  const OccluderScene plain_scene(plain);
  const std::array<float, 3> origin{float(r.pose.position_m.x), float(r.pose.position_m.y),
                                    float(r.pose.position_m.z)};
  const double tolerance = MeshOptions{}.centre_tolerance;
  double worst_plain = 0;
  for (int y = 0; y < r.camera.height; ++y)
    for (int x = 0; x < r.camera.width; ++x) {
      const Hit& p = r.hit(x, y);
      if (p.sky()) continue;
      const PixelCorners& c = corners[std::size_t(y) * r.camera.width + x];
      const PixelCorners& pc = plain_corners[std::size_t(y) * r.camera.width + x];
      EXPECT_TRUE(c.c00 == pc.c00 && c.c10 == pc.c10 && c.c01 == pc.c01 && c.c11 == pc.c11);
      const Vec3 wp = r.pose.ray_direction(r.camera, x, y);
      const float t = plain_scene.intersect_distance(
          origin, {float(wp.x), float(wp.y), float(wp.z)}, 0.0f, kInf);
      const double error = std::abs(t - p.distance_m) / p.distance_m;
      worst_plain = std::max(worst_plain, error);
      if (c.m != ~0u) {
        EXPECT_GT(error, tolerance - 1e-5) << "pixel (" << x << "," << y << ") fanned";
      } else {
        EXPECT_LE(error, tolerance + 1e-5) << "pixel (" << x << "," << y << ") not fanned";
      }
    }
  EXPECT_GT(worst_plain, 0.005);  // without fans the acceptance bar is missed
  RecordProperty("worst_relative_error_without_fans", std::to_string(worst_plain));

  // Extrusions come after the fans, vertices and triangles alike: the surface is unchanged.
  MeshOptions thick;
  thick.thickness_m = 0.5;
  const TriangleMesh extruded =
      reconstruct_occluder_mesh(r.distance_m.view(), r.camera, r.pose, thick);
  ASSERT_EQ(extruded.surface_triangle_count, fanned.surface_triangle_count);
  ASSERT_GT(extruded.triangle_count(), fanned.triangle_count());
  ASSERT_GT(extruded.vertex_count(), fanned.vertex_count());
  EXPECT_TRUE(
      std::equal(fanned.positions.begin(), fanned.positions.end(), extruded.positions.begin()));
  EXPECT_TRUE(std::equal(fanned.indices.begin(), fanned.indices.end(), extruded.indices.begin()));
  EXPECT_NO_THROW(OccluderScene{extruded});  // every index in range
}

// A bare ground plane seen from eye height up to the horizon, where neighbouring rows differ by
// far more than the 5 % ratio, stays one surface: no open edge except at the border and the sky
// (exact check).
TEST(OccluderMesh, GrazingGroundStaysContinuous) {
  CameraPose pose;
  pose.position_m = {0, 1.6, 0};
  pose.pitch_deg = -2;
  const Rendered r = render(Scene{}, Camera::from_horizontal_fov(320, 240, 60), pose);
  // The slope-aware test is exercised: some vertical neighbours differ by more than the ratio.
  double largest_gap = 0;
  for (int y = 0; y + 1 < r.camera.height; ++y) {
    const Hit &p = r.hit(100, y), &q = r.hit(100, y + 1);
    if (!p.sky() && !q.sky())
      largest_gap = std::max(largest_gap, relative_gap(p.distance_m, q.distance_m));
  }
  EXPECT_GT(largest_gap, 4 * kRatio);
  const TriangleMesh mesh = reconstruct_occluder_mesh(r.distance_m.view(), r.camera, r.pose);
  check_watertight(mesh, r);
  // One vertex per corner: (rows + 1) x (columns + 1) for the ground's rows, plus one per fanned
  // pixel. Only the top ground row may be fanned: its upper corner rays pass above the horizon,
  // miss the ground plane and take the pixels' own distances; everywhere else a pixel's corners
  // lie on the plane and its two triangles are exact.
  std::size_t ground_rows = 0;
  int top_ground_row = -1;
  for (int y = r.camera.height - 1; y >= 0; --y)
    if (!r.hit(0, y).sky()) ++ground_rows, top_ground_row = y;
  const std::size_t fans = fanned_pixel_count(mesh, r);
  EXPECT_LE(fans, std::size_t(r.camera.width));
  EXPECT_EQ(mesh.vertex_count(), (ground_rows + 1) * (r.camera.width + 1) + fans);
  const auto corners = corners_by_pixel(mesh, r);
  for (int y = 0; y < r.camera.height; ++y)
    for (int x = 0; x < r.camera.width; ++x) {
      if (corners[std::size_t(y) * r.camera.width + x].m != ~0u) {
        EXPECT_EQ(y, top_ground_row) << "pixel (" << x << "," << y << ") fanned";
      }
    }
}

// Normals: (0, 1, 0) on the ground and the face normal on the boxes within 1e-3 per component,
// for every pixel that has two more pixels of its own face on at least one side along each axis
// (so pixels next to silhouettes and creases are included: their one-sided differences must
// pick their own face). Every normal is unit length and faces the camera; sky gets 0.
TEST(Normals, GroundAndBoxFaces) {
  const Rendered r = make_box_scene();
  const Image normals = estimate_normals(r.distance_m.view(), r.camera, r.pose);
  ASSERT_EQ(normals.channels(), 3);
  const int w = r.camera.width, h = r.camera.height;
  auto same_face = [&](const Hit& p, int x, int y) {
    if (x < 0 || y < 0 || x >= w || y >= h) return false;
    const Hit& q = r.hit(x, y);
    return q.object == p.object && q.face == p.face;
  };
  int checked = 0, box_checked = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const Hit& p = r.hit(x, y);
      const float* n = normals.pixel(x, y);
      if (p.sky()) {
        EXPECT_EQ(n[0], 0.0f);
        EXPECT_EQ(n[1], 0.0f);
        EXPECT_EQ(n[2], 0.0f);
        continue;
      }
      const Vec3 wp = r.pose.ray_direction(r.camera, x, y);
      EXPECT_NEAR(n[0] * n[0] + n[1] * n[1] + n[2] * n[2], 1.0, 1e-5);
      EXPECT_LT(n[0] * wp.x + n[1] * wp.y + n[2] * wp.z, 0.0) << "(" << x << "," << y << ")";
      const bool x_ok = (same_face(p, x - 1, y) && same_face(p, x - 2, y)) ||
                        (same_face(p, x + 1, y) && same_face(p, x + 2, y));
      const bool y_ok = (same_face(p, x, y - 1) && same_face(p, x, y - 2)) ||
                        (same_face(p, x, y + 1) && same_face(p, x, y + 2));
      if (!x_ok || !y_ok) continue;
      ++checked;
      box_checked += p.object > 0;
      EXPECT_NEAR(n[0], p.normal.x, 1e-3) << "(" << x << "," << y << ") object " << p.object;
      EXPECT_NEAR(n[1], p.normal.y, 1e-3) << "(" << x << "," << y << ") object " << p.object;
      EXPECT_NEAR(n[2], p.normal.z, 1e-3) << "(" << x << "," << y << ") object " << p.object;
    }
  EXPECT_GT(checked, w * h / 2);
  EXPECT_GT(box_checked, 300);
}

Rendered& box_scene() {
  static Rendered r = make_box_scene();
  return r;
}
const OccluderScene& box_occluders() {
  static const OccluderScene scene(reconstruct_occluder_mesh(box_scene().distance_m.view(),
                                                             box_scene().camera, box_scene().pose));
  return scene;
}

// A ray straight up from under the low box's roof hits the roof (at 0.95 m within 0.5 %); one
// from open ground does not.
TEST(Embree, OccludedUnderRoofNotOnOpenGround) {
  const OccluderScene& scene = box_occluders();
  const std::array<float, 3> up{0, 1, 0};
  EXPECT_TRUE(scene.occluded({-1.4f, 0.05f, 4.75f}, up, 0.0f, 100.0f));
  EXPECT_NEAR(scene.intersect_distance({-1.4f, 0.05f, 4.75f}, up, 0.0f, 100.0f), 0.95,
              0.95 * 0.005);
  EXPECT_FALSE(scene.occluded({0.0f, 0.01f, 3.0f}, up, 0.0f, 100.0f));
  EXPECT_TRUE(std::isinf(scene.intersect_distance({0.0f, 0.01f, 3.0f}, up, 0.0f, 100.0f)));
  // The segment ends before the roof: not occluded.
  EXPECT_FALSE(scene.occluded({-1.4f, 0.05f, 4.75f}, up, 0.0f, 0.9f));
}

// occluded8 gives exactly the answers of occluded on random rays, invalid lanes included.
TEST(Embree, Occluded8AgreesWithOccluded) {
  const OccluderScene& scene = box_occluders();
  std::mt19937 rng(12345);
  std::uniform_real_distribution<float> px(-3, 3), py(0.01f, 2.0f), pz(2, 10), dir(-1, 1),
      len(0.1f, 10);
  int occluded_count = 0, lanes = 0;
  for (int packet_index = 0; packet_index < 500; ++packet_index) {
    RayPacket8 rays;
    for (int k = 0; k < 8; ++k) {
      rays.origin_x[k] = px(rng);
      rays.origin_y[k] = py(rng);
      rays.origin_z[k] = pz(rng);
      rays.direction_x[k] = dir(rng);
      rays.direction_y[k] = dir(rng);
      rays.direction_z[k] = dir(rng);
      rays.t_near[k] = 0.0f;
      rays.t_far[k] = len(rng);
      rays.valid[k] = (rng() % 5 == 0) ? 0 : -1;
    }
    bool out[8];
    scene.occluded8(rays, out);
    for (int k = 0; k < 8; ++k) {
      const bool single =
          rays.valid[k] != 0 &&
          scene.occluded({rays.origin_x[k], rays.origin_y[k], rays.origin_z[k]},
                         {rays.direction_x[k], rays.direction_y[k], rays.direction_z[k]},
                         rays.t_near[k], rays.t_far[k]);
      EXPECT_EQ(out[k], single) << "packet " << packet_index << " lane " << k;
      occluded_count += single;
      lanes += rays.valid[k] != 0;
    }
  }
  // Both outcomes are well represented.
  EXPECT_GT(occluded_count, lanes / 10);
  EXPECT_LT(occluded_count, lanes * 9 / 10);
  RecordProperty("native_packets", scene.native_packets() ? "yes" : "no");
}

TEST(Embree, EmptyMeshOccludesNothingAndMovesKeepScenes) {
  OccluderScene empty{TriangleMesh{}};
  EXPECT_EQ(empty.triangle_count(), 0u);
  EXPECT_FALSE(empty.occluded({0, 0, 0}, {0, 1, 0}, 0, 1e30f));
  // One triangle at z = 1; moving the scene keeps it traceable.
  TriangleMesh tri;
  tri.positions = {-1, -1, 1, 1, -1, 1, 0, 1, 1};
  tri.indices = {0, 1, 2};
  OccluderScene a(std::move(tri));
  OccluderScene b(std::move(a));
  EXPECT_NEAR(b.intersect_distance({0, 0, 0}, {0, 0, 1}, 0, 10), 1.0f, 1e-6);
  empty = std::move(b);
  EXPECT_TRUE(empty.occluded({0, 0, 0}, {0, 0, 2}, 0, 1));
  EXPECT_EQ(empty.triangle_count(), 1u);
}

TEST(Embree, RejectsMalformedMesh) {
  TriangleMesh bad;
  bad.positions = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  bad.indices = {0, 1, 3};
  try {
    OccluderScene scene(bad);
    FAIL() << "expected mr::Error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::invalid_argument);
    EXPECT_NE(std::string(e.what()).find("3"), std::string::npos) << e.what();
  }
  bad.indices = {0, 1};
  EXPECT_THROW(OccluderScene{bad}, Error);
}

// Ambient occlusion: 1 exactly on open ground (nothing within 1 m; tolerance 0), clearly lower
// (< 0.7, about 0.5 expected: the wall fills most of half the hemisphere) 5 cm in front of the
// low box's 1 m wall; the same seed gives the same value.
TEST(AmbientOcclusion, OpenGroundAndFootOfWall) {
  const OccluderScene& scene = box_occluders();
  const float open = ambient_occlusion(scene, {0.0f, 0.0f, 3.0f}, {0, 1, 0}, 256, 1.0f, 7);
  EXPECT_EQ(open, 1.0f);
  const float foot = ambient_occlusion(scene, {-1.4f, 0.0f, 3.95f}, {0, 1, 0}, 256, 1.0f, 7);
  RecordProperty("ao_at_foot_of_wall", std::to_string(foot));
  EXPECT_LT(foot, 0.7f);
  EXPECT_GT(foot, 0.3f);
  EXPECT_EQ(foot, ambient_occlusion(scene, {-1.4f, 0.0f, 3.95f}, {0, 1, 0}, 256, 1.0f, 7));
  // Another seed: a different estimate of the same quantity (within 4 standard errors of a
  // 256-ray binomial estimate, 4 * 0.5 / 16 = 0.125).
  EXPECT_NEAR(foot, ambient_occlusion(scene, {-1.4f, 0.0f, 3.95f}, {0, 1, 0}, 256, 1.0f, 8), 0.125);
  EXPECT_THROW(ambient_occlusion(scene, {0, 0, 3}, {0, 1, 0}, 0, 1.0f, 7), Error);
  EXPECT_THROW(ambient_occlusion(scene, {0, 0, 3}, {0, 0, 0}, 16, 1.0f, 7), Error);
}

// ambient_occlusion keeps its ray set's local directions per thread for the last (seed, set
// size, stride) asked (speed16): whatever a thread asked before, each query gives exactly the
// value a fresh thread (nothing kept) gives. Seeds, set sizes and partial sets alternate.
TEST(AmbientOcclusion, SameValueWhateverTheThreadAskedBefore) {
  const OccluderScene& scene = box_occluders();
  struct Query {
    std::uint32_t seed;
    int rays, partial;
  };
  const std::vector<Query> queries = {{7, 256, 0}, {8, 256, 0}, {9, 256, 0}, {7, 8, 32},
                                      {8, 8, 32},  {7, 8, 0},   {8, 16, 64}, {7, 256, 0}};
  // Points at the foot of the wall and by the box's corner: partly open, so every ray counts.
  const std::vector<std::array<float, 3>> points = {
      {-1.4f, 0.0f, 3.95f}, {-0.7f, 0.0f, 3.9f}, {-1.45f, 0.3f, 3.98f}};
  auto ao = [&](const Query& q, const std::array<float, 3>& p) {
    return ambient_occlusion(scene, p, {0, 1, 0}, q.rays, 1.0f, q.seed, {0, 0, -1}, q.partial);
  };
  for (const Query& q : queries)
    for (const auto& p : points) {
      float fresh = -1;
      std::thread([&] { fresh = ao(q, p); }).join();
      EXPECT_EQ(ao(q, p), fresh) << "seed " << q.seed << ", " << q.rays << " / " << q.partial;
    }
}

// With thickness, a fronto-parallel square 5 m away (in front of a wall at 20 m) blocks a ray
// passing sideways 0.2 m behind it; without, that ray slips behind the paper-thin square.
TEST(OccluderMesh, ThicknessExtrudesSilhouettes) {
  const Camera camera = Camera::from_horizontal_fov(64, 64, 40);
  CameraPose pose;
  pose.position_m = {0, 0, 0};
  Image depth(64, 64, 1);
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) {
      const Vec3 w = pose.ray_direction(camera, x, y);
      const bool square = x >= 24 && x < 40 && y >= 24 && y < 40;
      depth.at(x, y, 0) = float((square ? 5.0 : 20.0) / w.z);  // planes z = 5 and z = 20
    }
  // Sideways ray at z = 5.2, through the square's middle (off the row boundary at y = 0), from
  // far left to far right.
  const std::array<float, 3> from{-10.0f, 0.05f, 5.2f}, along{1, 0, 0};
  const OccluderScene thin(reconstruct_occluder_mesh(depth.view(), camera, pose));
  EXPECT_FALSE(thin.occluded(from, along, 0.0f, 20.0f));
  MeshOptions thick;
  thick.thickness_m = 0.5;
  const TriangleMesh mesh = reconstruct_occluder_mesh(depth.view(), camera, pose, thick);
  // 16 x 4 silhouette edges, two triangles each, after the 2 per pixel of the surface.
  EXPECT_EQ(mesh.surface_triangle_count, 2u * 64 * 64);
  EXPECT_EQ(mesh.triangle_count(), mesh.surface_triangle_count + 2u * 16 * 4);
  const OccluderScene extruded(mesh);
  EXPECT_TRUE(extruded.occluded(from, along, 0.0f, 20.0f));
  // 0.6 m behind the square is past the extrusion.
  EXPECT_FALSE(extruded.occluded({-10.0f, 0.05f, 5.6f}, along, 0.0f, 20.0f));
}

// Bad input: one clear mr::Error naming what was wrong.
TEST(OccluderMesh, RejectsBadInput) {
  const Camera camera = Camera::from_horizontal_fov(160, 120, 60);
  const CameraPose pose;
  try {
    reconstruct_occluder_mesh(Image(100, 80, 1).view(), camera, pose);
    FAIL() << "expected mr::Error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::size_mismatch);
    EXPECT_NE(std::string(e.what()).find("100x80"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("160x120"), std::string::npos) << e.what();
  }
  try {
    estimate_normals(Image(160, 120, 3).view(), camera, pose);
    FAIL() << "expected mr::Error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::invalid_argument);
    EXPECT_NE(std::string(e.what()).find("3 channels"), std::string::npos) << e.what();
  }
  EXPECT_THROW(estimate_normals(Image(100, 80, 1).view(), camera, pose), Error);
  MeshOptions bad;
  bad.thickness_m = -1;
  EXPECT_THROW(reconstruct_occluder_mesh(Image(160, 120, 1).view(), camera, pose, bad), Error);
  bad = {};
  bad.discontinuity_ratio = 0;
  EXPECT_THROW(reconstruct_occluder_mesh(Image(160, 120, 1).view(), camera, pose, bad), Error);
  bad = {};
  bad.centre_tolerance = -1e-3;
  EXPECT_THROW(reconstruct_occluder_mesh(Image(160, 120, 1).view(), camera, pose, bad), Error);
  bad.centre_tolerance = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(reconstruct_occluder_mesh(Image(160, 120, 1).view(), camera, pose, bad), Error);
  // All-sky (and NaN / zero / negative, which mean "no surface"): an empty mesh, no error.
  Image sky(160, 120, 1);
  for (float& v : sky.pixels()) v = std::numeric_limits<float>::infinity();
  sky.at(3, 4, 0) = std::numeric_limits<float>::quiet_NaN();
  sky.at(5, 4, 0) = -1.0f;
  EXPECT_EQ(reconstruct_occluder_mesh(sky.view(), camera, pose).triangle_count(), 0u);
}

// The mesh built from the caller's normals (estimate_normals, as the CPU core's geometry cache
// passes them) is the mesh built alone, bit for bit; normals of another size are a clear error.
TEST(OccluderMesh, KnownNormalsGiveTheSameMesh) {
  const Rendered r = make_box_scene();
  const Image normals = estimate_normals(r.distance_m.view(), r.camera, r.pose);
  const TriangleMesh own = reconstruct_occluder_mesh(r.distance_m.view(), r.camera, r.pose);
  const TriangleMesh given =
      reconstruct_occluder_mesh(r.distance_m.view(), r.camera, r.pose, {}, normals.view());
  ASSERT_GT(own.triangle_count(), 0u);
  EXPECT_EQ(own.positions, given.positions);
  EXPECT_EQ(own.indices, given.indices);
  EXPECT_EQ(own.surface_triangle_count, given.surface_triangle_count);
  const Image small = Image::uninitialized(r.camera.width - 1, r.camera.height, 3);
  try {
    reconstruct_occluder_mesh(r.distance_m.view(), r.camera, r.pose, {}, small.view());
    FAIL() << "no error for normals of the wrong size";
  } catch (const mr::Error& e) {
    EXPECT_EQ(e.code(), mr::ErrorCode::size_mismatch);
    EXPECT_NE(std::string(e.what()).find("normals"), std::string::npos) << e.what();
  }
}

// The caller's normals are read row by row through the view's row stride: normals inside a
// wider image (a sub-view, rows farther apart than width * 3 floats) give the same mesh.
TEST(OccluderMesh, KnownNormalsWithARowStrideGiveTheSameMesh) {
  const Rendered r = make_box_scene();
  const Image normals = estimate_normals(r.distance_m.view(), r.camera, r.pose);
  const int w = r.camera.width, h = r.camera.height;
  Image wide(w + 7, h + 2, 3);
  for (float& v : wide.pixels()) v = std::numeric_limits<float>::quiet_NaN();  // must not be read
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) wide.at(x + 5, y + 1, c) = normals.at(x, y, c);
  const ConstImageView inside = wide.view().sub(Rect{5, 1, w, h});
  ASSERT_FALSE(inside.contiguous());
  const TriangleMesh own = reconstruct_occluder_mesh(r.distance_m.view(), r.camera, r.pose);
  const TriangleMesh given =
      reconstruct_occluder_mesh(r.distance_m.view(), r.camera, r.pose, {}, inside);
  ASSERT_GT(own.triangle_count(), 0u);
  EXPECT_EQ(own.positions, given.positions);
  EXPECT_EQ(own.indices, given.indices);
  EXPECT_EQ(own.surface_triangle_count, given.surface_triangle_count);
}

// Issue 12: the share of sliver triangles (surface_sliver_share), against every triangle
// measured here. A wall facing the camera at 10 m has none; the same wall with its pixels
// alternately 4 % farther (a checkerboard: every neighbour within the mesh's 5 % continuity) is
// a fur: each pixel is fanned round its own vertex, its triangles reach halfway to its
// neighbours' depth, 0.2 m along the view rays, 20 pixel footprints of 1 cm.
TEST(SliverShare, CountsTheFurOfJaggedDepth) {
  const Camera camera =
      Camera::from_horizontal_fov(200, 150, 2 * std::atan(100.0 / 1000) * 180 / std::numbers::pi);
  ASSERT_NEAR(camera.focal_px, 1000, 1e-6);
  const CameraPose pose;
  const Vec3d eye{pose.position_m.x, pose.position_m.y, pose.position_m.z};
  auto wall = [&](double jitter) {
    Image depth(camera.width, camera.height, 1);
    for (int y = 0; y < camera.height; ++y)
      for (int x = 0; x < camera.width; ++x) {
        const double forward = pose.ray_direction(camera, x, y).z;  // the pose looks along +z
        depth.at(x, y, 0) = float(10.0 / forward * ((x + y) % 2 ? 1 + jitter : 1));
      }
    return reconstruct_occluder_mesh(depth.view(), camera, pose, MeshOptions{});
  };
  // Every triangle, measured as the share defines it (the function counts every fourth).
  auto all_triangles = [&](const TriangleMesh& mesh) {
    std::size_t slivers = 0;
    for (std::size_t t = 0; t < mesh.surface_triangle_count; ++t) {
      Vec3d v[3];
      for (int k = 0; k < 3; ++k) {
        const float* p = &mesh.positions[3 * std::size_t(mesh.indices[3 * t + std::size_t(k)])];
        v[k] = Vec3d{p[0], p[1], p[2]};
      }
      const double longest =
          std::max({length(v[1] - v[0]), length(v[2] - v[1]), length(v[0] - v[2])});
      slivers += longest > kSliverFootprints * length(v[0] - eye) / camera.focal_px;
    }
    return double(slivers) / double(mesh.surface_triangle_count);
  };
  const TriangleMesh flat = wall(0.0), fur = wall(0.04);
  ASSERT_EQ(flat.surface_triangle_count, 2u * 200 * 150);
  ASSERT_GE(fur.surface_triangle_count, 2u * 200 * 150);  // continuous: no pixel dropped
  EXPECT_EQ(surface_sliver_share(flat, pose.position_m, 1 / camera.focal_px), 0.0);
  EXPECT_EQ(all_triangles(flat), 0.0);
  const double share = surface_sliver_share(fur, pose.position_m, 1 / camera.focal_px);
  EXPECT_GT(share, 0.5);
  EXPECT_NEAR(share, all_triangles(fur), 0.02);
  // Half the steps (2 %): the fans' triangles about 10 footprints long, few of them slivers.
  const double half = surface_sliver_share(wall(0.02), pose.position_m, 1 / camera.focal_px);
  EXPECT_LT(half, share / 10);
  EXPECT_NEAR(half, all_triangles(wall(0.02)), 0.02);
  EXPECT_EQ(surface_sliver_share(TriangleMesh{}, pose.position_m, 0.002), 0.0);
}

// Issue 12: the share of pixels where the depth zig-zags (depth_fur_share), against its
// definition evaluated here. A wall facing the camera and a ground plane reaching the horizon
// have none (on any plane the inverse camera depth is affine in the image, however slanted); the
// wall with its pixels alternately 4 % farther (a checkerboard: every neighbour within the mesh's
// 5 % continuity) zig-zags by 7.7 % of the depth, 77 pixel footprints at a 1000 px focal length;
// a 0.4 % checkerboard by 7.7 footprints, under the 16 that count. A crease (one pixel bent one
// way), a box in front of the wall (a discontinuity) and the sky are not counted.
double depth_fur_share_of(ConstImageView distance_m, const Camera& camera) {
  return depth_fur_share(distance_m, camera).share;
}

TEST(FurShare, CountsTheZigZagOfJaggedDepthOnly) {
  const Camera camera =
      Camera::from_horizontal_fov(200, 150, 2 * std::atan(100.0 / 1000) * 180 / std::numbers::pi);
  ASSERT_NEAR(camera.focal_px, 1000, 1e-6);
  CameraPose pose;
  auto forward = [&](int x, int y) { return pose.ray_direction(camera, x, y).z; };
  auto wall = [&](double jitter, int box_columns) {
    Image depth(camera.width, camera.height, 1);
    for (int y = 0; y < camera.height; ++y)
      for (int x = 0; x < camera.width; ++x) {
        const double z = x < box_columns ? 5.0 : 10.0;  // a box's face in front, then the wall
        depth.at(x, y, 0) = float(z / forward(x, y) * ((x + y) % 2 ? 1 + jitter : 1));
      }
    return depth;
  };
  EXPECT_EQ(depth_fur_share_of(wall(0, 0).view(), camera), 0.0);
  // Every second row's inner pixels are counted: rows 1, 3, ..., 147, columns 1..198.
  EXPECT_EQ(depth_fur_share(wall(0, 0).view(), camera).pixels, 74u * 198u);
  EXPECT_NEAR(depth_fur_share_of(wall(0.04, 0).view(), camera), 1.0, 1e-12);
  EXPECT_EQ(depth_fur_share_of(wall(0.004, 0).view(), camera), 0.0);
  // The box's face zig-zags too; its edge (a discontinuity) adds no pixel of its own.
  EXPECT_NEAR(depth_fur_share_of(wall(0.04, 50).view(), camera), 1.0, 1e-12);
  const double half_smooth = [&] {
    Image depth = wall(0, 100);
    for (int y = 0; y < camera.height; ++y)
      for (int x = 0; x < 100; ++x)
        if ((x + y) % 2) depth.at(x, y, 0) *= 1.04f;
    return depth_fur_share_of(depth.view(), camera);
  }();
  // The left half zig-zags (and the column at its edge, whose neighbour does): about half.
  EXPECT_NEAR(half_smooth, 0.5, 0.01);
  // A crease: a wall facing the camera, and from column 100 on a plane turning away from it
  // (inverse depth falling 2 % a pixel, continuous): the column at the fold bends by 20
  // footprints, one way only.
  Image crease(camera.width, camera.height, 1);
  for (int y = 0; y < camera.height; ++y)
    for (int x = 0; x < camera.width; ++x) {
      const double inverse_z = 0.1 - (x > 100 ? 0.002 * (x - 100) : 0.0);
      crease.at(x, y, 0) = float(1 / (inverse_z * forward(x, y)));
    }
  EXPECT_EQ(depth_fur_share_of(crease.view(), camera), 0.0);
  // The same fold every other column is a zig-zag.
  for (int y = 0; y < camera.height; ++y)
    for (int x = 0; x < camera.width; ++x) {
      const double inverse_z = 0.1 - (x % 2 ? 0.002 : 0.0);
      crease.at(x, y, 0) = float(1 / (inverse_z * forward(x, y)));
    }
  EXPECT_GT(depth_fur_share_of(crease.view(), camera), 0.95);
  // A ground plane seen from eye height, sky above the horizon, pitched down: long grazing
  // triangles, but no zig-zag.
  pose.pitch_deg = -3;
  Image ground(camera.width, camera.height, 1);
  int sky = 0;
  for (int y = 0; y < camera.height; ++y)
    for (int x = 0; x < camera.width; ++x) {
      const Vec3 w = pose.ray_direction(camera, x, y);
      ground.at(x, y, 0) = w.y < 0 ? float(-pose.position_m.y / w.y) : kInfF;
      sky += w.y >= 0;
    }
  ASSERT_GT(sky, 0);
  ASSERT_LT(sky, camera.width * camera.height);
  EXPECT_EQ(depth_fur_share_of(ground.view(), camera), 0.0);
  // Too small to have a middle pixel; all sky.
  EXPECT_EQ(depth_fur_share_of(Image(2, 2, 1).view(), Camera::from_horizontal_fov(2, 2, 60)), 0.0);
  Image all_sky(camera.width, camera.height, 1);
  for (float& v : all_sky.pixels()) v = kInfF;
  EXPECT_EQ(depth_fur_share_of(all_sky.view(), camera), 0.0);
  EXPECT_EQ(depth_fur_share(all_sky.view(), camera).pixels, 0u);
}

}  // namespace
}  // namespace mr::render
