#include "render/blockers.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <string>
#include <utility>
#include <vector>

#include "mr/error.h"
#include "render/math.h"
#include "render/physics/medium.h"

namespace mr::render {

namespace {

using V = Vec3d;

double norm(const V& a) { return length(a); }
V at_height(const V& p, double y) { return {p[0], y, p[2]}; }

// Vertical structures: normals within ~17 degrees of horizontal.
constexpr double kVerticalNy = 0.3;
// Floors (normals within ~45 degrees of up) never shade the fog above them.
constexpr double kFloorNy = 0.7;
// Neighbours along an edge belong to one structure when their distances, or their planes'
// predictions of each other, agree within this fraction (as the occluder mesh's default).
constexpr double kContinuity = 0.05;
// A completed run's outline (one point per pixel along the frame's edge) is simplified to the
// points that stray more than this fraction of their distance from the straight line through
// their neighbours before it is extruded (Douglas-Peucker). Per-pixel quads 30 m long made the
// side edges' completion thousands of parallel slivers whose bounding boxes overlap along their
// whole length: every shadow ray passing them tested hundreds of triangles, and at 1080p the
// render's CPU time doubled (leuven, issue 12). The per-pixel points scatter with the depth's
// own noise, which is larger than this.
constexpr double kOutlineTolerance = 5e-3;

class Builder {
 public:
  Builder(TriangleMesh& mesh, ConstImageView distance, ConstImageView normals,
          const Camera& camera, const CameraPose& pose, const Blockers& blockers)
      : mesh_(mesh), d_(distance), n_(normals), cam_(camera), pose_(pose), b_(blockers) {
    o_ = vec(pose.position_m);
    const auto axes = pose.axes();
    up_cam_ = vec(axes[2]);
    right_cam_ = vec(axes[1]);
  }

  BlockerReport run() {
    const std::size_t before = mesh_.triangle_count();
    if (b_.completion.enabled) complete();
    if (b_.skyline) skyline(*b_.skyline);
    for (const Blockers::Polygon& p : b_.polygons) polygon(p);
    if (b_.canopy) canopy(*b_.canopy);
    report_.triangles = mesh_.triangle_count() - before;
    return std::move(report_);
  }

 private:
  struct Px {
    bool surface = false;
    double d = 0;
    V n{}, x{};
  };

  V ray(double px, double py) const { return vec(pose_.ray_direction(cam_, px, py)); }

  Px pixel(int x, int y) const {
    Px p;
    const double d = d_.at(x, y, 0);
    const V n = {n_.at(x, y, 0), n_.at(x, y, 1), n_.at(x, y, 2)};
    if (!(d > 0) || !std::isfinite(d) || dot(n, n) < 0.5) return p;
    p.surface = true;
    p.d = d;
    p.n = n;
    p.x = add(o_, ray(x, y), d);
    return p;
  }

  // Where ray r meets pixel p's plane, or a fallback distance along r when it meets it nearly
  // edge-on or far from the pixel's own distance.
  V on_plane(const Px& p, const V& r) const {
    const double dn = dot(r, p.n);
    if (std::fabs(dn) > 1e-6) {
      const double t = dot(sub(p.x, o_), p.n) / dn;
      if (t > 0.5 * p.d && t < 2 * p.d) return add(o_, r, t);
    }
    return add(o_, r, p.d);
  }

  bool continuous(const Px& a, const Px& b, const V& ra, const V& rb) const {
    if (!a.surface || !b.surface) return false;
    const bool va = std::fabs(a.n[1]) < kVerticalNy, vb = std::fabs(b.n[1]) < kVerticalNy;
    if (va != vb) return false;
    // Two vertical faces meeting at a corner (a pillar's front and side, the side seen at a
    // grazing angle a pixel or two wide, its normal often taken from the front) differ by more
    // than kContinuity where the side is hit far back; within 15 % they are one structure.
    const double ratio = va ? 0.15 : kContinuity;
    if (std::fabs(a.d - b.d) <= ratio * std::min(a.d, b.d)) return true;
    const double pa = norm(sub(on_plane(a, rb), o_)), pb = norm(sub(on_plane(b, ra), o_));
    return std::fabs(pa - b.d) <= kContinuity * b.d && std::fabs(pb - a.d) <= kContinuity * a.d;
  }

