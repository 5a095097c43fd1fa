// Private to libmr: the occluder mesh's pixel triangle pairs as quads (issue 12 item 4).
//
// reconstruct_occluder_mesh writes two triangles per pixel, (A, B, C) and (A, D, B), sharing
// the diagonal A-B (TriangleMesh's layout: (a, c11, c01), (a, c10, c11) and, for a fanned
// pixel, (m, c00, c10), (m, c01, c00)). Such a pair is the quad (C, A, D, B): Embree splits a
// quad (v0, v1, v2, v3) into (v0, v1, v3) and (v2, v3, v1), here (C, A, B) and (D, B, A), the
// same two triangles with the same winding. The quad's four indices lie consecutively in the
// triangle index buffer, two indices into the pair, so Embree reads them in place with a
// stride of six indices (no copy). OccluderScene gives the surface to Embree as quads when
// this holds: half the primitives, so the BVH builds in about half the time.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace mr::render {

/// Whether triangles first .. first + count - 1 of `indices` (3 per triangle) come in pairs
/// (A, B, C), (A, D, B): count even and non-zero, and every pair sharing A and B as above.
inline bool triangle_pairs(const std::vector<std::uint32_t>& indices, std::size_t first,
                           std::size_t count) {
  if (count == 0 || count % 2 != 0 || 3 * (first + count) > indices.size()) return false;
  const std::uint32_t* t = indices.data() + 3 * first;
  for (std::size_t k = 0; k < count / 2; ++k, t += 6)
    if (t[0] != t[3] || t[1] != t[5]) return false;
  return true;
}

/// Byte offset and stride of the quads of triangle pairs first .. first + count - 1 inside
/// the triangle index buffer (RTC_FORMAT_UINT4, count / 2 quads).
constexpr std::size_t quad_index_offset_bytes(std::size_t first) {
  return sizeof(std::uint32_t) * (3 * first + 2);
}
constexpr std::size_t kQuadIndexStrideBytes = 6 * sizeof(std::uint32_t);

}  // namespace mr::render
