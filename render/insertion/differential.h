// Private to libmr: compositing inserted objects into a photo by differential rendering
// (Debevec 1998; Karsch et al. 2011), issue 16, DESIGN.md section 1 item 7.
//
// The photo's reconstructed geometry (the occluder mesh of its depth map) is "rendered" twice
// under the estimated light, without and with the objects, at each photo pixel p:
//
//   shading(p) = E_sun (n.l)+ V_sun(p) / pi + L_sky A_sky(p) + sum_lamps I / r^2 (n.l)+ V_lamp / pi
//
// (the Lambertian irradiance / pi; V_sun the visible share of the sun's disk, A_sky the share of
// a uniform upper-hemisphere sky seen, (1 + n.y) / 2 times the cosine-weighted share of upward
// rays that escape, as render/surface_shading.h defines them), V and A traced once against the
// photo's mesh alone and once against mesh + objects WITH THE SAME RAYS, so their noise cancels
// in the ratio. The photo's albedo is I / shading_without, so the photo pixel becomes
//
//   I * shading_with / shading_without     (the "shadow layer" is that ratio),
//
// exactly 1 wherever no ray meets an object. Object pixels show the object's own radiance,
// shaded with render/surface_shading.h's BRDF (Lambert + GGX, split-sum sky; glTF's
// metallic-roughness mapped onto its diffuse albedo and F0), its sun and sky visibility traced
// against mesh + objects (so the photo's buildings shadow the objects, and objects shadow
// themselves). Each pixel takes samples_per_axis^2 stratified sub-pixel camera rays against the
// objects; each sample is depth-tested against the photo's depth map as a bilinear filter of the
// per-pixel test (percentage-closer filtering on the depth map): inside a continuous surface
// all four nearest pixels agree and the test is exact; across a depth discontinuity (where the
// map cannot say where within a pixel the edge lies) it fades over one pixel. The pixel is
// sum_k [vis_k L_obj,k + (1 - vis_k) I ratio] / S^2, its matte sum_k vis_k / S^2.
//
// Not modelled: light the objects reflect onto the photo (bounce, colour bleeding) and light the
// photo's surfaces reflect onto the objects (the lower hemisphere is dark, as in the scattering
// core's surface term); refraction. Normal maps perturb the objects' shading normal only
// (object_scene.h's normal_mapped): their shadow rays leave the true surface, and the photo's
// side of the ratio does not see the bumps.
//
// The seam for the real-time techniques (docs/architecture.md, "Inserted objects"): everything
// that decides visibility goes through VisibilityPath (shadow rays against "the photo" and "the
// objects", separately). EmbreeVisibility traces the occluder mesh and the objects' BVH; a
// screen-space path (shadows and reflections from the depth image), shadow maps rasterized from
// the same meshes, or all-frequency precomputed visibility implement the same two queries, and
// the renderer, the compositing and the AOVs stay as they are. The shading of object points is
// one function (shade_object_point) calling render/surface_shading.h, so an alternative BRDF
// evaluation (e.g. prefiltered environment lighting) replaces that one call.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "mr/camera.h"
#include "mr/cancel.h"
#include "mr/image.h"
#include "mr/scene.h"
#include "render/embree_scene.h"
#include "render/insertion/object_scene.h"

namespace mr::render::insertion {

/// Which geometry a shadow query asks about.
enum class Geometry { photo, objects };

/// The seam: shadow rays against the photo's reconstructed geometry and against the inserted
/// objects, separately. Implementations must be thread-safe (called from many TBB workers).
class VisibilityPath {
 public:
  virtual ~VisibilityPath() = default;
  virtual std::string name() const = 0;
  /// blocked[i] = whether `which` lies on rays[i] (within its t range).
  virtual void occluded(Geometry which, std::span<const ShadowRay> rays, bool* blocked) const = 0;
};

/// The CPU path: Embree rays against the occluder mesh (may be null: the photo casts nothing)
/// and the objects' scene.
class EmbreeVisibility final : public VisibilityPath {
 public:
  EmbreeVisibility(const OccluderScene* photo, const ObjectScene& objects)
      : photo_(photo), objects_(objects) {}
  std::string name() const override { return "cpu-embree"; }
  void occluded(Geometry which, std::span<const ShadowRay> rays, bool* blocked) const override;

