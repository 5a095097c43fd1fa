#include "render/occluder_mesh.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <functional>
#include <limits>
#include <memory>
#include <string>

#include "mr/error.h"
#include "render/huge_pages.h"
#include "render/math.h"

namespace mr::render {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

using V3 = Vec3d;  // render/math.h

/// The camera's rays in the world frame. Pixel (x, y)'s centre is image point (x + 0.5, y + 0.5)
/// and its corners are the integer image points, as in mr::CameraPose::ray_direction.
struct RayFrame {
  V3 forward, right, up;
  double cx = 0, cy = 0, inv_focal_px = 0;

  RayFrame(const Camera& camera, const CameraPose& pose) {
    const auto axes = pose.axes();
    forward = {axes[0].x, axes[0].y, axes[0].z};
    right = {axes[1].x, axes[1].y, axes[1].z};
    up = {axes[2].x, axes[2].y, axes[2].z};
    cx = camera.cx;
    cy = camera.cy;
    inv_focal_px = 1.0 / camera.focal_px;
  }
  /// Direction through image point (u, v), scaled so its forward component is 1: the point at
  /// z-depth z on the ray is z * direction.
  V3 direction(double u, double v) const {
    const double a = (u - cx) * inv_focal_px, b = (v - cy) * inv_focal_px;
    return a * right - b * up + forward;
  }
  V3 unit_direction(double u, double v) const {
    const V3 d = direction(u, v);
    return (1.0 / length(d)) * d;
  }
};

/// One pixel's surface sample, relative to the camera position (world orientation). Floats keep
/// the 1080p working set small; the inputs are float anyway. Trivial (no member initializers;
/// Sample{} is all zeros), so that arrays of them start uninitialized and the parallel loop
/// that fills them is the first to touch their pages (HugePageArray).
struct Sample {
  float x, y, z;     ///< the 3D point minus the camera position, metres
  float distance_m;  ///< along the centre ray; 0 = no surface
  float inv_z;       ///< 1 / z-depth; affine in image coordinates on any plane

  bool valid() const { return distance_m > 0; }
  V3 point() const { return {x, y, z}; }
};

/// Relative gap between two distances, the quantity MeshOptions::discontinuity_ratio bounds.
inline double relative_gap(double d1, double d2) {
  return std::abs(d1 - d2) / std::min(d1, d2);
}

void check_inputs(ConstImageView distance_m, const Camera& camera, double discontinuity_ratio) {
  if (distance_m.channels != 1)
    throw Error(ErrorCode::invalid_argument, "depth map has " +
                                                 std::to_string(distance_m.channels) +
                                                 " channels, expected 1 (distance in metres)");
  if (distance_m.width != camera.width || distance_m.height != camera.height)
    throw Error(ErrorCode::size_mismatch, "depth map is " + std::to_string(distance_m.width) + "x" +
                                              std::to_string(distance_m.height) + ", camera is " +
                                              std::to_string(camera.width) + "x" +
                                              std::to_string(camera.height));
  if (distance_m.width <= 0 || distance_m.height <= 0 || !distance_m.data)
    throw Error(ErrorCode::invalid_argument, "depth map is empty");
  if (!(camera.focal_px > 0) || !std::isfinite(camera.focal_px))
    throw Error(ErrorCode::invalid_argument,
                "camera focal length must be positive, got " + std::to_string(camera.focal_px));
  if (!(discontinuity_ratio > 0) || !std::isfinite(discontinuity_ratio))
    throw Error(ErrorCode::invalid_argument,
                "discontinuity ratio must be positive, got " + std::to_string(discontinuity_ratio));
}

HugePageArray<Sample> compute_samples(ConstImageView distance_m, const RayFrame& frame) {
  const int width = distance_m.width;
  HugePageArray<Sample> samples(distance_m.pixel_count());
  tbb::parallel_for(
      tbb::blocked_range<int>(0, distance_m.height), [&](const tbb::blocked_range<int>& rows) {
        for (int y = rows.begin(); y < rows.end(); ++y) {
          const float* row = distance_m.row(y);
          Sample* out = samples.data() + std::size_t(y) * width;
          for (int x = 0; x < width; ++x) {
            const double d = row[x];
            // load_depth maps NaN, 0 and negatives to +inf (no surface); do the
            // same here for depth maps from elsewhere.
            if (!(d > 0 && d < kInf)) {
              out[x] = Sample{};
              continue;
            }
            const V3 dir = frame.direction(x + 0.5, y + 0.5);
            const double len = length(dir);
            const V3 p = (d / len) * dir;
            out[x] = Sample{float(p.x), float(p.y), float(p.z), float(d), float(len / d)};
          }
        }
      });
  return samples;
}

/// How well the pixel continues the surface of the neighbours n1 (adjacent) and n2 (next one out)
/// on one side: the relative error of linearly extrapolating their inverse depth to the pixel
/// (exact for any plane, however slanted). With only n1 available: the plain relative gap.
inline double side_error(const Sample& c, const Sample* n1, const Sample* n2) {
  if (!n1) return kInf;
  if (!n2) return relative_gap(c.distance_m, n1->distance_m);
  const double predicted = 2.0 * double(n1->inv_z) - double(n2->inv_z);
  return std::abs(double(c.inv_z) - predicted) / double(c.inv_z);
}

/// The surface tangent at pixel c along one image axis (m = the neighbours before it, p = after
/// it; nullptr where outside the image or without a surface). Returns false when neither
/// neighbour continues c's surface.
bool axis_tangent(const Sample& c, const Sample* m1, const Sample* m2, const Sample* p1,
                  const Sample* p2, double ratio, V3& tangent) {
  const double e_minus = side_error(c, m1, m2);
  const double e_plus = side_error(c, p1, p2);
  const bool minus_ok =
      m1 && (e_minus <= ratio || relative_gap(c.distance_m, m1->distance_m) <= ratio);
  const bool plus_ok =
      p1 && (e_plus <= ratio || relative_gap(c.distance_m, p1->distance_m) <= ratio);
  if (minus_ok && plus_ok) {
    // Central differences where the surface is planar across the pixel (second difference of
    // inverse depth about as small as on either side): symmetric and least noisy. Otherwise
    // (a crease at the pixel) the one-sided difference on the flatter side keeps the pixel's
    // own face.
    const double e_centre =
        std::abs(double(m1->inv_z) - 2.0 * double(c.inv_z) + double(p1->inv_z)) / double(c.inv_z);
    if (e_centre <= std::max(2.0 * std::min(e_minus, e_plus), 1e-4)) {
      tangent = p1->point() - m1->point();
      return true;
    }
  }
  if (minus_ok && (!plus_ok || e_minus <= e_plus)) {
    tangent = c.point() - m1->point();
    return true;
  }
  if (plus_ok) {
    tangent = p1->point() - c.point();
    return true;
  }
  return false;
}

/// Unit normal of valid pixel (x, y), facing the camera.
V3 pixel_normal(const Sample* samples, int width, int height, int x, int y, double ratio) {
  const Sample* base = samples;
  auto at = [&](int px, int py) -> const Sample* {
    if (px < 0 || py < 0 || px >= width || py >= height) return nullptr;
    const Sample* s = base + std::size_t(py) * width + px;
    return s->valid() ? s : nullptr;
  };
  const Sample& c = *at(x, y);
  const V3 ray = (1.0 / double(c.distance_m)) * c.point();
  V3 tx, ty;
  const bool has_x =
      axis_tangent(c, at(x - 1, y), at(x - 2, y), at(x + 1, y), at(x + 2, y), ratio, tx);
  const bool has_y =
      axis_tangent(c, at(x, y - 1), at(x, y - 2), at(x, y + 1), at(x, y + 2), ratio, ty);
  V3 n = -1.0 * ray;
  if (has_x && has_y) {
    const V3 m = cross(tx, ty);
    if (length(m) > 0) n = m;
  } else if (has_x || has_y) {
    // One tangent only: of the normals perpendicular to it, the one closest to facing the
    // camera (the least committal guess).
    const V3 t = has_x ? tx : ty;
    const double t2 = dot(t, t);
    if (t2 > 0) {
      const V3 m = n - (dot(n, t) / t2) * t;
      if (length(m) > 1e-9) n = m;
    }
  }
  if (dot(n, ray) > 0) n = -1.0 * n;
  return (1.0 / length(n)) * n;
}

/// Writes the unit normal of every pixel (0 where there is no surface) to normals_out, 3 floats
/// per pixel, rows contiguous.
void compute_normals(const Sample* samples, int width, int height, double ratio,
                     float* normals_out) {
  tbb::parallel_for(tbb::blocked_range<int>(0, height), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y < rows.end(); ++y) {
      for (int x = 0; x < width; ++x) {
        const std::size_t i = std::size_t(y) * width + x;
        float* out = normals_out + 3 * i;
        if (!samples[i].valid()) {
          out[0] = out[1] = out[2] = 0.0f;
          continue;
        }
        const V3 n = pixel_normal(samples, width, height, x, y, ratio);
        out[0] = float(n.x);
        out[1] = float(n.y);
        out[2] = float(n.z);
      }
    }
  });
}