  // A pixel next to a run is in front of nothing: sky, or a surface clearly behind the run's.
  static bool behind_or_sky(const Px& neighbour, double d) {
    return !neighbour.surface || neighbour.d > 1.15 * d;
  }

  void add_triangle(const V& a, const V& b, const V& c) {
    const auto base = std::uint32_t(mesh_.vertex_count());
    for (const V* v : {&a, &b, &c})
      for (int k = 0; k < 3; ++k) mesh_.positions.push_back(float((*v)[k]));
    mesh_.indices.insert(mesh_.indices.end(), {base, base + 1, base + 2});
  }
  void add_quad(const V& a, const V& b, const V& c, const V& d) {
    if (norm(cross(sub(b, a), sub(c, a))) + norm(cross(sub(c, a), sub(d, a))) <= 1e-12) return;
    add_triangle(a, b, c);
    add_triangle(a, c, d);
  }

  // The outline's points that Douglas-Peucker keeps with a tolerance of kOutlineTolerance of
  // each point's distance from the camera (both ends always).
  std::vector<V> simplified(const std::vector<V>& outline) const {
    const std::size_t n = outline.size();
    if (n <= 2) return outline;
    std::vector<unsigned char> keep(n, 0);
    keep.front() = keep.back() = 1;
    std::vector<std::pair<std::size_t, std::size_t>> spans{{0, n - 1}};
    while (!spans.empty()) {
      const auto [i, j] = spans.back();
      spans.pop_back();
      if (j <= i + 1) continue;
      const V a = outline[i], ab = sub(outline[j], a);
      const double ab2 = dot(ab, ab);
      std::size_t worst = i;
      double worst_excess = 0;
      for (std::size_t k = i + 1; k < j; ++k) {
        const V ak = sub(outline[k], a);
        const double t = ab2 > 0 ? std::clamp(dot(ak, ab) / ab2, 0.0, 1.0) : 0.0;
        const double off = norm(sub(ak, V{t * ab[0], t * ab[1], t * ab[2]}));
        const double excess = off - kOutlineTolerance * norm(sub(outline[k], o_));
        if (excess > worst_excess) {
          worst_excess = excess;
          worst = k;
        }
      }
      if (worst == i) continue;
      keep[worst] = 1;
      spans.push_back({i, worst});
      spans.push_back({worst, j});
    }
    std::vector<V> out;
    for (std::size_t k = 0; k < n; ++k)
      if (keep[k]) out.push_back(outline[k]);
    return out;
  }

  // Horizontal distance from the camera.
  double horizontal(const V& p) const { return std::hypot(p[0] - o_[0], p[2] - o_[2]); }

  // The tops of vertical structures the photo shows (a vertical pixel below sky or below a
  // surface clearly behind it): (horizontal distance, world height), for estimating how tall
  // the structures cut by the frame are.
  // The maps are read directly first: the rays (trigonometry per pixel) only for the few pixels
  // that qualify (on a 1080p photo this stage took a third of a second, single-threaded).
  void collect_visible_tops() {
    auto surface_at = [&](int x, int y, double* d) {
      *d = d_.at(x, y, 0);
      const double nx = n_.at(x, y, 0), ny = n_.at(x, y, 1), nz = n_.at(x, y, 2);
      return *d > 0 && std::isfinite(*d) && nx * nx + ny * ny + nz * nz >= 0.5;
    };
    for (int y = 1; y < cam_.height; ++y)
      for (int x = 0; x < cam_.width; ++x) {
        double d = 0, d_above = 0;
        if (!surface_at(x, y, &d) || std::fabs(n_.at(x, y, 1)) >= kVerticalNy) continue;
        if (surface_at(x, y - 1, &d_above) && !(d_above > 1.15 * d)) continue;
        const Px p = pixel(x, y);
        if (!p.surface || !behind_or_sky(pixel(x, y - 1), p.d)) continue;  // as checked above
        const V top = on_plane(p, ray(x, y - 0.5));
        tops_.push_back({horizontal(top), top[1]});
      }
  }