 private:
  const OccluderScene* photo_;
  const ObjectScene& objects_;
};

struct InsertionSettings {
  int samples_per_axis = 4;  ///< camera rays per pixel = this^2 (anti-aliasing), 1..8
  int sun_rays = 16;         ///< per pixel over the sun's disk (split among sub-pixel samples)
  int sky_rays = 64;         ///< cosine-weighted per pixel for the sky's visibility
  /// Photo pixels farther than this many bounding radii from every object skip the sky rays
  /// against the objects: an object of radius r at distance D hides at most (r / D)^2 of the
  /// cosine-weighted sky (0.4 % at 16).
  double sky_influence_radii = 16;
  /// The sky influence counts the objects' tight bounding radius (the farthest vertex from the
  /// box's centre) instead of the box's half-diagonal (up to sqrt(3) larger for round objects):
  /// the preview's choice (a third of the area to shade for a sphere).
  bool sky_influence_tight = false;
  /// Relative depth tolerance of the occlusion test: an object sample is in front of the
  /// photo's surface when its distance < d (1 + tolerance).
  double depth_tolerance = 2e-3;
  /// The interactive preview's pattern: every pixel draws the same sun, sky and sub-pixel
  /// directions (stratum centres, no per-pixel rotation), so neighbouring pixels agree (no
  /// salt-and-pepper speckle: a few directions give smooth, slightly banded penumbrae and
  /// contact shadows instead) and a pixel's samples do not change between frames (no shimmer
  /// while an object is dragged). Off: each pixel's pattern is rotated by a hash of the pixel
  /// (noise instead of bands; what the full-quality render converges with).
  bool fixed_pattern = false;
  int threads = 0;  ///< 0: all cores
};

/// What the renderer needs. Views must outlive the call.
struct InsertionInputs {
  Camera camera;
  CameraPose pose;
  /// Sun, sky (must have a radiance; lamps allowed), all in the photo's scene-linear units.
  Lighting lighting;
  ConstImageView photo;       ///< scene-linear, >= 3 channels, the camera's size
  ConstImageView distance_m;  ///< 1 channel, +inf = sky, the camera's size
  ConstImageView normals;     ///< 3 channels, world (render::estimate_normals)
  const ObjectScene* objects = nullptr;
  const VisibilityPath* visibility = nullptr;
  const CancelToken* cancel = nullptr;
};

struct InsertionLayers {
  Image composite;   ///< R,G,B(,A carried): the photo with the objects
  Image matte;       ///< 1 channel: object coverage after occlusion, in [0, 1]
  Image shadow;      ///< R,G,B: shading_with / shading_without on the photo's surfaces (1: none)
  Image difference;  ///< R,G,B: composite - photo
  Image distance_m;  ///< 1 channel: the object's distance where it covers the pixel centre
                     ///< in front of the photo, else the photo's
  Image object_radiance;  ///< R,G,B: the objects' shaded radiance, premultiplied by the matte
  std::size_t shadow_rays = 0, camera_rays = 0;
};

/// Renders the layers. Deterministic. Throws mr::Error(invalid_argument / size_mismatch) for bad
/// inputs, mr::Error(cancelled).
InsertionLayers render_insertion(const InsertionInputs& in, const InsertionSettings& settings);

/// The interactive preview's region rendering. The photo in square screen tiles, each with the
/// bounding sphere of its pixels' shadow-ray origins (the photo's surface points, lifted as the
/// renderer lifts them) and its widest pixel footprint: what does not depend on the objects, made
/// once per photo. A tile whose sphere no object's shadow cone, sky-influence sphere or lamp
/// segment can reach, and that no object's screen rectangle overlaps, holds the photo unchanged:
/// the tile tests are the per-pixel tests of render_insertion widened by the tile's radius, so
/// they are conservative (rendering only the influenced tiles gives render_insertion's image
/// exactly; tests/insert_test.cpp checks it).
struct PhotoTiles {
  int tile_px = 8;
  int tiles_x = 0, tiles_y = 0;
  /// Per tile, row-major: centre x, y, z, radius (< 0: no pixel with a surface), footprint (m).
  std::vector<std::array<float, 5>> bounds;
};
PhotoTiles photo_tiles(const InsertionInputs& in, int tile_px = 8);
/// 1 for every tile the objects of `in` may change (a few microseconds per tile).
std::vector<std::uint8_t> influenced_tiles(const InsertionInputs& in,
                                           const InsertionSettings& settings,
                                           const PhotoTiles& tiles);
/// Renders the tiles with render_mask[i] != 0 into `out` (allocated at the camera's size when it
/// is not) and resets those with clean_mask[i] != 0 (and not rendered) to the photo's own values
/// (the composite = the photo, shadow 1, matte 0, the photo's distance); others are left alone.
/// clean_mask may be empty. out's ray counts are this call's.
void render_insertion_tiles(const InsertionInputs& in, const InsertionSettings& settings,
                            const PhotoTiles& tiles, std::span<const std::uint8_t> render_mask,
                            std::span<const std::uint8_t> clean_mask, InsertionLayers& out);

}  // namespace mr::render::insertion
