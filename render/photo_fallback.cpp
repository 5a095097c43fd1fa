#include "render/photo_fallback.h"

#include <tbb/parallel_for.h>

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

Vec3d PhotoFallback::point(int x, int y, double distance) const {
  return add(origin_, ray(x, y), distance);
}

void PhotoFallback::cache_points() {
  const int w = distance_m_.width, h = distance_m_.height;
  points_.emplace(std::size_t(w) * std::size_t(h));
  tbb::parallel_for(0, h, [&](int y) {
    Vec3d* row = points_->data() + std::size_t(y) * std::size_t(w);
    for (int x = 0; x < w; ++x) row[x] = point(x, y, distance_m_.at(x, y, 0));
  });
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
  const double here = luminance(photo_.pixel(x, y));
  if (!(here > 0)) return false;  // what every path below ends in
  const Vec3d xp = point(x, y, distance);
  const double root_k = std::sqrt(k);
  // The tests below compare `here` with the median (element count / 2 of the sorted values) of
  // each level. Both comparisons are monotone in the level (rounded products and quotients by a
  // positive root_k are), so the median passes exactly when more than half of the values
  // (count / 2 + 1 of them) pass: counted here, with no values kept and no selection.
  int n_lit = 0, n_dark = 0, lit_pass = 0, dark_pass = 0;
  constexpr int kRadius = 3;
  const int w = distance_m_.width, h = distance_m_.height;
  const Vec3d* points = points_ ? points_->data() : nullptr;
  const int i0 = std::max(0, x - kRadius), i1 = std::min(w - 1, x + kRadius);
  const int j0 = std::max(0, y - kRadius), j1 = std::min(h - 1, y + kRadius);
  // A level already counted 3 times fails for good when, even if every neighbour not yet seen
  // (at most `unseen`) joined it and passed, fewer than half of it would pass: the answer is
  // false then, whatever the rest (deep inside a shadow, after about half of the window; the
  // bound grows with `unseen`, so the largest is the one to test).
  auto fails_for_good = [](int count, int pass, int unseen) {
    return count >= 3 && pass + unseen < (count + unseen) / 2 + 1;
  };
  for (int j = j0; j <= j1; ++j) {
    const int unseen = (j1 - j + 1) * (i1 - i0 + 1);  // rows j..j1
    if (fails_for_good(n_dark, dark_pass, unseen) || fails_for_good(n_lit, lit_pass, unseen))
      return false;
    for (int i = i0; i <= i1; ++i) {
      if (i == x && j == y) continue;
      const float v = sun_disk[std::size_t(j) * w + i];
      if (v != 1.0f && v != 0.0f) continue;
      const double dn = distance_m_.at(i, j, 0);
      if (!std::isfinite(dn)) continue;
      const Vec3d nn = {normals_.at(i, j, 0), normals_.at(i, j, 1), normals_.at(i, j, 2)};
      if (dot(nn, n) < 0.9) continue;
      const Vec3d xn = points ? points[std::size_t(j) * w + i] : point(i, j, dn);
      if (std::fabs(dot(sub(xn, xp), n)) > 0.02 * distance) continue;
      const double level = luminance(photo_.pixel(i, j));
      if (v == 1.0f) {
        ++n_lit;
        lit_pass += here >= level / root_k;
      } else {
        ++n_dark;
        dark_pass += here >= root_k * level;
      }
    }
  }
  if (n_lit < 3 && n_dark < 3) return false;
  if (n_dark >= 3 && dark_pass < n_dark / 2 + 1) return false;
  if (n_lit >= 3 && lit_pass < n_lit / 2 + 1) return false;
  return true;
}

}  // namespace mr::render
