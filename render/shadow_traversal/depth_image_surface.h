// Private to libmr: shadow rays against the occluder mesh's surface traced in the image, over
// a min-max pyramid of the surface's camera depth, instead of through a BVH (issue 12 item 4).
//
// The surface of a mesh made by reconstruct_occluder_mesh is a depth image: every one of its
// triangles belongs to one pixel, and its vertices lie on that pixel's corner rays (a fanned
// pixel's own vertex on a ray through the pixel), so each triangle projects into its pixel's
// square. A ray that meets a triangle therefore meets it at a point that projects into that
// square, at a camera depth between the triangle's vertices' nearest and farthest. The pyramid
// holds, per pixel and per square of 2^L x 2^L pixels, the range of camera depth of the
// vertices of the triangles within; a ray is followed down the pyramid only through the
// squares its projection crosses where its own depth range there overlaps theirs, and tested
// exactly (watertight, render/shadow_traversal/triangle_test.h) against the triangles of the
// pixels it reaches. The answers are those of a BVH over the same triangles (robust mode): the
// culling is conservative (margins for rounding), the triangle test the same closed triangles.
// Building it is two passes over the pixels (no BVH build, no sorting): ~12 bytes a pixel.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "mr/camera.h"
#include "mr/scene.h"
#include "render/huge_pages.h"
#include "render/occluder_mesh.h"

namespace mr::render {

/// Four floats / ints in one SSE register (GCC and Clang vector extensions).
typedef float V4 __attribute__((vector_size(16)));
typedef int I4 __attribute__((vector_size(16)));

struct RayPacket8;  // render/embree_scene.h
namespace shadow {
struct WoopRay;  // render/shadow_traversal/triangle_test.h
}

class DepthImageSurface {
 public:
  /// Over the surface triangles of `mesh` (the first surface_triangle_count), which must carry
  /// its pixel layout (MeshOptions::pixel_layout; no planar merge) and have been made for
  /// `camera` and `pose`. Keeps a pointer to the mesh's positions and indices: the mesh must
  /// outlive this and not change. Parallel (TBB). Throws mr::Error(invalid_argument) when the
  /// mesh has no layout, the layout's size is not the camera's, or the camera is not supported.
  DepthImageSurface(const TriangleMesh& mesh, const Camera& camera, const CameraPose& pose);

  /// Whether a camera's size is within what the walk handles (2^15 px a side).
  static bool supports(const Camera& camera) {
    return camera.width > 0 && camera.height > 0 && camera.width <= 32768 && camera.height <= 32768;
  }

  /// Whether a surface triangle lies on origin + t * direction, t_near < t <= t_far (the
  /// semantics of render/shadow_query.h).
  bool occluded(const std::array<float, 3>& origin, const std::array<float, 3>& direction,
                float t_near, float t_far) const;
  /// The nearest surface triangle's t on the ray within (t_near, t_far], or +infinity.
  float intersect_distance(const std::array<float, 3>& origin,
                           const std::array<float, 3>& direction, float t_near, float t_far) const;
  /// occluded() for the valid lanes of a packet; invalid lanes get false.
  void occluded8(const RayPacket8& rays, bool occluded_out[8]) const;

  /// Pyramid nodes visited and triangles tested by this thread so far, counted while
  /// count_work(true) (benchmarks).
  static std::array<std::uint64_t, 2> thread_counters();
  void count_work(bool on) { count_work_ = on; }

 private:
  struct Level {
    int width = 0, height = 0;
    /// Per square, its triangles' inverse camera depth (1 / z), nearest (the largest, widened
    /// by kDepthMargin) and farthest (narrowed by it); (-inf, +inf) where it has none. The
    /// four squares of each 2 x 2 group (the children of one square above) side by side,
    /// nearest four then farthest four, groups row by row: a ray's step down reads 32 bytes.
    HugePageArray<float> range{0};
    std::size_t group_of(int x, int y) const {
      return std::size_t(y >> 1) * std::size_t((width + 1) >> 1) + std::size_t(x >> 1);
    }
    std::size_t slots() const {
      return 8 * std::size_t((width + 1) >> 1) * std::size_t((height + 1) >> 1);
    }
    float nearest(int x, int y) const {
      return range[8 * group_of(x, y) + ((y & 1) << 1 | (x & 1))];
    }
    float farthest(int x, int y) const {
      return range[8 * group_of(x, y) + 4 + ((y & 1) << 1 | (x & 1))];
    }
    /// Stores a square's range (w_near >= w_far; -inf, +inf: empty), with the margins.
    void set(int x, int y, float w_near, float w_far);
    /// Marks the squares past the last column and row (odd sizes) empty.
    void pad();
    /// The four children of group (x, y) (both even).
    void group(int x, int y, V4& near, V4& far) const;
  };
  /// occluded (closest false: 0 for a hit, +inf for none) and intersect_distance (closest true).
  float trace(const std::array<float, 3>& origin, const std::array<float, 3>& direction,
              float t_near, float t_far, bool closest) const;
  /// A ray's segment within the surface's depth range and the image: its ends in pixel
  /// coordinates and their inverse camera depths.
  struct Segment {
    double x0, y0, x1, y1, w0, w1;
  };
  struct Walk;
  /// occluded8 where the CPU has AVX2: the eight rays walk the pyramid together.
  void occluded8_walk(const RayPacket8& rays, bool occluded_out[8]) const;
  bool image_segment(const float* origin, const float* direction, float t_near, float t_far,
                     Segment& seg) const;
  /// Whether the ray hits one of pixel (x, y)'s triangles; with t_best, lowers *t_best to the
  /// nearest hit's t (and tests all of them).
  bool test_pixel(int x, int y, const shadow::WoopRay& ray, std::uint64_t& tested,
                  float* t_best = nullptr) const;

  int width_ = 0, height_ = 0;
  double position_[3]{}, axis_[3][3]{};  // camera position; rows: right, down, forward
  double focal_ = 0, cx_ = 0, cy_ = 0;
  const float* positions_ = nullptr;
  const std::uint32_t* indices_ = nullptr;
  /// Per pixel: its first triangle (2k), and for a fanned pixel its other two (2N + 2f), or
  /// kNone.
  HugePageArray<std::uint32_t> first_triangle_{0}, fan_triangle_{0};
  std::vector<Level> levels_;  // levels_[0]: pixels; the last: one square
  float z_lo_ = 0, z_hi_ = 0;  // the nearest and farthest vertex depth
  bool count_work_ = false;
};

}  // namespace mr::render
