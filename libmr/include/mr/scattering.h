// Physically based single scattering (DESIGN.md section 3): transmittance and in-scatter maps
// of a photo with its depth, under sun, sky and lamps, with volumetric shadows from the photo's
// own geometry; and the composite C = I * T + R.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "mr/camera.h"
#include "mr/export.h"
#include "mr/fog.h"
#include "mr/image.h"
#include "mr/scene.h"

namespace mr {

class CancelToken;  // mr/cancel.h

/// The core's output, all the photo's size.
struct MR_API ScatteringLayers {
  Image transmittance;   ///< T (R,G,B): tau(camera, surface) * S(surface), in [0, 1]
  Image inscatter;       ///< R (R,G,B): single-scattered light along the view ray
  Image sun_visibility;  ///< 1 channel: fraction of the sun's disk seen from the surface (AOV;
                         ///< 1 for sky pixels or without a sun)
  Image optical_depth;   ///< R,G,B: optical depth from the camera to the surface (AOV; inf
                         ///< for sky in unbounded fog)
  Rgb sky_radiance{};    ///< the sky radiance used (given or estimated from the photo)
  struct Timings {
    double mesh_s = 0;     ///< depth -> occluder mesh
    double bvh_s = 0;      ///< Embree scene build
    double scatter_s = 0;  ///< marching (including the sparse-grid pass)
    double total_s = 0;
    std::size_t exact_pixels = 0;         ///< pixels marched exactly
    std::size_t interpolated_pixels = 0;  ///< pixels filled by gradient interpolation
    std::size_t shadow_rays = 0;          ///< CPU only (the GPU looks up shadow maps)
    // Vulkan backend only (0 on the CPU): each stage's GPU time (timestamp queries) plus, for
    // upload and download, the host's copies into / out of staging memory.
    double upload_s = 0;       ///< depth, normals, mesh, parameters to the device
    double shadow_maps_s = 0;  ///< rasterizing the occluder mesh into shadow maps
    double gpu_scatter_s = 0;  ///< the compute passes (sparse grid, interpolation, T)
    double download_s = 0;     ///< T, R and the AOVs back to the host
    int tiles = 0;             ///< dispatches the image was split into
  } timings;
  /// Structures cut by the frame that were continued beyond it (empty with completion off or
  /// without sun or lamps: only light paths need them).
  std::vector<CompletedBlocker> completed_blockers;
  std::string backend;         ///< what rendered: "cpu" or "vulkan: <device name>"
  std::string backend_notice;  ///< one line when Backend::automatic fell back to the CPU
  /// false when the fall-back is the expected choice on this machine (no Vulkan loader, no
  /// device, only a software device, a sanitizer build): front ends show the notice only when
  /// asked (verbose). true when a usable GPU failed (e.g. out of device memory): a warning.
  bool backend_notice_is_warning = false;
};

/// Renders T and R for `photo` (scene-linear RGB; used only to estimate the sky radiance when
/// the scene does not give it) with `distance_m` (1 channel, metres along each ray; +inf = sky)
/// seen by `camera` from `scene.pose`. Deterministic for a scene (including its seed).
/// `cancel` (optional, caller-owned, may be requested from any thread): the render stops within
/// about one image row (CPU) or one tile (Vulkan: a token caps tiles at 65536 pixels) of the
/// request and throws mr::Error(cancelled), returning nothing; never requested, the result is
/// bit-identical to a render without a token.
/// Throws mr::Error: invalid_argument for a bad scene (naming the field, see validate_scene),
/// size_mismatch, invalid_argument for NaN distances, cancelled.
MR_API ScatteringLayers render_scattering(const Image& photo, const Image& distance_m,
                                   const Camera& camera, const FogScene& scene,
                                   const CancelToken* cancel = nullptr);

/// render_scattering followed by the composite C = I * T + R (alpha carried).
/// The returned FogLayers' `airlight` holds the sky radiance used. `cancel`: as for
/// render_scattering (a cancelled call throws mr::Error(cancelled) and leaves `layers_out` as
/// it was).
MR_API FogLayers fog(const Image& photo, const Image& distance_m, const Camera& camera,
              const FogScene& scene, ScatteringLayers* layers_out = nullptr,
              const CancelToken* cancel = nullptr);
/// fog() with a soft sky matte (issue 11 item 4), e.g. GeometryEstimate::sky_alpha: one channel
/// at the photo's size in [0, 1], 1 = sky (an empty image: as fog() above). A pixel with a
/// fractional matte shows partly a surface and partly the sky; its T and R become the matte's
/// mix of those of the nearest pixel that is all surface (alpha 0) and of the nearest that is
/// all sky (alpha 1), the two fogs it shows, so the fogged edge is as soft as the photo's edge
/// instead of a one-pixel step between the depth's two sides. Pixels with alpha 0 or 1 are
/// exactly as fog() above renders them. Throws as fog() above, and mr::Error(size_mismatch)
/// for a non-empty matte of another size or channel count.
MR_API FogLayers fog(const Image& photo, const Image& distance_m, const Image& sky_alpha,
              const Camera& camera, const FogScene& scene, ScatteringLayers* layers_out = nullptr,
              const CancelToken* cancel = nullptr);

/// What soften_fog_seams did: created-edge pixels of the composite before and after, the
/// pixels whose T or R changed, and the filter rounds run (0: the fog made no edge).
struct MR_API SeamSoftening {
  std::size_t created_before = 0;
  std::size_t created_after = 0;
  std::size_t pixels_changed = 0;
  int rounds = 0;
};

/// Issue 11 item 3: for a fog over a *guessed* depth (mr::estimate_scene), softens the seams
/// the guess makes. Where the composite, as `mr fog` displays it by default (sRGB after the
/// highlight roll-off, mr/color.h), has an edge the photo (sRGB) does not have (the gallery's
/// created-edge measure: luma gradient after a 1 px blur more than twice the photo's and above
/// 0.01 a pixel), T and R in a feathered band around it are smoothed edge-aware against the
/// photo (photo/fog_seams.h: a few rounds, each kept only if it leaves such edges weaker): the
/// fog becomes smooth where the photo is, and keeps its steps along the photo's plain edges. Every
/// other pixel keeps T and R exactly, and a fog that makes no edge is returned unchanged. `layers`
/// (from fog(), with `photo` the image it fogged) has its transmittance, inscatter and composite
/// updated. Not for a depth the user measured or drew: there an edge the fog makes is the scene's,
/// and is kept by not calling this. Throws mr::Error(size_mismatch) when the layers' sizes differ
/// from the photo's.
MR_API SeamSoftening soften_fog_seams(const Image& photo, FogLayers& layers);

/// Checks every field of a scene and throws mr::Error(invalid_argument) naming the first bad
/// one by its path ("medium.g", "lighting.lamps[2].position_m") and what was found.
MR_API void validate_scene(const FogScene& scene);

/// Things in a valid scene that are almost certainly not what its author meant, one sentence
/// each (empty when there are none); front ends show them as warnings. Today: a sun whose light
/// cannot reach the camera's surroundings because the fog above is (close to) infinitely thick,
/// e.g. homogeneous fog with no layer top: the core then correctly renders no sunlight at all.
MR_API std::vector<std::string> scene_warnings(const FogScene& scene);

}  // namespace mr