  // Height to continue a vertical structure cut at world height cut_y, distance r, up to.
  std::pair<double, double> estimate_top(double r, double cut_y) const {
    std::vector<double> heights;
    for (const auto& [tr, ty] : tops_)
      if (tr >= 0.5 * r && tr <= 2 * r && ty > cut_y + 0.25) heights.push_back(ty);
    const double cap = b_.completion.max_height_m;
    if (heights.size() >= 3) {
      std::sort(heights.begin(), heights.end());
      const double h = heights[std::size_t(0.9 * double(heights.size() - 1))];
      return {std::min(h, cap), 0.7};
    }
    return {cap, 0.3};
  }

  // The structures cut by one edge of the frame. `edge_px(k)`: the pixel at position k along the
  // edge; `corner_ray(k)`: the ray through the frame's edge between positions k - 1 and k (k in
  // 0..count); `outward`: the frustum side plane's outward normal.
  template <typename EdgePx, typename CornerRay, typename Inner>
  void complete_edge(CompletedBlocker::Edge edge, int count, EdgePx edge_px, CornerRay corner_ray,
                     Inner inner_px, const V& outward) {
    std::vector<Px> px(static_cast<std::size_t>(count));
    std::vector<V> rays(static_cast<std::size_t>(count));
    for (int k = 0; k < count; ++k) {
      const auto [x, y] = edge_px(k);
      px[std::size_t(k)] = pixel(x, y);
      rays[std::size_t(k)] = ray(x, y);
    }
    int a = 0;
    while (a < count) {
      if (!px[std::size_t(a)].surface) {
        ++a;
        continue;
      }
      int b = a;
      while (b + 1 < count && continuous(px[std::size_t(b)], px[std::size_t(b + 1)],
                                         rays[std::size_t(b)], rays[std::size_t(b + 1)]))
        ++b;
      complete_run(edge, a, b, px, corner_ray, inner_px, outward);
      a = b + 1;
    }
  }

