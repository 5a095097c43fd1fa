// Private to libmr: the watertight ray-triangle test (Woop, Benthin & Wald 2013, JCGT 2(1)) that
// the CPU's own shadow traversals share (render/shadow_traversal/kd_tree.cpp,
// depth_image_surface.cpp): closed triangles (a ray through an edge or vertex hits every
// triangle sharing it), t_near < t <= t_far as Embree's rtcOccluded, no hit for a ray in the
// triangle's plane. Compile its users with -ffp-contract=off: a fused multiply-add in the edge
// functions would break the watertightness the test is for.
#pragma once

#include <cmath>
#include <utility>

namespace mr::render::shadow {

/// The ray, prepared for the watertight test (Woop et al. 2013, section 3).
struct WoopRay {
  float o[3], d[3], inv[3];
  int kx, ky, kz;
  float sx, sy, sz;
  float t_near, t_far;
  bool valid;
};

inline WoopRay prepare_woop_ray(const float origin[3], const float direction[3], float t_near,
                                float t_far) {
  WoopRay w{};
  for (int k = 0; k < 3; ++k) {
    w.o[k] = origin[k];
    w.d[k] = direction[k];
    w.inv[k] = 1.0f / direction[k];
  }
  w.t_near = t_near;
  w.t_far = t_far;
  const float ax = std::fabs(w.d[0]), ay = std::fabs(w.d[1]), az = std::fabs(w.d[2]);
  w.kz = ax > ay ? (ax > az ? 0 : 2) : (ay > az ? 1 : 2);
  w.kx = (w.kz + 1) % 3;
  w.ky = (w.kx + 1) % 3;
  if (w.d[w.kz] < 0.0f) std::swap(w.kx, w.ky);  // keep the winding
  w.valid = w.d[w.kz] != 0.0f && std::isfinite(w.d[w.kz]) && t_far > t_near;
  if (w.valid) {
    w.sx = w.d[w.kx] / w.d[w.kz];
    w.sy = w.d[w.ky] / w.d[w.kz];
    w.sz = 1.0f / w.d[w.kz];
  }
  return w;
}

/// Whether the prepared ray hits the triangle v[0..2], v[3..5], v[6..8], and where (t_hit).
inline bool hit_triangle(const WoopRay& r, const float* v, float& t_hit) {
  const float a[3] = {v[0] - r.o[0], v[1] - r.o[1], v[2] - r.o[2]};
  const float b[3] = {v[3] - r.o[0], v[4] - r.o[1], v[5] - r.o[2]};
  const float c[3] = {v[6] - r.o[0], v[7] - r.o[1], v[8] - r.o[2]};
  const float ax = a[r.kx] - r.sx * a[r.kz], ay = a[r.ky] - r.sy * a[r.kz];
  const float bx = b[r.kx] - r.sx * b[r.kz], by = b[r.ky] - r.sy * b[r.kz];
  const float cx = c[r.kx] - r.sx * c[r.kz], cy = c[r.ky] - r.sy * c[r.kz];
  float u = cx * by - cy * bx;
  float vv = ax * cy - ay * cx;
  float w = bx * ay - by * ax;
  if (u == 0.0f || vv == 0.0f || w == 0.0f) {  // the paper's fallback: exact in double
    u = float(double(cx) * double(by) - double(cy) * double(bx));
    vv = float(double(ax) * double(cy) - double(ay) * double(cx));
    w = float(double(bx) * double(ay) - double(by) * double(ax));
  }
  if ((u < 0.0f || vv < 0.0f || w < 0.0f) && (u > 0.0f || vv > 0.0f || w > 0.0f)) return false;
  const float det = u + vv + w;
  if (det == 0.0f) return false;
  const float az = r.sz * a[r.kz], bz = r.sz * b[r.kz], cz = r.sz * c[r.kz];
  t_hit = (u * az + vv * bz + w * cz) / det;
  return t_hit > r.t_near && t_hit <= r.t_far;
}

inline bool hit_triangle(const WoopRay& r, const float* v) {
  float t;
  return hit_triangle(r, v, t);
}

}  // namespace mr::render::shadow
