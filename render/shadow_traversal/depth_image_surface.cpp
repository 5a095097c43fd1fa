#include "render/shadow_traversal/depth_image_surface.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <cstring>
#include <string>

#include "mr/error.h"
#include "render/embree_scene.h"
#include "render/shadow_traversal/triangle_test.h"

namespace mr::render {

namespace {

constexpr std::uint32_t kNone = ~0u;
constexpr float kInf = std::numeric_limits<float>::infinity();
// Conservative margins of the culling (the triangle test itself is exact): a square is widened
// by this many pixels, a depth range by this fraction. The vertices project onto their corners
// to within ~1e-4 px (float positions), and the ray's image coordinates are computed in float
// from a camera-frame ray computed in double.
constexpr float kPixelMargin = 2e-3f;
constexpr float kDepthMargin = 1e-5f;
constexpr int kStackSize = 96;

thread_local std::uint64_t t_nodes = 0, t_triangles = 0;

inline V4 max4(V4 a, V4 b) { return a > b ? a : b; }
inline V4 min4(V4 a, V4 b) { return a < b ? a : b; }

}  // namespace

void DepthImageSurface::Level::set(int x, int y, float w_near, float w_far) {
  const std::size_t g = 8 * group_of(x, y), k = std::size_t((y & 1) << 1 | (x & 1));
  range[g + k] = w_near * (1.0f + kDepthMargin);
  range[g + 4 + k] = w_far * (1.0f - kDepthMargin);
}

void DepthImageSurface::Level::pad() {
  if (width & 1)
    for (int y = 0; y < height + (height & 1); ++y) set(width, y, -kInf, kInf);
  if (height & 1)
    for (int x = 0; x < width + (width & 1); ++x) set(x, height, -kInf, kInf);
}

void DepthImageSurface::Level::group(int x, int y, V4& near, V4& far) const {
  const float* g = range.data() + 8 * group_of(x, y);
  std::memcpy(&near, g, sizeof near);
  std::memcpy(&far, g + 4, sizeof far);
}

std::array<std::uint64_t, 2> DepthImageSurface::thread_counters() { return {t_nodes, t_triangles}; }

DepthImageSurface::DepthImageSurface(const TriangleMesh& mesh, const Camera& camera,
                                     const CameraPose& pose) {
  const SurfacePixelLayout* layout = mesh.layout.get();
  if (!layout)
    throw Error(ErrorCode::invalid_argument,
                "depth-image shadow traversal: the occluder mesh has no pixel layout");
  if (layout->width != camera.width || layout->height != camera.height)
    throw Error(ErrorCode::invalid_argument,
                "depth-image shadow traversal: the mesh's layout is " +
                    std::to_string(layout->width) + "x" + std::to_string(layout->height) +
                    ", the camera " + std::to_string(camera.width) + "x" +
                    std::to_string(camera.height));
  width_ = camera.width;
  height_ = camera.height;
  const auto [forward, right, up] = pose.axes();
  const Vec3 rows[3] = {right, Vec3{-up.x, -up.y, -up.z}, forward};
  for (int r = 0; r < 3; ++r) {
    axis_[r][0] = rows[r].x;
    axis_[r][1] = rows[r].y;
    axis_[r][2] = rows[r].z;
  }
  position_[0] = pose.position_m.x;
  position_[1] = pose.position_m.y;
  position_[2] = pose.position_m.z;
  focal_ = camera.focal_px;
  cx_ = camera.cx;
  cy_ = camera.cy;
  positions_ = mesh.positions.data();
  indices_ = mesh.indices.data();

  const int w = width_, h = height_;
  const std::size_t n = std::size_t(w) * std::size_t(h);
  // Triangle 2k is the k-th surface pixel's, 2N + 2f the f-th fanned pixel's (TriangleMesh).
  std::vector<std::uint32_t> row_surface(std::size_t(h) + 1, 0), row_fan(std::size_t(h) + 1, 0);
  const std::uint8_t* flags = layout->pixel.data();
  tbb::parallel_for(0, h, [&](int y) {
    std::uint32_t s = 0, f = 0;
    for (int x = 0; x < w; ++x) {
      const std::uint8_t b = flags[std::size_t(y) * w + x];
      if (b & SurfacePixelLayout::kSurface) {
        ++s;
        if (b & SurfacePixelLayout::kFanned) ++f;
      }
    }
    row_surface[std::size_t(y) + 1] = s;
    row_fan[std::size_t(y) + 1] = f;
  });
  for (int y = 0; y < h; ++y) {
    row_surface[std::size_t(y) + 1] += row_surface[std::size_t(y)];
    row_fan[std::size_t(y) + 1] += row_fan[std::size_t(y)];
  }
  const std::uint64_t surface_n = row_surface[std::size_t(h)], fan_n = row_fan[std::size_t(h)];
  if (2 * (surface_n + fan_n) != mesh.surface_triangle_count)
    throw Error(ErrorCode::internal,
                "depth-image shadow traversal: the mesh's layout does not match its triangles");
  first_triangle_ = HugePageArray<std::uint32_t>(n);
  fan_triangle_ = HugePageArray<std::uint32_t>(n);
  Level pixels;
  pixels.width = w;
  pixels.height = h;
  pixels.range = HugePageArray<float>(pixels.slots());
  const double* p0 = position_;
  const double* fwd = axis_[2];
  auto depth_of = [&](std::uint32_t vertex) {
    const float* v = positions_ + 3 * std::size_t(vertex);
    return (double(v[0]) - p0[0]) * fwd[0] + (double(v[1]) - p0[1]) * fwd[1] +
           (double(v[2]) - p0[2]) * fwd[2];
  };
  tbb::parallel_for(0, h, [&](int y) {
    std::uint32_t k = row_surface[std::size_t(y)], f = row_fan[std::size_t(y)];
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      const std::uint8_t b = flags[i];
      std::uint32_t first = kNone, fan = kNone;
      double lo = kInf, hi = -kInf;
      if (b & SurfacePixelLayout::kSurface) {
        first = 2 * k++;
        if (b & SurfacePixelLayout::kFanned) fan = std::uint32_t(2 * surface_n + 2 * f++);
        for (std::uint32_t t : {first, fan}) {
          if (t == kNone) continue;
          for (std::uint32_t c = 0; c < 6; ++c) {  // the pair's six corners (shared ones twice)
            const double z = depth_of(indices_[3 * std::size_t(t) + c]);
            lo = std::min(lo, z);
            hi = std::max(hi, z);
          }
        }
      }
      first_triangle_[i] = first;
      fan_triangle_[i] = fan;
      pixels.set(x, y, lo <= hi ? float(1 / lo) : -kInf, lo <= hi ? float(1 / hi) : kInf);
    }
  });
  levels_.push_back(std::move(pixels));
  while (levels_.back().width > 1 || levels_.back().height > 1) {
    const Level& below = levels_.back();
    Level up;
    up.width = (below.width + 1) / 2;
    up.height = (below.height + 1) / 2;
    up.range = HugePageArray<float>(up.slots());
    tbb::parallel_for(0, up.height, [&](int j) {
      for (int i = 0; i < up.width; ++i) {
        float w_near = -kInf, w_far = kInf;
        for (int dj = 0; dj < 2; ++dj)
          for (int di = 0; di < 2; ++di) {
            const int x = 2 * i + di, y = 2 * j + dj;
            if (x >= below.width || y >= below.height) continue;
            w_near = std::max(w_near, below.nearest(x, y));
            w_far = std::min(w_far, below.farthest(x, y));
          }
        up.set(i, j, w_near, w_far);
      }
    });
    levels_.push_back(std::move(up));
  }
  for (Level& level : levels_) level.pad();
  z_lo_ = 1.0f / levels_.back().nearest(0, 0);  // empty: z_lo_ < 0, and nothing is hit
  z_hi_ = 1.0f / levels_.back().farthest(0, 0);
}

