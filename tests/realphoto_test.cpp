// Issue 11 items 3 and 4 on synthetic photos made to fail the way real ones did: a seascape with
// boats on the horizon, a sunset band and a hazy hillside (edge-free regions next to the sky and
// the sea), a forest canopy with sky seen through its gaps, a hill fading softly into the sky.
// Measured: depth jumps where the photo has no edge, edges the fog creates (fog only softens:
// the result's gradient more than twice the photo's plus a floor), sky through the canopy, and
// the soft sky matte's continuity. Each test prints its numbers; "before" is the estimate
// without the refinement, the rise test and a fog top (EstimateOptions, as the code was).
#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "mr/error.h"
#include "mr/estimate.h"
#include "mr/fog.h"
#include "mr/io.h"
#include "mr/scattering.h"
#include "photo/geometry.h"
#include "photo/sky_mask.h"
#include "tests/display_luma.h"

namespace mr {
namespace {

constexpr int kW = 640, kH = 480;
const Camera kCamera = Camera::from_horizontal_fov(kW, kH, 60);
constexpr double kHorizonRow = 239.5;  // a level camera: through the principal point

cv::Vec3f mix(const cv::Vec3f& a, const cv::Vec3f& b, float t) {
  return a * (1 - t) + b * t;
}

// Scene-linear photo of a display-referred [0, 1] CV_32FC3 picture (gamma 2.2, as the sky mask
// reads it), with a little deterministic grain.
Image to_photo(const cv::Mat& display, unsigned seed = 7) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> grain(-0.003f, 0.003f);
  Image out(display.cols, display.rows, 3);
  for (int y = 0; y < display.rows; ++y)
    for (int x = 0; x < display.cols; ++x)
      for (int c = 0; c < 3; ++c)
        out.at(x, y, c) =
            std::pow(std::clamp(display.at<cv::Vec3f>(y, x)[c] + grain(rng), 0.0f, 1.0f), 2.2f);
  return out;
}

// Sky: blue at the top to pale at the horizon; `sunset` adds a warm band above the horizon
// that fades into the sky with no edge.
cv::Vec3f sky_colour(int y, float sunset) {
  const float t = std::clamp(float((kHorizonRow - y) / kHorizonRow), 0.0f, 1.0f);
  const cv::Vec3f blue(0.36f, 0.55f, 0.86f), pale(0.80f, 0.82f, 0.86f), warm(0.97f, 0.62f, 0.36f);
  const cv::Vec3f base = mix(pale, blue, t * t * (3 - 2 * t));
  const float band = std::exp(-std::pow(float(kHorizonRow - y) / 28.0f, 2.0f));
  return mix(base, warm, sunset * band);
}

// The seascape: sky (with a sunset band), the sea as a smooth gradient down to a beach, boats
// and a mast on the horizon, and a hazy hill on the right whose edge fades into the sky.
cv::Mat seascape_display() {
  cv::Mat m(kH, kW, CV_32FC3);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      cv::Vec3f c;
      if (y < kHorizonRow) {
        c = sky_colour(y, 0.8f);
      } else if (y < 400) {
        const float t = float((y - kHorizonRow) / (400 - kHorizonRow));
        c = mix(cv::Vec3f(0.30f, 0.40f, 0.52f), cv::Vec3f(0.12f, 0.22f, 0.36f), t);
      } else {
        c = cv::Vec3f(0.74f, 0.64f, 0.48f);
      }
      m.at<cv::Vec3f>(y, x) = c;
    }
  // A hazy hill: its silhouette blurred over ~10 px, its colour close to the sky's.
  cv::Mat hill(kH, kW, CV_32F, cv::Scalar(0));
  std::vector<cv::Point> poly{{440, 240}, {500, 212}, {560, 200}, {639, 214}, {639, 240}};
  cv::fillConvexPoly(hill, poly, cv::Scalar(1), cv::LINE_AA);
  cv::GaussianBlur(hill, hill, cv::Size(0, 0), 4.0);
  for (int y = 0; y < 240; ++y)
    for (int x = 0; x < kW; ++x) {
      const float a = hill.at<float>(y, x);
      if (a > 0)
        m.at<cv::Vec3f>(y, x) = mix(m.at<cv::Vec3f>(y, x), cv::Vec3f(0.62f, 0.60f, 0.66f), a);
    }
  // Boats on the horizon, one with a mast.
  const cv::Scalar hull(0.16, 0.13, 0.11), sail(0.9, 0.88, 0.84);
  cv::rectangle(m, cv::Point(100, 233), cv::Point(152, 246), hull, cv::FILLED, cv::LINE_AA);
  cv::line(m, cv::Point(126, 233), cv::Point(126, 188), hull, 2, cv::LINE_AA);
  cv::fillConvexPoly(m, std::vector<cv::Point>{{128, 190}, {128, 230}, {150, 230}}, sail,
                     cv::LINE_AA);
  cv::rectangle(m, cv::Point(300, 236), cv::Point(324, 244), hull, cv::FILLED, cv::LINE_AA);
  cv::rectangle(m, cv::Point(380, 234), cv::Point(396, 245), hull, cv::FILLED, cv::LINE_AA);
  return m;
}

Annotations level_horizon() {
  Annotations a;
  a.horizon =
      std::array<PixelPoint, 2>{PixelPoint{0, kHorizonRow}, PixelPoint{kW - 1, kHorizonRow}};
  a.camera_height_m = 1.6;
  return a;
}

using mr::test::display_luma;  // tests/display_luma.h
constexpr auto gradient = mr::test::forward_gradient;