/// A pixel's plane: unit normal n (facing the camera) and offset h = dot(n, point - camera),
/// negative. A camera ray with unit direction w meets it at distance h / dot(n, w).
struct Plane {
  float nx, ny, nz, h;  // trivial, as Sample
  V3 normal() const { return {nx, ny, nz}; }
};

/// Distance at which the plane of a pixel at distance d_m meets the unit ray w, within a factor
/// 4 window around d_m (which admits every legitimate case, where the pixel's own centre ray is
/// at most a pixel away). A ray that meets the plane beyond the window, edge-on or not at all in
/// front of the camera has passed the plane's horizon (in practice: the top corners of the
/// last ground row under the sky): it gets the window's far end, 4 d_m, so the pixel's
/// triangles stay close to its plane (at d_m they rose to the camera's height within one pixel,
/// a wall on which the sun shadowed that row at every quality, issue 13). A ray that meets it
/// nearer than d_m / 4 gets d_m.
inline double plane_distance(const Plane& plane, double d_m, V3 w) {
  const double den = dot(plane.normal(), w);
  if (den < 0) {
    const double t = double(plane.h) / den;
    if (t >= 0.25 * d_m) return std::min(t, 4.0 * d_m);
    return d_m;
  }
  return 4.0 * d_m;
}

/// Whether neighbouring pixels p and q lie on one continuous surface (MeshOptions).
inline bool continuous(const Sample& p, const Plane& pp, const Sample& q, const Plane& pq,
                       double ratio) {
  const double dp = p.distance_m, dq = q.distance_m;
  if (relative_gap(dp, dq) <= ratio) return true;
  // Slanted surfaces: each pixel's plane must predict the other's distance. Requiring both
  // keeps a foreground silhouette apart from a background that one plane happens to graze.
  const V3 wq = (1.0 / dq) * q.point(), wp = (1.0 / dp) * p.point();
  const double den_pq = dot(pp.normal(), wq), den_qp = dot(pq.normal(), wp);
  if (!(den_pq < 0 && den_qp < 0)) return false;
  const double t_pq = double(pp.h) / den_pq, t_qp = double(pq.h) / den_qp;
  return relative_gap(t_pq, dq) <= ratio && relative_gap(t_qp, dp) <= ratio;
}

// Per-pixel flags.
constexpr std::uint8_t kValid = 1, kRightContinuous = 2, kDownContinuous = 4, kFan = 8;
constexpr std::uint8_t kGridEligible = SurfacePixelLayout::kGridEligible;
static_assert(kValid == SurfacePixelLayout::kSurface);
static_assert(kFan == SurfacePixelLayout::kFanned);
static_assert((kGridEligible & (kValid | kRightContinuous | kDownContinuous | kFan)) == 0);

/// How the up-to-four pixels around a corner share it. Slots: 0 = top-left, 1 = top-right,
/// 2 = bottom-left, 3 = bottom-right pixel. Key bits 0-3: slot has a surface; bits 4-7: the
/// pairs (TL,TR), (BL,BR), (TL,BL), (TR,BR) are continuous. Pixels connected through continuous
/// pairs share one vertex (`label` numbers the groups 0..count-1 in slot order).
struct CornerGroups {
  std::uint8_t count = 0;
  std::array<std::uint8_t, 4> label{0xFF, 0xFF, 0xFF, 0xFF};
};

