// Ambient-occlusion rays, shared by the CPU (render/embree_scene.cpp, traced with Embree) and the
// Vulkan shaders (shaders/scattering_common.glsl, marched in screen space against the depth
// map's surface): the same cosine-weighted directions for the same seed. In the common subset of
// C++ and GLSL (render/physics/types.h).
#ifndef MR_RENDER_PHYSICS_OCCLUSION_H
#define MR_RENDER_PHYSICS_OCCLUSION_H

#include "render/physics/medium.h"

MR_PHYSICS_BEGIN

/// An orthonormal basis (t1, t2) around unit n (Duff et al. 2017, branchless).
MR_FN void ao_basis(Float3 n, MR_OUT(Float3) t1, MR_OUT(Float3) t2) {
  const Float sign_ = copysign_one(n.z);
  const Float a = -1.0 / (sign_ + n.z);
  const Float b = n.x * n.y * a;
  t1 = Float3(1.0 + sign_ * n.x * n.x * a, sign_ * b, -sign_ * n.x);
  t2 = Float3(b, sign_ + n.y * n.y * a, -n.y);
}

/// A frame (t1, t2) around unit n that turns continuously with n: the frame (p1, p2) of the unit
/// pole p (ao_basis(p)), carried to n by the smallest rotation that takes p to n (Rodrigues).
/// Neighbouring pixels, whose normals differ a little, so get nearly the same AO directions
/// (ao_direction), and their AO differs where the geometry does, not from ray set to ray set.
/// ao_basis alone flips wherever n.z changes sign (a side wall's normals estimated from depth
/// do, at random). Singular only at n = -p: the backends take the camera's backward axis for p,
/// which no visible surface faces away from (a sample's normal that does gets any frame).
MR_FN void ao_frame(Float3 n, Float3 pole, MR_OUT(Float3) t1, MR_OUT(Float3) t2) {
  Float3 p1, p2;
  ao_basis(pole, p1, p2);
  const Float c = dot(pole, n);
  if (c < -0.999) {
    ao_basis(n, t1, t2);
    return;
  }
  const Float3 k = cross(pole, n);
  t1 = normalize(p1 * c + cross(k, p1) + k * (dot(k, p1) / (1.0 + c)));
  t2 = cross(n, t1);
}

/// The rotation of a render's AO ray set, from its seed.
MR_FN uint ao_stream(uint seed) {
  return hash32(seed ^ 0x5bd1e995u);
}

/// Direction `index` of `ray_count` around unit n (frame t1, t2 from ao_frame): cosine-weighted,
/// a spiral over the projected unit disk (its area, u1 = sin^2 of the polar angle, stratified at
/// the strata's midpoints), turned by the stream's rotation. The same set at every pixel: a
/// low-discrepancy set whose estimate changes only where a ray's visibility does, which
/// interpolation between grid samples keeps smooth (independent random sets per sample gave
/// blotches there, issue surf16). The angle advances by the golden angle every `stride` rays,
/// so that every stride-th ray (indices r, r + stride, ...) is itself a golden-angle spiral
/// (Fibonacci set; the AO traces those first, the rest only where they disagree); stride 1:
/// one spiral.
/// The frame-independent part of ao_direction: the direction's components (lx, ly, cos_theta)
/// along t1, t2 and n, the same at every point (the CPU keeps one render's set in a table).
MR_FN Float3 ao_local_direction(uint stream, int index, int ray_count, int stride) {
  const Float u1 = (Float(index) + 0.5) / Float(ray_count);
  const Float turn = Float(index) * (0.6180339887498949 / Float(stride)) + unit_float(stream);
  const Float phi = 2.0 * kPi * fract(turn);
  const Float r = sqrt(u1);
  const Float cos_theta = sqrt(max(0.0, 1.0 - u1));
  return Float3(r * cos(phi), r * sin(phi), cos_theta);
}
/// A local direction (ao_local_direction) in the frame t1, t2, n.
MR_FN Float3 ao_world_direction(Float3 local, Float3 n, Float3 t1, Float3 t2) {
  const Float lx = local.x;
  const Float ly = local.y;
  const Float cos_theta = local.z;
  return Float3(lx * t1.x + ly * t2.x + cos_theta * n.x, lx * t1.y + ly * t2.y + cos_theta * n.y,
                lx * t1.z + ly * t2.z + cos_theta * n.z);
}
MR_FN Float3 ao_direction(uint stream, int index, int ray_count, int stride, Float3 n, Float3 t1,
                          Float3 t2) {
  return ao_world_direction(ao_local_direction(stream, index, ray_count, stride), n, t1, t2);
}

MR_PHYSICS_END

#endif  // MR_RENDER_PHYSICS_OCCLUSION_H