bool DepthImageSurface::test_pixel(int x, int y, const shadow::WoopRay& ray,
                                   std::uint64_t& tested, float* t_best) const {
  const std::size_t i = std::size_t(y) * width_ + x;
  const std::uint32_t tris[2] = {first_triangle_[i], fan_triangle_[i]};
  for (std::uint32_t first : tris) {
    if (first == kNone) continue;
    for (std::uint32_t t = first; t < first + 2; ++t) {
      ++tested;
      float v[9];
      for (int c = 0; c < 3; ++c) {
        const float* p = positions_ + 3 * std::size_t(indices_[3 * std::size_t(t) + c]);
        v[3 * c] = p[0];
        v[3 * c + 1] = p[1];
        v[3 * c + 2] = p[2];
      }
      float t_hit;
      if (!shadow::hit_triangle(ray, v, t_hit)) continue;
      if (!t_best) return true;
      *t_best = std::min(*t_best, t_hit);
    }
  }
  return t_best && *t_best < kInf;
}

bool DepthImageSurface::image_segment(const float* origin, const float* direction, float t_near,
                                      float t_far, Segment& seg) const {
  if (!(t_far > t_near) || !(z_lo_ > 0 && z_lo_ <= z_hi_)) return false;
  // The ray in the camera frame (x right, y down, z forward), in double.
  double o[3], d[3];
  for (int r = 0; r < 3; ++r) {
    o[r] = axis_[r][0] * (double(origin[0]) - position_[0]) +
           axis_[r][1] * (double(origin[1]) - position_[1]) +
           axis_[r][2] * (double(origin[2]) - position_[2]);
    d[r] = axis_[r][0] * double(direction[0]) + axis_[r][1] * double(direction[1]) +
           axis_[r][2] * double(direction[2]);
  }
  // Where the ray lies within the surface's depth range and in front of the image's square:
  // in homogeneous image coordinates (u z, v z, z), linear in t, each bound is p + t q >= 0.
  double lo = t_near, hi = t_far;
  auto clip = [&](double p, double q) {
    if (q > 0)
      lo = std::max(lo, -p / q);
    else if (q < 0)
      hi = std::min(hi, -p / q);
    else if (p < 0)
      hi = -kInf;
  };
  const double z_min = double(z_lo_) * (1 - double(kDepthMargin));
  const double z_max = double(z_hi_) * (1 + double(kDepthMargin));
  clip(o[2] - z_min, d[2]);
  clip(z_max - o[2], -d[2]);
  const double hu0 = focal_ * o[0] + cx_ * o[2], hu1 = focal_ * d[0] + cx_ * d[2];
  const double hv0 = focal_ * o[1] + cy_ * o[2], hv1 = focal_ * d[1] + cy_ * d[2];
  const double m = kPixelMargin, wm = width_ + m, hm = height_ + m;
  clip(hu0 + m * o[2], hu1 + m * d[2]);
  clip(wm * o[2] - hu0, wm * d[2] - hu1);
  clip(hv0 + m * o[2], hv1 + m * d[2]);
  clip(hm * o[2] - hv0, hm * d[2] - hv1);
  if (!(lo <= hi) || !std::isfinite(hi)) return false;
  // The segment's image from (x0, y0) to (x1, y1); the inverse depth w = 1 / z is affine along
  // it (a perspective projection keeps lines, and inverse depth linear along them).
  const double za = o[2] + lo * d[2], zb = o[2] + hi * d[2];
  seg.x0 = (hu0 + lo * hu1) / za;
  seg.y0 = (hv0 + lo * hv1) / za;
  seg.x1 = (hu0 + hi * hu1) / zb;
  seg.y1 = (hv0 + hi * hv1) / zb;
  seg.w0 = 1 / za;
  seg.w1 = 1 / zb;
  return true;
}