constexpr std::array<CornerGroups, 256> make_corner_table() {
  std::array<CornerGroups, 256> table{};
  constexpr int pairs[4][2] = {{0, 1}, {2, 3}, {0, 2}, {1, 3}};
  for (int key = 0; key < 256; ++key) {
    int parent[4] = {0, 1, 2, 3};
    auto find = [&parent](int a) {
      while (parent[a] != a) a = parent[a];
      return a;
    };
    for (int e = 0; e < 4; ++e) {
      const int a = pairs[e][0], b = pairs[e][1];
      if (!((key >> (4 + e)) & 1) || !((key >> a) & 1) || !((key >> b) & 1)) continue;
      const int ra = find(a), rb = find(b);
      if (ra != rb) parent[std::max(ra, rb)] = std::min(ra, rb);
    }
    CornerGroups groups;
    int root_label[4] = {-1, -1, -1, -1};
    for (int s = 0; s < 4; ++s) {
      if (!((key >> s) & 1)) continue;
      const int r = find(s);
      if (root_label[r] < 0) root_label[r] = groups.count++;
      groups.label[s] = std::uint8_t(root_label[r]);
    }
    table[key] = groups;
  }
  return table;
}
constexpr std::array<CornerGroups, 256> kCornerTable = make_corner_table();

constexpr int kTopLeft = 0, kTopRight = 1, kBottomLeft = 2, kBottomRight = 3;

// Step 8 of reconstruct_occluder_mesh (MeshOptions::planar_merge_tolerance): replaces the two
// triangles per pixel of planar rectangles of pixels by a triangulation of each rectangle's
// boundary. Rectangles are grown greedily (right, then down) in bands of kMergeMax rows, over
// pixels that are not fanned and share their corner vertices with each other (no discontinuity
// inside), while every corner vertex of the rectangle lies within tolerance * its distance from
// the camera of the plane through three of the rectangle's corners. The triangulation uses every
// vertex on the rectangle's boundary (and only those), so the neighbours' edges end at vertices
// of the rectangle's edges: no T-junction, hence no crack for light to leak through; the mesh
// stays exactly as watertight as before, with the same vertex positions. A rectangle of n x m
// pixels (n, m >= 2) takes 2 (n + m) - 2 triangles instead of 2 n m; the interior corners'
// vertices stay in the buffer, unreferenced.
constexpr int kMergeMax = 32;

// Spare index capacity for what render/blockers.cpp appends (hundreds of triangles): without
// it the first appended triangle reallocated and copied the whole index buffer (33-50 MB at
// 1080p, fresh pages the kernel zeroes). Pages never written are never committed.
constexpr std::size_t kAppendHeadroomIndices = 3 * 65536;

