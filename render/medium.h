// Private to libmr: the participating medium as the scattering core evaluates it: density,
// closed-form optical depth along rays (DESIGN.md section 3), and the inverse map from optical
// depth back to distance that places march steps uniformly in transmittance.
#pragma once

#include <array>
#include <cmath>

#include "mr/scene.h"

namespace mr::render {

using Vec3d = std::array<double, 3>;

/// A ray o + t w inside the medium, with the parts of the medium's closed form that depend only
/// on the ray precomputed. All optical depths here are of the SMOOTH density (no noise) and for
/// a unit extinction: multiply by sigma_t (per channel) to get the channel's optical depth.
class RayDensity {
 public:
  RayDensity(const Medium& medium, const Vec3d& origin, const Vec3d& direction);

  /// Unit-extinction optical depth from t0 to t1 (t1 may be +inf), >= 0; +inf if the ray runs
  /// forever through density bounded away from 0.
  double optical_depth(double t0, double t1) const;
  /// The t >= 0 where optical_depth(0, t) == target (target < optical_depth(0, inf)).
  double distance_at_optical_depth(double target) const;
  /// Density rho at distance t (smooth part; 0 outside the layer).
  double density(double t) const;

 private:
  // Inside the layer [t_enter, t_exit] the density is k * exp(-a t) (a = w_y / H; a = 0 and
  // k = 1 for homogeneous fog).
  double t_enter_ = 0, t_exit_ = 0;
  double k_ = 0, a_ = 0;
  bool empty_ = true;
  double integral_from_enter(double t) const;  // of k exp(-a s) ds over [t_enter, t]
};

/// Smooth density at a world point (0 outside the layer).
double density_at(const Medium& medium, const Vec3d& x);

/// The noise modulation max(0, 1 + amplitude * fbm(x / scale)) (1 when noise is off).
double noise_modulation(const Medium::Noise& noise, const Vec3d& x);

/// Sky light only (no sun, no lamps, no noise; DESIGN.md section 3): the in-scatter R of a
/// pixel whose camera optical depths are `optical_depth` (per channel: sigma_t times
/// RayDensity's unit optical depth). The source albedo L_sky is constant along the ray, so the
/// march's sum telescopes to R = albedo L_sky (1 - tau) exactly; expm1 keeps thin fog's 1 - tau
/// precise, and grey fog needs it once. T is exp(-optical_depth) (S = 1: ambient light only).
/// The scattering core's sky-only path and the streaming pipeline (libmr/src/fog_stream.cpp)
/// both call this, so they give the same bits.
/// sigma_t (1/m) times a unit-density optical depth (m): 0 where there is no medium, also along
/// an infinite ray (0 * inf would be NaN: clear air transmits everything).
inline double scaled_optical_depth(double sigma_t_per_m, double unit_optical_depth_m) {
  return sigma_t_per_m > 0 ? sigma_t_per_m * unit_optical_depth_m : 0.0;
}

inline void sky_only_inscatter(const double optical_depth[3], const std::array<float, 3>& albedo,
                               const std::array<float, 3>& sky_radiance, double inscatter[3]) {
  double scattered = 0;  // 1 - tau
  for (int c = 0; c < 3; ++c) {
    if (c == 0 || !(optical_depth[c] == optical_depth[c - 1]))
      scattered = -std::expm1(-optical_depth[c]);
    inscatter[c] = albedo[c] * sky_radiance[c] * scattered;
  }
}

/// Henyey-Greenstein phase function; cos_theta = dot(view direction, direction to the light).
inline double henyey_greenstein(double g, double cos_theta) {
  const double denom = 1.0 + g * g - 2.0 * g * cos_theta;
  return (1.0 - g * g) / (4.0 * 3.14159265358979323846 * denom * std::sqrt(denom));
}

}  // namespace mr::render
