#include "render/photo_fallback.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "render/math.h"
#include "render/physics/scattering.h"

namespace mr::render {

namespace {

template <typename T>
double luminance(const T* rgb) {
  return 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2];
}

}  // namespace

bool PhotoFallback::wanted(const FogScene& scene, ConstImageView distance_m, ConstImageView normals,
                           ConstImageView photo, bool casts_shadows) {
  return casts_shadows && scene.lighting.sun && normals.data != nullptr && photo.data != nullptr &&
         photo.channels >= 3 && photo.width == distance_m.width &&
         photo.height == distance_m.height;
}

PhotoFallback::PhotoFallback(const Camera& camera, const FogScene& scene, ConstImageView distance_m,
                             ConstImageView normals, ConstImageView photo,
                             const std::array<float, 3>& sky_radiance)
    : camera_(camera),
      scene_(scene),
      distance_m_(distance_m),
      normals_(normals),
      photo_(photo),
      sky_radiance_(sky_radiance) {
  origin_ = vec(scene.pose.position_m);
  const auto [forward, right, up] = scene.pose.axes();
  forward_ = vec(forward);
  right_ = vec(right);
  up_ = vec(up);
  if (scene.lighting.sun) sun_dir_ = normalized(vec(scene.lighting.sun->direction_to_sun));
}

// The cores' ray (the same function, so all find the same neighbours on a plane).
Vec3d PhotoFallback::ray(int x, int y) const {
  return physics::camera_ray(forward_, right_, up_, camera_.focal_px, camera_.cx, camera_.cy, x, y);
}

bool PhotoFallback::faces_sun(int x, int y) const {
  if (!scene_.lighting.sun || normals_.data == nullptr) return false;
  if (!std::isfinite(distance_m_.at(x, y, 0))) return false;
  const Vec3d n = {normals_.at(x, y, 0), normals_.at(x, y, 1), normals_.at(x, y, 2)};
  return dot(n, n) >= 0.5 && dot(n, sun_dir_) > 0;
}

std::vector<float> PhotoFallback::sun_disk_map(ConstImageView sun_visibility) const {
  const int w = distance_m_.width, h = distance_m_.height;
  std::vector<float> disk(std::size_t(w) * h, -1.0f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (faces_sun(x, y)) disk[std::size_t(y) * w + x] = sun_visibility.at(x, y, 0);
  return disk;
}

// The model predicts the contrast between the sunlit and the shadowed parts of one surface,
// k = (E cos + pi L_sky AO) / (pi L_sky AO). The pixel's neighbours within 3 pixels that lie on
// its plane and face the same way give the photo's two levels: the median of those the mesh
// calls fully sunlit and of those it calls fully shadowed. The pixel counts as sunlit when it is
// at least sqrt(k) times brighter than the shadowed level (so inside a real shadow, where the
// mesh's edge may have put a few sunlit neighbours that the photo shows dark, it stays
// shadowed) and no more than sqrt(k) times darker than the sunlit level. Each level needs 3
// neighbours; with neither (deep inside a shadow there are no sunlit ones: the shadowed level
// decides) the mesh decides, as it does where lit and shadowed would look alike (k < 1.25).
bool PhotoFallback::shows_sunlit(int x, int y, double ao, const float* sun_disk) const {
  if (photo_.data == nullptr || !scene_.lighting.sun) return false;
  const double distance = distance_m_.at(x, y, 0);
  const Vec3d n = {normals_.at(x, y, 0), normals_.at(x, y, 1), normals_.at(x, y, 2)};
  const double cos_i = dot(n, sun_dir_);
  if (!std::isfinite(distance) || cos_i <= 0) return false;
  const double e = luminance(scene_.lighting.sun->irradiance.data()) * cos_i;
  const double amb = std::numbers::pi * luminance(sky_radiance_.data()) * ao;
  const double k = amb > 0 ? std::min(100.0, (e + amb) / amb) : 100.0;
  if (k < 1.25) return false;
  const Vec3d xp = add(origin_, ray(x, y), distance);
  constexpr int kRadius = 3;
  constexpr int kMax = (2 * kRadius + 1) * (2 * kRadius + 1);
  double lit[kMax], dark[kMax];
  int n_lit = 0, n_dark = 0;
  const int w = distance_m_.width, h = distance_m_.height;
  for (int j = std::max(0, y - kRadius); j <= std::min(h - 1, y + kRadius); ++j)
    for (int i = std::max(0, x - kRadius); i <= std::min(w - 1, x + kRadius); ++i) {
      if (i == x && j == y) continue;
      const float v = sun_disk[std::size_t(j) * w + i];
      if (v != 1.0f && v != 0.0f) continue;
      const double dn = distance_m_.at(i, j, 0);
      if (!std::isfinite(dn)) continue;
      const Vec3d nn = {normals_.at(i, j, 0), normals_.at(i, j, 1), normals_.at(i, j, 2)};
      if (dot(nn, n) < 0.9) continue;
      const Vec3d xn = add(origin_, ray(i, j), dn);
      if (std::fabs(dot(sub(xn, xp), n)) > 0.02 * distance) continue;
      (v == 1.0f ? lit[n_lit++] : dark[n_dark++]) = luminance(photo_.pixel(i, j));
    }
  auto median = [](double* v, int count) {
    std::nth_element(v, v + count / 2, v + count);
    return v[count / 2];
  };
  const double here = luminance(photo_.pixel(x, y));
  const double root_k = std::sqrt(k);
  if (n_lit < 3 && n_dark < 3) return false;
  if (n_dark >= 3 && !(here >= root_k * median(dark, n_dark))) return false;
  if (n_lit >= 3 && !(here >= median(lit, n_lit) / root_k)) return false;
  return here > 0;
}

}  // namespace mr::render
