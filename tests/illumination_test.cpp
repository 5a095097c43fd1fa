// photo/illumination: sun direction from shadow pairs (Ceres) and the sun/sky ratio, against
// synthetic ground truth: a known camera and sun, vertical poles of known heights on the ground,
// projected to pixels (optionally with pixel noise); patches rendered with the Lambertian model.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "mr/error.h"
#include "photo/illumination.h"

namespace mr::photo {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

double dot(const Vec3& a, const Vec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
double angle_deg(const Vec3& a, const Vec3& b) {
  const Vec3 c{a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
  return std::atan2(std::sqrt(dot(c, c)), dot(a, b)) / kDeg;
}

/// The test camera: 1280x720, 60 degrees across, 1.6 m above the ground, pitched 5 degrees
/// down, turned 12 degrees to the right and rolled 1.5 degrees (so no axis is special).
struct Rig {
  Camera camera = Camera::from_horizontal_fov(1280, 720, 60);
  CameraPose pose;
  Rig() {
    pose.position_m = {0, 1.6, 0};
    pose.pitch_deg = -5;
    pose.yaw_deg = 12;
    pose.roll_deg = 1.5;
  }
  /// Inverse of CameraPose::ray_direction: the pixel coordinates at which a world point is seen.
  /// Returns false behind the camera.
  bool project(const Vec3& p, std::array<double, 2>& px) const {
    const auto [f, r, u] = pose.axes();
    const Vec3 d{p.x - pose.position_m.x, p.y - pose.position_m.y, p.z - pose.position_m.z};
    const double zf = dot(d, f);
    if (zf <= 1e-6) return false;
    px[0] = dot(d, r) / zf * camera.focal_px + camera.cx - 0.5;
    px[1] = -dot(d, u) / zf * camera.focal_px + camera.cy - 0.5;
    return true;
  }
  bool in_frame(const std::array<double, 2>& px) const {
    return px[0] >= 0 && px[0] < camera.width && px[1] >= 0 && px[1] < camera.height;
  }
};

/// `n` poles 1 to 4 m tall standing 10 to 45 m ahead, whose top, foot and shadow tip under
/// `sun` are all inside the frame; Gaussian pixel noise of `noise_px` (standard deviation, on
/// every coordinate).
std::vector<ShadowPair> make_pairs(const Rig& rig, const Vec3& sun, int n, double noise_px,
                                   unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uz(10, 45), ux(-0.4, 0.4), uh(1, 4);
  std::normal_distribution<double> noise(0, noise_px > 0 ? noise_px : 1);
  const auto [f, r, u] = rig.pose.axes();
  std::vector<ShadowPair> pairs;
  for (int attempt = 0; attempt < 100000 && int(pairs.size()) < n; ++attempt) {
    const double z = uz(rng), x = ux(rng) * z, h = uh(rng);
    // Ground point x to the right and z ahead along the camera's heading.
    const Vec3 fwd{f.x, 0, f.z}, right{r.x, 0, r.z};
    const double fl = std::sqrt(dot(fwd, fwd)), rl = std::sqrt(dot(right, right));
    const Vec3 foot{z * fwd.x / fl + x * right.x / rl, 0, z * fwd.z / fl + x * right.z / rl};
    const Vec3 top{foot.x, h, foot.z};
    const Vec3 tip{foot.x - h * sun.x / sun.y, 0, foot.z - h * sun.z / sun.y};
    ShadowPair p;
    if (!rig.project(top, p.caster_top_px) || !rig.project(foot, p.caster_foot_px) ||
        !rig.project(tip, p.shadow_tip_px))
      continue;
    if (!rig.in_frame(p.caster_top_px) || !rig.in_frame(p.caster_foot_px) ||
        !rig.in_frame(p.shadow_tip_px))
      continue;
    // Shadows shorter than 0.5 m are too short to mark.
    if (h * std::sqrt(sun.x * sun.x + sun.z * sun.z) / sun.y < 0.5) continue;
    if (noise_px > 0)
      for (auto* c : {&p.caster_top_px, &p.caster_foot_px, &p.shadow_tip_px})
        for (double& v : *c) v += noise(rng);
    pairs.push_back(p);
  }
  EXPECT_EQ(int(pairs.size()), n) << "could not place the poles";
  return pairs;
}

const double kAzimuths[] = {0, 75, 160, 230, 310};
const double kElevations[] = {15, 35, 60, 80};

// Exact pixel coordinates: the fit is exact up to the solver's tolerances. Tolerance 1e-3 deg
// on the direction and on every residual (double-precision lifting, Ceres tolerances 1e-12).
TEST(SunFit, RecoversTheSunFromExactMarks) {
  const Rig rig;
  double worst = 0;
  for (double az : kAzimuths)
    for (double el : kElevations) {
      const Vec3 sun = direction_from_azimuth_elevation(az, el);
      const auto pairs = make_pairs(rig, sun, 6, 0, unsigned(az * 100 + el));
      const SunFit fit = fit_sun_direction(pairs, rig.camera, rig.pose);
      const double err = angle_deg(fit.direction_to_sun, sun);
      worst = std::max(worst, err);
      EXPECT_LT(err, 1e-3) << "az " << az << " el " << el;
      EXPECT_NEAR(fit.elevation_deg, el, 1e-3);
      EXPECT_NEAR(std::remainder(fit.azimuth_deg - az, 360.0), 0.0, el < 89 ? 1e-2 : 1.0);
      EXPECT_TRUE(fit.converged);
      ASSERT_EQ(fit.residuals_deg.size(), pairs.size());
      for (double r : fit.residuals_deg) EXPECT_LT(r, 1e-3);
      for (double r : fit.residuals_px) EXPECT_LT(r, 1e-6);
      EXPECT_LT(fit.rms_residual_deg, 1e-3);
    }
  std::printf("[ measured ] exact marks: worst sun error %.2e deg\n", worst);
}

// 0.5 px Gaussian noise on every marked coordinate, 8 poles: within 2 degrees (the issue's
// acceptance bar) for every sun. The reported reprojection error reflects the noise: each
// pair's RMS mark distance is about 0.5 sqrt(2) px less what the fit absorbs, so its median
// stays below 1.5 px. (The angular residuals of distant poles are larger: their lifted tips move
// along the view by z^2 / (f h_c) per pixel; they are only required to be positive and finite.)
TEST(SunFit, WithinTwoDegreesWithHalfPixelNoise) {
  const Rig rig;
  double worst = 0, sum = 0, worst_px = 0;
  int count = 0;
  for (double az : kAzimuths)
    for (double el : kElevations)
      for (unsigned trial = 0; trial < 4; ++trial) {
        const Vec3 sun = direction_from_azimuth_elevation(az, el);
        const auto pairs = make_pairs(rig, sun, 8, 0.5, 1000 + trial * 7919 + unsigned(az + el));
        const SunFit fit = fit_sun_direction(pairs, rig.camera, rig.pose);
        const double err = angle_deg(fit.direction_to_sun, sun);
        worst = std::max(worst, err);
        sum += err;
        ++count;
        EXPECT_LT(err, 2.0) << "az " << az << " el " << el << " trial " << trial;
        EXPECT_LT(fit.median_residual_px, 1.5);
        EXPECT_GT(fit.rms_residual_deg, 0.0);
        EXPECT_TRUE(std::isfinite(fit.rms_residual_deg));
        worst_px = std::max(worst_px, fit.median_residual_px);
      }
  std::printf("[ measured ] 0.5 px noise, 8 pairs, %d fits: mean error %.3f deg, worst %.3f deg, "
              "worst median reprojection %.2f px\n", count, sum / count, worst, worst_px);
}

// Bad starting points: opposite the true azimuth at elevation 80 deg, opposite at -80 deg
// (below the horizon), and the exact mirror of the sun below the horizon. Same tolerances as
// without a start point: 1e-3 deg on exact marks, 2 deg with 0.5 px noise.
TEST(SunFit, ConvergesFromBadStartingPoints) {
  const Rig rig;
  for (double az : kAzimuths)
    for (double el : {15.0, 45.0, 70.0}) {
      const Vec3 sun = direction_from_azimuth_elevation(az, el);
      const auto exact = make_pairs(rig, sun, 6, 0, 77 + unsigned(az));
      const auto noisy = make_pairs(rig, sun, 8, 0.5, 78 + unsigned(az));
      for (auto [start_az, start_el] : {std::pair{az + 180, 80.0}, std::pair{az + 180, -80.0},
                                        std::pair{az, -el}}) {
        SunFitOptions o;
        o.use_initial_guess = true;
        o.initial_azimuth_deg = start_az;
        o.initial_elevation_deg = start_el;
        const SunFit a = fit_sun_direction(exact, rig.camera, rig.pose, o);
        EXPECT_LT(angle_deg(a.direction_to_sun, sun), 1e-3)
            << "az " << az << " el " << el << " from " << start_az << "/" << start_el;
        EXPECT_TRUE(a.converged);
        const SunFit b = fit_sun_direction(noisy, rig.camera, rig.pose, o);
        EXPECT_LT(angle_deg(b.direction_to_sun, sun), 2.0)
            << "az " << az << " el " << el << " from " << start_az << "/" << start_el;
      }
    }
}

// One mis-click among eight pairs (a tip marked 150 px away): the Cauchy loss keeps the fit
// within 2 degrees (0.5 px noise on the others), and the bad pair stands out in the residuals
// (above 5 degrees and 20 px, the others below 3 degrees and 2 px).
TEST(SunFit, OneMisclickDoesNotDragTheFit) {
  const Rig rig;
  const Vec3 sun = direction_from_azimuth_elevation(130, 30);
  auto pairs = make_pairs(rig, sun, 8, 0.5, 5);
  pairs[3].shadow_tip_px[0] += 150;
  const SunFit fit = fit_sun_direction(pairs, rig.camera, rig.pose);
  const double err = angle_deg(fit.direction_to_sun, sun);
  std::printf("[ measured ] one mis-click of 8: error %.3f deg, its residual %.1f deg\n", err,
              fit.residuals_deg[3]);
  EXPECT_LT(err, 2.0);
  EXPECT_GT(fit.residuals_deg[3], 5.0);
  EXPECT_GT(fit.residuals_px[3], 20.0);
  for (std::size_t i = 0; i < pairs.size(); ++i)
    if (i != 3) {
      EXPECT_LT(fit.residuals_deg[i], 3.0) << i;
      EXPECT_LT(fit.residuals_px[i], 2.0) << i;
    }
}

// Contradictory marks fail with mr::Error(invalid_argument) saying so, not with a wrong sun:
// shadows pointing opposite ways (half the poles under a sun at azimuth 40, half at 220), and
// just two opposite pairs. Threshold: median reprojection error above 5 px (the default).
TEST(SunFit, ContradictoryPairsFailCleanly) {
  const Rig rig;
  auto a = make_pairs(rig, direction_from_azimuth_elevation(40, 35), 4, 0.5, 11);
  const auto b = make_pairs(rig, direction_from_azimuth_elevation(220, 35), 4, 0.5, 12);
  a.insert(a.end(), b.begin(), b.end());
  for (const auto& pairs : {a, std::vector<ShadowPair>{a[0], b[0]}}) {
    try {
      fit_sun_direction(pairs, rig.camera, rig.pose);
      ADD_FAILURE() << "contradictory pairs were fitted";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::invalid_argument);
      EXPECT_NE(std::string(e.what()).find("contradictory"), std::string::npos) << e.what();
      std::printf("[ message  ] %s\n", e.what());
    }
  }
  // Three consistent pairs and one contradictory one: the median is still small, so the fit
  // succeeds (within 2 degrees) and reports the odd one out.
  auto c = make_pairs(rig, direction_from_azimuth_elevation(40, 35), 3, 0.5, 13);
  c.push_back(b[1]);
  const SunFit fit = fit_sun_direction(c, rig.camera, rig.pose);
  EXPECT_LT(angle_deg(fit.direction_to_sun, direction_from_azimuth_elevation(40, 35)), 2.0);
  EXPECT_GT(fit.residuals_deg[3], 30.0);
  EXPECT_LT(fit.median_residual_px, 5.0);
}

void expect_invalid(const std::vector<ShadowPair>& pairs, const Rig& rig, const std::string& needle1,
                    const std::string& needle2) {
  try {
    fit_sun_direction(pairs, rig.camera, rig.pose);
    ADD_FAILURE() << "no error for " << needle2;
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::invalid_argument);
    const std::string m = e.what();
    EXPECT_NE(m.find(needle1), std::string::npos) << m;
    EXPECT_NE(m.find(needle2), std::string::npos) << m;
  }
}

TEST(SunFit, BadMarksNameThePairAndTheProblem) {
  const Rig rig;
  const auto good = make_pairs(rig, direction_from_azimuth_elevation(60, 40), 4, 0, 21);
  expect_invalid({}, rig, "sun fit", "no shadow pairs");
  auto p = good;
  p[2].shadow_tip_px[1] = std::nan("");
  expect_invalid(p, rig, "shadow pair 2", "NaN");
  // The horizon is near row 263 (pitch -5 deg): row 100 is sky.
  p = good;
  p[1].caster_foot_px[1] = 100;
  expect_invalid(p, rig, "shadow pair 1", "caster foot");
  p = good;
  p[3].shadow_tip_px[1] = 100;
  expect_invalid(p, rig, "shadow pair 3", "horizon");
  p = good;
  p[0].caster_top_px = {p[0].caster_foot_px[0], p[0].caster_foot_px[1] + 20};  // below the foot
  expect_invalid(p, rig, "shadow pair 0", "not above its foot");
  CameraPose underground = rig.pose;
  underground.position_m.y = -1;
  EXPECT_THROW(fit_sun_direction(good, rig.camera, underground), Error);
}

// ---- sun / sky ratio -----------------------------------------------------------------------

struct Light {
  std::array<double, 3> e_sun{3.2, 2.9, 2.3};      // warm sun, W/m^2-ish per channel
  std::array<double, 3> l_sky{0.18, 0.24, 0.36};  // blue sky
  Vec3 sun = direction_from_azimuth_elevation(40, 35);
  double truth(int c) const { return e_sun[c] / (std::numbers::pi * l_sky[c]); }  // E/(pi L)
};

/// `n` pixels of a Lambertian material (albedo `rho` with 8 % texture variation per pixel)
/// under the light, plus sensor noise of 0.01 (standard deviation, absolute).
std::vector<std::array<float, 3>> render_patch(const Light& light, const std::array<double, 3>& rho,
                                              const Vec3& normal, bool sunlit, double sky_visibility,
                                              int n, std::mt19937& rng) {
  std::normal_distribution<double> texture(1.0, 0.08), sensor(0.0, 0.01);
  const double nl = std::sqrt(dot(normal, normal));
  const double cos_t = dot(normal, light.sun) / nl;
  std::vector<std::array<float, 3>> px(n);
  for (auto& p : px) {
    const double t = texture(rng);
    for (int c = 0; c < 3; ++c) {
      const double e = (sunlit ? light.e_sun[c] * cos_t : 0) +
                       std::numbers::pi * light.l_sky[c] * sky_visibility;
      p[c] = float(rho[c] * t * e + sensor(rng));
    }
  }
  return px;
}

// 400 noisy pixels per patch; the ratio E_sun / (pi L_sky) within 10 % in every channel (the
// issue's bar) and in the luminance-weighted value, on the ground and on a tilted wall, and the
// reported sigma explains the error (within 4 sigma).
TEST(SunSkyRatio, WithinTenPercentOnNoisyPatches) {
  const Light light;
  std::mt19937 rng(99);
  const std::array<double, 3> rho{0.45, 0.38, 0.30};
  double worst = 0;
  for (const Vec3 normal : {Vec3{0, 1, 0}, Vec3{0.6, 0.2, 0.77}}) {
    SunSkyPatches in;
    in.lit = PatchStats::from_pixels(render_patch(light, rho, normal, true, 1, 400, rng));
    in.shadowed = PatchStats::from_pixels(render_patch(light, rho, normal, false, 1, 400, rng));
    in.normal = normal;
    in.direction_to_sun = light.sun;
    const SunSkyRatio r = fit_sun_sky_ratio(in);
    double truth_y = 0;
    const double luma[3] = {0.2126, 0.7152, 0.0722};
    for (int c = 0; c < 3; ++c) {
      const double truth = light.truth(c);
      truth_y += luma[c] * truth;
      const double rel = std::abs(r.ratio_rgb[c] / truth - 1);
      worst = std::max(worst, rel);
      EXPECT_LT(rel, 0.10) << "channel " << c;
      EXPECT_GT(r.ratio_sigma_rgb[c], 0);
      EXPECT_LT(std::abs(r.ratio_rgb[c] - truth), 4 * r.ratio_sigma_rgb[c]) << "channel " << c;
      EXPECT_NEAR(r.patch_ratio_rgb[c], r.ratio_rgb[c] * r.cos_theta, 1e-12);
    }
    EXPECT_LT(std::abs(r.ratio / truth_y - 1), 0.10);
    EXPECT_NEAR(r.cos_theta, dot(normal, light.sun) / std::sqrt(dot(normal, normal)), 1e-12);
    EXPECT_GT(r.channel_spread, 0.3);  // the sun is warmer than the sky: a real colour difference
  }
  std::printf("[ measured ] sun/sky ratio: worst channel error %.2f %%\n", 100 * worst);
}

// A shadowed patch that sees only 70 % of the sky: given that, within 10 %; assumed 1 (the
// default), the ratio is overestimated, as the header says (by more than 10 % here).
TEST(SunSkyRatio, SkyVisibilityOfTheShadowedPatch) {
  const Light light;
  std::mt19937 rng(7);
  const std::array<double, 3> rho{0.3, 0.3, 0.3};
  SunSkyPatches in;
  in.lit = PatchStats::from_pixels(render_patch(light, rho, {0, 1, 0}, true, 1, 400, rng));
  in.shadowed = PatchStats::from_pixels(render_patch(light, rho, {0, 1, 0}, false, 0.7, 400, rng));
  in.direction_to_sun = light.sun;
  const SunSkyRatio naive = fit_sun_sky_ratio(in);
  in.sky_visibility_shadowed = 0.7;
  const SunSkyRatio r = fit_sun_sky_ratio(in);
  for (int c = 0; c < 3; ++c) {
    EXPECT_LT(std::abs(r.ratio_rgb[c] / light.truth(c) - 1), 0.10) << c;
    EXPECT_GT(naive.ratio_rgb[c] / light.truth(c) - 1, 0.10) << c;
  }
}

// Exact means (no noise) give the closed form to rounding: lit/shadowed - 1 over cos(theta).
TEST(SunSkyRatio, ClosedFormOnExactMeans) {
  SunSkyPatches in;
  in.lit.mean = {0.9, 0.6, 0.3};
  in.shadowed.mean = {0.3, 0.2, 0.15};
  in.direction_to_sun = direction_from_azimuth_elevation(0, 30);
  const SunSkyRatio r = fit_sun_sky_ratio(in);
  EXPECT_NEAR(r.cos_theta, 0.5, 1e-12);
  EXPECT_NEAR(r.patch_ratio_rgb[0], 2.0, 1e-12);
  EXPECT_NEAR(r.patch_ratio_rgb[1], 2.0, 1e-12);
  EXPECT_NEAR(r.patch_ratio_rgb[2], 1.0, 1e-12);
  EXPECT_NEAR(r.ratio_rgb[0], 4.0, 1e-12);
  EXPECT_EQ(r.ratio_sigma, 0.0);
}

TEST(SunSkyRatio, BadInputIsRejected) {
  SunSkyPatches good;
  good.lit.mean = {0.9, 0.6, 0.3};
  good.shadowed.mean = {0.3, 0.2, 0.15};
  good.direction_to_sun = direction_from_azimuth_elevation(0, 30);
  auto expect = [](const SunSkyPatches& in, const std::string& needle) {
    try {
      fit_sun_sky_ratio(in);
      ADD_FAILURE() << "no error for " << needle;
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::invalid_argument);
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  SunSkyPatches in = good;
  std::swap(in.lit, in.shadowed);
  expect(in, "not brighter");
  in = good;
  in.lit.mean[2] = 0.1;
  expect(in, "blue");
  in = good;
  in.direction_to_sun = {0, -1, 0};
  expect(in, "behind");
  in = good;
  in.shadowed.mean[1] = std::nan("");
  expect(in, "NaN");
  in = good;
  in.sky_visibility_lit = 0;
  expect(in, "sky visibility");
  in = good;
  in.shadowed.mean[0] = 0;
  expect(in, "not positive");
  EXPECT_THROW(PatchStats::from_pixels({}), Error);
}

}  // namespace
}  // namespace mr::photo