  template <typename CornerRay, typename Inner>
  void complete_run(CompletedBlocker::Edge edge, int a, int b, const std::vector<Px>& px,
                    CornerRay corner_ray, Inner inner_px, const V& outward) {
    const int n = b - a + 1;
    std::vector<double> ny;
    for (int k = a; k <= b; ++k) ny.push_back(px[std::size_t(k)].n[1]);
    std::nth_element(ny.begin(), ny.begin() + n / 2, ny.end());
    const double median_ny = ny[std::size_t(n / 2)];
    const bool vertical = std::fabs(median_ny) < kVerticalNy;
    if (median_ny > kFloorNy) return;  // a floor: it shades nothing above it
    // The run's outline on the frame's edge: corner k between pixels k - 1 and k, on their planes.
    std::vector<V> outline;
    for (int k = a; k <= b + 1; ++k) {
      const V r = corner_ray(k);
      V sum{0, 0, 0};
      int m = 0;
      for (int q : {k - 1, k})
        if (q >= a && q <= b) {
          sum = add(sum, on_plane(px[std::size_t(q)], r));
          ++m;
        }
      outline.push_back({sum[0] / m, sum[1] / m, sum[2] / m});
    }
    // A representative normal (the middle pixel's).
    const V normal = px[std::size_t((a + b) / 2)].n;
    CompletedBlocker s;
    s.edge = edge;
    s.first_px = a;
    s.last_px = b;
    s.vertical = vertical;
    const double max_y = b_.completion.max_height_m;
    if (edge == CompletedBlocker::Edge::top && vertical) {
      double cut_y = -1e300, r_sum = 0;
      for (const V& p : outline) {
        cut_y = std::max(cut_y, p[1]);
        r_sum += horizontal(p);
      }
      const auto [top, confidence] = estimate_top(r_sum / double(outline.size()), cut_y);
      s.top_m = top;
      s.confidence = confidence;
      const std::vector<V> wall = simplified(outline);
      for (std::size_t k = 0; k + 1 < wall.size(); ++k) {
        const V& p = wall[k];
        const V& q = wall[k + 1];
        if (top > std::min(p[1], q[1])) add_quad(p, q, at_height(q, top), at_height(p, top));
      }
      for (int k = a; k <= b; ++k) top_height_[std::size_t(k)] = top;
      // Pillars and trunks: narrow, standing free (sky or something farther on both sides).
      const double width = std::hypot(outline.back()[0] - outline.front()[0],
                                      outline.back()[2] - outline.front()[2]);
      const double d_mid = px[std::size_t((a + b) / 2)].d;
      const bool free_standing = a > 0 && b + 1 < int(px.size()) &&
                                 behind_or_sky(px[std::size_t(a - 1)], d_mid) &&
                                 behind_or_sky(px[std::size_t(b + 1)], d_mid);
      if (free_standing && width > 0 && width <= b_.completion.prism_max_width_m) {
        s.prism = true;
        s.confidence -= 0.1;
        std::vector<V> normals;
        for (int k = a; k <= b; ++k) normals.push_back(px[std::size_t(k)].n);
        prism(outline, normals, inner_px((a + b) / 2), top);
      }
    } else {
      // Along the surface's plane, away from the frame: the in-plane direction perpendicular to
      // where the plane crosses the frustum's side, pointing out of the frustum. Vertical
      // surfaces cut by a side edge stay level.
      V dir = vertical && edge != CompletedBlocker::Edge::top
                  ? unit(cross(normal, V{0, 1, 0}))
                  : unit(cross(cross(normal, outward), normal));
      if (dot(dir, outward) < 0) dir = {-dir[0], -dir[1], -dir[2]};
      if (dot(dir, outward) < 0.05) return;  // the plane runs along the frustum's side
      s.confidence = 0.4;
      auto extended = [&](const V& p) {
        double length = b_.completion.max_extent_m;
        if (dir[1] > 1e-9) length = std::min(length, std::max(0.0, (max_y - p[1]) / dir[1]));
        return add(p, dir, length);
      };
      const std::vector<V> edge_line = simplified(outline);
      for (std::size_t k = 0; k + 1 < edge_line.size(); ++k)
        add_quad(edge_line[k], edge_line[k + 1], extended(edge_line[k + 1]),
                 extended(edge_line[k]));
      // A vertical wall cut by a side edge and by the top: the corner beyond both, up to the
      // height the top edge's completion gave its column.
      if (vertical && a == 0) {
        const double top = edge == CompletedBlocker::Edge::left ? top_height_.front()
                                                                  : top_height_.back();
        const V& p = outline.front();
        const V q = extended(p);
        if (top > p[1]) add_quad(p, q, at_height(q, top), at_height(p, top));
      }
    }
    report_.completed.push_back(s);
  }

