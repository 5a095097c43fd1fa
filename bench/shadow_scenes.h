// Procedural scenes for the shadow-traversal benchmark and tests (issue 17, seed 004's kind of
// scenes): a Sponza-like atrium, a bedroom-like interior, a forest of thin occluders, plus random
// triangle soup and a watertight grid for the agreement tests. Each comes with a camera and a
// point and an area light inside it. Deterministic (fixed seeds). World metres, +Y up.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "render/occluder_mesh.h"

namespace mr::bench {

using V3 = std::array<float, 3>;

struct ShadowScene {
  std::string name;
  render::TriangleMesh mesh;
  V3 eye{}, look_at{};
  float fov_deg = 60;
  V3 point_light{};
  V3 area_light_corner{}, area_light_u{}, area_light_v{};  ///< a parallelogram
};

class MeshBuilder {
 public:
  explicit MeshBuilder(render::TriangleMesh& mesh) : mesh_(mesh) {}
  std::uint32_t vertex(const V3& p) {
    mesh_.positions.insert(mesh_.positions.end(), p.begin(), p.end());
    return std::uint32_t(mesh_.positions.size() / 3 - 1);
  }
  void triangle(std::uint32_t a, std::uint32_t b, std::uint32_t c) {
    mesh_.indices.insert(mesh_.indices.end(), {a, b, c});
  }
  /// A parallelogram corner + s u + t v split into nu x nv quads (shared vertices: watertight).
  void grid(const V3& corner, const V3& u, const V3& v, int nu, int nv) {
    const std::uint32_t base = std::uint32_t(mesh_.positions.size() / 3);
    for (int j = 0; j <= nv; ++j)
      for (int i = 0; i <= nu; ++i) {
        const float s = float(i) / float(nu), t = float(j) / float(nv);
        vertex({corner[0] + s * u[0] + t * v[0], corner[1] + s * u[1] + t * v[1],
                corner[2] + s * u[2] + t * v[2]});
      }
    for (int j = 0; j < nv; ++j)
      for (int i = 0; i < nu; ++i) {
        const std::uint32_t a = base + std::uint32_t(j * (nu + 1) + i), b = a + 1,
                            c = a + std::uint32_t(nu + 1), d = c + 1;
        triangle(a, b, d);
        triangle(a, d, c);
      }
  }
  /// An axis-aligned box, each face an n x n grid.
  void box(const V3& lo, const V3& hi, int n = 1) {
    const float dx = hi[0] - lo[0], dy = hi[1] - lo[1], dz = hi[2] - lo[2];
    grid(lo, {dx, 0, 0}, {0, dy, 0}, n, n);                    // z = lo
    grid({lo[0], lo[1], hi[2]}, {dx, 0, 0}, {0, dy, 0}, n, n);  // z = hi
    grid(lo, {0, dy, 0}, {0, 0, dz}, n, n);                    // x = lo
    grid({hi[0], lo[1], lo[2]}, {0, dy, 0}, {0, 0, dz}, n, n);  // x = hi
    grid(lo, {dx, 0, 0}, {0, 0, dz}, n, n);                    // y = lo
    grid({lo[0], hi[1], lo[2]}, {dx, 0, 0}, {0, 0, dz}, n, n);  // y = hi
  }
  /// A vertical cylinder (side only) of `segments` x `rings` quads.
  void cylinder(const V3& base, float radius, float height, int segments, int rings) {
    const std::uint32_t first = std::uint32_t(mesh_.positions.size() / 3);
    for (int j = 0; j <= rings; ++j)
      for (int i = 0; i < segments; ++i) {
        const float a = 2.0f * std::numbers::pi_v<float> * float(i) / float(segments);
        vertex({base[0] + radius * std::cos(a), base[1] + height * float(j) / float(rings),
                base[2] + radius * std::sin(a)});
      }
    for (int j = 0; j < rings; ++j)
      for (int i = 0; i < segments; ++i) {
        const std::uint32_t a = first + std::uint32_t(j * segments + i);
        const std::uint32_t b = first + std::uint32_t(j * segments + (i + 1) % segments);
        triangle(a, b, b + std::uint32_t(segments));
        triangle(a, b + std::uint32_t(segments), a + std::uint32_t(segments));
      }
  }
  /// A UV sphere.
  void sphere(const V3& c, float radius, int segments, int rings) {
    const std::uint32_t first = std::uint32_t(mesh_.positions.size() / 3);
    for (int j = 0; j <= rings; ++j) {
      const float th = std::numbers::pi_v<float> * float(j) / float(rings);
      for (int i = 0; i < segments; ++i) {
        const float ph = 2.0f * std::numbers::pi_v<float> * float(i) / float(segments);
        vertex({c[0] + radius * std::sin(th) * std::cos(ph), c[1] + radius * std::cos(th),
                c[2] + radius * std::sin(th) * std::sin(ph)});
      }
    }
    for (int j = 0; j < rings; ++j)
      for (int i = 0; i < segments; ++i) {
        const std::uint32_t a = first + std::uint32_t(j * segments + i);
        const std::uint32_t b = first + std::uint32_t(j * segments + (i + 1) % segments);
        triangle(a, b, b + std::uint32_t(segments));
        triangle(a, b + std::uint32_t(segments), a + std::uint32_t(segments));
      }
  }