bool DepthImageSurface::occluded(const std::array<float, 3>& origin,
                                 const std::array<float, 3>& direction, float t_near,
                                 float t_far) const {
  return trace(origin, direction, t_near, t_far, false) < kInf;
}

float DepthImageSurface::intersect_distance(const std::array<float, 3>& origin,
                                            const std::array<float, 3>& direction, float t_near,
                                            float t_far) const {
  return trace(origin, direction, t_near, t_far, true);
}

// One ray's walk down the pyramid, one square per step().
struct DepthImageSurface::Walk {
  const DepthImageSurface* surface = nullptr;
  float x0 = 0, y0 = 0, dx = 0, dy = 0, w0 = 0, dw = 0, inv_dx = 0, inv_dy = 0, w_slack = 0;
  int first_child = 0, last_child = 0, middle_a = 0, middle_b = 0;
  shadow::WoopRay ray{};
  bool closest = false;
  float t_best = kInf;
  bool hit = false;
  std::uint64_t nodes = 0, tested = 0;
  int top = 0;
  // The stack as separate arrays: an entry is written and read back field by field (a struct
  // copied in one wide load after narrow stores stalls on store forwarding).
  int stack_level[kStackSize], stack_i[kStackSize], stack_j[kStackSize];
  float stack_a[kStackSize], stack_b[kStackSize];