// The created-edge measure: the fraction of pixels where the fogged image's gradient
// (display-referred luma) is more than twice the photo's plus a floor of 0.01 (2.5 / 255).
constexpr float kEdgeFloor = 0.01f;
void dump(const std::string& name, const Image& image);
double created_edge_fraction(const Image& photo, const Image& fogged,
                             const std::string& name = "") {
  const cv::Mat gp = gradient(display_luma(photo)), gf = gradient(display_luma(fogged));
  std::size_t created = 0;
  Image mask(gp.cols, gp.rows, 3);
  for (int y = 0; y < gp.rows; ++y)
    for (int x = 0; x < gp.cols; ++x) {
      const bool c = gf.at<float>(y, x) > 2 * gp.at<float>(y, x) + kEdgeFloor;
      created += c;
      for (int k = 0; k < 3; ++k) mask.at(x, y, k) = c ? float(k == 0) : 0.3f * fogged.at(x, y, k);
    }
  if (!name.empty()) dump(name, mask);
  return double(created) / double(gp.total());
}

// Depth jumps where the photo has no edge: neighbouring pixels whose transmittance in a
// reference fog (150 m visibility, unbounded: the sky's is 0) differs by more than 0.1 while
// the photo's gradient within one pixel of both stays below 0.02.
std::size_t jumps_off_edges(const Image& photo, const Image& distance) {
  const double sigma = 3.912 / 150;
  const cv::Mat gp = gradient(display_luma(photo));
  cv::Mat edge;
  cv::dilate(gp, edge, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(3, 3)));
  auto t = [&](int x, int y) {
    const float d = distance.at(x, y, 0);
    return std::isfinite(d) ? std::exp(-sigma * d) : 0.0;
  };
  std::size_t n = 0;
  for (int y = 0; y + 1 < photo.height(); ++y)
    for (int x = 0; x + 1 < photo.width(); ++x) {
      if (edge.at<float>(y, x) >= 0.02f) continue;
      n += std::abs(t(x + 1, y) - t(x, y)) > 0.1 && edge.at<float>(y, x + 1) < 0.02f;
      n += std::abs(t(x, y + 1) - t(x, y)) > 0.1 && edge.at<float>(y + 1, x) < 0.02f;
    }
  return n;
}

// With MR_TEST_IMAGES=<folder>: the photos, depths and fogged results as PNGs, to look at.
void dump(const std::string& name, const Image& image) {
  const char* folder = std::getenv("MR_TEST_IMAGES");
  if (!folder || !*folder) return;
  if (image.channels() == 1) {  // a distance map: 1 - exp(-d / 50 m), sky white
    Image v(image.width(), image.height(), 3);
    for (int y = 0; y < image.height(); ++y)
      for (int x = 0; x < image.width(); ++x) {
        const float d = image.at(x, y, 0);
        const float g = std::isfinite(d) ? float(-std::expm1(-d / 50.0)) : 1.0f;
        for (int c = 0; c < 3; ++c)
          v.at(x, y, c) = std::pow(g, 2.2f) * (c == 2 || std::isfinite(d) ? 1.0f : 0.9f);
      }
    write_image(std::string(folder) + "/" + name + ".png", v);
    return;
  }
  write_image(std::string(folder) + "/" + name + ".png", image);
}

EstimateOptions before_options() {
  EstimateOptions o;
  o.refine_depth = false;
  o.min_rise_ratio = 0;
  return o;
}

// Sky light only, as the looks without sun or lamps: the fog of `visibility_m`, in a layer with
// the default top when `layer_top`.
FogLayers fog_look(const Image& photo, const SceneEstimate& est, double visibility_m,
                   bool layer_top) {
  FogScene s = est.scene;
  const float sigma = float(extinction_from_visibility(visibility_m));
  s.medium.sigma_t_per_m = {sigma, sigma, sigma};
  if (layer_top) s.medium.layer_top_m = default_layer_top_m(s.medium);
  s.render.backend = Backend::cpu;
  return fog(photo, est.geometry.distance_m, kCamera, s);
}

TEST(RealPhoto, SeascapeDepthJumpsOnlyAtPhotoEdges) {
  const Image photo = to_photo(seascape_display());
  const GeometryEstimate before =
      estimate_geometry(photo, kCamera, level_horizon(), before_options());
  const GeometryEstimate after = estimate_geometry(photo, kCamera, level_horizon());
  dump("seascape_photo", photo);
  dump("seascape_depth_before", before.distance_m);
  dump("seascape_depth_after", after.distance_m);
  const std::size_t jb = jumps_off_edges(photo, before.distance_m),
                    ja = jumps_off_edges(photo, after.distance_m);
  std::printf("seascape: depth jumps off the photo's edges: before %zu, after %zu\n", jb, ja);
  EXPECT_EQ(ja, 0u);
  EXPECT_GT(jb, ja);  // the case does exercise what was wrong
  // The estimate carries its soft matte and confidence at the photo's size.
  ASSERT_EQ(after.sky_alpha.width(), kW);
  ASSERT_EQ(after.depth_confidence.height(), kH);
  // The sea (below the horizon, away from the boats) is the ground plane: flat water, not a
  // wall of columns. Bar: within 2 % of the plane's distance where the plane is trusted (more
  // than 4 degrees below the horizon, row 279; above, the refinement smooths it).
  double worst = 0;
  for (int y = 285; y < 390; y += 7)
    for (int x = 180; x < 620; x += 13) {
      if (x > 290 && x < 410) continue;  // beside the small boats
      const Vec3 d = after.pose.ray_direction(kCamera, x, y);
      const double plane = after.pose.position_m.y / -d.y;
      const double e = std::abs(after.distance_m.at(x, y, 0) - plane) / plane;
      worst = std::max(worst, e);
    }
  std::printf("seascape: sea vs the ground plane, worst relative difference %.4f\n", worst);
  EXPECT_LT(worst, 0.02);
}

TEST(RealPhoto, SeascapeFogCreatesNoEdges) {
  const Image photo = to_photo(seascape_display());
  const SceneEstimate before = estimate_scene(photo, kCamera, level_horizon(), before_options());
  const SceneEstimate after = estimate_scene(photo, kCamera, level_horizon());
  for (const double visibility : {150.0, 3000.0}) {
    const Image b = fog_look(photo, before, visibility, false).composite;
    const Image a = fog_look(photo, after, visibility, true).composite;
    dump("seascape_fog" + std::to_string(int(visibility)) + "_before", b);
    dump("seascape_fog" + std::to_string(int(visibility)) + "_after", a);
    const double fb = created_edge_fraction(photo, b),
                 fa = created_edge_fraction(photo, a,
                                            "seascape_edges" + std::to_string(int(visibility)));
    std::printf("seascape, visibility %g m: created-edge pixels before %.4f %%, after %.4f %%\n",
                visibility, 100 * fb, 100 * fa);
    EXPECT_LE(fa, 2e-4);  // the target: 0.02 % of the pixels
  }
}