  // Closes a pillar whose faces the photo shows (`outline`, at the frame's top edge, segment k
  // on the plane with normals[k]) from the foot of the visible pillar up to `top`, as a box
  // aligned with its widest visible face: as wide as the outline spans along that face, as deep
  // as it is wide (a square section; a round trunk's guess too) or as the visible side shows,
  // whichever is more. Measured from the face's plane, not behind each outline point: a side
  // face seen at a grazing angle already shows part of the depth (behind every point, a pillar
  // 1.2 m deep became 2.1 m).
  void prism(const std::vector<V>& outline, const std::vector<V>& normals,
             const std::pair<int, int>& column, double top) {
    // The foot: walk down the middle column while the pixels stay on the same vertical face.
    const auto [x, y0] = column;
    double foot = outline.front()[1];
    Px prev = pixel(x, y0);
    for (int y = y0 + 1; y < cam_.height && prev.surface; ++y) {
      const Px p = pixel(x, y);
      if (!continuous(prev, p, ray(x, y - 1), ray(x, y))) break;
      foot = std::min(foot, on_plane(p, ray(x, y + 0.5))[1]);
      prev = p;
    }
    for (const V& p : outline) foot = std::min(foot, p[1]);
    // The widest face: the segments whose normals agree with one segment's, the most length
    // of outline between them; its normal their length-weighted mean (a single pixel's normal
    // is noisy, and a turned box grows with it; pixels that straddle a corner have a blend of
    // both faces' normals, hence the tight agreement).
    V along{0, 0, 0};
    double best = -1;
    for (std::size_t i = 0; i < normals.size(); ++i) {
      const V ni = unit(V{normals[i][0], 0, normals[i][2]});
      V sum{0, 0, 0};
      double length = 0;
      for (std::size_t k = 0; k < normals.size(); ++k) {
        const V nk = unit(V{normals[k][0], 0, normals[k][2]});
        if (dot(nk, ni) > 0.97) {
          const double l = norm(sub(at_height(outline[k + 1], 0), at_height(outline[k], 0)));
          sum = add(sum, nk, l);
          length += l;
        }
      }
      if (length > best && norm(sum) > 0) {
        best = length;
        along = unit(V{-sum[2], 0, sum[0]});
      }
    }
    if (best <= 0) return;
    const V mid = outline[outline.size() / 2];
    // Into the pillar: away from the camera, horizontally.
    V inward{along[2], 0, -along[0]};
    if (dot(inward, V{mid[0] - o_[0], 0, mid[2] - o_[2]}) < 0) inward = {-inward[0], 0, -inward[2]};
    double lo = 1e300, hi = -1e300, near = 1e300, far = -1e300;
    for (const V& p : outline) {
      lo = std::min(lo, dot(sub(p, mid), along));
      hi = std::max(hi, dot(sub(p, mid), along));
      near = std::min(near, dot(sub(p, mid), inward));
      far = std::max(far, dot(sub(p, mid), inward));
    }
    const double depth = std::max(hi - lo, far - near);
    auto corner = [&](double a, double b) {
      return add(add(at_height(mid, 0), along, a), inward, b);
    };
    const std::array<V, 4> ring{corner(lo, near), corner(hi, near), corner(hi, near + depth),
                                corner(lo, near + depth)};
    for (std::size_t k = 0; k < 4; ++k) {
      const V& p = ring[k];
      const V& q = ring[(k + 1) % 4];
      add_quad(at_height(p, foot), at_height(q, foot), at_height(q, top), at_height(p, top));
    }
    add_quad(at_height(ring[0], top), at_height(ring[1], top), at_height(ring[2], top),
             at_height(ring[3], top));
  }

  // Outward normal of the frustum plane through the camera and rays r1, r2, on the side of
  // `toward`.
  static V outward(const V& r1, const V& r2, const V& toward) {
    V m = unit(cross(r1, r2));
    if (dot(m, toward) < 0) m = {-m[0], -m[1], -m[2]};
    return m;
  }

  void complete() {
    const int w = cam_.width, h = cam_.height;
    collect_visible_tops();
    top_height_.assign(std::size_t(w), -1e300);
    const V tl = ray(-0.5, -0.5), tr = ray(w - 0.5, -0.5), bl = ray(-0.5, h - 0.5),
            br = ray(w - 0.5, h - 0.5);
    const V left_out = outward(tl, bl, {-right_cam_[0], -right_cam_[1], -right_cam_[2]});
    const V right_out = outward(tr, br, right_cam_);
    const V top_out = outward(tl, tr, up_cam_);
    using Pos = std::pair<int, int>;
    complete_edge(
        CompletedBlocker::Edge::top, w, [](int k) { return Pos{k, 0}; },
        [&](int k) { return ray(k - 0.5, -0.5); }, [](int k) { return Pos{k, 0}; }, top_out);
    complete_edge(
        CompletedBlocker::Edge::left, h, [](int k) { return Pos{0, k}; },
        [&](int k) { return ray(-0.5, k - 0.5); }, [](int k) { return Pos{0, k}; }, left_out);
    complete_edge(
        CompletedBlocker::Edge::right, h, [&](int k) { return Pos{w - 1, k}; },
        [&](int k) { return ray(w - 0.5, k - 0.5); }, [&](int k) { return Pos{w - 1, k}; },
        right_out);
  }