  /// False when there is nothing to walk: the ray misses the surface's image and depth range,
  /// or its segment lies within one pixel (then tested here).
  bool start(const DepthImageSurface& s, const float* origin, const float* direction,
             float t_near, float t_far, bool closest_hit) {
    surface = &s;
    closest = closest_hit;
    top = 0;
    Segment seg;
    if (!s.image_segment(origin, direction, t_near, t_far, seg)) return false;
    ray = shadow::prepare_woop_ray(origin, direction, t_near, t_far);
    if (!ray.valid) return false;
    x0 = float(seg.x0);
    y0 = float(seg.y0);
    const float x1 = float(seg.x1), y1 = float(seg.y1);
    w0 = float(seg.w0);
    const float w1 = float(seg.w1);
    dx = x1 - x0;
    dy = y1 - y0;
    dw = w1 - w0;
    // s in [0, 1] along the segment; s at image column x: (x - x0) / dx; a margin of
    // kPixelMargin (which covers the rounding of the ends, a few ulps of ~2^11 px) on each side
    // of a boundary.
    inv_dx = dx != 0 ? 1.0f / dx : kInf;
    inv_dy = dy != 0 ? 1.0f / dy : kInf;
    w_slack = 4e-7f * (std::fabs(w0) + std::fabs(w1));
    // The children of a square in the order the segment meets them: the first is on the side
    // it starts from in both axes, the last on the other in both; the middle two (one side in
    // one axis, the other in the other) in the order their intervals start.
    const int first_column = dx >= 0 ? 0 : 1, first_row = dy >= 0 ? 0 : 1;
    first_child = first_row * 2 + first_column;
    last_child = 3 - first_child;
    middle_a = first_row * 2 + (1 - first_column);
    middle_b = (1 - first_row) * 2 + first_column;
    // Start at the smallest square that holds the whole segment.
    const int top_level = int(s.levels_.size()) - 1;
    auto pixel_of = [](float v, int size) { return std::clamp(int(std::floor(v)), 0, size - 1); };
    const int px_lo = pixel_of(std::min(x0, x1) - kPixelMargin, s.width_);
    const int px_hi = pixel_of(std::max(x0, x1) + kPixelMargin, s.width_);
    const int py_lo = pixel_of(std::min(y0, y1) - kPixelMargin, s.height_);
    const int py_hi = pixel_of(std::max(y0, y1) + kPixelMargin, s.height_);
    const unsigned spread = unsigned((px_lo ^ px_hi) | (py_lo ^ py_hi));
    const int start_level = std::min(top_level, spread ? 32 - __builtin_clz(spread) : 0);
    if (start_level == 0) {
      test(px_lo, py_lo);
      return false;
    }
    stack_level[0] = start_level;
    stack_i[0] = px_lo >> start_level;
    stack_j[0] = py_lo >> start_level;
    stack_a[0] = 0.0f;
    stack_b[0] = 1.0f;
    top = 1;
    return true;
  }

  bool finished() const { return top == 0 || (hit && !closest); }

  /// Tests pixel (x, y)'s triangles. Any hit: the first ends the walk. Closest: every hit lowers
  /// the ray's t_far, and the walk goes on (a nearer hit can only lie in a pixel it reaches
  /// later within the margins, or in the same one).
  void test(int x, int y) {
    if (!surface->test_pixel(x, y, ray, tested, closest ? &t_best : nullptr)) return;
    hit = true;
    if (closest) ray.t_far = t_best;
  }

