// Test meshes for the object-insertion tests and benchmark (issue 16): a UV sphere with smooth
// normals and an axis-aligned box with flat faces, built here so the renderer's tests do not
// depend on the loaders.
#pragma once

#include <cmath>
#include <cstdint>
#include <numbers>
#include <string>

#include "mr/objects.h"

namespace mr::test {

/// A UV sphere of `radius` about the origin: `stacks` x `slices` quads (two triangles each,
/// one at the poles), smooth vertex normals.
inline ObjectMesh uv_sphere(double radius, int stacks, int slices, Rgb base, float roughness,
                            float metallic = 0) {
  ObjectMesh m;
  m.source = "test:sphere";
  for (int i = 0; i <= stacks; ++i) {
    const double theta = std::numbers::pi * i / stacks;
    for (int j = 0; j <= slices; ++j) {
      const double phi = 2 * std::numbers::pi * j / slices;
      const float nx = float(std::sin(theta) * std::cos(phi)), ny = float(std::cos(theta)),
                  nz = float(std::sin(theta) * std::sin(phi));
      m.positions.push_back({float(radius) * nx, float(radius) * ny, float(radius) * nz});
      m.normals.push_back({nx, ny, nz});
      m.uvs.push_back({float(j) / float(slices), float(i) / float(stacks)});
    }
  }
  const auto idx = [&](int i, int j) { return std::uint32_t(i * (slices + 1) + j); };
  for (int i = 0; i < stacks; ++i)
    for (int j = 0; j < slices; ++j) {
      if (i > 0) m.triangles.push_back({idx(i, j), idx(i + 1, j), idx(i, j + 1)});
      if (i + 1 < stacks) m.triangles.push_back({idx(i, j + 1), idx(i + 1, j), idx(i + 1, j + 1)});
    }
  ObjectMaterial mat;
  mat.base_color = base;
  mat.roughness = roughness;
  mat.metallic = metallic;
  m.materials.push_back(mat);
  return m;
}

/// An axis-aligned box [min, max] (object frame), flat faces (no vertex normals).
inline ObjectMesh box_mesh(std::array<float, 3> lo, std::array<float, 3> hi, Rgb base, float roughness) {
  ObjectMesh m;
  m.source = "test:box";
  for (int k = 0; k < 8; ++k)
    m.positions.push_back({(k & 1) ? hi[0] : lo[0], (k & 2) ? hi[1] : lo[1], (k & 4) ? hi[2] : lo[2]});
  const std::uint32_t faces[6][4] = {{0, 2, 6, 4}, {1, 5, 7, 3}, {0, 4, 5, 1},
                                     {2, 3, 7, 6}, {0, 1, 3, 2}, {4, 6, 7, 5}};
  for (const auto& f : faces) {
    m.triangles.push_back({f[0], f[1], f[2]});
    m.triangles.push_back({f[0], f[2], f[3]});
  }
  ObjectMaterial mat;
  mat.base_color = base;
  mat.roughness = roughness;
  m.materials.push_back(mat);
  return m;
}

}  // namespace mr::test
