// render/photo_fallback's pixel test (issue 13) against a direct reading of its rule: the
// neighbours' levels collected, sorted and their medians compared. PhotoFallback counts instead
// of sorting and stops once a level has failed for good (issue 12 item 4); both must give the
// same answer for every pixel of random maps, at the image's borders too.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

#include "mr/camera.h"
#include "mr/image.h"
#include "mr/scene.h"
#include "render/math.h"
#include "render/photo_fallback.h"
#include "render/physics/scattering.h"

namespace mr {
namespace {

using render::Vec3d;

double luminance(const float* rgb) {
  return 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2];
}

struct Maps {
  Camera camera = Camera::from_horizontal_fov(48, 36, 60);
  FogScene scene;
  Image distance, normals, photo;
  std::vector<float> sun_disk, ao;
};

// Ground (y = 0) below a wall 20 m ahead, both facing a sun behind the camera, with random
// off-plane depths, turned normals, sky pixels, sun-disk values and photo levels. `deep`: a
// shadow nearly everywhere, with photo levels spread evenly, so that about half of a pixel's
// neighbours pass (where stopping early could go wrong).
Maps random_maps(unsigned seed, bool deep) {
  Maps m;
  const int w = m.camera.width, h = m.camera.height;
  m.scene.lighting.sun = Sun{direction_from_azimuth_elevation(180, 45), {3, 3, 3}, 0.27};
  m.distance = Image(w, h, 1);
  m.normals = Image(w, h, 3);
  m.photo = Image(w, h, 3);
  m.sun_disk.resize(std::size_t(w) * h);
  m.ao.resize(std::size_t(w) * h);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const Vec3 r = m.scene.pose.ray_direction(m.camera, x, y);
      const bool ground = r.y < -0.05;
      double d = ground ? m.scene.pose.position_m.y / -r.y : 20.0 / r.z;
      Vec3 n = ground ? Vec3{0, 1, 0} : Vec3{0, 0, -1};
      const double roll = u(rng);
      if (roll < 0.08)
        d *= 1.5;  // off the plane
      else if (roll < 0.13)
        n = {1, 0, 0};  // facing another way
      else if (roll < 0.16)
        d = std::numeric_limits<double>::infinity();  // sky
      m.distance.at(x, y, 0) = float(d);
      m.normals.at(x, y, 0) = float(n.x);
      m.normals.at(x, y, 1) = float(n.y);
      m.normals.at(x, y, 2) = float(n.z);
      const double disk = u(rng);
      const double lit_share = deep ? 0.03 : 0.4, dark_share = deep ? 0.95 : 0.4;
      const float v = disk < lit_share                            ? 1.0f
                      : disk < lit_share + dark_share             ? 0.0f
                      : disk < 0.5 * (1 + lit_share + dark_share) ? 0.5f
                                                                  : -1.0f;
      m.sun_disk[std::size_t(y) * w + x] = v;
      double level = (v == 1.0f ? 0.8 : 0.2) * (0.7 + 0.6 * u(rng));
      if (deep || u(rng) < 0.2) level = u(rng);  // a photo that disagrees with the mesh
      if (u(rng) < 0.02) level = 0;
      for (int c = 0; c < 3; ++c) m.photo.at(x, y, c) = float(level * (0.9 + 0.1 * c));
      m.ao[std::size_t(y) * w + x] = float(0.3 + 0.7 * u(rng));
    }
  return m;
}

// The rule as render/photo_fallback.h states it, medians taken by sorting.
bool reference_shows_sunlit(const Maps& m, const std::array<float, 3>& sky, int x, int y) {
  const int w = m.camera.width, h = m.camera.height;
  const double distance = m.distance.at(x, y, 0);
  const Vec3d sun = render::normalized(render::vec(m.scene.lighting.sun->direction_to_sun));
  const Vec3d n = {m.normals.at(x, y, 0), m.normals.at(x, y, 1), m.normals.at(x, y, 2)};
  const double cos_i = render::dot(n, sun);
  if (!std::isfinite(distance) || cos_i <= 0) return false;
  const double e = luminance(m.scene.lighting.sun->irradiance.data()) * cos_i;
  const double amb = std::numbers::pi * luminance(sky.data()) * m.ao[std::size_t(y) * w + x];
  const double k = amb > 0 ? std::min(100.0, (e + amb) / amb) : 100.0;
  if (k < 1.25) return false;
  const auto [forward, right, up] = m.scene.pose.axes();
  auto point = [&](int i, int j, double d) {
    const Vec3d r =
        render::physics::camera_ray(render::vec(forward), render::vec(right), render::vec(up),
                                    m.camera.focal_px, m.camera.cx, m.camera.cy, i, j);
    return render::add(render::vec(m.scene.pose.position_m), r, d);
  };
  const Vec3d xp = point(x, y, distance);
  const double here = luminance(m.photo.pixel(x, y));
  std::vector<double> lit, dark;
  for (int j = std::max(0, y - 3); j <= std::min(h - 1, y + 3); ++j)
    for (int i = std::max(0, x - 3); i <= std::min(w - 1, x + 3); ++i) {
      if (i == x && j == y) continue;
      const float v = m.sun_disk[std::size_t(j) * w + i];
      if (v != 1.0f && v != 0.0f) continue;
      const double dn = m.distance.at(i, j, 0);
      if (!std::isfinite(dn)) continue;
      const Vec3d nn = {m.normals.at(i, j, 0), m.normals.at(i, j, 1), m.normals.at(i, j, 2)};
      if (render::dot(nn, n) < 0.9) continue;
      if (std::fabs(render::dot(render::sub(point(i, j, dn), xp), n)) > 0.02 * distance) continue;
      (v == 1.0f ? lit : dark).push_back(luminance(m.photo.pixel(i, j)));
    }
  if (lit.size() < 3 && dark.size() < 3) return false;
  const double root_k = std::sqrt(k);
  auto median = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  if (dark.size() >= 3 && !(here >= root_k * median(dark))) return false;
  if (lit.size() >= 3 && !(here >= median(lit) / root_k)) return false;
  return here > 0;
}

TEST(PhotoFallback, CountingEqualsTheMediansOfTheRule) {
  const std::array<float, 3> sky{0.2f, 0.2f, 0.2f};
  int sunlit = 0, shadowed = 0;
  for (unsigned seed = 1; seed <= 24; ++seed) {
    const Maps m = random_maps(seed, seed > 12);
    render::PhotoFallback fallback(m.camera, m.scene, m.distance.view(), m.normals.view(),
                                   m.photo.view(), sky);
    if (seed % 2 == 0) fallback.cache_points();  // both ways of finding a neighbour's point
    for (int y = 0; y < m.camera.height; ++y)
      for (int x = 0; x < m.camera.width; ++x) {
        const double ao = m.ao[std::size_t(y) * m.camera.width + x];
        const bool expected = reference_shows_sunlit(m, sky, x, y);
        ASSERT_EQ(fallback.shows_sunlit(x, y, ao, m.sun_disk.data()), expected)
            << "seed " << seed << ", pixel " << x << ", " << y;
        (expected ? sunlit : shadowed) += 1;
      }
  }
  // Both answers, many times (the maps are not trivially one way).
  EXPECT_GT(sunlit, 500);
  EXPECT_GT(shadowed, 500);
}

}  // namespace
}  // namespace mr
