// The gallery's haze and dense looks on an automatic estimate (`mr fog --depth auto` with
// gallery/looks: sky light 'auto', i.e. by direction with the estimate's sky radiance) and its
// created-edge measure (gallery/measures.py), for synthetic photos of the gallery's failure
// classes; shared by the sky light and the sky-through-a-lattice tests.
#pragma once

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <string>

#include "mr/estimate.h"
#include "mr/fog.h"
#include "mr/image.h"
#include "mr/io.h"
#include "mr/scattering.h"
#include "tests/display_luma.h"

namespace mr::test {

#ifdef MR_SOURCE_DIR
// A photo of the gallery's tuning half (gallery/tune/<name>), scene-linear.
inline Image tuning_photo(const std::string& name) {
  return read_image(std::string(MR_SOURCE_DIR) + "/gallery/tune/" + name);
}
#endif

// The automatic estimate of `photo` (a 60 degree lens, no annotations) with the default
// options and with `without` (a rule switched off): the rule's effect.
struct WithAndWithout {
  Camera camera;
  SceneEstimate with, without;
};
inline WithAndWithout estimate_with_and_without(const Image& photo,
                                                const EstimateOptions& without) {
  WithAndWithout out{Camera::from_horizontal_fov(photo.width(), photo.height(), 60), {}, {}};
  out.with = estimate_scene(photo, out.camera, Annotations{});
  out.without = estimate_scene(photo, out.camera, Annotations{}, without);
  return out;
}

// Display-referred [0, 1] colour -> scene-linear (gamma 2.2).
inline float linear(float display) {
  return std::pow(display, 2.2f);
}

// The scene-linear photo of a display-referred CV_32FC3 picture (clamped to [0, 1] first).
inline Image linear_photo(const cv::Mat& display) {
  Image photo(display.cols, display.rows, 3);
  for (int y = 0; y < display.rows; ++y)
    for (int x = 0; x < display.cols; ++x)
      for (int c = 0; c < 3; ++c)
        photo.at(x, y, c) = linear(std::clamp(display.at<cv::Vec3f>(y, x)[c], 0.0f, 1.0f));
  return photo;
}

// The gallery's created-edge measure exactly (gallery/measures.py: display luma of the clamped,
// gamma-2.2 values, Gaussian blur sigma 1 px (radius 3, edges replicated), central differences;
// created where the fogged image's gradient is more than twice the photo's and above 0.01). With
// `map`: the created pixels (1) for a picture to look at.
inline double gallery_created_edges(const Image& photo, const Image& fogged, Image* map = nullptr) {
  auto strength = [](const Image& img) {
    cv::Mat l = display_luma(img), b, g(l.rows, l.cols, CV_32F);
    cv::GaussianBlur(l, b, cv::Size(7, 7), 1.0, 1.0, cv::BORDER_REPLICATE);
    for (int y = 0; y < l.rows; ++y)
      for (int x = 0; x < l.cols; ++x) {
        const int x0 = std::max(0, x - 1), x1 = std::min(l.cols - 1, x + 1);
        const int y0 = std::max(0, y - 1), y1 = std::min(l.rows - 1, y + 1);
        const float gx = 0.5f * (b.at<float>(y, x1) - b.at<float>(y, x0));
        const float gy = 0.5f * (b.at<float>(y1, x) - b.at<float>(y0, x));
        g.at<float>(y, x) = std::hypot(gx, gy);
      }
    return g;
  };
  const cv::Mat gp = strength(photo), gf = strength(fogged);
  std::size_t created = 0;
  if (map) *map = Image(photo.width(), photo.height(), 3);
  for (int y = 0; y < gp.rows; ++y)
    for (int x = 0; x < gp.cols; ++x) {
      const bool c = gf.at<float>(y, x) > 2 * gp.at<float>(y, x) && gf.at<float>(y, x) > 0.01f;
      created += c;
      if (map)
        for (int k = 0; k < 3; ++k)
          map->at(x, y, k) = c ? float(k == 0) : 0.3f * std::min(1.0f, fogged.at(x, y, k));
    }
  return double(created) / double(gp.total());
}

// A distance map to look at: 1 - exp(-d / 200 m) in grey, the sky (infinite) white.
inline Image depth_picture(const Image& distance_m) {
  Image picture(distance_m.width(), distance_m.height(), 3);
  for (int y = 0; y < distance_m.height(); ++y)
    for (int x = 0; x < distance_m.width(); ++x) {
      const float d = distance_m.at(x, y, 0);
      const float v = std::isfinite(d) ? float(-std::expm1(-d / 200.0)) : 1.0f;
      for (int c = 0; c < 3; ++c) picture.at(x, y, c) = v;
    }
  return picture;
}

// The scene of a gallery look (gallery/looks: sky light 'auto', i.e. by direction with the
// estimate's sky radiance) over an automatic estimate.
inline FogScene gallery_look_scene(const Image& photo, const SceneEstimate& est,
                                   double visibility_m, double top_m, double g) {
  FogScene s = est.scene;
  const float sigma = float(extinction_from_visibility(visibility_m));
  s.medium.sigma_t_per_m = {sigma, sigma, sigma};
  s.medium.g = g;
  s.medium.layer_top_m = top_m;
  s.render.backend = Backend::cpu;
  s.lighting.sky_by_direction = true;
  if (!s.lighting.sky_radiance) s.lighting.sky_radiance = estimate_airlight(photo);
  return s;
}

// As `mr fog --depth auto` with a gallery look: the automatic estimate, its matte, the fog.
inline FogLayers fog_auto_look(const Image& photo, const Camera& camera, const SceneEstimate& est,
                               double visibility_m, double top_m, double g) {
  return fog(photo, est.geometry.distance_m, est.geometry.sky_alpha, camera,
             gallery_look_scene(photo, est, visibility_m, top_m, g));
}

// The gallery's haze and dense looks of one estimate and their created edges; with
// MR_TEST_IMAGES set, the photo, the haze and its created-edge map are written there as
// <name>_photo.png, <name>_haze.png, <name>_haze_edges.png to look at.
struct GalleryLooks {
  double haze_edges = 0, dense_edges = 0;  // fractions of the pixels
};
// With `dense_out`: the dense look itself too (its transmittance), not rendered twice.
inline GalleryLooks haze_and_dense_looks(const Image& photo, const Camera& camera,
                                         const SceneEstimate& est, const std::string& name,
                                         FogLayers* dense_out = nullptr) {
  const FogLayers haze = fog_auto_look(photo, camera, est, 2000, 1500, 0.6);
  const FogLayers dense = fog_auto_look(photo, camera, est, 60, 80, 0.3);
  Image haze_map;
  GalleryLooks looks;
  looks.haze_edges = gallery_created_edges(photo, haze.composite, &haze_map);
  looks.dense_edges = gallery_created_edges(photo, dense.composite);
  if (dense_out) *dense_out = dense;
  if (const char* folder = std::getenv("MR_TEST_IMAGES"); folder && *folder) {
    const std::string f(folder);
    write_image(f + "/" + name + "_photo.png", photo);
    write_image(f + "/" + name + "_haze.png", haze.composite);
    write_image(f + "/" + name + "_haze_edges.png", haze_map);
  }
  return looks;
}

}  // namespace mr::test
