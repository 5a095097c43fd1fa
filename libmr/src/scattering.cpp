// The scattering core's public entry points: validation, the lights estimated from the photo
// (photo/), the render (render/backend.h: backend choice, fall-back, occluder geometry), and the
// composite.
#include "mr/scattering.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>

#include "core/srgb_encode.h"
#include "mr/cancel.h"
#include "mr/color.h"
#include "mr/depth.h"
#include "mr/error.h"
#include "mr/sky_light.h"
#include "photo/airlight.h"
#include "photo/composite.h"
#include "photo/fog_seams.h"
#include "photo/illumination.h"
#include "photo/lamps.h"
#include "photo/sky_matte.h"
#include "render/backend.h"

namespace mr {

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

std::string size_text(int w, int h) {
  return std::to_string(w) + "x" + std::to_string(h);
}

// A lamp a little behind the visible surface at its pixel is inside the reconstructed geometry
// (the mesh is a thin shell of what the camera sees): its light would leak or vanish.
void check_lamps_outside_geometry(const Image& distance_m, const Camera& camera,
                                  const FogScene& scene) {
  const auto [forward, right, up] = scene.pose.axes();
  for (std::size_t i = 0; i < scene.lighting.lamps.size(); ++i) {
    const Vec3& p = scene.lighting.lamps[i].position_m;
    const Vec3 rel{p.x - scene.pose.position_m.x, p.y - scene.pose.position_m.y,
                   p.z - scene.pose.position_m.z};
    const double z = rel.x * forward.x + rel.y * forward.y + rel.z * forward.z;
    if (z <= 0) continue;  // behind the camera
    const double u = (rel.x * right.x + rel.y * right.y + rel.z * right.z) / z;
    const double v = -(rel.x * up.x + rel.y * up.y + rel.z * up.z) / z;
    const int px = int(std::floor(camera.cx + u * camera.focal_px));
    const int py = int(std::floor(camera.cy + v * camera.focal_px));
    if (px < 0 || py < 0 || px >= camera.width || py >= camera.height) continue;
    const double lamp_distance = std::sqrt(rel.x * rel.x + rel.y * rel.y + rel.z * rel.z);
    const double surface = distance_m.at(px, py, 0);
    const double depth_behind = lamp_distance - surface;
    if (std::isfinite(surface) && depth_behind > 0.01 * surface && depth_behind < 0.1 * surface)
      throw Error(ErrorCode::invalid_argument,
                  "lighting.lamps[" + std::to_string(i) +
                      "].position_m is inside the scene's geometry: " +
                      std::to_string(depth_behind) + " m behind the surface seen at pixel (" +
                      std::to_string(px) + "," + std::to_string(py) + ")");
  }
}

}  // namespace

