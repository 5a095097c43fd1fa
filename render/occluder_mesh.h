// Private to libmr: the occluder mesh of a photo, reconstructed from its metric depth map
// (DESIGN.md section 3, "Occluder geometry"; seed 000, Algorithm 4).
//
// Every pixel with a surface is a small planar patch: the plane through its 3D point with its
// estimated normal. The mesh's vertices sit at pixel corners, on the corner's camera ray. A corner
// is one vertex for all the pixels around it that are mutually continuous, and is split into
// several vertices where a depth discontinuity separates them, so a continuous surface comes out
// watertight while no triangle ever bridges a jump in depth (such bridging triangles are long and
// thin, and made shadow rays ~100x slower in measurements, besides casting false shadows).
// A pixel's two triangles follow its corners only; where that would miss the pixel's measured
// depth (a crease crossing the pixel, whose corners serve planes on both sides), the pixel gets a
// vertex of its own that puts the surface through its measured point, so every pixel centre
// re-renders to its input depth (MeshOptions::centre_tolerance).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include "mr/camera.h"
#include "mr/image.h"
#include "mr/scene.h"
#include "render/huge_pages.h"

namespace mr::render {

/// The pixel structure behind a mesh made by reconstruct_occluder_mesh without planar merging
/// (issue 12 item 4), for OccluderScene to hand regular stretches of the surface to Embree as
/// grids (RTC_GEOMETRY_TYPE_GRID): one vertex per corner, no per-pair index to build over.
struct SurfacePixelLayout {
  /// pixel[] bits: the pixel has a surface (its two triangles are the surface's next pair, see
  /// TriangleMesh), and it is grid-eligible: it has a surface, is not fanned, and each of its
  /// four corners has exactly one vertex (no discontinuity splits it), so its triangles are
  /// (c00, c11, c01), (c00, c10, c11) over corner_vertex[] of its corners; fanned: it has a
  /// surface and four triangles (MeshOptions::centre_tolerance). Other bits: private.
  static constexpr std::uint8_t kSurface = 1, kFanned = 8, kGridEligible = 16;
  SurfacePixelLayout(int width_px, int height_px, HugePageArray<std::uint8_t> pixels,
                     HugePageArray<std::uint32_t> corners)
      : width(width_px),
        height(height_px),
        pixel(std::move(pixels)),
        corner_vertex(std::move(corners)) {}
  int width = 0, height = 0;  ///< pixels of the depth map the mesh was made from
  /// width x height, row by row (top row first).
  HugePageArray<std::uint8_t> pixel;
  /// (width + 1) x (height + 1) corners, row by row: the index of the corner's first vertex;
  /// the corner's only vertex for every corner of a grid-eligible pixel.
  HugePageArray<std::uint32_t> corner_vertex;
};

/// An indexed triangle mesh in the world frame (metres, +Y up; see mr/scene.h).
///
/// Layout of a mesh made by reconstruct_occluder_mesh (callers may rely on it, e.g. to map an
/// Embree primitive id below 2N back to its pixel k = id / 2): the first 2 * N triangles are
/// the surface, two per pixel with a surface (N of them), visited row by row (top row first,
/// left to right). Triangle 2k is (a, c11, c01) and 2k+1 is (a, c10, c11), where cXY is the
/// vertex index of the pixel's corner X right / Y down of its top-left corner and a is c00,
/// except for a fanned pixel (see MeshOptions::centre_tolerance), where a is the pixel's own
/// vertex m. The F fanned pixels' other two triangles follow, in the same pixel order:
/// triangles 2N + 2f and 2N + 2f + 1 of the f-th fanned pixel are (m, c00, c10) and
/// (m, c01, c00). In every surface triangle cross(v1 - v0, v2 - v0) points towards the camera.
/// With MeshOptions::planar_merge_tolerance > 0 the surface triangles (still the first
/// surface_triangle_count) are fewer and in no per-pixel order.
/// Triangles after the first 2N + 2F (surface_triangle_count) are the optional silhouette
/// extrusions (MeshOptions::thickness_m; their winding is unspecified), and after those any
/// blockers the photo does not show (render/blockers.h).
struct TriangleMesh {
  std::vector<float> positions;            ///< x, y, z per vertex, world metres
  std::vector<std::uint32_t> indices;      ///< 3 vertex indices per triangle
  std::size_t surface_triangle_count = 0;  ///< the first triangles, 2N + 2F (see above)
  /// The surface's pixel structure (see SurfacePixelLayout), or null: set by
  /// reconstruct_occluder_mesh with MeshOptions::pixel_layout (and no planar merge). Whoever changes
  /// the surface triangles or the corner vertices of a mesh must reset it; appending triangles
  /// and vertices after the surface's (extrusions, blockers) keeps it valid.
  std::shared_ptr<const SurfacePixelLayout> layout;

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
  /// A pixel's two triangles meet its centre ray at the depth their corners c00 and c11 give
  /// it, which misses the pixel's measured distance where a crease crosses the pixel (by up to
  /// ~1/4 of the per-pixel change in relative depth slope between the two faces: percents on
  /// faces seen at grazing angles). Where it would miss by more than this fraction of the
  /// distance, the pixel is fanned instead: four triangles around a vertex of its own that puts
  /// the surface through its measured point (see reconstruct_occluder_mesh; layout: see
  /// TriangleMesh), so re-rendered depth at every pixel centre is within this fraction of the
  /// input (plus float rounding). Only pixels at creases, or where the depth is noisy, are
  /// fanned; 0 fans nearly every pixel (twice the triangles), +inf none. Must be >= 0.
  double centre_tolerance = 1e-3;
  /// Decimation (issue 12): > 0 merges rectangles of pixels (up to 32 x 32) whose corner
  /// vertices all lie within this fraction of their distance from the camera of one plane, and
  /// that no discontinuity or fanned pixel interrupts, into a triangulation of the rectangle's
  /// boundary vertices: 2 (n + m) - 2 triangles for n x m pixels instead of 2 n m. No vertex
  /// moves and no T-junction is made (every boundary vertex is a vertex of the triangulation),
  /// so the mesh stays watertight; the surface inside a rectangle moves by at most twice the
  /// tolerance (relative to the distance). The surface triangles are then no longer two per
  /// pixel: the layout of TriangleMesh holds only with 0 (the default, off). Must be >= 0.
  double planar_merge_tolerance = 0;
  /// Keep the surface's pixel structure in TriangleMesh::layout (flags and corner table, ~5
  /// bytes a pixel, moved into the mesh rather than released), for an OccluderScene with
  /// OccluderSceneOptions::surface_grids. Off by default, as are the grids; ignored with
  /// planar_merge_tolerance > 0.
  bool pixel_layout = false;
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

/// Issue 12: the share of the surface's triangles that are slivers, i.e. whose longest edge is
/// more than kSliverFootprints pixel footprints (their distance from the camera times
/// `pixel_angle_rad`, the angle one mesh pixel subtends) long. Jagged estimated depth (foliage,
/// rough ground) makes a fur of such slivers along the view rays, in which a shadow ray crosses
/// tens of their bounding boxes before its hit (render/occluder_cache.cpp chooses how to trace
/// the surface by it). Every fourth surface triangle is counted (deterministic); 0 for a mesh
/// without surface triangles. Parallel (TBB).
inline constexpr double kSliverFootprints = 16;
double surface_sliver_share(const TriangleMesh& mesh, const Vec3& camera_position_m,
                            double pixel_angle_rad);

/// Issue 12: the share of a depth map's surface pixels where the surface zig-zags: along a row
/// or a column it bends by more than kFurFootprints pixel footprints one way and at a neighbour
/// the other way. The bend is the second difference of inverse camera depth across the pixel
/// (zero on any plane, however slanted), relative to the pixel's and times the focal length in
/// pixels, over continuous pixels (relative gap at most `discontinuity_ratio`). Jagged estimated
/// depth (foliage, rock) zig-zags so, and its mesh is a fur of slivers along the view rays; a
/// smooth surface seen at a grazing angle has long triangles but no bend, and a crease (a wall's
/// foot) bends one pixel one way. Every second row is counted (deterministic); 0 for a map
/// without surface pixels that have continuous neighbours. Parallel (TBB).
inline constexpr double kFurFootprints = 16;
struct DepthFur {
  double share = 0;        ///< of the pixels counted, those that zig-zag
  std::size_t pixels = 0;  ///< surface pixels counted (with continuous neighbours)
};
DepthFur depth_fur_share(ConstImageView distance_m, const Camera& camera,
                         double discontinuity_ratio = MeshOptions{}.discontinuity_ratio);

/// Reconstructs the occluder mesh of a distance map (seed 000, Algorithm 4, see the file comment).
///
/// `distance_m` as for estimate_normals. Each pixel with a surface contributes two triangles over
/// its four corners, or four around a vertex of its own (layout: see TriangleMesh); pixels without
/// one contribute none. A corner's vertex is on the corner's camera ray at the average of the
/// distances where that ray meets the planes of the pixels sharing the vertex (a pixel whose
/// plane the ray meets nearly edge-on, or far from the pixel's own distance, contributes its own
/// distance instead); the average is the best one corner can do for pixels on both sides of a
/// crease (taking the nearer or farther plane fixes one side's pixel centres and doubles the
/// other side's error). A fanned pixel (x, y)'s vertex m is on the ray through image point
/// (x + 1/4, y + 1/4) (on the diagonal, halfway from corner c00 to the centre), at the depth where
/// the segment from m to c11 meets the centre ray at the pixel's measured point (m no farther than
/// 4x the pixel's depth). The centre ray then crosses the edge shared by the pixel's first two
/// triangles, as it crosses c00-c11 for an unfanned pixel; with a vertex on the centre ray itself,
/// Embree's (non-robust) edge tests there come down to rounding noise, and rays through it were
/// lost in tests.
/// Vertices: corners first, then the fanned pixels' vertices in pixel order, then the
/// extrusions. Deterministic, and parallel over rows (TBB). The returned mesh owns its
/// buffers.
///
/// Throws mr::Error(invalid_argument) for a depth map with other than 1 channel or bad options,
/// mr::Error(size_mismatch) when its size differs from the camera's (the message names both
/// sizes), and mr::Error(invalid_argument) if the mesh would exceed 2^32 - 1 vertices.
///
/// `normals`: estimate_normals(distance_m, camera, pose, options.discontinuity_ratio) when the
/// caller has them already (the same values the mesh would compute; saves recomputing them), or
/// an empty view. Throws mr::Error(size_mismatch) unless they are 3 channels of the map's size.
TriangleMesh reconstruct_occluder_mesh(ConstImageView distance_m, const Camera& camera,
                                       const CameraPose& pose, const MeshOptions& options = {},
                                       ConstImageView normals = {});

}  // namespace mr::render