  /// One square: its children that the segment crosses where its depth overlaps theirs go on
  /// the stack (or, pixels, are tested).
  void step() {
    --top;
    const int level = stack_level[top], ci = 2 * stack_i[top], cj = 2 * stack_j[top];
    const float ea = stack_a[top], eb = stack_b[top];
    ++nodes;
    const Level& below = surface->levels_[std::size_t(level) - 1];
    const int half = 1 << (level - 1);
    // The segment's parameter interval in each column and row of the children: up to the
    // boundary (plus its margin) on the side it starts from, from it on the other.
    float col_a[2] = {ea, ea}, col_b[2] = {eb, eb};
    float row_a[2] = {ea, ea}, row_b[2] = {eb, eb};
    const float xm = float((ci + 1) * half), ym = float((cj + 1) * half);
    if (dx != 0) {
      const float s_left = (xm + kPixelMargin - x0) * inv_dx;   // leaving x <= xm + margin
      const float s_right = (xm - kPixelMargin - x0) * inv_dx;  // reaching x >= xm - margin
      if (dx > 0) {
        col_b[0] = std::min(eb, s_left);
        col_a[1] = std::max(ea, s_right);
      } else {
        col_a[0] = std::max(ea, s_left);
        col_b[1] = std::min(eb, s_right);
      }
    } else if (x0 > xm + kPixelMargin) {
      col_b[0] = -kInf;
    } else if (x0 < xm - kPixelMargin) {
      col_b[1] = -kInf;
    }
    if (dy != 0) {
      const float s_top = (ym + kPixelMargin - y0) * inv_dy;
      const float s_bottom = (ym - kPixelMargin - y0) * inv_dy;
      if (dy > 0) {
        row_b[0] = std::min(eb, s_top);
        row_a[1] = std::max(ea, s_bottom);
      } else {
        row_a[0] = std::max(ea, s_top);
        row_b[1] = std::min(eb, s_bottom);
      }
    } else if (y0 > ym + kPixelMargin) {
      row_b[0] = -kInf;
    } else if (y0 < ym - kPixelMargin) {
      row_b[1] = -kInf;
    }
    // The four children at once (lanes in slot order (0,0), (1,0), (0,1), (1,1)); a child
    // outside the image has an empty range (Level::pad).
    const V4 ca = max4(V4{col_a[0], col_a[1], col_a[0], col_a[1]},
                       V4{row_a[0], row_a[0], row_a[1], row_a[1]});
    const V4 cb = min4(V4{col_b[0], col_b[1], col_b[0], col_b[1]},
                       V4{row_b[0], row_b[0], row_b[1], row_b[1]});
    const V4 wa = w0 + ca * dw, wb = w0 + cb * dw;
    const V4 ray_hi = max4(wa, wb) + w_slack, ray_lo = min4(wa, wb) - w_slack;
    V4 near, far;
    below.group(ci, cj, near, far);
    const I4 keep = (ca <= cb) & (ray_hi >= far) & (ray_lo <= near);
    const bool swap_middle = ca[middle_b] < ca[middle_a];
    const int order[4] = {first_child, swap_middle ? middle_b : middle_a,
                          swap_middle ? middle_a : middle_b, last_child};
    if (level == 1) {  // the children are pixels: test them in order
      for (int n = 0; n < 4 && !(hit && !closest); ++n) {
        const int k = order[n];
        if (keep[k]) test(ci + (k & 1), cj + (k >> 1));
      }
      return;
    }
    for (int n = 3; n >= 0; --n) {
      const int k = order[n];
      if (!keep[k]) continue;
      stack_level[top] = level - 1;
      stack_i[top] = ci + (k & 1);
      stack_j[top] = cj + (k >> 1);
      stack_a[top] = ca[k];
      stack_b[top] = cb[k];
      ++top;
    }
  }

  void count() const {
    if (!surface->count_work_) return;
    t_nodes += nodes;
    t_triangles += tested;
  }
};

float DepthImageSurface::trace(const std::array<float, 3>& origin,
                               const std::array<float, 3>& direction, float t_near, float t_far,
                               bool closest) const {
  Walk walk;
  if (walk.start(*this, origin.data(), direction.data(), t_near, t_far, closest))
    while (!walk.finished()) walk.step();
  walk.count();
  if (closest) return walk.t_best;
  return walk.hit ? 0.0f : kInf;
}

void DepthImageSurface::occluded8(const RayPacket8& rays, bool occluded_out[8]) const {
  // Ray by ray: the march's packets (steps along one view ray toward points of the sun's disk)
  // fan out over several pixels of the image, so a shared walk gains little; nor did
  // interleaving the eight walks step by step (measured slower: more mispredicted branches).
  for (int k = 0; k < 8; ++k)
    occluded_out[k] =
        rays.valid[k] != 0 &&
        occluded({rays.origin_x[k], rays.origin_y[k], rays.origin_z[k]},
                 {rays.direction_x[k], rays.direction_y[k], rays.direction_z[k]}, rays.t_near[k],
                 rays.t_far[k]);
}

}  // namespace mr::render