// A canopy of dark textured leaves with gaps through which the sky shows, open sky at the top
// right, grass below the horizon.
cv::Mat forest_display(std::vector<cv::Point>* gap_centres) {
  cv::Mat m(kH, kW, CV_32FC3);
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> leaf(-0.09f, 0.09f);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      cv::Vec3f c;
      const bool canopy = y < 215 && !(x > 470 && y < 110);
      if (y >= kHorizonRow) {
        const float n = leaf(rng);
        c = cv::Vec3f(0.25f + n, 0.42f + n, 0.18f + n);
      } else if (canopy) {
        const float n = leaf(rng);
        c = cv::Vec3f(0.12f + n, 0.24f + n, 0.10f + n);
      } else {
        c = sky_colour(y, 0);
      }
      m.at<cv::Vec3f>(y, x) = c;
    }
  std::uniform_int_distribution<int> gx(20, 440), gy(20, 190), gr(5, 9);
  for (int k = 0; k < 40; ++k) {
    const cv::Point p(gx(rng), gy(rng));
    const int r = gr(rng);
    gap_centres->push_back(p);
    for (int y = p.y - r; y <= p.y + r; ++y)
      for (int x = p.x - r; x <= p.x + r; ++x)
        if ((x - p.x) * (x - p.x) + (y - p.y) * (y - p.y) <= r * r)
          m.at<cv::Vec3f>(y, x) = sky_colour(y, 0);
  }
  return m;
}

TEST(RealPhoto, SkyThroughTheCanopyStaysSky) {
  std::vector<cv::Point> gaps;
  const Image photo = to_photo(forest_display(&gaps));
  const GeometryEstimate after = estimate_geometry(photo, kCamera, level_horizon());
  dump("forest_photo", photo);
  dump("forest_depth_after", after.distance_m);
  std::size_t inside = 0, sky = 0;
  for (const cv::Point& p : gaps)
    for (int dy = -2; dy <= 2; ++dy)  // the gaps' centres: at least 5 px inside
      for (int dx = -2; dx <= 2; ++dx) {
        ++inside;
        sky += std::isinf(after.distance_m.at(p.x + dx, p.y + dy, 0));
      }
  photo::SkyMaskOptions off;
  off.max_gap_fraction = 0;
  const photo::SkyMask without = photo::estimate_sky_mask(
      photo.view(), {PixelPoint{0, kHorizonRow}, PixelPoint{kW - 1, kHorizonRow}}, off);
  std::size_t sky_before = 0;
  for (const cv::Point& p : gaps)
    for (int dy = -2; dy <= 2; ++dy)
      for (int dx = -2; dx <= 2; ++dx)
        sky_before += without.sky[std::size_t(p.y + dy) * kW + p.x + dx];
  std::printf("canopy gaps: %zu of %zu centre pixels are sky (before: %zu); %zu gap pixels\n", sky,
              inside, sky_before, after.sky_gap_pixels);
  // Bar: 90 % of the gaps' centres (a gap overlapping another or the open sky is still sky).
  EXPECT_GE(double(sky), 0.9 * double(inside));
  EXPECT_LT(sky_before, sky);
  // The canopy itself is not sky: its leaves are dark and textured.
  std::size_t leaf_sky = 0, leaves = 0;
  for (int y = 10; y < 200; y += 3)
    for (int x = 10; x < 460; x += 3) {
      bool near_gap = false;
      for (const cv::Point& p : gaps) near_gap |= std::hypot(x - p.x, y - p.y) < 12;
      if (near_gap) continue;
      ++leaves;
      leaf_sky += std::isinf(after.distance_m.at(x, y, 0));
    }
  std::printf("canopy: %zu of %zu leaf pixels are sky\n", leaf_sky, leaves);
  EXPECT_EQ(leaf_sky, 0u);
}

// A hill whose silhouette fades into the sky over ~15 px.
cv::Mat soft_hill_display() {
  cv::Mat m(kH, kW, CV_32FC3);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x)
      m.at<cv::Vec3f>(y, x) = y < kHorizonRow ? sky_colour(y, 0) : cv::Vec3f(0.3f, 0.36f, 0.28f);
  cv::Mat hill(kH, kW, CV_32F, cv::Scalar(0));
  std::vector<cv::Point> poly;
  for (int x = 0; x < kW; x += 8)
    poly.emplace_back(x, int(170 + 25 * std::sin(x / 90.0) + 10 * std::sin(x / 23.0)));
  poly.emplace_back(kW - 1, 240);
  poly.emplace_back(0, 240);
  cv::fillPoly(hill, std::vector<std::vector<cv::Point>>{poly}, cv::Scalar(1), cv::LINE_AA);
  cv::GaussianBlur(hill, hill, cv::Size(0, 0), 5.0);
  for (int y = 0; y < 240; ++y)
    for (int x = 0; x < kW; ++x)
      m.at<cv::Vec3f>(y, x) =
          mix(m.at<cv::Vec3f>(y, x), cv::Vec3f(0.45f, 0.5f, 0.52f), hill.at<float>(y, x));
  return m;
}

