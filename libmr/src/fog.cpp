#include "mr/fog.h"

#include <cmath>
#include <string>

#include "mr/error.h"
#include "photo/airlight.h"
#include "photo/composite.h"
#include "photo/illumination.h"
#include "render/homogeneous_fog.h"

namespace mr {

namespace {

void check_rgb(const Rgb& v, const char* name) {
  for (float c : v)
    if (!std::isfinite(c) || c < 0)
      throw Error(ErrorCode::invalid_argument,
                  std::string(name) + " (" + std::to_string(v[0]) + "," + std::to_string(v[1]) +
                      "," + std::to_string(v[2]) + ") must be finite and >= 0");
}

}  // namespace

// -ln(0.02): the contrast threshold of 2 % that defines meteorological visibility.
constexpr double kKoschmiederContrast = 3.912;

double extinction_from_visibility(double visibility_m) {
  if (!std::isfinite(visibility_m) || !(visibility_m > 0))
    throw Error(ErrorCode::invalid_argument,
                "visibility " + std::to_string(visibility_m) + " m must be positive and finite");
  return kKoschmiederContrast / visibility_m;
}

double visibility_from_extinction(double sigma_t_per_m) {
  if (!std::isfinite(sigma_t_per_m) || !(sigma_t_per_m > 0))
    throw Error(ErrorCode::invalid_argument,
                "extinction " + std::to_string(sigma_t_per_m) + " 1/m must be positive and finite");
  return kKoschmiederContrast / sigma_t_per_m;
}

Rgb estimate_airlight(const Image& photo) {
  if (photo.empty() || photo.channels() < 3)
    throw Error(ErrorCode::invalid_argument, "estimate_airlight needs an RGB image");
  return photo::estimate_airlight_dark_channel(photo.view());
}

Rgb exposure_relative_sun_irradiance(const Image& photo, const Image& distance_m,
                                     const Rgb& sky_radiance) {
  if (photo.empty() || photo.channels() < 3)
    throw Error(ErrorCode::invalid_argument, "exposure_relative_sun_irradiance needs an RGB photo");
  return photo::exposure_relative_sun(
             photo.view(), distance_m.empty() ? ConstImageView{} : distance_m.view(), sky_radiance)
      .irradiance;
}

FogLayers fog(const Image& photo, const Image& distance_m, const FogParams& params) {
  if (photo.empty() || photo.channels() < 3)
    throw Error(ErrorCode::invalid_argument, "fog: photo must have at least 3 channels, has " +
                                                 std::to_string(photo.channels()));
  if (distance_m.channels() != 1)
    throw Error(ErrorCode::invalid_argument, "fog: distance map must have 1 channel, has " +
                                                 std::to_string(distance_m.channels()));
  if (distance_m.width() != photo.width() || distance_m.height() != photo.height())
    throw Error(ErrorCode::size_mismatch,
                "fog: depth map is " + std::to_string(distance_m.width()) + "x" +
                    std::to_string(distance_m.height()) + ", photo is " +
                    std::to_string(photo.width()) + "x" + std::to_string(photo.height()));
  check_rgb(params.sigma_t_per_m, "extinction sigma_t");
  for (float d : distance_m.pixels())
    if (std::isnan(d)) throw Error(ErrorCode::invalid_argument, "fog: distance map holds NaN");

  FogLayers out;
  out.airlight = params.airlight ? *params.airlight : estimate_airlight(photo);
  check_rgb(out.airlight, "airlight");

  out.transmittance = Image::uninitialized(photo.width(), photo.height(), 3);
  out.inscatter = Image::uninitialized(photo.width(), photo.height(), 3);
  // Koschmieder: albedo 1, the sky radiance is the airlight (the radiance of deep fog).
  render::render_homogeneous_sky(distance_m.view(),
                                 {params.sigma_t_per_m, {1.0f, 1.0f, 1.0f}, out.airlight},
                                 out.transmittance.view(), out.inscatter.view());
  out.composite =
      Image::uninitialized(photo.width(), photo.height(), photo.channels(), photo.channel_names());
  out.composite.metadata() = photo.metadata();
  photo::composite(photo.view(), out.transmittance.view(), out.inscatter.view(),
                   out.composite.view());
  return out;
}

}  // namespace mr
