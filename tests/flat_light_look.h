// mr::fog's steps with the sky light's brightness scale chosen (SkyLight::scale, on by default
// since helper haze15): the render with the flat sky light (the render before haze15) shows
// defects of an estimate that the scale would also hide, for tests whose "before" is such a
// defect (the sea bound, the far shore). Needs photo/ internals (the sky matte, the composite).
#pragma once

#include "mr/estimate.h"
#include "mr/fog.h"
#include "mr/image.h"
#include "mr/scattering.h"
#include "mr/sky_light.h"
#include "photo/composite.h"
#include "photo/sky_matte.h"
#include "tests/gallery_look.h"

namespace mr::test {

// mr::fog's steps (render, sky light by direction, matte, composite), with or without the sky
// light's brightness scale.
inline FogLayers fog_with_sky_light(const Image& photo, const Image& distance, const Image& alpha,
                                    const FogScene& scene, bool brightness_from_photo,
                                    const Camera& camera) {
  FogScene plain = scene;
  plain.lighting.sky_by_direction = false;
  ScatteringLayers layers = render_scattering(photo, distance, camera, plain);
  const SkyLight light = sky_light_from_photo(photo, distance, camera, scene, layers.sky_radiance,
                                              brightness_from_photo);
  add_sky_light(light, scene.medium, camera, scene.pose, layers.optical_depth, layers.inscatter);
  if (!alpha.empty())
    photo::apply_sky_matte(alpha.view(), layers.transmittance.view(), layers.inscatter.view());
  FogLayers out;
  out.composite = Image(photo.width(), photo.height(), 3);
  photo::composite(photo.view(), layers.transmittance.view(), layers.inscatter.view(),
                   out.composite.view());
  return out;
}

// The gallery look of fog_auto_look (tests/gallery_look.h) with the flat sky light.
inline FogLayers fog_auto_look_flat_light(const Image& photo, const Camera& camera,
                                          const SceneEstimate& est, double visibility_m,
                                          double top_m, double g) {
  return fog_with_sky_light(photo, est.geometry.distance_m, est.geometry.sky_alpha,
                            gallery_look_scene(photo, est, visibility_m, top_m, g), false, camera);
}

}  // namespace mr::test
