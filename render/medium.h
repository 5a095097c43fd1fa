// Private to libmr: the participating medium as the CPU scattering core evaluates it. The
// physics (density, closed-form optical depth along rays, DESIGN.md section 3, the inverse map
// from optical depth back to distance, noise) is render/physics/medium.h, shared with the GLSL
// shaders; this is its C++ face over mr::Medium.
#pragma once

#include <array>
#include <cmath>

#include "mr/scene.h"
#include "render/math.h"
#include "render/physics/medium.h"

namespace mr::render {

/// The shared physics' description of a medium's smooth density.
inline physics::MediumShape medium_shape(const Medium& m) {
  physics::MediumShape s;
  s.bottom_m = m.layer_bottom_m;
  s.top_m = m.layer_top_m;
  s.base_m = m.height_fog ? m.height_fog->base_height_m : 0.0;
  s.scale_m = m.height_fog ? m.height_fog->scale_height_m : 0.0;
  return s;
}

/// A ray o + t w inside the medium, with the parts of the medium's closed form that depend only
/// on the ray precomputed. All optical depths here are of the SMOOTH density (no noise) and for
/// a unit extinction: multiply by sigma_t (per channel) to get the channel's optical depth.
class RayDensity {
 public:
  RayDensity(const Medium& medium, const Vec3d& origin, const Vec3d& direction)
      : r_(physics::ray_density(medium_shape(medium), origin, direction)) {}
  explicit RayDensity(const physics::RayDensity& r) : r_(r) {}

  /// Unit-extinction optical depth from t0 to t1 (t1 may be +inf), >= 0; +inf if the ray runs
  /// forever through density bounded away from 0.
  double optical_depth(double t0, double t1) const { return physics::optical_depth(r_, t0, t1); }
  /// The t >= 0 where optical_depth(0, t) == target (target < optical_depth(0, inf)).
  double distance_at_optical_depth(double target) const {
    return physics::distance_at_optical_depth(r_, target);
  }
  /// Density rho at distance t (smooth part; 0 outside the layer).
  double density(double t) const { return physics::density(r_, t); }
  const physics::RayDensity& shared() const { return r_; }

 private:
  physics::RayDensity r_;
};

/// Smooth density at a world point (0 outside the layer).
inline double density_at(const Medium& medium, const Vec3d& x) {
  return physics::density_at(medium_shape(medium), x);
}

/// The noise modulation max(0, 1 + amplitude * fbm(x / scale)) (1 when noise is off).
inline double noise_modulation(const Medium::Noise& noise, const Vec3d& x) {
  return physics::noise_modulation(x, noise.amplitude, 1.0 / noise.scale_m, noise.octaves,
                                   noise.seed);
}

/// sigma_t (1/m) times a unit-density optical depth (m): 0 where there is no medium, also along
/// an infinite ray (0 * inf would be NaN: clear air transmits everything).
using physics::scaled_optical_depth;

/// Sky light only (physics::sky_only_inscatter) for optical depths `optical_depth` per channel.
/// The scattering core's sky-only path and the streaming pipeline (libmr/src/fog_stream.cpp)
/// both call this, so they give the same bits.
inline void sky_only_inscatter(const double optical_depth[3], const std::array<float, 3>& albedo,
                               const std::array<float, 3>& sky_radiance, double inscatter[3]) {
  // albedo L_sky in float, as it always was.
  const Vec3d albedo_sky{albedo[0] * sky_radiance[0], albedo[1] * sky_radiance[1],
                         albedo[2] * sky_radiance[2]};
  const Vec3d r = physics::sky_only_inscatter(
      Vec3d{optical_depth[0], optical_depth[1], optical_depth[2]}, albedo_sky);
  for (int c = 0; c < 3; ++c) inscatter[c] = r[c];
}

}  // namespace mr::render