TEST(RealPhoto, SoftSkyMatteIsContinuous) {
  const Image photo = to_photo(soft_hill_display());
  dump("hill_photo", photo);
  const std::array<PixelPoint, 2> horizon{PixelPoint{0, kHorizonRow},
                                          PixelPoint{kW - 1, kHorizonRow}};
  const photo::SkyMask mask = photo::estimate_sky_mask(photo.view(), horizon);
  ASSERT_EQ(mask.alpha.size(), std::size_t(kW) * kH);
  // The binary mask is the matte at 0.5; the matte is in [0, 1] and 0 below the horizon.
  std::size_t fractional = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const std::size_t i = std::size_t(y) * kW + x;
      const float a = mask.alpha[i];
      ASSERT_TRUE(a >= 0 && a <= 1) << x << "," << y;
      EXPECT_EQ(mask.sky[i] != 0, a >= 0.5f) << x << "," << y;
      if (y > kHorizonRow) {
        EXPECT_EQ(a, 0.0f);
      }
      fractional += a > 0.02f && a < 0.98f;
    }
  // Continuity: across the soft silhouette the matte steps by at most 0.35 between neighbours
  // (it follows the photo's 5 px blur; a binary mask steps by 1).
  float worst = 0;
  for (int y = 0; y + 1 < 230; ++y)
    for (int x = 0; x < kW; ++x)
      worst = std::max(worst, std::abs(mask.alpha[std::size_t(y + 1) * kW + x] -
                                       mask.alpha[std::size_t(y) * kW + x]));
  std::printf("soft hill: %zu fractional matte pixels, largest vertical step %.3f\n", fractional,
              worst);
  EXPECT_GT(fractional, std::size_t(kW));  // a band along the whole silhouette
  EXPECT_LE(worst, 0.35f);
  // Through the estimate and the fog: no hard transition at the matte's edge.
  const SceneEstimate before = estimate_scene(photo, kCamera, level_horizon(), before_options());
  const SceneEstimate after = estimate_scene(photo, kCamera, level_horizon());
  for (const double visibility : {150.0, 3000.0}) {
    const Image b = fog_look(photo, before, visibility, false).composite;
    const Image a = fog_look(photo, after, visibility, true).composite;
    dump("hill_fog" + std::to_string(int(visibility)) + "_before", b);
    dump("hill_fog" + std::to_string(int(visibility)) + "_after", a);
    const double fb = created_edge_fraction(photo, b),
                 fa = created_edge_fraction(photo, a,
                                            "hill_edges" + std::to_string(int(visibility)));
    std::printf("soft hill, visibility %g m: created-edge pixels before %.4f %%, after %.4f %%\n",
                visibility, 100 * fb, 100 * fa);
    EXPECT_LE(fa, 2e-4);
  }
}

TEST(RealPhoto, DefaultLayerTopFromTheVisibility) {
  Medium m;
  auto top = [&](double visibility_m) {
    const float s = float(extinction_from_visibility(visibility_m));
    m.sigma_t_per_m = {s, s, s};
    return default_layer_top_m(m);
  };
  EXPECT_NEAR(top(40), 30, 1e-9);      // dense ground fog: the floor
  EXPECT_NEAR(top(150), 75, 1e-3);     // half the visibility
  EXPECT_NEAR(top(3000), 1500, 0.05);  // haze: the boundary layer
  EXPECT_NEAR(top(20000), 2000, 1e-9);
  m.sigma_t_per_m = {0, 0, 0};
  EXPECT_THROW(default_layer_top_m(m), Error);
}

// The gallery's looks (gallery/looks): haze, 2 km in a 1.5 km layer; dense fog, 60 m in 80 m.
FogLayers fog_gallery_look(const Image& photo, const SceneEstimate& est, double visibility_m,
                           double layer_top_m) {
  FogScene s = est.scene;
  const float sigma = float(extinction_from_visibility(visibility_m));
  s.medium.sigma_t_per_m = {sigma, sigma, sigma};
  s.medium.layer_top_m = layer_top_m;
  s.render.backend = Backend::cpu;
  return fog(photo, est.geometry.distance_m, kCamera, s);
}

// A calm sea under a hazy sky (a real case from the tuning half: coldripple): the sky's pale
// grey runs into the sea's at the horizon with no edge, the sea darkens toward a jetty of dark
// planks in the foreground whose end rises a little above the horizon. The refinement spreads
// the jetty's and the near sea's distances up to the horizon, where the sky, seen through the
// whole haze layer, is opaque.
cv::Mat calm_sea_display() {
  cv::Mat m(kH, kW, CV_32FC3);
  const cv::Vec3f top(0.62f, 0.63f, 0.64f), horizon(0.70f, 0.70f, 0.71f), near(0.42f, 0.43f, 0.45f);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x)
      m.at<cv::Vec3f>(y, x) =
          y < kHorizonRow ? mix(top, horizon, float(y / kHorizonRow))
                          : mix(horizon, near, float((y - kHorizonRow) / (kH - kHorizonRow)));
  // The jetty: a dark trapezoid from the bottom to a platform just above the horizon.
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> wood(-0.04f, 0.04f);
  const std::vector<cv::Point> jetty{{150, kH}, {490, kH}, {360, 232}, {280, 232}};
  cv::Mat inside(kH, kW, CV_8U, cv::Scalar(0));
  cv::fillConvexPoly(inside, jetty, cv::Scalar(1), cv::LINE_8);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x)
      if (inside.at<std::uint8_t>(y, x)) {
        const float n = wood(rng) + ((y / 6) % 2 ? 0.03f : -0.03f);  // planks
        m.at<cv::Vec3f>(y, x) = cv::Vec3f(0.2f + n, 0.19f + n, 0.18f + n);
      }
  return m;
}