template <class VertexOf>
void merge_planar_pixels(TriangleMesh& mesh, const HugePageArray<std::uint8_t>& flags, int width,
                         int height, const std::vector<std::uint64_t>& row_pixel_offset,
                         const std::vector<std::uint64_t>& row_fan_offset,
                         std::uint64_t fan_triangle_base, double tolerance, V3 origin,
                         const VertexOf& vertex_of) {
  auto pixel_index = [width](int x, int y) { return std::size_t(y) * width + x; };
  auto position = [&mesh](std::uint32_t v) {
    const float* p = &mesh.positions[3 * std::size_t(v)];
    return V3{p[0], p[1], p[2]};
  };
  auto mergeable = [&](int x, int y) {
    return (flags[pixel_index(x, y)] & (kValid | kFan)) == kValid;
  };
  // Whether pixel (x, y) shares both vertices of its right (down) edge with its neighbour.
  auto linked_right = [&](int x, int y) {
    return vertex_of(x + 1, y, kBottomLeft) == vertex_of(x + 1, y, kBottomRight) &&
           vertex_of(x + 1, y + 1, kTopLeft) == vertex_of(x + 1, y + 1, kTopRight);
  };
  auto linked_down = [&](int x, int y) {
    return vertex_of(x, y + 1, kTopRight) == vertex_of(x, y + 1, kBottomRight) &&
           vertex_of(x + 1, y + 1, kTopLeft) == vertex_of(x + 1, y + 1, kBottomLeft);
  };
  // The vertex at corner (i, j) of a rectangle ending at corners (x1, y1) whose pixels all
  // share their corners.
  auto corner = [&](int i, int j, int x1, int y1) {
    const bool right = i == x1, bottom = j == y1;
    return vertex_of(
        i, j, right ? (bottom ? kTopLeft : kBottomLeft) : (bottom ? kTopRight : kBottomRight));
  };
  auto planar = [&](int x0, int y0, int x1, int y1) {
    const V3 a = position(corner(x0, y0, x1, y1)), b = position(corner(x1, y0, x1, y1)),
             c = position(corner(x0, y1, x1, y1));
    const V3 n = cross(b - a, c - a);
    const double n_len = length(n);
    if (!(n_len > 0)) return false;
    const V3 unit = (1.0 / n_len) * n;
    // Newest vertices first (the rectangle grows right and down): where the depth is not
    // planar the check fails at once instead of after the whole rectangle.
    for (int j = y1; j >= y0; --j)
      for (int i = x1; i >= x0; --i) {
        const V3 v = position(corner(i, j, x1, y1));
        if (std::abs(dot(v - a, unit)) > tolerance * length(v - origin)) return false;
      }
    return true;
  };

  const int bands = (height + kMergeMax - 1) / kMergeMax;
  std::vector<std::vector<std::uint32_t>> band_indices(static_cast<std::size_t>(bands));
  tbb::parallel_for(0, bands, [&](int band) {
    const int y_begin = band * kMergeMax, y_end = std::min(height, y_begin + kMergeMax);
    std::vector<std::uint8_t> in_rectangle(std::size_t(y_end - y_begin) * width, 0);
    auto taken = [&](int x, int y) -> std::uint8_t& {
      return in_rectangle[std::size_t(y - y_begin) * width + x];
    };
    std::vector<std::uint32_t>& out = band_indices[std::size_t(band)];
    // Emits a triangle wound as the per-pixel ones (towards the camera: positive image-space
    // signed area, y down), from its vertices' image corners.
    auto emit = [&](std::uint32_t v0, std::uint32_t v1, std::uint32_t v2, int u0, int w0, int u1,
                    int w1, int u2, int w2) {
      const long area = long(u1 - u0) * (w2 - w0) - long(w1 - w0) * (u2 - u0);
      out.push_back(v0);
      out.push_back(area > 0 ? v1 : v2);
      out.push_back(area > 0 ? v2 : v1);
    };
    for (int y = y_begin; y < y_end; ++y) {
      const std::uint32_t* row_tris = mesh.indices.data() + 6 * row_pixel_offset[y];
      std::uint64_t fan = row_fan_offset[y];
      int rank = 0;  // the pixel's place among the row's surface pixels
      for (int x = 0; x < width; ++x) {
        const std::uint8_t f = flags[pixel_index(x, y)];
        if (!(f & kValid)) continue;
        const int k = rank++;
        const bool fanned = (f & kFan) != 0;
        const std::uint64_t my_fan = fanned ? fan++ : 0;
        if (taken(x, y)) continue;
        int n = 0, m = 0;
        if (mergeable(x, y)) {
          // Grow right, then down, while the rectangle stays linked and planar.
          n = 1;
          while (x + n < width && n < kMergeMax && mergeable(x + n, y) && !taken(x + n, y) &&
                 linked_right(x + n - 1, y) && planar(x, y, x + n + 1, y + 1))
            ++n;
          m = 1;
          while (n >= 2 && y + m < y_end) {
            bool ok = true;
            for (int i = x; i < x + n && ok; ++i)
              ok = mergeable(i, y + m) && !taken(i, y + m) && linked_down(i, y + m - 1) &&
                   (i == x || linked_right(i - 1, y + m));
            if (!ok || !planar(x, y, x + n, y + m + 1)) break;
            ++m;
          }
        }
        if (n < 2 || m < 2) {
          // The pixel's own triangles (two, or four when fanned).
          const std::uint32_t* t = row_tris + 6 * k;
          out.insert(out.end(), t, t + 6);
          if (fanned) {
            const std::uint32_t* e = mesh.indices.data() + 3 * (fan_triangle_base + 2 * my_fan);
            out.insert(out.end(), e, e + 6);
          }
          continue;
        }
        for (int j = y; j < y + m; ++j)
          for (int i = x; i < x + n; ++i) taken(i, j) = 1;
        // Triangulate the boundary. With u along the longer side and s across: a fan from the
        // second vertex of the first long chain (s = 0) to the first short side, one from the
        // second-to-last vertex of the other chain to the other short side, and a zig-zag
        // between the chains in between; every triangle spans the shorter side only.
        const int x1 = x + n, y1 = y + m;
        const bool along_x = n >= m;
        const int len = along_x ? n : m, span = along_x ? m : n;
        struct Point {
          std::uint32_t vertex;
          int i, j;
        };
        auto at = [&](int u, int s) {
          const int i = along_x ? x + u : x + s, j = along_x ? y + s : y + u;
          return Point{corner(i, j, x1, y1), i, j};
        };
        auto tri = [&](Point p, Point q, Point r) {
          emit(p.vertex, q.vertex, r.vertex, p.i, p.j, q.i, q.j, r.i, r.j);
        };
        for (int s = 0; s < span; ++s) tri(at(0, s), at(0, s + 1), at(1, 0));
        for (int s = 0; s < span; ++s) tri(at(len, s), at(len, s + 1), at(len - 1, span));
        for (int u = 0; u + 1 < len; ++u) {
          tri(at(u + 1, 0), at(u, span), at(u + 1, span));
          tri(at(u + 1, 0), at(u + 1, span), at(u + 2, 0));
        }
      }
    }
  });
  std::size_t surface_indices = 0;
  for (const auto& b : band_indices) surface_indices += b.size();
  std::vector<std::uint32_t> indices;
  indices.reserve(surface_indices + (mesh.indices.size() - 3 * mesh.surface_triangle_count) +
                  kAppendHeadroomIndices);
  advise_huge_pages(indices.data(), sizeof(std::uint32_t) * indices.capacity());
  for (const auto& b : band_indices) indices.insert(indices.end(), b.begin(), b.end());
  indices.insert(indices.end(), mesh.indices.begin() + 3 * mesh.surface_triangle_count,
                 mesh.indices.end());
  mesh.indices = std::move(indices);
  mesh.surface_triangle_count = surface_indices / 3;
}

}  // namespace

Image estimate_normals(ConstImageView distance_m, const Camera& camera, const CameraPose& pose,
                       double discontinuity_ratio) {
  check_inputs(distance_m, camera, discontinuity_ratio);
  const RayFrame frame(camera, pose);
  const HugePageArray<Sample> samples = compute_samples(distance_m, frame);
  Image normals =
      Image::uninitialized(distance_m.width, distance_m.height, 3, {"N.x", "N.y", "N.z"});
  advise_huge_pages(normals.data(), sizeof(float) * normals.pixels().size());
  compute_normals(samples.data(), distance_m.width, distance_m.height, discontinuity_ratio,
                  normals.data());
  return normals;
}

