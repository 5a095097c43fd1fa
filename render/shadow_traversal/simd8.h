// Private to libmr: 8-wide helpers (GCC/Clang vector extensions) for the CPU's own packet
// traversals of shadow rays (render/shadow_traversal/kd_tree.cpp, depth_image_surface.cpp).
// Functions using them are compiled for AVX2 (MR_PACKET_TARGET: one AVX2 op per 8 lanes; GCC
// lowers 8-wide vector comparisons lane by lane with scalar code on plain x86-64) and run where
// the CPU has it (MR_PACKET_ISA_PRESENT()); elsewhere their callers answer ray by ray. AVX2 does
// not include FMA: no fused operations. Vectors are passed by reference (an AVX argument by
// value to a function compiled without AVX changes the ABI).
#pragma once

#include <cstdint>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define MR_PACKET_TARGET __attribute__((target("avx2")))
#define MR_PACKET_ISA_PRESENT() __builtin_cpu_supports("avx2")
#else
#define MR_PACKET_TARGET
#define MR_PACKET_ISA_PRESENT() true
#endif

namespace mr::render::shadow {

using F8 = float __attribute__((vector_size(32)));
using I8 = std::int32_t __attribute__((vector_size(32)));

/// Bit k set where lane k of the mask is true (all ones).
MR_PACKET_TARGET inline unsigned bits(const I8& m) {
#if defined(__x86_64__) && defined(__GNUC__)
  return unsigned(_mm256_movemask_ps(reinterpret_cast<__m256>(m)));
#else
  unsigned r = 0;
  for (int k = 0; k < 8; ++k) r |= unsigned(m[k] < 0) << k;
  return r;
#endif
}

// Lane-wise choices as bit operations (and a vector ?: is lowered lane by lane with branches
// wherever the vectors are wider than the target's).
MR_PACKET_TARGET inline void blend(const I8& m, const F8& a, const F8& b, F8& out) {  // m ? a : b
  out = reinterpret_cast<F8>((m & reinterpret_cast<I8>(a)) | (~m & reinterpret_cast<I8>(b)));
}
MR_PACKET_TARGET inline void blend(const I8& m, const I8& a, const I8& b, I8& out) {
  out = (m & a) | (~m & b);
}
// std::max(a, b) and std::min(a, b) lane by lane, NaNs included.
MR_PACKET_TARGET inline void vmax(const F8& a, const F8& b, F8& out) {
  blend(a < b, b, a, out);
}
MR_PACKET_TARGET inline void vmin(const F8& a, const F8& b, F8& out) {
  blend(b < a, b, a, out);
}

}  // namespace mr::render::shadow