TEST(RealPhoto, SkyMeetsCalmSeaWithNoCreatedEdge) {
  const Image photo = to_photo(calm_sea_display());
  dump("calm_sea_photo", photo);
  EstimateOptions unfolded;
  unfolded.sky_fold = false;
  const SceneEstimate before = estimate_scene(photo, kCamera, level_horizon(), unfolded);
  const SceneEstimate after = estimate_scene(photo, kCamera, level_horizon());
  dump("calm_sea_depth_before", before.geometry.distance_m);
  dump("calm_sea_depth_after", after.geometry.distance_m);
  ASSERT_GT(after.geometry.sky_pixels, std::size_t(kW) * 200);  // the sky was found
  // Under the horizon, away from the jetty, the sea's distance meets the sky's: the first row
  // is as far as the estimate's farthest surface (1e5 m), and the distance falls steadily down
  // the sea (no step back up: the fold only ever takes a pixel farther).
  for (const int x : {40, 100, 560, 620}) {
    const int y0 = int(kHorizonRow + 1);
    EXPECT_GE(after.geometry.distance_m.at(x, y0, 0), 1e4f) << x;
    EXPECT_LT(before.geometry.distance_m.at(x, y0, 0), 1e3f) << x;  // the case: pulled near
    for (int y = y0; y + 1 < kH; ++y)
      EXPECT_GE(after.geometry.distance_m.at(x, y, 0) * 1.0001f,
                after.geometry.distance_m.at(x, y + 1, 0))
          << x << "," << y;
  }
  const struct {
    const char* name;
    double visibility_m, top_m;
  } looks[] = {{"haze", 2000, 1500}, {"dense", 60, 80}};
  for (const auto& look : looks) {
    const Image b = fog_gallery_look(photo, before, look.visibility_m, look.top_m).composite;
    const Image a = fog_gallery_look(photo, after, look.visibility_m, look.top_m).composite;
    dump(std::string("calm_sea_") + look.name + "_before", b);
    dump(std::string("calm_sea_") + look.name + "_after", a);
    const double fb = created_edge_fraction(photo, b),
                 fa = created_edge_fraction(photo, a, std::string("calm_sea_edges_") + look.name);
    std::printf("calm sea, %s: created-edge pixels without the fold %.4f %%, with it %.4f %%\n",
                look.name, 100 * fb, 100 * fa);
    EXPECT_LE(fa, 2e-4);  // the target: 0.02 % of the pixels
  }
  // The haze look is the case that failed: a seam along the horizon without the fold.
  const double seam =
      created_edge_fraction(photo, fog_gallery_look(photo, before, 2000, 1500).composite);
  EXPECT_GT(seam, 2e-4);
}

// Fold: 1 apart from the sky, 0 from where the photo shows no edge to it, continuous between.
TEST(RealPhoto, SkyFoldIsContinuousAndStopsAtEdges) {
  EXPECT_EQ(photo::sky_fold(0.0f), 1.0f);
  EXPECT_EQ(photo::sky_fold(0.5f), 0.0f);
  EXPECT_EQ(photo::sky_fold(1.0f), 0.0f);
  EXPECT_NEAR(photo::sky_fold(0.25f), 0.25f, 1e-6f);
  float last = 1.0f;
  for (float p = 0; p <= 1.0f; p += 1.0f / 64) {
    const float f = photo::sky_fold(p);
    EXPECT_LE(f, last);
    EXPECT_LE(last - f, 0.07f);  // no step: the slope is at most 4 per unit of proximity
    last = f;
  }
  EXPECT_EQ(photo::sky_fold(std::numeric_limits<float>::quiet_NaN()), 1.0f);
  // Proximity: a flat grey picture, the top third sky. With no edge the grey below the sky
  // is about half sky at the boundary and fades with distance; a dark band (an edge) under the
  // sky in the right half stops it.
  cv::Mat m(kH, kW, CV_32FC3, cv::Scalar(0.6, 0.6, 0.6));
  cv::rectangle(m, cv::Point(kW / 2, 160), cv::Point(kW - 1, 200), cv::Scalar(0.1, 0.1, 0.1),
                cv::FILLED);
  const Image photo = to_photo(m);
  std::vector<std::uint8_t> sky(std::size_t(kW) * kH, 0);
  for (int y = 0; y < 160; ++y)
    for (int x = 0; x < kW; ++x) sky[std::size_t(y) * kW + x] = 1;
  // An enclosed piece of "sky" in the grey below (a misjudged patch): it does not spread.
  for (int y = 380; y < 392; ++y)
    for (int x = 100; x < 112; ++x) sky[std::size_t(y) * kW + x] = 1;
  const std::vector<float> p = photo::sky_proximity(photo.view(), sky);
  auto at = [&](int x, int y) { return p[std::size_t(y) * kW + x]; };
  EXPECT_EQ(at(105, 385), 1.0f);
  EXPECT_LT(at(105, 395), 0.01f);
  EXPECT_LT(at(115, 385), 0.01f);
  EXPECT_EQ(at(100, 159), 1.0f);
  EXPECT_GT(at(100, 160), 0.35f);  // no edge: close to half sky
  EXPECT_LT(at(100, 300), at(100, 180));
  EXPECT_LT(at(500, 160), 0.05f);  // the dark band's edge
  EXPECT_LT(at(500, 300), 0.05f);
  std::printf("sky proximity: under the sky %.3f (no edge), %.3f (edge); 140 px down %.3f\n",
              at(100, 160), at(500, 160), at(100, 300));
  EXPECT_THROW(photo::sky_proximity(photo.view(), std::vector<std::uint8_t>(10)), Error);
}