TriangleMesh reconstruct_occluder_mesh(ConstImageView distance_m, const Camera& camera,
                                       const CameraPose& pose, const MeshOptions& options,
                                       ConstImageView known_normals) {
  check_inputs(distance_m, camera, options.discontinuity_ratio);
  if (!(options.thickness_m >= 0) || !std::isfinite(options.thickness_m))
    throw Error(ErrorCode::invalid_argument,
                "mesh thickness must be >= 0 metres, got " + std::to_string(options.thickness_m));
  if (!(options.centre_tolerance >= 0))
    throw Error(ErrorCode::invalid_argument, "mesh centre tolerance must be >= 0, got " +
                                                 std::to_string(options.centre_tolerance));
  if (!(options.planar_merge_tolerance >= 0) || !std::isfinite(options.planar_merge_tolerance))
    throw Error(ErrorCode::invalid_argument, "mesh planar merge tolerance must be >= 0, got " +
                                                 std::to_string(options.planar_merge_tolerance));
  const int width = distance_m.width, height = distance_m.height;
  const double ratio = options.discontinuity_ratio;
  const RayFrame frame(camera, pose);
  const V3 origin{pose.position_m.x, pose.position_m.y, pose.position_m.z};
  const std::size_t pixel_count = distance_m.pixel_count();
  auto pixel_index = [width](int x, int y) { return std::size_t(y) * width + x; };

  // 1. Points, normals and planes per pixel.
  const HugePageArray<Sample> samples = compute_samples(distance_m, frame);
  HugePageArray<Plane> planes(pixel_count);
  {
    if (known_normals.data && (known_normals.width != width || known_normals.height != height ||
                               known_normals.channels != 3))
      throw Error(ErrorCode::size_mismatch, "normals are " + std::to_string(known_normals.width) +
                                                "x" + std::to_string(known_normals.height) + "x" +
                                                std::to_string(known_normals.channels) +
                                                ", the depth map is " + std::to_string(width) +
                                                "x" + std::to_string(height) + "x1");
    // The caller's normals (estimate_normals: the same computation) spare computing them twice,
    // a fifth of the 1080p mesh stage.
    std::unique_ptr<HugePageArray<float>> own_normals;
    if (!known_normals.data) {
      own_normals = std::make_unique<HugePageArray<float>>(3 * pixel_count);
      compute_normals(samples.data(), width, height, ratio, own_normals->data());
    }
    // By rows (the caller's normals have a row stride of their own): no division per pixel.
    tbb::parallel_for(tbb::blocked_range<int>(0, height), [&](const tbb::blocked_range<int>& rows) {
      for (int y = rows.begin(); y < rows.end(); ++y) {
        const float* n =
            known_normals.data ? known_normals.row(y) : own_normals->data() + 3 * pixel_index(0, y);
        for (int x = 0; x < width; ++x, n += 3) {
          const std::size_t i = pixel_index(x, y);
          planes[i] = Plane{n[0], n[1], n[2], float(dot(V3{n[0], n[1], n[2]}, samples[i].point()))};
        }
      }
    });
  }

  // 2. Continuity with the right and lower neighbours; surface pixels per row.
  HugePageArray<std::uint8_t> flags(pixel_count);
  // row_pixel_offset[y + 1] first counts row y's surface pixels, then (prefix sum) is the number
  // of surface pixels in rows 0..y.
  std::vector<std::uint64_t> row_pixel_offset(height + 1, 0);
  tbb::parallel_for(tbb::blocked_range<int>(0, height), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y < rows.end(); ++y) {
      std::uint64_t count = 0;
      for (int x = 0; x < width; ++x) {
        const std::size_t i = pixel_index(x, y);
        const Sample& p = samples[i];
        if (!p.valid()) {
          flags[i] = 0;
          continue;
        }
        ++count;
        std::uint8_t f = kValid;
        if (x + 1 < width && samples[i + 1].valid() &&
            continuous(p, planes[i], samples[i + 1], planes[i + 1], ratio))
          f |= kRightContinuous;
        const std::size_t below = i + width;
        if (y + 1 < height && samples[below].valid() &&
            continuous(p, planes[i], samples[below], planes[below], ratio))
          f |= kDownContinuous;
        flags[i] = f;
      }
      row_pixel_offset[y + 1] = count;
    }
  });

  // 3. Corner keys and vertex counts. Corner (i, j) is image point (i, j), 0 <= i <= width,
  // 0 <= j <= height. corner_base first holds the offset within its row, then the global index
  // of the corner's first vertex.
  const int corner_width = width + 1, corner_height = height + 1;
  const std::size_t corner_count = std::size_t(corner_width) * corner_height;
  HugePageArray<std::uint8_t> corner_key(corner_count);
  HugePageArray<std::uint32_t> corner_base(corner_count);
  std::vector<std::uint64_t> row_vertex_offset(corner_height + 1, 0);
  auto flags_at = [&](int x, int y) -> std::uint8_t {
    return (x < 0 || y < 0 || x >= width || y >= height) ? 0 : flags[pixel_index(x, y)];
  };
  tbb::parallel_for(
      tbb::blocked_range<int>(0, corner_height), [&](const tbb::blocked_range<int>& rows) {
        for (int j = rows.begin(); j < rows.end(); ++j) {
          std::uint32_t running = 0;
          for (int i = 0; i < corner_width; ++i) {
            const std::uint8_t tl = flags_at(i - 1, j - 1), tr = flags_at(i, j - 1);
            const std::uint8_t bl = flags_at(i - 1, j), br = flags_at(i, j);
            const unsigned key = (tl & kValid) | (tr & kValid) << 1 | (bl & kValid) << 2 |
                                 (br & kValid) << 3 | ((tl & kRightContinuous) ? 1u << 4 : 0u) |
                                 ((bl & kRightContinuous) ? 1u << 5 : 0u) |
                                 ((tl & kDownContinuous) ? 1u << 6 : 0u) |
                                 ((tr & kDownContinuous) ? 1u << 7 : 0u);
            const std::size_t c = std::size_t(j) * corner_width + i;
            corner_key[c] = std::uint8_t(key);
            corner_base[c] = running;
            running += kCornerTable[key].count;
          }
          row_vertex_offset[j + 1] = running;
        }
      });
  for (int j = 0; j < corner_height; ++j) row_vertex_offset[j + 1] += row_vertex_offset[j];
  for (int y = 0; y < height; ++y) row_pixel_offset[y + 1] += row_pixel_offset[y];
  const std::uint64_t surface_vertices = row_vertex_offset[corner_height];
  const std::uint64_t surface_pixels = row_pixel_offset[height];

  // 4. Silhouette edges to extrude (optional): per pixel, bit s set when side s (0 top,
  // 1 bottom, 2 left, 3 right) faces a farther discontinuous neighbour or the sky.
  const bool extrude = options.thickness_m > 0;
  std::vector<std::uint8_t> silhouette;
  std::vector<std::uint64_t> row_edge_offset;
  if (extrude) {
    silhouette.assign(pixel_count, 0);
    row_edge_offset.assign(height + 1, 0);
    tbb::parallel_for(tbb::blocked_range<int>(0, height), [&](const tbb::blocked_range<int>& rows) {
      for (int y = rows.begin(); y < rows.end(); ++y) {
        std::uint64_t count = 0;
        for (int x = 0; x < width; ++x) {
          const std::size_t i = pixel_index(x, y);
          if (!(flags[i] & kValid)) continue;
          const float d = samples[i].distance_m;
          // Whether the neighbour across a side is behind a discontinuity, farther away.
          auto behind = [&](int qx, int qy, bool linked) {
            if (qx < 0 || qy < 0 || qx >= width || qy >= height) return false;  // image border
            const Sample& q = samples[pixel_index(qx, qy)];
            return !q.valid() || (!linked && q.distance_m > d);
          };
          std::uint8_t bits = 0;
          if (behind(x, y - 1, y > 0 && (flags_at(x, y - 1) & kDownContinuous))) bits |= 1;
          if (behind(x, y + 1, flags[i] & kDownContinuous)) bits |= 2;
          if (behind(x - 1, y, x > 0 && (flags_at(x - 1, y) & kRightContinuous))) bits |= 4;
          if (behind(x + 1, y, flags[i] & kRightContinuous)) bits |= 8;
          silhouette[i] = bits;
          count += std::popcount(bits);
        }
        row_edge_offset[y + 1] = count;
      }
    });
    for (int y = 0; y < height; ++y) row_edge_offset[y + 1] += row_edge_offset[y];
  }
  const std::uint64_t extruded_edges = extrude ? row_edge_offset[height] : 0;
  auto check_vertex_count = [&](std::uint64_t vertices) {
    if (vertices > std::numeric_limits<std::uint32_t>::max())
      throw Error(ErrorCode::invalid_argument,
                  "occluder mesh of a " + std::to_string(width) + "x" + std::to_string(height) +
                      " depth map would need " + std::to_string(vertices) +
                      " vertices, more than 32-bit indices hold");
  };
  check_vertex_count(surface_vertices + 2 * extruded_edges);  // before corner_base narrows

  TriangleMesh mesh;
  // The vertex count depends on the pixels to fan (step 6), known only once the corners are
  // placed: reserve for the worst case, every pixel fanned (pages never written are never
  // committed), plus one float: OccluderScene pads the vertex buffer for Embree's 16-byte loads
  // and should not have to reallocate 25 MB (1080p) to do it.
  mesh.positions.reserve(3 * (surface_vertices + surface_pixels + 2 * extruded_edges) + 1);
  advise_huge_pages(mesh.positions.data(), sizeof(float) * mesh.positions.capacity());
  mesh.positions.resize(3 * surface_vertices);
  auto store = [&mesh](std::uint64_t vertex, V3 v) {
    float* out = &mesh.positions[3 * vertex];
    out[0] = float(v.x);
    out[1] = float(v.y);
    out[2] = float(v.z);
  };
  // A vertex's z-depth (along the camera's forward axis).
  auto vertex_z = [&mesh, &frame, &origin](std::uint32_t vertex) {
    const float* v = &mesh.positions[3 * std::size_t(vertex)];
    return dot(V3{v[0], v[1], v[2]} - origin, frame.forward);
  };

  // 5. Corner vertices: per corner and group, the average distance at which the corner ray
  // meets the planes of the group's pixels.
  tbb::parallel_for(
      tbb::blocked_range<int>(0, corner_height), [&](const tbb::blocked_range<int>& rows) {
        for (int j = rows.begin(); j < rows.end(); ++j) {
          for (int i = 0; i < corner_width; ++i) {
            const std::size_t c = std::size_t(j) * corner_width + i;
            const std::uint64_t base = row_vertex_offset[j] + corner_base[c];
            corner_base[c] = std::uint32_t(base);
            const CornerGroups& groups = kCornerTable[corner_key[c]];
            if (groups.count == 0) continue;
            const V3 w = frame.unit_direction(i, j);
            double sum[4] = {0, 0, 0, 0};
            int n[4] = {0, 0, 0, 0};
            const int slot_x[4] = {i - 1, i, i - 1, i}, slot_y[4] = {j - 1, j - 1, j, j};
            for (int s = 0; s < 4; ++s) {
              if (groups.label[s] == 0xFF) continue;
              const std::size_t p = pixel_index(slot_x[s], slot_y[s]);
              sum[groups.label[s]] += plane_distance(planes[p], samples[p].distance_m, w);
              ++n[groups.label[s]];
            }
            for (int g = 0; g < groups.count; ++g) store(base + g, origin + (sum[g] / n[g]) * w);
          }
        }
      });
  auto vertex_of = [&](int i, int j, int slot) {
    const std::size_t c = std::size_t(j) * corner_width + i;
    return corner_base[c] + kCornerTable[corner_key[c]].label[slot];
  };

  // 6. Pixels to fan. A pixel's centre is the image midpoint of its diagonal c00-c11, where both
  // its triangles meet; inverse z-depth is affine in image coordinates along a 3D segment, so the
  // triangles pass the centre ray at the z-depth whose inverse is the mean of those of c00 and
  // c11. Where a crease crosses the pixel no choice of corners on the corner rays gets every
  // pixel centre right (a shared corner serves planes on both sides); such pixels get a vertex
  // of their own that puts the surface through their measured point (step 7).
  const double centre_tolerance = options.centre_tolerance;
  std::vector<std::uint64_t> row_fan_offset(height + 1, 0);
  tbb::parallel_for(tbb::blocked_range<int>(0, height), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y < rows.end(); ++y) {
      std::uint64_t count = 0;
      for (int x = 0; x < width; ++x) {
        const std::size_t i = pixel_index(x, y);
        if (!(flags[i] & kValid)) continue;
        const double inv_z = 0.5 / vertex_z(vertex_of(x, y, kBottomRight)) +
                             0.5 / vertex_z(vertex_of(x + 1, y + 1, kTopLeft));
        // The triangles' distance along the centre ray relative to the measured one.
        if (std::abs(double(samples[i].inv_z) / inv_z - 1.0) > centre_tolerance) {
          flags[i] |= kFan;
          ++count;
        }
      }
      row_fan_offset[y + 1] = count;
    }
  });
  for (int y = 0; y < height; ++y) row_fan_offset[y + 1] += row_fan_offset[y];
  const std::uint64_t fanned_pixels = row_fan_offset[height];
  // Vertices: corners, then one per fanned pixel, then the extrusions.
  const std::uint64_t centre_base = surface_vertices;
  const std::uint64_t extrusion_base = surface_vertices + fanned_pixels;
  const std::uint64_t total_vertices = extrusion_base + 2 * extruded_edges;
  check_vertex_count(total_vertices);
  mesh.positions.resize(3 * total_vertices);  // within the reserved capacity
  mesh.surface_triangle_count = 2 * (surface_pixels + fanned_pixels);
  mesh.indices.reserve(3 * (mesh.surface_triangle_count + 2 * extruded_edges) +
                       kAppendHeadroomIndices);
  advise_huge_pages(mesh.indices.data(), sizeof(std::uint32_t) * mesh.indices.capacity());
  mesh.indices.resize(3 * (mesh.surface_triangle_count + 2 * extruded_edges));

  // 7. Two triangles per surface pixel; a fanned pixel's centre vertex and its other two
  // triangles (layout: see TriangleMesh). The centre ray crosses the edge that the pixel's first
  // two triangles share (c00-c11, or m-c11 when fanned), which is v0 -> v1 in one and v2 -> v0
  // in the other: Embree's edge tests then compute the same value with opposite signs, so the
  // ray cannot slip between them even in non-robust mode. (A vertex on the centre ray itself
  // would be fragile: for a ray through a vertex Embree's edge tests come down to rounding
  // noise, and such rays were lost in tests.)
  const std::uint64_t fan_triangle_base = 2 * surface_pixels;
  tbb::parallel_for(tbb::blocked_range<int>(0, height), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y < rows.end(); ++y) {
      std::uint32_t* tri = mesh.indices.data() + 6 * row_pixel_offset[y];
      std::uint64_t fan = row_fan_offset[y];
      for (int x = 0; x < width; ++x) {
        const std::size_t i = pixel_index(x, y);
        if (!(flags[i] & kValid)) continue;
        // The pixel is the bottom-right neighbour of its top-left corner, and so on.
        const std::uint32_t c00 = vertex_of(x, y, kBottomRight);
        const std::uint32_t c10 = vertex_of(x + 1, y, kBottomLeft);
        const std::uint32_t c01 = vertex_of(x, y + 1, kTopRight);
        const std::uint32_t c11 = vertex_of(x + 1, y + 1, kTopLeft);
        if (flags[i] & kFan) {
          // m on the diagonal, halfway from c00 to the centre, at the depth that puts the
          // centre (1/3 of the way from m to c11 in the image) at the measured point; no
          // farther than 4x the pixel's z-depth (the limit applies only when c11 is over 2.5x
          // nearer than the pixel).
          const double inv_z = double(samples[i].inv_z);
          const double inv_zm = std::max(1.5 * inv_z - 0.5 / vertex_z(c11), 0.25 * inv_z);
          const std::uint32_t m = std::uint32_t(centre_base + fan);
          store(m, origin + (1.0 / inv_zm) * frame.direction(x + 0.25, y + 0.25));
          tri[0] = m, tri[1] = c11, tri[2] = c01;
          tri[3] = m, tri[4] = c10, tri[5] = c11;
          std::uint32_t* extra = mesh.indices.data() + 3 * (fan_triangle_base + 2 * fan);
          extra[0] = m, extra[1] = c00, extra[2] = c10;
          extra[3] = m, extra[4] = c01, extra[5] = c00;
          ++fan;
        } else {
          tri[0] = c00, tri[1] = c11, tri[2] = c01;
          tri[3] = c00, tri[4] = c10, tri[5] = c11;
          // Grid-eligible (SurfacePixelLayout): each corner has one vertex, corner_base's.
          auto single = [&](int ci, int cj) {
            return kCornerTable[corner_key[std::size_t(cj) * corner_width + ci]].count == 1;
          };
          if (options.pixel_layout && single(x, y) && single(x + 1, y) && single(x, y + 1) &&
              single(x + 1, y + 1))
            flags[i] |= kGridEligible;
        }
        tri += 6;
      }
    }
  });
  if (options.planar_merge_tolerance > 0) {
    merge_planar_pixels(mesh, flags, width, height, row_pixel_offset, row_fan_offset,
                        fan_triangle_base, options.planar_merge_tolerance, origin, vertex_of);
  }
  const bool keep_layout = options.pixel_layout && !(options.planar_merge_tolerance > 0);
  if (extrude) {
    const double thickness_m = options.thickness_m;
    tbb::parallel_for(tbb::blocked_range<int>(0, height), [&](const tbb::blocked_range<int>& rows) {
      for (int y = rows.begin(); y < rows.end(); ++y) {
        std::uint64_t edge = row_edge_offset[y];
        for (int x = 0; x < width; ++x) {
          const std::size_t i = pixel_index(x, y);
          const std::uint8_t bits = silhouette[i];
          if (!bits) continue;
          const std::uint32_t c00 = vertex_of(x, y, kBottomRight);
          const std::uint32_t c10 = vertex_of(x + 1, y, kBottomLeft);
          const std::uint32_t c01 = vertex_of(x, y + 1, kTopRight);
          const std::uint32_t c11 = vertex_of(x + 1, y + 1, kTopLeft);
          const std::uint32_t ends[4][2] = {{c00, c10}, {c01, c11}, {c00, c01}, {c10, c11}};
          const int neighbour_x[4] = {x, x, x - 1, x + 1}, neighbour_y[4] = {y - 1, y + 1, y, y};
          for (int side = 0; side < 4; ++side) {
            if (!((bits >> side) & 1)) continue;
            // Stop at the background behind the silhouette, if there is one.
            const Sample& q = samples[pixel_index(neighbour_x[side], neighbour_y[side])];
            const double depth_m =
                q.valid() ? std::min(thickness_m, double(q.distance_m - samples[i].distance_m))
                          : thickness_m;
            const std::uint64_t first = extrusion_base + 2 * edge;
            for (int e = 0; e < 2; ++e) {
              const float* v = &mesh.positions[3 * std::size_t(ends[side][e])];
              const V3 front{v[0], v[1], v[2]};
              const V3 ray = front - origin;
              const V3 back = front + (depth_m / length(ray)) * ray;
              float* out = &mesh.positions[3 * (first + e)];
              out[0] = float(back.x);
              out[1] = float(back.y);
              out[2] = float(back.z);
            }
            std::uint32_t* tri = mesh.indices.data() + 3 * (mesh.surface_triangle_count + 2 * edge);
            const std::uint32_t a = ends[side][0], b = ends[side][1];
            const std::uint32_t a_back = std::uint32_t(first), b_back = std::uint32_t(first + 1);
            tri[0] = a, tri[1] = b, tri[2] = b_back;
            tri[3] = a, tri[4] = b_back, tri[5] = a_back;
            ++edge;
          }
        }
      }
    });
  }
  if (keep_layout) {
    // The flags and corner table are done with: handed over, not copied.
    mesh.layout = std::make_shared<const SurfacePixelLayout>(width, height, std::move(flags),
                                                             std::move(corner_base));
  }
  return mesh;
}