  void skyline(const Blockers::Skyline& sk) {
    std::vector<Blockers::SkylineSample> s = sk.samples;
    std::sort(s.begin(), s.end(),
              [](const auto& p, const auto& q) { return p.azimuth_deg < q.azimuth_deg; });
    // An open polyline of wall pieces between neighbouring samples; a ring when the samples
    // span 360 degrees (the first one repeated at its azimuth + 360).
    const std::vector<Blockers::SkylineSample>& ring = s;
    const double ground = 0;  // the wall stands on the ground
    constexpr double kPi = std::numbers::pi;
    auto point = [&](double az_deg, double y) {
      const double az = az_deg * kPi / 180;
      return V{o_[0] + sk.distance_m * std::sin(az), y, o_[2] + sk.distance_m * std::cos(az)};
    };
    for (std::size_t i = 0; i + 1 < ring.size(); ++i) {
      const auto& p = ring[i];
      const auto& q = ring[i + 1];
      // At most 5 degrees a piece, so the wall follows the circle.
      const int pieces = std::max(1, int(std::ceil((q.azimuth_deg - p.azimuth_deg) / 5.0)));
      for (int k = 0; k < pieces; ++k) {
        const double f0 = double(k) / pieces, f1 = double(k + 1) / pieces;
        const double az0 = p.azimuth_deg + f0 * (q.azimuth_deg - p.azimuth_deg);
        const double az1 = p.azimuth_deg + f1 * (q.azimuth_deg - p.azimuth_deg);
        const double h0 = p.height_m + f0 * (q.height_m - p.height_m);
        const double h1 = p.height_m + f1 * (q.height_m - p.height_m);
        add_quad(point(az0, ground), point(az1, ground), point(az1, h1), point(az0, h0));
      }
    }
  }

  void polygon(const Blockers::Polygon& p) {
    for (std::size_t k = 1; k + 1 < p.corners_m.size(); ++k)
      add_triangle(vec(p.corners_m[0]), vec(p.corners_m[k]), vec(p.corners_m[k + 1]));
  }

  static std::uint32_t hash(std::uint32_t x) { return physics::hash32(x); }

  void canopy(const Blockers::Canopy& c) {
    const int n = int(std::ceil(c.radius_m / c.cell_m));
    for (int j = -n; j < n; ++j) {
      int run_start = 0;
      bool in_run = false;
      for (int i = -n; i <= n; ++i) {
        bool blocked = false;
        if (i < n) {
          const double cx = (i + 0.5) * c.cell_m, cz = (j + 0.5) * c.cell_m;
          const std::uint32_t key = hash(c.seed ^ hash(std::uint32_t(i + 65536) * 73856093u ^
                                                       std::uint32_t(j + 65536) * 19349663u));
          const bool gap = double(key) / 4294967296.0 < c.gap_fraction;
          blocked = std::hypot(cx, cz) <= c.radius_m && !gap;
        }
        if (blocked && !in_run) {
          run_start = i;
          in_run = true;
        } else if (!blocked && in_run) {
          const double x0 = o_[0] + run_start * c.cell_m, x1 = o_[0] + i * c.cell_m;
          const double z0 = o_[2] + j * c.cell_m, z1 = o_[2] + (j + 1) * c.cell_m;
          add_quad({x0, c.height_m, z0}, {x1, c.height_m, z0}, {x1, c.height_m, z1},
                   {x0, c.height_m, z1});
          in_run = false;
        }
      }
    }
  }

  TriangleMesh& mesh_;
  ConstImageView d_, n_;
  const Camera& cam_;
  const CameraPose& pose_;
  const Blockers& b_;
  V o_{}, up_cam_{}, right_cam_{};
  std::vector<std::pair<double, double>> tops_;
  std::vector<double> top_height_;  // per column of the top row: height it was continued to
  BlockerReport report_;
};

}  // namespace

BlockerReport append_blockers(TriangleMesh& mesh, ConstImageView distance_m,
                              ConstImageView normals, const Camera& camera, const CameraPose& pose,
                              const Blockers& blockers) {
  const bool need_maps = blockers.completion.enabled;
  if (need_maps &&
      (distance_m.channels != 1 || distance_m.width != camera.width ||
       distance_m.height != camera.height || normals.channels != 3 ||
       normals.width != camera.width || normals.height != camera.height))
    throw Error(ErrorCode::invalid_argument,
                "append_blockers: need a 1-channel distance map and 3-channel normals of the "
                "camera's size " +
                    std::to_string(camera.width) + "x" + std::to_string(camera.height));
  return Builder(mesh, distance_m, normals, camera, pose, blockers).run();
}

}  // namespace mr::render