// A close-up with no sky (a real case from the tuning half: a coffee cup on a wooden table):
// the level fall-back horizon crosses the table. Without a bound the table below the horizon
// is a ground plane running to 1e5 m while the table above it is the far billboard: a seam
// along the horizon row.
TEST(RealPhoto, NoSkyBoundsTheDepth) {
  cv::Mat m(kH, kW, CV_32FC3);
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> grain(-0.05f, 0.05f);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      // Wood grain running across the view (a table seen from its edge): rows of streaks.
      const float n = grain(rng) + 0.08f * std::sin(y / 2.5f + x / 90.0f);
      m.at<cv::Vec3f>(y, x) = cv::Vec3f(0.45f + n, 0.30f + n, 0.18f + n);
    }
  // The table's far edge against a dark, plain background: a band under the horizon whose
  // edges keep the refinement from bringing the plane's distances under the horizon near.
  cv::rectangle(m, cv::Point(0, 243), cv::Point(kW - 1, 262), cv::Scalar(0.08, 0.07, 0.07),
                cv::FILLED);
  cv::circle(m, cv::Point(320, 330), 110, cv::Scalar(0.92, 0.9, 0.88), cv::FILLED, cv::LINE_AA);
  const Image photo = to_photo(m);
  dump("closeup_photo", photo);
  const SceneEstimate est = estimate_scene(photo, kCamera, Annotations{});
  dump("closeup_depth", est.geometry.distance_m);
  EXPECT_EQ(est.geometry.sky_pixels, 0u);
  // Every distance is finite and no farther than the far billboard (its forward distance
  // h / tan(2 deg) over the ray's horizontal forward component); the unrefined estimate too
  // (where nothing smooths the ground plane near the horizon, it ran to 886 m a pixel under it).
  const EstimateOptions defaults;
  EstimateOptions unrefined;
  unrefined.refine_depth = false;
  for (const GeometryEstimate& g :
       {est.geometry, estimate_geometry(photo, kCamera, Annotations{}, unrefined)}) {
    const double h = g.pose.position_m.y;
    const double far_forward =
        h / std::tan(defaults.billboard_depression_deg * std::numbers::pi / 180);
    // The refinement mixes neighbours' values: the bound is the far billboard's largest
    // distance in the frame (at a corner).
    const Vec3 f = g.pose.axes()[0];
    const double fl = std::hypot(f.x, f.z);
    double bound = 0, worst = 0;
    for (int y = 0; y < kH; ++y)
      for (int x = 0; x < kW; ++x) {
        const Vec3 r = g.pose.ray_direction(kCamera, x, y);
        const double along = (r.x * f.x + r.z * f.z) / fl;  // the ray's horizontal forward part
        bound = std::max(bound, far_forward / std::max(0.05, along));
      }
    for (int y = 0; y < kH; ++y)
      for (int x = 0; x < kW; ++x) {
        const float d = g.distance_m.at(x, y, 0);
        ASSERT_TRUE(std::isfinite(d)) << x << "," << y;
        worst = std::max(worst, d / bound);
      }
    std::printf("close-up: largest distance / the far billboard's largest %.4f\n", worst);
    EXPECT_LE(worst, 1.0 + 1e-4);
  }
  for (const auto& [vis, top] : {std::pair{2000.0, 1500.0}, std::pair{60.0, 80.0}}) {
    const Image a = fog_gallery_look(photo, est, vis, top).composite;
    const double fa = created_edge_fraction(photo, a, "closeup_edges" + std::to_string(int(vis)));
    std::printf("close-up, visibility %g m: created-edge pixels %.4f %%\n", vis, 100 * fa);
    EXPECT_LE(fa, 2e-4);
  }
}

// A dusk sky (a real case from the tuning half: a launch pad at twilight): deep blue at the top,
// too dark for a day sky's test, lighter toward the horizon; a building on the right reaching
// the top border with dark grey-blue windows, which stay out of the sky.
TEST(RealPhoto, DuskSkyIsSkyWindowsAreNot) {
  cv::Mat m(kH, kW, CV_32FC3);
  std::mt19937 rng(13);
  std::uniform_real_distribution<float> grain(-0.06f, 0.06f);
  const cv::Vec3f zenith(0.07f, 0.13f, 0.26f), low(0.25f, 0.34f, 0.50f);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const float n = grain(rng);
      m.at<cv::Vec3f>(y, x) = y < kHorizonRow ? mix(zenith, low, float(y / kHorizonRow))
                                              : cv::Vec3f(0.2f + n, 0.18f + n, 0.15f + n);
    }
  const int x0 = 470;
  for (int y = 0; y < kH; ++y)
    for (int x = x0; x < kW; ++x) {
      const float n = 0.5f * grain(rng);
      m.at<cv::Vec3f>(y, x) = cv::Vec3f(0.35f + n, 0.30f + n, 0.28f + n);
    }
  for (int wy = 0; wy < 220; wy += 45)  // the first row of windows touches the top border
    for (int wx = x0 + 12; wx + 28 < kW; wx += 44)
      cv::rectangle(m, cv::Point(wx, wy), cv::Point(wx + 27, wy + 30), cv::Scalar(0.12, 0.14, 0.18),
                    cv::FILLED);
  const Image photo = to_photo(m);
  dump("dusk_photo", photo);
  const std::array<PixelPoint, 2> horizon{PixelPoint{0, kHorizonRow},
                                          PixelPoint{kW - 1, kHorizonRow}};
  const photo::SkyMask mask = photo::estimate_sky_mask(photo.view(), horizon);
  std::vector<std::uint8_t> truth(std::size_t(kW) * kH, 0);
  std::size_t inter = 0, uni = 0, building_sky = 0, top_sky = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const std::size_t i = std::size_t(y) * kW + x;
      const bool t = y < kHorizonRow && x < x0;
      inter += t && mask.sky[i];
      uni += t || mask.sky[i];
      building_sky += x >= x0 + 2 && mask.sky[i];
      top_sky += y < 40 && x < x0 && mask.sky[i];
    }
  const double v = uni ? double(inter) / double(uni) : 0.0;
  std::printf("dusk: sky IoU %.4f, building pixels taken as sky %zu, top band %zu of %d\n", v,
              building_sky, top_sky, 40 * x0);
  EXPECT_GE(v, 0.95);
  EXPECT_GE(double(top_sky), 0.95 * 40 * x0);  // the deep blue at the top is sky
  EXPECT_EQ(building_sky, 0u);
}

