// Private to libmr: the surface term's photo fallback (issue 13, section 3), one implementation
// for both backends. Where the occluder mesh says a sun-facing surface pixel is (partly)
// shadowed but the photo shows it as bright as its sunlit neighbours on its plane (silhouettes,
// shadow edges the mesh misplaces), the surface term takes the sun as seen (S from the light
// path's transmittance) instead of S = 1. The CPU core asks it per pixel in its last pass; the
// Vulkan backend after reading back the sun visibility, AO and the "sun seen" T of each pixel.
#pragma once

#include <array>
#include <optional>
#include <vector>

#include "mr/camera.h"
#include "mr/image.h"
#include "mr/scene.h"
#include "render/huge_pages.h"
#include "render/math.h"

namespace mr::render {

class PhotoFallback {
 public:
  /// Whether the fallback has anything to do: a photo of the distance map's size (>= 3
  /// channels), a sun, normals, and occluders that cast shadows.
  static bool wanted(const FogScene& scene, ConstImageView distance_m, ConstImageView normals,
                     ConstImageView photo, bool casts_shadows);

  /// The views must outlive this object.
  PhotoFallback(const Camera& camera, const FogScene& scene, ConstImageView distance_m,
                ConstImageView normals, ConstImageView photo,
                const std::array<float, 3>& sky_radiance);

  /// Whether the pixel has a sun-disk visibility at all: a surface with a normal that faces the
  /// sun (where the CPU core's sun_disk_visibility is not -1).
  bool faces_sun(int x, int y) const;

  /// The sun-disk map the test reads from a backend's sun visibility output (row-major, the
  /// image's size): the visibility where faces_sun, else -1.
  std::vector<float> sun_disk_map(ConstImageView sun_visibility) const;

  /// Whether the photo shows pixel (x, y), which the mesh calls (partly) shadowed, as sunlit.
  /// ao: its ambient occlusion; sun_disk: every pixel's sun-disk visibility from the mesh
  /// (row-major, -1 where it does not apply), before any fallback.
  bool shows_sunlit(int x, int y, double ao, const float* sun_disk) const;

  /// Computes every pixel's surface point once (in parallel; 24 bytes a pixel) for
  /// shows_sunlit, which otherwise recomputes a neighbour's point, a normalized camera ray, for
  /// each of the up to 48 pixels around every pixel it is asked about (the CPU core asks about
  /// every shadowed sun-facing pixel). The same expression: answers are unchanged.
  void cache_points();

 private:
  Vec3d ray(int x, int y) const;
  Vec3d point(int x, int y, double distance) const;  // the surface point of pixel (x, y)

  const Camera& camera_;
  const FogScene& scene_;
  ConstImageView distance_m_, normals_, photo_;
  std::array<float, 3> sky_radiance_;
  Vec3d origin_{}, forward_{}, right_{}, up_{}, sun_dir_{};
  std::optional<HugePageArray<Vec3d>> points_;  // cache_points(): row-major, the image's size
};

}  // namespace mr::render
