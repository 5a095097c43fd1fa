// Sky light by direction (mr/sky_light.h): the photo's environment, its phase convolution
// (photo/sky_light.h) and the correction of R with the core's closed form (render/medium.h).
#include "mr/sky_light.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "mr/error.h"
#include "photo/airlight.h"
#include "photo/sky_light.h"
#include "render/medium.h"

namespace mr {

namespace {

std::string size_text(int w, int h) {
  return std::to_string(w) + "x" + std::to_string(h);
}

}  // namespace

Rgb SkyLight::deviation_at(const Vec3& direction) const {
  if (deviation.empty()) return {0, 0, 0};
  const auto d = photo::sample_latlong(deviation, direction);
  return {float(d[0]), float(d[1]), float(d[2])};
}

Rgb SkyLight::deviation_at(const Vec3& direction, int x, int y) const {
  const Rgb d = deviation_at(direction);
  const float s = scale.empty() ? 1.0f : scale.at(x, y, 0);
  const float* t = tint.empty() ? nullptr : tint.pixel(x, y);
  if (s == 1.0f && (!t || (t[0] == 1.0f && t[1] == 1.0f && t[2] == 1.0f))) return d;
  Rgb out;
  for (int c = 0; c < 3; ++c)
    out[c] = s * (t ? t[c] : 1.0f) * (sky_radiance[c] + d[c]) - sky_radiance[c];
  return out;
}

SkyLight sky_light_from_photo(const Image& photo, const Image& distance_m, const Camera& camera,
                              const FogScene& scene, const Rgb& sky_radiance,
                              bool brightness_from_photo) {
  if (photo.empty() || photo.channels() < 3)
    throw Error(ErrorCode::invalid_argument,
                "sky_light_from_photo: the photo must have at least 3 channels, has " +
                    std::to_string(photo.channels()));
  if (distance_m.channels() != 1)
    throw Error(ErrorCode::invalid_argument,
                "sky_light_from_photo: the distance map must have 1 channel, has " +
                    std::to_string(distance_m.channels()));
  if (photo.width() != camera.width || photo.height() != camera.height ||
      distance_m.width() != camera.width || distance_m.height() != camera.height)
    throw Error(ErrorCode::size_mismatch,
                "sky_light_from_photo: photo " + size_text(photo.width(), photo.height()) +
                    ", distance map " + size_text(distance_m.width(), distance_m.height()) +
                    ", camera " + size_text(camera.width, camera.height));
  SkyLight out;
  out.sky_radiance = sky_radiance;
  out.g = scene.medium.g;
  const photo::LatLongSizes sizes = photo::latlong_sizes_for(out.g);
  const Image env = photo::environment_deviation(photo.view(), distance_m.view(), camera,
                                                 scene.pose, sky_radiance, sizes.env_width,
                                                 sizes.env_height);
  if (photo::all_zero(env)) return out;  // uniform: exactly today's render
  out.deviation =
      photo::convolve_henyey_greenstein(env, out.g, sizes.out_width, sizes.out_height);
  // Every automatic fog colour goes through the neutral prior (photo/airlight.h: fog takes the
  // colour of daylight, 4000..10000 K): so does the light from each direction, so a deep blue
  // sky or a red sunset tints the fog as a daylight would, no more.
  for (int y = 0; y < out.deviation.height(); ++y)
    for (int x = 0; x < out.deviation.width(); ++x) {
      float* d = out.deviation.pixel(x, y);
      const std::array<float, 3> light{std::max(0.0f, sky_radiance[0] + d[0]),
                                       std::max(0.0f, sky_radiance[1] + d[1]),
                                       std::max(0.0f, sky_radiance[2] + d[2])};
      const std::array<float, 3> bounded = photo::neutral_fog_colour(light);
      for (int c = 0; c < 3; ++c) d[c] = bounded[c] - sky_radiance[c];
    }
  const double weight = sky_brightness_scale_weight(scene.medium);
  if (brightness_from_photo && weight > 0) {
    out.scale = photo::sky_brightness_scale(photo.view(), distance_m.view(), camera, scene.pose,
                                            out.deviation, sky_radiance, &out.tint);
    if (weight < 1) {
      for (float& s : out.scale.pixels()) s = float(std::pow(double(s), weight));
      for (float& t : out.tint.pixels()) t = float(std::pow(double(t), weight));
    }
  }
  return out;
}

double sky_brightness_scale_weight(const Medium& medium) {
  const double sigma_t_per_m =
      (double(medium.sigma_t_per_m[0]) + medium.sigma_t_per_m[1] + medium.sigma_t_per_m[2]) / 3;
  if (!(sigma_t_per_m > 0)) return 1;
  return std::clamp(std::log2(visibility_from_extinction(sigma_t_per_m) / 500), 0.0, 1.0);
}

void add_sky_light(const SkyLight& sky_light, const Medium& medium, const Camera& camera,
                   const CameraPose& pose, const Image& optical_depth, Image& inscatter) {
  if (optical_depth.channels() != 3 || inscatter.channels() != 3 ||
      optical_depth.width() != camera.width || optical_depth.height() != camera.height ||
      inscatter.width() != camera.width || inscatter.height() != camera.height)
    throw Error(ErrorCode::size_mismatch,
                "add_sky_light: optical depth " +
                    size_text(optical_depth.width(), optical_depth.height()) + " and in-scatter " +
                    size_text(inscatter.width(), inscatter.height()) +
                    " must be 3-channel and the camera's " + size_text(camera.width, camera.height));
  if (sky_light.deviation.empty()) return;
  // The per-pixel maps (scale: 1 channel, tint: 3), when present, are the camera's size.
  auto check_map = [&](const Image& map, int channels, const char* name) {
    if (!map.empty() && (map.width() != camera.width || map.height() != camera.height ||
                         map.channels() != channels))
      throw Error(ErrorCode::size_mismatch,
                  std::string("add_sky_light: the sky light's ") + name + " is " +
                      size_text(map.width(), map.height()) + " with " +
                      std::to_string(map.channels()) + " channels, the camera " +
                      size_text(camera.width, camera.height) + " with " + std::to_string(channels));
  };
  check_map(sky_light.scale, 1, "scale");
  check_map(sky_light.tint, 3, "tint");
  tbb::parallel_for(0, camera.height, [&](int y) {
    for (int x = 0; x < camera.width; ++x) {
      const Rgb deviation = sky_light.deviation_at(pose.ray_direction(camera, x, y), x, y);
      const double od[3] = {optical_depth.at(x, y, 0), optical_depth.at(x, y, 1),
                            optical_depth.at(x, y, 2)};
      double extra[3];
      render::sky_only_inscatter(od, medium.albedo, deviation, extra);
      for (int c = 0; c < 3; ++c)
        inscatter.at(x, y, c) = float(std::max(0.0, inscatter.at(x, y, c) + extra[c]));
    }
  });
}

}  // namespace mr