// A portrait against a pale grey studio backdrop (a real case from the tuning half): the
// backdrop passes for an overcast sky, and a highlight on the textured face has its colour.
// Gaps of sky through foliage are looked for under a blue sky only, so the highlight stays
// part of the face.
TEST(RealPhoto, HighlightOnAFaceIsNotSkyUnderAGreyBackdrop) {
  cv::Mat m(kH, kW, CV_32FC3, cv::Scalar(0.84, 0.82, 0.80));
  std::mt19937 rng(17);
  std::uniform_real_distribution<float> skin(-0.1f, 0.1f);
  for (int y = 120; y < kH; ++y)
    for (int x = 200; x < 440; ++x) {
      const float n = skin(rng);
      m.at<cv::Vec3f>(y, x) = cv::Vec3f(0.62f + n, 0.45f + n, 0.38f + n);
    }
  const cv::Point highlight(300, 220);
  cv::circle(m, highlight, 7, cv::Scalar(0.84, 0.82, 0.80), cv::FILLED);
  const Image photo = to_photo(m);
  dump("backdrop_photo", photo);
  const double low = kH - 2.5;  // a horizon near the bottom: all of the backdrop could be sky
  const photo::SkyMask mask =
      photo::estimate_sky_mask(photo.view(), {PixelPoint{0, low}, PixelPoint{kW - 1, low}});
  auto sky = [&](int x, int y) { return mask.sky[std::size_t(y) * kW + x] != 0; };
  EXPECT_TRUE(sky(50, 50));
  EXPECT_TRUE(sky(600, 300));
  std::size_t taken = 0;
  for (int y = highlight.y - 5; y <= highlight.y + 5; ++y)
    for (int x = highlight.x - 5; x <= highlight.x + 5; ++x) taken += sky(x, y);
  std::printf("backdrop: highlight pixels taken as sky %zu of 121, gap pixels %zu\n", taken,
              mask.gap_pixels);
  EXPECT_EQ(taken, 0u);
  EXPECT_EQ(mask.gap_pixels, 0u);
}

// Issue 11 item 4, the sky matte in the fog (photo/sky_matte.h): a pixel on the sky's edge gets
// the matte's mix of the surface's fog and the sky's. A row of surface (x < 24), an 8 px ramp
// and sky (x >= 32), all looking up through haze in a layer with a top (the sky's path through
// it is finite): pixels with alpha 0 or 1 are bit-identical to the fog without a matte, which
// matches the closed forms T = exp(-sigma d) for the surface and
// T = exp(-sigma (top - camera height) / dir.y) for the sky; mixed pixels hold exactly the mix.
TEST(RealPhoto, SkyMatteMixesTheFogOfBothSides) {
  constexpr int w = 64, h = 16;
  const Camera camera = Camera::from_horizontal_fov(w, h, 40);
  FogScene s;
  s.pose.position_m = {0, 1.6, 0};
  s.pose.pitch_deg = 25;  // every ray goes up: the sky's path ends at the layer's top
  const float sigma = float(extinction_from_visibility(2000));
  s.medium.sigma_t_per_m = {sigma, sigma, sigma};
  s.medium.layer_top_m = 1500;
  s.lighting.sky_radiance = Rgb{0.7f, 0.75f, 0.8f};
  s.render.backend = Backend::cpu;
  constexpr float kSurfaceM = 80;
  const float surface[3] = {0.06f, 0.05f, 0.03f}, sky[3] = {0.2f, 0.35f, 0.8f};
  Image photo(w, h, 3), distance(w, h, 1), alpha(w, h, 1);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float a = std::clamp((float(x) - 23.5f) / 8.0f, 0.0f, 1.0f);
      alpha.at(x, y, 0) = a;
      distance.at(x, y, 0) = a < 0.5f ? kSurfaceM : std::numeric_limits<float>::infinity();
      for (int c = 0; c < 3; ++c) photo.at(x, y, c) = (1 - a) * surface[c] + a * sky[c];
    }
  const FogLayers plain = fog(photo, distance, camera, s);
  const FogLayers matted = fog(photo, distance, alpha, camera, s);
  double worst_closed_form = 0, worst_mix = 0;
  for (int y = 0; y < h; ++y) {
    const Vec3 d = s.pose.ray_direction(camera, 32, y);
    ASSERT_GT(d.y, 0);
    const double t_sky = std::exp(-double(sigma) * (1500 - 1.6) / d.y);
    const double t_surface = std::exp(-double(sigma) * kSurfaceM);
    for (int c = 0; c < 3; ++c) {
      worst_closed_form =
          std::max({worst_closed_form, std::abs(plain.transmittance.at(23, y, c) - t_surface),
                    std::abs(plain.transmittance.at(32, y, c) - t_sky)});
    }
    for (int x = 0; x < w; ++x) {
      const float a = alpha.at(x, y, 0);
      for (int c = 0; c < 3; ++c) {
        if (a <= 0 || a >= 1) {
          ASSERT_EQ(matted.transmittance.at(x, y, c), plain.transmittance.at(x, y, c));
          ASSERT_EQ(matted.inscatter.at(x, y, c), plain.inscatter.at(x, y, c));
          ASSERT_EQ(matted.composite.at(x, y, c), plain.composite.at(x, y, c));
          continue;
        }
        const double t =
            (1 - a) * plain.transmittance.at(23, y, c) + a * plain.transmittance.at(32, y, c);
        const double r = (1 - a) * plain.inscatter.at(23, y, c) + a * plain.inscatter.at(32, y, c);
        worst_mix =
            std::max({worst_mix, std::abs(matted.transmittance.at(x, y, c) - t),
                      std::abs(matted.inscatter.at(x, y, c) - r),
                      std::abs(matted.composite.at(x, y, c) - (photo.at(x, y, c) * t + r))});
      }
    }
  }
  std::printf("sky matte: closed forms off by %.2e, the mix by %.2e\n", worst_closed_form,
              worst_mix);
  EXPECT_LT(worst_closed_form, 1e-5);
  EXPECT_LT(worst_mix, 1e-6);
  // The fogged edge is not sharpened: its largest one-pixel luma step, relative to the mean
  // step over the ramp (total rise / 9 steps), is within 1.3 x the photo's (the photo's own
  // ratio is not 1: a linear-light ramp is not linear in display luma; the cross term
  // a (1 - a) (I_surface - I_sky) (T_surface - T_sky) bends the fogged one a little more).
  // Without the matte the whole rise is one step, which this bound must catch.
  auto sharpness = [&](const Image& img) {
    const cv::Mat l = display_luma(img);
    float largest = 0;
    for (int x = 23; x < 32; ++x)
      largest = std::max(largest, std::abs(l.at<float>(8, x + 1) - l.at<float>(8, x)));
    return largest / (std::abs(l.at<float>(8, 32) - l.at<float>(8, 23)) / 9.0f);
  };
  const float with = sharpness(matted.composite), without = sharpness(plain.composite);
  const float in_photo = sharpness(photo);
  std::printf(
      "sky matte: largest step / mean step, photo %.3f, fog with matte %.3f, without %.3f\n",
      in_photo, with, without);
  EXPECT_LE(with, 1.3f * in_photo);
  EXPECT_GT(without, 1.3f * in_photo);
  // A matte of another size is refused, naming both.
  EXPECT_THROW(fog(photo, distance, Image(w - 1, h, 1), camera, s), Error);
}

