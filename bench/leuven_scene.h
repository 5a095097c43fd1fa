// The benchmark scene shared by bench_scattering and bench_vulkan: sample_photos/leuven.jpg +
// leuven_depth.exr (hfov 60 deg, camera 1.6 m above the street, horizon at row 362 of 563:
// pitch +7.05 deg), resized with OIIO (depth: nearest, so discontinuities stay sharp); a fog
// bank 15 m deep of 120 m visibility, albedo 0.9, g 0.5, sun at azimuth -70, elevation 18
// degrees casting shafts, sky radiance from the photo.
#pragma once

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>

#include <cmath>
#include <filesystem>
#include <map>
#include <utility>

#include "mr/mr.h"

namespace mr::bench {

struct Inputs {
  Image photo, depth;
  Camera camera;
};

inline Image to_image(const OIIO::ImageBuf& buf) {
  const auto& spec = buf.spec();
  Image im(spec.width, spec.height, spec.nchannels);
  buf.get_pixels(buf.roi(), OIIO::TypeDesc::FLOAT, im.data());
  return im;
}

/// The photo and its distance map at width x height (cached per size).
inline const Inputs& leuven_inputs(int width, int height) {
  static std::map<std::pair<int, int>, Inputs> cache;
  const auto key = std::make_pair(width, height);
  if (auto it = cache.find(key); it != cache.end()) return it->second;
  const std::filesystem::path dir = std::filesystem::path(MR_SOURCE_DIR) / "sample_photos";
  const Image photo = read_image(dir / "leuven.jpg");  // scene-linear
  ReadOptions raw;
  raw.to_scene_linear = false;
  raw.reject_non_finite = false;
  const Image depth = read_image(dir / "leuven_depth.exr", raw);
  OIIO::ImageBuf photo_buf(OIIO::ImageSpec(photo.width(), photo.height(), 3, OIIO::TypeDesc::FLOAT),
                           const_cast<float*>(photo.data()));
  OIIO::ImageBuf depth_buf(OIIO::ImageSpec(depth.width(), depth.height(), 1, OIIO::TypeDesc::FLOAT),
                           const_cast<float*>(depth.data()));
  Inputs in;
  in.photo = to_image(
      OIIO::ImageBufAlgo::resize(photo_buf, "", 0, OIIO::ROI(0, width, 0, height, 0, 1, 0, 3)));
  in.depth = to_image(
      OIIO::ImageBufAlgo::resample(depth_buf, false, OIIO::ROI(0, width, 0, height, 0, 1, 0, 1)));
  in.depth.set_channel_names({"Z"});
  for (float& d : in.depth.pixels())
    if (!(d > 0) || !std::isfinite(d)) d = INFINITY;
  in.camera = Camera::from_horizontal_fov(width, height, 60.0);
  return cache[key] = std::move(in);
}

inline constexpr double kLeuvenSunAzimuthDeg = -70, kLeuvenSunElevationDeg = 18;

/// The fog bank with a low sun (see the file comment) at a quality preset.
inline FogScene leuven_sun_scene(Quality quality) {
  FogScene s;
  const float sigma = float(extinction_from_visibility(120.0));
  s.medium.sigma_t_per_m = {sigma, sigma, sigma};
  s.medium.albedo = {0.9f, 0.9f, 0.9f};
  s.medium.g = 0.5;
  s.medium.layer_bottom_m = 0;  // a fog bank 15 m deep: sunlight enters through its top
  s.medium.layer_top_m = 15;
  s.pose.pitch_deg = 7.05;
  s.lighting.sun =
      Sun{direction_from_azimuth_elevation(kLeuvenSunAzimuthDeg, kLeuvenSunElevationDeg),
          {4, 3.8f, 3.4f},
          0.27};
  s.render.quality = quality;
  return s;
}

}  // namespace mr::bench
