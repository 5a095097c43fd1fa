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

/// The ray stream of a pixel's seed.
MR_FN uint ao_stream(uint seed) {
  return hash32(seed ^ 0x5bd1e995u);
}

/// Direction `index` of `ray_count` around unit normal n: cosine-weighted, stratified in
/// u1 = sin^2 of the polar angle, hashed (results depend only on the seed and the ray number).
MR_FN Float3 ao_direction(uint stream, int index, int ray_count, Float3 n, Float3 t1, Float3 t2) {
  const uint h1 = hash32(stream + 2u * uint(index));
  const uint h2 = hash32(h1 ^ 0x68e31da4u);
  const Float u1 = (Float(min(index, ray_count - 1)) + unit_float(h1)) / Float(ray_count);
  const Float phi = 2.0 * kPi * unit_float(h2);
  const Float r = sqrt(u1);
  const Float cos_theta = sqrt(max(0.0, 1.0 - u1));
  const Float lx = r * cos(phi);
  const Float ly = r * sin(phi);
  return Float3(lx * t1.x + ly * t2.x + cos_theta * n.x, lx * t1.y + ly * t2.y + cos_theta * n.y,
                lx * t1.z + ly * t2.z + cos_theta * n.z);
}

MR_PHYSICS_END

#endif  // MR_RENDER_PHYSICS_OCCLUSION_H