// A near building with a crisp, anti-aliased roof line against a deep blue sky (the tuning
// photo "palace": the fog's edge, a one-pixel step between the surface's fog and the sky's,
// was sharper than the photo's, and its flanks counted as created edges). Through the estimate
// and haze (the gallery's look: 2 km visibility, 1.5 km top): with the estimate's matte the
// created-edge pixels stay within the 0.02 %.
cv::Mat roofline_display(cv::Mat* sky_coverage = nullptr) {
  cv::Mat m(kH, kW, CV_32FC3);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const float t = float(y) / kH;
      m.at<cv::Vec3f>(y, x) = mix(cv::Vec3f(0.08f, 0.32f, 0.78f), cv::Vec3f(0.3f, 0.5f, 0.85f), t);
    }
  cv::Mat wall(kH, kW, CV_32F, cv::Scalar(0));
  std::vector<cv::Point> poly{{0, 479},   {0, 300},   {180, 250}, {180, 150}, {230, 150},
                              {230, 110}, {280, 110}, {280, 150}, {400, 170}, {470, 90},
                              {560, 70},  {639, 80},  {639, 479}};
  // Sub-pixel vertices (shift 3: 1/8 px) and anti-aliasing: a crisp edge one pixel wide.
  for (auto& p : poly) p *= 8;
  cv::fillPoly(wall, std::vector<std::vector<cv::Point>>{poly}, cv::Scalar(1), cv::LINE_AA, 3);
  cv::GaussianBlur(wall, wall, cv::Size(0, 0), 0.6);  // the lens
  if (sky_coverage) *sky_coverage = 1 - wall;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      // Stone with a little large-scale shading, not flat.
      const cv::Vec3f stone(0.86f - 0.1f * float(y) / kH, 0.76f,
                            0.45f + 0.04f * std::sin(x / 40.0f));
      m.at<cv::Vec3f>(y, x) = mix(m.at<cv::Vec3f>(y, x), stone, wall.at<float>(y, x));
    }
  return m;
}

TEST(RealPhoto, HazeEdgeAgainstTheSkyIsAsSoftAsThePhotos) {
  cv::Mat coverage;
  const Image photo = to_photo(roofline_display(&coverage));
  dump("roofline_photo", photo);
  // The matte sits on the photo's edge: against the true sky coverage of each pixel (known
  // here), along the roof line (pixels where either is fractional), the unmixed matte is off by
  // at most 0.1 on average; the guided filter alone (the matte before) was several times
  // farther off, a ramp beside the edge.
  const std::array<PixelPoint, 2> horizon{PixelPoint{0, kHorizonRow},
                                          PixelPoint{kW - 1, kHorizonRow}};
  photo::SkyMaskOptions guided_only;
  guided_only.unmix_edges = false;
  const photo::SkyMask unmixed = photo::estimate_sky_mask(photo.view(), horizon),
                       guided = photo::estimate_sky_mask(photo.view(), horizon, guided_only);
  double err_unmixed = 0, err_guided = 0;
  std::size_t band = 0;
  for (int y = 0; y < 230; ++y)
    for (int x = 2; x < kW - 2; ++x) {
      const std::size_t i = std::size_t(y) * kW + x;
      const float truth = coverage.at<float>(y, x);
      const bool fractional = (truth > 0.01f && truth < 0.99f) ||
                              (unmixed.alpha[i] > 0 && unmixed.alpha[i] < 1) ||
                              (guided.alpha[i] > 0 && guided.alpha[i] < 1);
      if (!fractional) continue;
      ++band;
      err_unmixed += std::abs(unmixed.alpha[i] - truth);
      err_guided += std::abs(guided.alpha[i] - truth);
    }
  ASSERT_GT(band, std::size_t(kW));
  err_unmixed /= double(band), err_guided /= double(band);
  std::printf(
      "roof line: matte vs true coverage over %zu edge pixels, mean error unmixed %.3f, "
      "guided filter alone %.3f\n",
      band, err_unmixed, err_guided);
  EXPECT_LE(err_unmixed, 0.1);
  EXPECT_GT(err_guided, 2 * err_unmixed);
  const SceneEstimate est = estimate_scene(photo, kCamera, level_horizon());
  dump("roofline_depth", est.geometry.distance_m);
  ASSERT_GT(est.geometry.sky_pixels, std::size_t(kW) * 50);  // the sky is found
  FogScene s = est.scene;
  const float sigma = float(extinction_from_visibility(2000));
  s.medium.sigma_t_per_m = {sigma, sigma, sigma};
  s.medium.layer_top_m = 1500;
  s.render.backend = Backend::cpu;
  const Image without = fog(photo, est.geometry.distance_m, kCamera, s).composite;
  const Image with =
      fog(photo, est.geometry.distance_m, est.geometry.sky_alpha, kCamera, s).composite;
  dump("roofline_haze_without_matte", without);
  dump("roofline_haze_with_matte", with);
  const double fb = created_edge_fraction(photo, without, "roofline_edges_without_matte"),
               fa = created_edge_fraction(photo, with, "roofline_edges_with_matte");
  std::printf("roof line, haze: created-edge pixels without the matte %.4f %%, with it %.4f %%\n",
              100 * fb, 100 * fa);
  EXPECT_LE(fa, 2e-4);
}

}  // namespace
}  // namespace mr
