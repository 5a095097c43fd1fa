#include "render/shadow_traversal/depth_image_surface.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>

#include "mr/error.h"
#include "render/embree_scene.h"
#include "render/shadow_traversal/simd8.h"
#include "render/shadow_traversal/triangle_test.h"

namespace mr::render {

using shadow::bits;
using shadow::blend;
using shadow::F8;
using shadow::I8;
using shadow::vmax;
using shadow::vmin;

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
constexpr int kMaxLevels = 16;  // 2^15 px a side

thread_local std::uint64_t t_nodes = 0, t_triangles = 0;

/// The packet walk's intervals, per lane, of the segment within each of n columns (or rows)
/// [first + c, first + c + 1) * size, c < n, widened by kPixelMargin, within (ea, eb): the
/// single ray's Walk::step for one axis, for n children.
MR_PACKET_TARGET inline void child_intervals(int first, int size, int n, const F8& v0,
                                             const F8& inv_d, const I8& pos, const I8& neg,
                                             const F8& ea, const F8& eb, F8* a, F8* b) {
  const F8 minus_inf = F8{} - kInf;
  for (int c = 0; c < n; ++c) {
    const float lo_edge = float((first + c) * size) - kPixelMargin;
    const float hi_edge = float((first + c + 1) * size) + kPixelMargin;
    const F8 s_lo = (lo_edge - v0) * inv_d, s_hi = (hi_edge - v0) * inv_d;
    // Rising (pos): from s_lo to s_hi; falling (neg): from s_hi to s_lo; parallel: all or none.
    F8 rise_a, rise_b, fall_a, fall_b, flat_b, u;
    vmax(ea, s_lo, rise_a);
    vmin(eb, s_hi, rise_b);
    vmax(ea, s_hi, fall_a);
    vmin(eb, s_lo, fall_b);
    const I8 inside = (v0 >= lo_edge) & (v0 <= hi_edge);
    blend(inside, eb, minus_inf, flat_b);
    blend(neg, fall_a, ea, u);
    blend(pos, rise_a, u, a[c]);
    blend(neg, fall_b, flat_b, u);
    blend(pos, rise_b, u, b[c]);
  }
}

/// Triangle t's three vertices, x y z each.
inline void gather_triangle(const float* positions, const std::uint32_t* indices, std::uint32_t t,
                            float v[9]) {
  for (int c = 0; c < 3; ++c) {
    const float* p = positions + 3 * std::size_t(indices[3 * std::size_t(t) + c]);
    v[3 * c] = p[0];
    v[3 * c + 1] = p[1];
    v[3 * c + 2] = p[2];
  }
}

inline V4 max4(V4 a, V4 b) {
  return a > b ? a : b;
}
inline V4 min4(V4 a, V4 b) {
  return a < b ? a : b;
}

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

std::array<std::uint64_t, 2> DepthImageSurface::thread_counters() {
  return {t_nodes, t_triangles};
}

DepthImageSurface::DepthImageSurface(const TriangleMesh& mesh, const Camera& camera,
                                     const CameraPose& pose) {
  const SurfacePixelLayout* layout = mesh.layout.get();
  if (!layout)
    throw Error(ErrorCode::invalid_argument,
                "depth-image shadow traversal: the occluder mesh has no pixel layout");
  if (!supports(camera))
    throw Error(ErrorCode::invalid_argument,
                "depth-image shadow traversal: a camera of " + std::to_string(camera.width) + "x" +
                    std::to_string(camera.height) + " is larger than 32768 px a side");
  if (layout->width != camera.width || layout->height != camera.height)
    throw Error(ErrorCode::invalid_argument, "depth-image shadow traversal: the mesh's layout is " +
                                                 std::to_string(layout->width) + "x" +
                                                 std::to_string(layout->height) + ", the camera " +
                                                 std::to_string(camera.width) + "x" +
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

bool DepthImageSurface::test_pixel(int x, int y, const shadow::WoopRay& ray, std::uint64_t& tested,
                                   float* t_best) const {
  const std::size_t i = std::size_t(y) * width_ + x;
  const std::uint32_t tris[2] = {first_triangle_[i], fan_triangle_[i]};
  for (std::uint32_t first : tris) {
    if (first == kNone) continue;
    for (std::uint32_t t = first; t < first + 2; ++t) {
      ++tested;
      float v[9];
      gather_triangle(positions_, indices_, t, v);
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
  bool start(const DepthImageSurface& s, const float* origin, const float* direction, float t_near,
             float t_far, bool closest_hit) {
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

// occluded8's walk: the packet's rays down the pyramid together, one square at a time for all
// of them, each lane with its own segment and interval (the march's packets are steps along one
// view ray toward points of the sun's disk: they start at one pixel and fan out slightly, so
// they visit mostly the same squares, and a square's test costs about the same for eight lanes
// as for one). A lane's culling is the single ray's, in 8-wide form: the answers are the same.
MR_PACKET_TARGET void DepthImageSurface::occluded8_walk(const RayPacket8& rays,
                                                        bool occluded_out[8]) const {
  alignas(32) float x0[8], y0[8], dx[8], dy[8], inv_dx[8], inv_dy[8], w0[8], dw[8], slack[8];
  shadow::WoopRay woop[8];
  unsigned active = 0;
  float x_lo = kInf, x_hi = -kInf, y_lo = kInf, y_hi = -kInf;
  std::uint64_t tested = 0, nodes = 0;
  for (int k = 0; k < 8; ++k) {
    occluded_out[k] = false;
    x0[k] = y0[k] = dx[k] = dy[k] = w0[k] = dw[k] = slack[k] = 0;
    inv_dx[k] = inv_dy[k] = kInf;
    if (!rays.valid[k]) continue;
    const float origin[3] = {rays.origin_x[k], rays.origin_y[k], rays.origin_z[k]};
    const float direction[3] = {rays.direction_x[k], rays.direction_y[k], rays.direction_z[k]};
    Segment seg;
    if (!image_segment(origin, direction, rays.t_near[k], rays.t_far[k], seg)) continue;
    woop[k] = shadow::prepare_woop_ray(origin, direction, rays.t_near[k], rays.t_far[k]);
    if (!woop[k].valid) continue;
    x0[k] = float(seg.x0);
    y0[k] = float(seg.y0);
    const float x1 = float(seg.x1), y1 = float(seg.y1), w1 = float(seg.w1);
    w0[k] = float(seg.w0);
    dx[k] = x1 - x0[k];
    dy[k] = y1 - y0[k];
    dw[k] = w1 - w0[k];
    inv_dx[k] = dx[k] != 0 ? 1.0f / dx[k] : kInf;
    inv_dy[k] = dy[k] != 0 ? 1.0f / dy[k] : kInf;
    slack[k] = 4e-7f * (std::fabs(w0[k]) + std::fabs(w1));
    x_lo = std::min(x_lo, std::min(x0[k], x1));
    x_hi = std::max(x_hi, std::max(x0[k], x1));
    y_lo = std::min(y_lo, std::min(y0[k], y1));
    y_hi = std::max(y_hi, std::max(y0[k], y1));
    active |= 1u << k;
  }
  auto test = [&](int x, int y, unsigned lanes) {
    for (unsigned m = lanes & active; m; m &= m - 1) {
      const int k = std::countr_zero(m);
      if (test_pixel(x, y, woop[k], tested)) {
        occluded_out[k] = true;
        active &= ~(1u << k);
      }
    }
  };
  if (active) {
    auto pixel_of = [](float v, int size) { return std::clamp(int(std::floor(v)), 0, size - 1); };
    const int px_lo = pixel_of(x_lo - kPixelMargin, width_),
              px_hi = pixel_of(x_hi + kPixelMargin, width_);
    const int py_lo = pixel_of(y_lo - kPixelMargin, height_),
              py_hi = pixel_of(y_hi + kPixelMargin, height_);
    const unsigned spread = unsigned((px_lo ^ px_hi) | (py_lo ^ py_hi));
    const int top_level = int(levels_.size()) - 1;
    const int start_level = std::min(top_level, spread ? 32 - __builtin_clz(spread) : 0);
    if (start_level == 0) test(px_lo, py_lo, active);
    if (start_level > 0) {
      F8 vx0, vy0, vinv_dx, vinv_dy, vw0, vdw, vslack;
      std::memcpy(&vx0, x0, sizeof vx0);
      std::memcpy(&vy0, y0, sizeof vy0);
      std::memcpy(&vinv_dx, inv_dx, sizeof vinv_dx);
      std::memcpy(&vinv_dy, inv_dy, sizeof vinv_dy);
      std::memcpy(&vw0, w0, sizeof vw0);
      std::memcpy(&vdw, dw, sizeof vdw);
      std::memcpy(&vslack, slack, sizeof vslack);
      F8 vdx, vdy;
      std::memcpy(&vdx, dx, sizeof vdx);
      std::memcpy(&vdy, dy, sizeof vdy);
      const F8 zero = F8{} + 0.0f;
      const I8 pos_x = vdx > zero, neg_x = vdx<zero, pos_y = vdy> zero, neg_y = vdy < zero;
      // The children are visited in the order the first lane meets them (any order gives the
      // same answers).
      const int lead = std::countr_zero(active);
      struct alignas(32) Entry {
        F8 a, b;
        int level, i, j;
        unsigned lanes;
      };
      // At most 7 of a square's 16 children lie along a segment (9 within the margins) and
      // a walk is 6 levels deep at 1080p (8 at 50 MP): 16 a level is ample.
      Entry stack[16 * kMaxLevels];
      int top = 0;
      stack[0].a = zero;
      stack[0].b = zero + 1.0f;
      stack[0].level = start_level;
      stack[0].i = px_lo >> start_level;
      stack[0].j = py_lo >> start_level;
      stack[0].lanes = active;
      top = 1;
      while (top > 0 && active) {
        --top;
        const unsigned lanes = stack[top].lanes & active;
        if (!lanes) continue;
        const int level = stack[top].level;
        const F8 ea = stack[top].a, eb = stack[top].b;
        ++nodes;
        // Down two levels at once where there are two (its 16 grandchildren, whose ranges lie
        // in two cache lines: half the steps of a walk, each a miss or two), else one.
        const int down = level >= 2 ? 2 : 1, n = 1 << down;
        const int child_level = level - down, size = 1 << child_level;
        const int bi = stack[top].i << down, bj = stack[top].j << down;
        const Level& below = levels_[std::size_t(child_level)];
        F8 col_a[4], col_b[4], row_a[4], row_b[4];
        child_intervals(bi, size, n, vx0, vinv_dx, pos_x, neg_x, ea, eb, col_a, col_b);
        child_intervals(bj, size, n, vy0, vinv_dy, pos_y, neg_y, ea, eb, row_a, row_b);
        // The children's ranges, 2 x 2 groups at a time (a group past the level's last row or
        // column: empty).
        alignas(16) float near[16], far[16];
        for (int gr = 0; gr < n; gr += 2)
          for (int gc = 0; gc < n; gc += 2) {
            V4 gn = V4{} - kInf, gf = V4{} + kInf;
            if (bi + gc < below.width && bj + gr < below.height)
              below.group(bi + gc, bj + gr, gn, gf);
            for (int k = 0; k < 4; ++k) {
              const int c = gc + (k & 1), r = gr + (k >> 1);
              near[r * n + c] = gn[k];
              far[r * n + c] = gf[k];
            }
          }
        int kept[16];
        F8 kept_a[16], kept_b[16];
        unsigned kept_lanes[16];
        float key[16];
        int count = 0;
        for (int r = 0; r < n; ++r)
          for (int c = 0; c < n; ++c) {
            F8 ca, cb, hi, lo;
            vmax(col_a[c], row_a[r], ca);
            vmin(col_b[c], row_b[r], cb);
            const F8 wa = vw0 + ca * vdw, wb = vw0 + cb * vdw;
            vmax(wa, wb, hi);
            vmin(wa, wb, lo);
            hi += vslack;
            lo -= vslack;
            const int k = r * n + c;
            const unsigned keep = bits((ca <= cb) & (hi >= far[k]) & (lo <= near[k])) & lanes;
            if (!keep) continue;
            // In the order the lead lane's segment meets them (insertion by where it enters).
            const float enter = ca[lead];
            int m = count++;
            while (m > 0 && key[m - 1] > enter) {
              kept[m] = kept[m - 1];
              kept_a[m] = kept_a[m - 1];
              kept_b[m] = kept_b[m - 1];
              kept_lanes[m] = kept_lanes[m - 1];
              key[m] = key[m - 1];
              --m;
            }
            kept[m] = k;
            kept_a[m] = ca;
            kept_b[m] = cb;
            kept_lanes[m] = keep;
            key[m] = enter;
          }
        if (child_level == 0) {  // the children are pixels: test them in order
          for (int m = 0; m < count && active; ++m)
            test(bi + kept[m] % n, bj + kept[m] / n, kept_lanes[m]);
          continue;
        }
        for (int m = count - 1; m >= 0; --m) {
          Entry& e = stack[top++];
          e.a = kept_a[m];
          e.b = kept_b[m];
          e.level = child_level;
          e.i = bi + kept[m] % n;
          e.j = bj + kept[m] / n;
          e.lanes = kept_lanes[m];
        }
      }
    }
  }
  if (count_work_) {
    t_nodes += nodes;
    t_triangles += tested;
  }
}

void DepthImageSurface::occluded8(const RayPacket8& rays, bool occluded_out[8]) const {
  static const bool packet_isa = MR_PACKET_ISA_PRESENT();
  if (packet_isa) return occluded8_walk(rays, occluded_out);
  for (int k = 0; k < 8; ++k)
    occluded_out[k] = rays.valid[k] != 0 &&
                      occluded({rays.origin_x[k], rays.origin_y[k], rays.origin_z[k]},
                               {rays.direction_x[k], rays.direction_y[k], rays.direction_z[k]},
                               rays.t_near[k], rays.t_far[k]);
}

}  // namespace mr::render
