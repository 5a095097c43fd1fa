// Private to libmr: the occluder mesh of a photo, reconstructed from its metric depth map
// (DESIGN.md section 3, "Occluder geometry"; seed 000, Algorithm 4).
//
// Every pixel with a surface is a small planar patch: the plane through its 3D point with its
// estimated normal. The mesh's vertices sit at pixel corners, on the corner's camera ray. A corner
// is one vertex for all the pixels around it that are mutually continuous, and is split into
// several vertices where a depth discontinuity separates them, so a continuous surface comes out
// watertight while no triangle ever bridges a jump in depth (such bridging triangles are long and
// thin, and made shadow rays ~100x slower in measurements, besides casting false shadows).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "mr/camera.h"
#include "mr/image.h"
#include "mr/scene.h"

namespace mr::render {

/// An indexed triangle mesh in the world frame (metres, +Y up; see mr/scene.h).
///
/// Layout of a mesh made by reconstruct_occluder_mesh (callers may rely on it, e.g. to map an
/// Embree primitive id back to its pixel): the first 2 * N triangles are the surface, two per
/// pixel with a surface (N of them), visited row by row (top row first, left to right).
/// Triangle 2k is (c00, c11, c01) and 2k+1 is (c00, c10, c11), where cXY is the vertex index of
/// the pixel's corner X right / Y down of its top-left corner, so cross(v1 - v0, v2 - v0) points
/// towards the camera. Triangles after the first 2N are the optional silhouette extrusions
/// (MeshOptions::thickness_m; their winding is unspecified).
struct TriangleMesh {
  std::vector<float> positions;            ///< x, y, z per vertex, world metres
  std::vector<std::uint32_t> indices;      ///< 3 vertex indices per triangle
  std::size_t surface_triangle_count = 0;  ///< the first triangles, 2 per pixel (see above)

  std::size_t vertex_count() const { return positions.size() / 3; }
  std::size_t triangle_count() const { return indices.size() / 3; }
};

struct MeshOptions {
  /// Two neighbouring pixels at distances d1, d2 lie on one continuous surface when
  /// |d1 - d2| <= ratio * min(d1, d2), or when each pixel's plane predicts the other's distance
  /// within that ratio (so a surface seen at a grazing angle, whose distance changes fast from
  /// pixel to pixel, stays continuous). Must be > 0.
  double discontinuity_ratio = 0.05;
  /// Surfaces seen only from the front are paper-thin and cast too-thin shadows when lit from
  /// the side. With thickness_m > 0 every silhouette edge of the surface (an edge in front of a
  /// depth discontinuity or of the sky) is extruded away from the camera, along the corner rays,
  /// by this many metres (limited to the depth of the background behind it). 0 = off; must be
  /// >= 0 and finite.
  double thickness_m = 0;
};

/// Estimates a unit surface normal per pixel of a distance map.
///
/// `distance_m`: 1 channel, the Euclidean distance in metres along each pixel's centre ray; values
/// that are not finite and positive (+inf for the sky, NaN, 0, negative) mean "no surface".
/// Returns a 3-channel image of the camera's size: WORLD-frame unit normals (x, y, z), oriented
/// towards the camera (dot(n, -ray) > 0); (0, 0, 0) where there is no surface.
///
/// The normal is the cross product of the two tangents from neighbour differences, one per image
/// axis. Per axis it takes the central difference where the surface is planar across the pixel,
/// else the one-sided difference towards the neighbour that continues the pixel's surface (its
/// inverse depth extrapolates linearly, which is exact on planes at any viewing angle), so normals
/// next to a depth discontinuity or a crease belong to the pixel's own face. A pixel with no
/// continuous neighbour along an axis takes the normal closest to facing the camera.
///
/// Throws mr::Error(invalid_argument) unless `distance_m` has 1 channel and `discontinuity_ratio`
/// > 0, and mr::Error(size_mismatch) when its size differs from the camera's (the message names
/// both sizes).
Image estimate_normals(ConstImageView distance_m, const Camera& camera, const CameraPose& pose,
                       double discontinuity_ratio = MeshOptions{}.discontinuity_ratio);

/// Reconstructs the occluder mesh of a distance map (seed 000, Algorithm 4, see the file comment).
///
/// `distance_m` as for estimate_normals. Each pixel with a surface contributes two triangles over
/// its four corners (layout: see TriangleMesh); pixels without one contribute none. A corner's
/// vertex is on the corner's camera ray at the average of the distances where that ray meets the
/// planes of the pixels sharing the vertex (a pixel whose plane the ray meets nearly edge-on, or
/// far from the pixel's own distance, contributes its own distance instead). Deterministic, and
/// parallel over rows (TBB). The returned mesh owns its buffers.
///
/// Throws mr::Error(invalid_argument) for a depth map with other than 1 channel or bad options,
/// mr::Error(size_mismatch) when its size differs from the camera's (the message names both
/// sizes), and mr::Error(invalid_argument) if the mesh would exceed 2^32 - 1 vertices.
TriangleMesh reconstruct_occluder_mesh(ConstImageView distance_m, const Camera& camera,
                                       const CameraPose& pose, const MeshOptions& options = {});

}  // namespace mr::render