double surface_sliver_share(const TriangleMesh& mesh, const Vec3& camera_position_m,
                            double pixel_angle_rad) {
  constexpr std::size_t kStride = 4;
  const std::size_t sampled = (mesh.surface_triangle_count + kStride - 1) / kStride;
  if (sampled == 0) return 0;
  const V3 camera{camera_position_m.x, camera_position_m.y, camera_position_m.z};
  auto vertex = [&](std::uint32_t index) {
    const float* p = &mesh.positions[3 * std::size_t(index)];
    return V3{p[0], p[1], p[2]};
  };
  const std::size_t slivers = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, sampled), std::size_t(0),
      [&](const tbb::blocked_range<std::size_t>& range, std::size_t count) {
        for (std::size_t s = range.begin(); s < range.end(); ++s) {
          const std::uint32_t* t = &mesh.indices[3 * kStride * s];
          const V3 a = vertex(t[0]), b = vertex(t[1]), c = vertex(t[2]);
          const double longest = std::max({length(b - a), length(c - b), length(a - c)});
          const double footprint = length(a - camera) * pixel_angle_rad;
          count += longest > kSliverFootprints * footprint;
        }
        return count;
      },
      std::plus<>());
  return double(slivers) / double(sampled);
}

DepthFur depth_fur_share(ConstImageView distance_m, const Camera& camera,
                         double discontinuity_ratio) {
  const int width = distance_m.width, height = distance_m.height;
  if (width < 3 || height < 3) return {};
  // Inverse camera depth of pixel (x, y): 1 / (distance * cos) = |(u, v, 1)| / distance; -1
  // where there is no surface.
  auto inverse_z = [&](int x, int y) {
    if (x < 0 || y < 0 || x >= width || y >= height) return -1.0;
    const double d = distance_m.at(x, y, 0);
    if (!(d > 0 && d < kInf)) return -1.0;
    const double u = (x + 0.5 - camera.cx) / camera.focal_px;
    const double v = (y + 0.5 - camera.cy) / camera.focal_px;
    return std::sqrt(u * u + v * v + 1) / d;
  };
  // Continuous in the mesh's plain sense: |d1 - d2| <= ratio * min(d1, d2), on 1 / d.
  auto close = [&](double w1, double w2) {
    return w1 > 0 && w2 > 0 && std::abs(w1 - w2) <= discontinuity_ratio * std::min(w1, w2);
  };
  // The signed second difference at the middle of three continuous pixels, in footprints; NaN
  // where they are not.
  auto bend = [&](double a, double b, double c) {
    if (!close(a, b) || !close(b, c)) return std::numeric_limits<double>::quiet_NaN();
    return (a - 2 * b + c) / b * camera.focal_px;
  };
  // A zig-zag: the pixel bends by more than kFurFootprints one way and a neighbour along the
  // same line the other way (a crease bends one pixel, one way: not counted).
  auto zig_zag = [&](double before, double here, double after) {
    auto opposite = [&](double other) {
      return std::abs(other) > kFurFootprints && (other > 0) != (here > 0);
    };
    return std::abs(here) > kFurFootprints && (opposite(before) || opposite(after));
  };
  struct Counts {
    std::size_t fur = 0, seen = 0;
  };
  const int rows = (height - 2 + 1) / 2;  // y = 1, 3, 5, ... < height - 1
  const Counts total = tbb::parallel_reduce(
      tbb::blocked_range<int>(0, rows), Counts{},
      [&](const tbb::blocked_range<int>& range, Counts counts) {
        for (int r = range.begin(); r < range.end(); ++r) {
          const int y = 1 + 2 * r;
          for (int x = 1; x + 1 < width; ++x) {
            const double w = inverse_z(x, y);
            if (w < 0) continue;
            const double wl = inverse_z(x - 1, y), wr = inverse_z(x + 1, y);
            const double wu = inverse_z(x, y - 1), wd = inverse_z(x, y + 1);
            const double along_x = bend(wl, w, wr), along_y = bend(wu, w, wd);
            if (std::isnan(along_x) && std::isnan(along_y)) continue;
            ++counts.seen;
            const bool fur = zig_zag(bend(inverse_z(x - 2, y), wl, w), along_x,
                                     bend(w, wr, inverse_z(x + 2, y))) ||
                             zig_zag(bend(inverse_z(x, y - 2), wu, w), along_y,
                                     bend(w, wd, inverse_z(x, y + 2)));
            counts.fur += fur;
          }
        }
        return counts;
      },
      [](Counts a, const Counts& b) {
        a.fur += b.fur;
        a.seen += b.seen;
        return a;
      });
  if (total.seen == 0) return {};
  return {double(total.fur) / double(total.seen), total.seen};
}

}  // namespace mr::render