 private:
  render::TriangleMesh& mesh_;
};

inline void finish(render::TriangleMesh& mesh) {
  mesh.surface_triangle_count = mesh.triangle_count();
}

/// A two-storey courtyard 40 m x 16 m with colonnades, galleries, arch lintels and hanging drapes,
/// open to the sky (about 70 k triangles; Sponza has 66 k).
inline ShadowScene atrium() {
  ShadowScene s;
  s.name = "atrium";
  MeshBuilder b(s.mesh);
  b.grid({-20, 0, -8}, {40, 0, 0}, {0, 0, 16}, 80, 32);  // floor
  b.box({-21, 0, -9}, {-20, 14, 9}, 8);                   // end walls
  b.box({20, 0, -9}, {21, 14, 9}, 8);
  for (int side = -1; side <= 1; side += 2) {
    const float z_wall = 9.0f * float(side), z_col = 5.5f * float(side);
    b.box({-20, 0, std::min(z_wall, z_wall + float(side))},
          {20, 14, std::max(z_wall, z_wall + float(side))}, 16);  // outer walls
    for (int storey = 0; storey < 2; ++storey) {
      const float y0 = 7.0f * float(storey);
      for (int i = 0; i < 14; ++i) {
        const float x = -18.0f + 36.0f * float(i) / 13.0f;
        b.cylinder({x, y0, z_col}, storey ? 0.3f : 0.45f, 5.5f, 24, 12);
        if (i < 13) {  // lintels approximating arches
          const float x1 = -18.0f + 36.0f * float(i + 1) / 13.0f;
          for (int k = 0; k < 4; ++k)
            b.box({x + 0.3f + 0.25f * float(k), y0 + 5.5f + 0.25f * float(k), z_col - 0.4f},
                  {x1 - 0.3f - 0.25f * float(k), y0 + 5.75f + 0.25f * float(k), z_col + 0.4f}, 2);
        }
      }
      b.box({-20, y0 + 6.5f, std::min(z_col, z_wall) - 0.4f},
            {20, y0 + 7.0f, std::max(z_col, z_wall) + 0.4f}, 12);  // gallery slab / roof
    }
    for (int i = 0; i < 6; ++i) {  // drapes hanging from the upper gallery
      const float x = -15.0f + 6.0f * float(i);
      b.grid({x, 6.5f, z_col - 0.6f * float(side)}, {2.0f, 0, 0}, {0, -4.0f, 0.3f * float(side)},
             20, 40);
    }
  }
  finish(s.mesh);
  s.eye = {-17, 1.7f, 0.5f};
  s.look_at = {10, 4, 0};
  s.fov_deg = 70;
  s.point_light = {2, 12, 0.3f};
  s.area_light_corner = {-6, 20, -3};
  s.area_light_u = {12, 0, 0};
  s.area_light_v = {0, 0, 6};
  return s;
}

/// A 6 m x 3 m x 5 m room: bed, wardrobe, desk, chair, shelves of books, a rug of small tiles
/// and ornaments (about 120 k triangles).
inline ShadowScene bedroom() {
  ShadowScene s;
  s.name = "bedroom";
  MeshBuilder b(s.mesh);
  b.grid({0, 0, 0}, {6, 0, 0}, {0, 0, 5}, 60, 50);          // floor
  b.grid({0, 3, 0}, {0, 0, 5}, {6, 0, 0}, 30, 30);          // ceiling
  b.grid({0, 0, 0}, {0, 3, 0}, {6, 0, 0}, 30, 60);          // walls
  b.grid({0, 0, 5}, {6, 0, 0}, {0, 3, 0}, 60, 30);
  b.grid({0, 0, 0}, {0, 0, 5}, {0, 3, 0}, 50, 30);
  b.grid({6, 0, 0}, {0, 3, 0}, {0, 0, 5}, 30, 50);
  b.box({0.5f, 0, 0.2f}, {2.5f, 0.45f, 2.4f}, 12);         // bed base
  b.box({0.55f, 0.45f, 0.25f}, {2.45f, 0.65f, 2.35f}, 24);  // mattress
  b.box({0.5f, 0.45f, 0.1f}, {2.5f, 1.3f, 0.2f}, 10);      // headboard
  b.sphere({1.0f, 0.75f, 0.5f}, 0.22f, 32, 16);            // pillows
  b.sphere({2.0f, 0.75f, 0.5f}, 0.22f, 32, 16);
  b.box({4.6f, 0, 0.1f}, {5.9f, 2.3f, 0.8f}, 16);           // wardrobe
  b.box({3.0f, 0.72f, 4.2f}, {4.6f, 0.76f, 4.9f}, 8);       // desk top
  for (float x : {3.05f, 4.5f})
    for (float z : {4.25f, 4.8f}) b.box({x, 0, z}, {x + 0.05f, 0.72f, z + 0.05f}, 4);
  b.box({3.5f, 0.42f, 3.5f}, {4.0f, 0.46f, 4.0f}, 6);       // chair
  b.box({3.5f, 0.46f, 3.95f}, {4.0f, 1.0f, 4.0f}, 6);
  for (int shelf = 0; shelf < 4; ++shelf) {                 // shelves of books
    const float y = 1.0f + 0.4f * float(shelf);
    b.box({5.7f, y, 1.5f}, {6.0f, y + 0.03f, 4.0f}, 6);
    for (int k = 0; k < 40; ++k) {
      const float z = 1.52f + 0.06f * float(k), h = 0.2f + 0.1f * float((k * 7 + shelf) % 3) / 2.0f;
      b.box({5.72f, y + 0.03f, z}, {5.95f, y + 0.03f + h, z + 0.05f}, 2);
    }
  }
  std::mt19937 rng(4);
  std::uniform_real_distribution<float> u(0, 1);
  for (int k = 0; k < 60; ++k)  // ornaments
    b.sphere({0.3f + 5.4f * u(rng), 0.8f + 1.8f * u(rng), 0.3f + 4.4f * u(rng)},
             0.03f + 0.06f * u(rng), 24, 12);
  b.grid({1.0f, 0.01f, 2.6f}, {3.0f, 0, 0}, {0, 0, 1.8f}, 120, 72);  // rug
  b.sphere({3.0f, 2.6f, 2.5f}, 0.15f, 48, 24);  // ceiling lamp shade (the point light is below)
  finish(s.mesh);
  s.eye = {5.5f, 1.6f, 4.6f};
  s.look_at = {1.5f, 0.6f, 1.0f};
  s.fov_deg = 75;
  s.point_light = {3.0f, 2.3f, 2.5f};
  s.area_light_corner = {2.0f, 2.95f, 1.5f};
  s.area_light_u = {2.0f, 0, 0};
  s.area_light_v = {0, 0, 2.0f};
  return s;
}

/// 150 trees (trunks, branches, ~1000 small leaf triangles each) on a tessellated ground: thin
/// occluders everywhere (about 170 k triangles; FairyForest has 174 k).
inline ShadowScene forest() {
  ShadowScene s;
  s.name = "forest";
  MeshBuilder b(s.mesh);
  b.grid({-30, 0, -30}, {60, 0, 0}, {0, 0, 60}, 60, 60);
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(0, 1);
  for (int tree = 0; tree < 150; ++tree) {
    const float x = -28 + 56 * u(rng), z = -28 + 56 * u(rng), h = 4 + 6 * u(rng);
    b.cylinder({x, 0, z}, 0.08f + 0.1f * u(rng), h, 8, 4);
    for (int leaf = 0; leaf < 1000; ++leaf) {
      // Leaves in a crown around the top of the trunk.
      const float r = 0.5f + 2.0f * u(rng), a = 6.2832f * u(rng), y = h * (0.5f + 0.5f * u(rng));
      const V3 p{x + r * std::cos(a), y, z + r * std::sin(a)};
      const float sz = 0.06f + 0.08f * u(rng);
      const std::uint32_t i0 = b.vertex(p);
      const std::uint32_t i1 = b.vertex({p[0] + sz * (u(rng) - 0.5f), p[1] + sz * u(rng),
                                         p[2] + sz * (u(rng) - 0.5f)});
      const std::uint32_t i2 = b.vertex({p[0] + sz * (u(rng) - 0.5f), p[1] - sz * u(rng),
                                         p[2] + sz * (u(rng) - 0.5f)});
      b.triangle(i0, i1, i2);
    }
  }
  finish(s.mesh);
  s.eye = {-25, 1.7f, -25};
  s.look_at = {0, 3, 0};
  s.fov_deg = 65;
  s.point_light = {0, 25, 5};
  s.area_light_corner = {-10, 40, -10};
  s.area_light_u = {20, 0, 0};
  s.area_light_v = {0, 0, 20};
  return s;
}

/// `count` random triangles (edges up to `size`) in the unit cube.
inline render::TriangleMesh random_soup(int count, float size, std::uint32_t seed) {
  render::TriangleMesh mesh;
  MeshBuilder b(mesh);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0, 1), e(-0.5f, 0.5f);
  for (int k = 0; k < count; ++k) {
    const V3 p{u(rng), u(rng), u(rng)};
    const std::uint32_t a = b.vertex(p);
    const std::uint32_t c = b.vertex({p[0] + size * e(rng), p[1] + size * e(rng), p[2] + size * e(rng)});
    const std::uint32_t d = b.vertex({p[0] + size * e(rng), p[1] + size * e(rng), p[2] + size * e(rng)});
    b.triangle(a, c, d);
  }
  finish(mesh);
  return mesh;
}

/// A watertight n x n grid of unit quads in the plane z = 0 (x, y in [0, n]), plus a stack of
/// `layers` such grids at z = 1, 2, ... shifted by a quarter quad.
inline render::TriangleMesh grid_scene(int n, int layers) {
  render::TriangleMesh mesh;
  MeshBuilder b(mesh);
  for (int l = 0; l <= layers; ++l) {
    const float shift = 0.25f * float(l);
    b.grid({shift, shift, float(l)}, {float(n), 0, 0}, {0, float(n), 0}, n, n);
  }
  finish(mesh);
  return mesh;
}

}  // namespace mr::bench
