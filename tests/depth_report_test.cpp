// Depth error per geometry source on sample_photos (issue 4 acceptance: "report the depth error
// (AbsRel, delta<1.25) of each geometry source, and of the relative->metric fit from a perturbed
// map"). aloe has ground truth (Middlebury); the other maps are approximate hand-built ones
// (sample_photos/README.md), so their rows compare two estimates. A report, not a bar: the
// checks are only sanity (finite numbers in range; the fit from sparse truth on aloe < 5 %).
//
// Sources: (a) mr::estimate_geometry with the photo and no annotations (automatic), (a') with
// sample_photos/leuven_annotations.json, (b1) mr::fit_relative_depth of a perturbed relative
// inverse-depth map (alpha / z + beta, 2 % noise, 5 % outliers) to every 97th true distance
// with 1 % noise, (b2) the same map fitted to the automatic estimate (a) as the reference.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <string>

#include "mr/annotations.h"
#include "mr/depth.h"
#include "mr/depth_fit.h"
#include "mr/error.h"
#include "mr/estimate.h"
#include "mr/io.h"

namespace mr {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

struct Metrics {
  double abs_rel = 0, delta1 = 0;
  std::size_t pixels = 0;
};

// Over the pixels where the reference is finite; a non-finite estimate there is a miss (AbsRel 1).
Metrics metrics(const Image& est, const Image& truth) {
  double sum = 0;
  std::size_t n = 0, good = 0;
  for (std::size_t i = 0; i < truth.pixel_count(); ++i) {
    const double d = est.data()[i], g = truth.data()[i];
    if (!std::isfinite(g) || !(g > 0)) continue;
    ++n;
    sum += std::isfinite(d) ? std::abs(d - g) / g : 1.0;
    if (std::isfinite(d) && d > 0 && std::max(d / g, g / d) < 1.25) ++good;
  }
  return {n ? sum / double(n) : 0, n ? double(good) / double(n) : 0, n};
}

void report(const char* photo, const char* source, const char* reference, const Metrics& m) {
  std::printf("%-9s %-34s vs %-12s AbsRel %.4f  delta<1.25 %.4f  (%zu px)\n", photo, source,
              reference, m.abs_rel, m.delta1, m.pixels);
  EXPECT_TRUE(std::isfinite(m.abs_rel));
  EXPECT_GE(m.delta1, 0);
  EXPECT_LE(m.delta1, 1);
  EXPECT_GT(m.pixels, 0u);
}

Image perturbed_inverse(const Image& truth, const Camera& camera) {
  std::mt19937 rng(1234);
  std::normal_distribution<double> gauss(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  Image rel(truth.width(), truth.height(), 1, {"Y"});
  // alpha / z + beta with alpha, beta chosen per map so that the values span about [0.1, 1].
  double zmin = 1e300, zmax = 0;
  for (int y = 0; y < truth.height(); ++y)
    for (int x = 0; x < truth.width(); ++x)
      if (const double d = truth.at(x, y, 0); std::isfinite(d))
        zmin = std::min(zmin, d / camera.z_to_distance(x, y)), zmax = std::max(zmax, d / camera.z_to_distance(x, y));
  const double alpha = 0.9 / (1 / zmin - 1 / zmax), beta = 0.1 - alpha / zmax;
  for (int y = 0; y < truth.height(); ++y)
    for (int x = 0; x < truth.width(); ++x) {
      const double d = truth.at(x, y, 0);
      double r = std::isfinite(d) ? alpha / (d / camera.z_to_distance(x, y)) + beta : 0.0;
      r += 0.02 * gauss(rng);
      if (uniform(rng) < 0.05) r = 1.2 * uniform(rng);
      rel.at(x, y, 0) = float(r);
    }
  return rel;
}

struct Sample {
  const char* stem;
  Camera camera;
  const char* reference;  // "ground truth" or "approximate"
};

TEST(DepthReport, PerGeometrySource) {
  const std::string dir = std::string(MR_SOURCE_DIR) + "/sample_photos/";
  const Sample samples[] = {
      {"aloe", Camera::from_focal_px(1282, 1110, 3740), "ground truth"},
      {"leuven", Camera::from_horizontal_fov(751, 563, 60), "approximate"},
      {"building", Camera::from_horizontal_fov(868, 600, 50), "approximate"},
      {"aerial", Camera::from_horizontal_fov(640, 480, 50), "approximate"},
  };
  for (const Sample& s : samples) {
    const Image photo = read_image(dir + s.stem + ".jpg");
    const Image truth = read_depth(dir + s.stem + "_depth.exr", s.camera).distance_m;
    const GeometryEstimate automatic = estimate_geometry(photo, s.camera, Annotations{});
    report(s.stem, "(a) automatic", s.reference, metrics(automatic.distance_m, truth));
    if (std::string(s.stem) == "leuven") {
      const GeometryEstimate annotated =
          estimate_geometry(photo, s.camera, load_annotations(dir + "leuven_annotations.json"));
      report(s.stem, "(a') leuven_annotations.json", s.reference,
             metrics(annotated.distance_m, truth));
    }
    const Image rel = perturbed_inverse(truth, s.camera);
    Image sparse(truth.width(), truth.height(), 1, {"Z"});
    std::mt19937 rng(99);
    std::normal_distribution<double> gauss(0.0, 1.0);
    for (std::size_t i = 0; i < truth.pixel_count(); ++i)
      sparse.data()[i] = i % 97 == 0 && std::isfinite(truth.data()[i])
                             ? float(truth.data()[i] * (1 + 0.01 * gauss(rng)))
                             : kInf;
    DepthFitOptions o;
    o.camera = s.camera;
    const DepthFit b1 = fit_relative_depth(rel, sparse, o);
    const Metrics m1 = metrics(b1.distance_m, truth);
    report(s.stem, "(b1) fit to sparse truth", s.reference, m1);
    if (std::string(s.stem) == "aloe") {
      EXPECT_LT(m1.abs_rel, 0.05);
    }
    try {
      const DepthFit b2 = fit_relative_depth(rel, automatic.distance_m, o);
      report(s.stem, "(b2) fit to the automatic estimate", s.reference, metrics(b2.distance_m, truth));
    } catch (const Error& e) {
      std::printf("%-9s (b2) fit to the automatic estimate: fails cleanly: %s\n", s.stem, e.what());
    }
  }
}

}  // namespace
}  // namespace mr