ScatteringLayers render_scattering(const Image& photo, const Image& distance_m,
                                   const Camera& camera, const FogScene& scene_given,
                                   const CancelToken* cancel) {
  FogScene scene = scene_given;  // an automatic sun irradiance is resolved into it below
  const auto start = Clock::now();
  constexpr const char* kWhat = "render_scattering";
  throw_if_cancelled(cancel, kWhat);
  validate_scene(scene);
  if (distance_m.empty() || distance_m.channels() != 1)
    throw Error(ErrorCode::invalid_argument, "render_scattering: the depth map is missing or has " +
                                                 std::to_string(distance_m.channels()) +
                                                 " channels (expected 1)");
  if (distance_m.width() != camera.width || distance_m.height() != camera.height)
    throw Error(ErrorCode::size_mismatch, "render_scattering: depth map is " +
                                              size_text(distance_m.width(), distance_m.height()) +
                                              ", camera is " +
                                              size_text(camera.width, camera.height));
  bool beyond_far_limit = false;
  for (float d : distance_m.pixels()) {
    if (std::isnan(d) || d <= 0)
      throw Error(ErrorCode::invalid_argument,
                  "render_scattering: distance map holds NaN, zero or negative values "
                  "(use +inf for sky; mr::read_depth converts them)");
    beyond_far_limit = beyond_far_limit || (std::isfinite(d) && d > kMaxSurfaceDistanceM);
  }
  if (beyond_far_limit) {
    // Every finite distance renders: those past the far limit (mr/depth.h) are clamped to it,
    // as read_depth does; the ray tracer rejects rays whose points lie past ~1.8e18 m.
    Image clamped = distance_m;
    for (float& d : clamped.pixels())
      if (std::isfinite(d) && d > kMaxSurfaceDistanceM) d = float(kMaxSurfaceDistanceM);
    return render_scattering(photo, clamped, camera, scene, cancel);
  }
  const bool need_sky_estimate = !scene.lighting.sky_radiance.has_value();
  const bool need_sun_estimate = scene.lighting.sun && scene.lighting.sun->irradiance_auto;
  const bool need_lamp_estimate =
      std::any_of(scene.lighting.lamps.begin(), scene.lighting.lamps.end(),
                  [](const Lamp& l) { return l.intensity_auto; });
  if ((need_sky_estimate || need_sun_estimate || need_lamp_estimate) &&
      (photo.empty() || photo.channels() < 3 || photo.width() != camera.width ||
       photo.height() != camera.height))
    throw Error(ErrorCode::invalid_argument,
                std::string("render_scattering: the ") +
                    (need_sky_estimate   ? "sky radiance"
                     : need_sun_estimate ? "sun irradiance"
                                         : "lamp intensity") +
                    " is 'auto' but no photo of the camera's size was given to estimate it from");
  if (scene.lighting.sky_by_direction.value_or(false) &&
      (photo.channels() < 3 || photo.width() != camera.width || photo.height() != camera.height))
    throw Error(ErrorCode::invalid_argument,
                "render_scattering: lighting.sky_by_direction needs the photo at the camera's size");
  check_lamps_outside_geometry(distance_m, camera, scene);

  ScatteringLayers out;
  out.sky_radiance = need_sky_estimate ? photo::estimate_airlight_dark_channel(photo.view())
                                       : *scene.lighting.sky_radiance;
  if (need_sun_estimate) {  // issue 11 item 5: the sun relative to the photo's exposure
    scene.lighting.sun->irradiance =
        photo::exposure_relative_sun(photo.view(), distance_m.view(), out.sky_radiance).irradiance;
    scene.lighting.sun->irradiance_auto = false;
  }
  for (Lamp& lamp : scene.lighting.lamps)  // issue 11 item 5: lamps relative to the exposure too
    if (lamp.intensity_auto) {
      lamp.intensity_per_sr =
          photo::exposure_relative_lamp(photo, distance_m, camera, scene.pose, lamp.position_m,
                                        lamp.intensity_per_sr, scene.medium)
              .intensity_per_sr;
      lamp.intensity_auto = false;
    }
  const int w = camera.width, h = camera.height;
  out.transmittance = Image::uninitialized(w, h, 3);
  out.inscatter = Image::uninitialized(w, h, 3);
  out.sun_visibility = Image::uninitialized(w, h, 1, {"Y"});
  out.optical_depth = Image::uninitialized(w, h, 3);

  render::CoreInputs in;
  in.camera = &camera;
  in.scene = &scene;
  in.distance_m = distance_m.view();
  // The photo lets the surface term tell a misplaced mesh shadow from a real one (issue 13).
  if (photo.channels() >= 3 && photo.width() == w && photo.height() == h) in.photo = photo.view();
  in.sky_radiance = out.sky_radiance;
  in.cancel = cancel;
  render::CoreOutputs core{out.transmittance.view(), out.inscatter.view(),
                           out.sun_visibility.view(), out.optical_depth.view()};
  // Backend choice, fall-back, occluder geometry: render/backend.h.
  render::FrameResult frame = render::render_frame(in, core);
  out.backend = std::move(frame.backend);
  out.backend_notice = std::move(frame.notice);
  out.backend_notice_is_warning = frame.notice_is_warning;
  out.completed_blockers = std::move(frame.completed_blockers);
  // Issue 11: the sky term lit by the photo's sky by direction (mr/sky_light.h), exact in
  // closed form from each pixel's optical depth, whichever backend rendered.
  if (scene.lighting.sky_by_direction.value_or(false))
    add_sky_light(sky_light_from_photo(photo, distance_m, camera, scene, out.sky_radiance),
                  scene.medium, camera, scene.pose, out.optical_depth, out.inscatter);
  const render::FrameTimings& t = frame.timings;
  out.timings.mesh_s = t.mesh_s;
  out.timings.bvh_s = t.bvh_s;
  out.timings.scatter_s = t.scatter_s;
  out.timings.exact_pixels = t.exact_pixels;
  out.timings.interpolated_pixels = t.interpolated_pixels;
  out.timings.shadow_rays = t.shadow_rays;
  out.timings.upload_s = t.upload_s;
  out.timings.shadow_maps_s = t.shadow_maps_s;
  out.timings.gpu_scatter_s = t.gpu_scatter_s;
  out.timings.download_s = t.download_s;
  out.timings.tiles = t.tiles;
  out.timings.total_s = seconds_since(start);
  return out;
}

FogLayers fog(const Image& photo, const Image& distance_m, const Camera& camera,
              const FogScene& scene, ScatteringLayers* layers_out, const CancelToken* cancel) {
  return fog(photo, distance_m, Image(), camera, scene, layers_out, cancel);
}

FogLayers fog(const Image& photo, const Image& distance_m, const Image& sky_alpha,
              const Camera& camera, const FogScene& scene, ScatteringLayers* layers_out,
              const CancelToken* cancel) {
  if (photo.empty() || photo.channels() < 3)
    throw Error(ErrorCode::invalid_argument, "fog: photo must have at least 3 channels, has " +
                                                 std::to_string(photo.channels()));
  if (photo.width() != distance_m.width() || photo.height() != distance_m.height())
    throw Error(ErrorCode::size_mismatch,
                "fog: depth map is " + size_text(distance_m.width(), distance_m.height()) +
                    ", photo is " + size_text(photo.width(), photo.height()));
  if (!sky_alpha.empty() && (sky_alpha.channels() != 1 || sky_alpha.width() != photo.width() ||
                             sky_alpha.height() != photo.height()))
    throw Error(ErrorCode::size_mismatch, "fog: the sky matte is " +
                                              size_text(sky_alpha.width(), sky_alpha.height()) +
                                              " with " + std::to_string(sky_alpha.channels()) +
                                              " channel(s), expected 1 channel at the photo's " +
                                              size_text(photo.width(), photo.height()));
  ScatteringLayers layers = render_scattering(photo, distance_m, camera, scene, cancel);
  // Issue 11 item 4: a pixel on the sky's edge gets the matte mix of the surface's fog and the
  // sky's (photo/sky_matte.h), so the fogged edge is as soft as the photo's.
  if (!sky_alpha.empty())
    photo::apply_sky_matte(sky_alpha.view(), layers.transmittance.view(), layers.inscatter.view());
  FogLayers out;
  out.airlight = layers.sky_radiance;
  out.composite =
      Image::uninitialized(photo.width(), photo.height(), photo.channels(), photo.channel_names());
  out.composite.metadata() = photo.metadata();
  photo::composite(photo.view(), layers.transmittance.view(), layers.inscatter.view(),
                   out.composite.view());
  out.transmittance = std::move(layers.transmittance);
  out.inscatter = std::move(layers.inscatter);
  if (layers_out) {
    layers_out->sun_visibility = std::move(layers.sun_visibility);
    layers_out->optical_depth = std::move(layers.optical_depth);
    layers_out->sky_radiance = layers.sky_radiance;
    layers_out->timings = layers.timings;
    layers_out->completed_blockers = std::move(layers.completed_blockers);
    layers_out->backend = std::move(layers.backend);
    layers_out->backend_notice = std::move(layers.backend_notice);
    layers_out->backend_notice_is_warning = layers.backend_notice_is_warning;
  }
  return out;
}

namespace {

using detail::srgb_encode;

// `mr fog`'s default display output (colorspace::srgb_rolloff): the roll-off, then sRGB.
float srgb_rolloff_encode(float linear) {
  return srgb_encode(float(highlight_rolloff(linear)));
}

}  // namespace

SeamSoftening soften_fog_seams(const Image& photo, FogLayers& layers) {
  if (layers.composite.width() != photo.width() || layers.composite.height() != photo.height() ||
      layers.composite.channels() != photo.channels())
    throw Error(ErrorCode::size_mismatch,
                "soften_fog_seams: the composite is " +
                    size_text(layers.composite.width(), layers.composite.height()) +
                    ", the photo " + size_text(photo.width(), photo.height()));
  const photo::SeamSoftening s =
      photo::soften_fog_seams(photo.view(), layers.transmittance.view(), layers.inscatter.view(),
                              photo::SeamDisplay{srgb_encode, srgb_rolloff_encode});
  if (s.pixels_changed > 0)
    photo::composite(photo.view(), layers.transmittance.view(), layers.inscatter.view(),
                     layers.composite.view());
  SeamSoftening out;
  out.created_before = s.created_before;
  out.created_after = s.created_after;
  out.pixels_changed = s.pixels_changed;
  out.rounds = s.rounds;
  return out;
}

}  // namespace mr
