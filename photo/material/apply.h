// Private to libmr: re-rendering regions of a photo with new materials while keeping the photo's
// fine detail (issue 7, step 5).
//
// The split (an intrinsic-image decomposition in its simplest form, not a learned one):
//   photo I = A * S + specular,  S = shading of a unit-albedo Lambert surface under the photo's
//   lights (sun with shadows, sky, lamps; render/surface_shading.h), so A = I / S is the photo's
//   apparent albedo, with everything the lighting model does not explain folded into it.
//   A is split in log space with an edge-aware filter (OpenCV ximgproc guided filter, guided by
//   log A itself): log A = log A_smooth + log D. A_smooth is the material's base colour, which
//   the new material replaces; D (clamped to [min_detail, max_detail]) is the fine texture and the
//   small-scale shading the model misses (mortar lines, grain, small unmodelled shadows), which
//   is kept:
//   new = D * diffuse_albedo * S + specular(new material).
// Limits: the photo's own highlights are part of A (a glossy original leaves bright blobs in D
// when they are smaller than the filter radius, and in A_smooth otherwise, where they are
// replaced); large-scale errors of the lighting estimate (a wrong sun direction, shadows of things
// the depth map lacks) are larger than the filter and get replaced by the model's shading;
// strong edges inside a region (log-contrast well above sqrt(eps)) stay in A_smooth, so they are
// replaced too instead of being carried as detail.
#pragma once
#include <cstdint>
#include <span>
#include "mr/image.h"
#include "mr/material.h"
#include "mr/scene.h"
#include "render/surface_shading.h"

namespace mr::photo {

struct DetailOptions {
  int radius_px = 0;        ///< guided-filter radius; 0: 2 % of the image's short side, 4..48
  double eps_log = 0.5;     ///< guided-filter eps in (log albedo)^2: only edges of log-contrast
                            ///< above ~sqrt(eps) = 0.7 (a factor 2) stay in the smooth part
  float min_detail = 0.2f;  ///< D is clamped to [min_detail, max_detail]
  float max_detail = 5.0f;
};

/// Unit-albedo diffuse shading S (3 channels, the geometry's size; 0 where there is no surface):
/// render::shading_terms(...).diffuse, exactly the part of the rendering that scales with the
/// diffuse albedo (no Fresnel-at-grazing specular, which a {diffuse 1, F0 0} render would add).
Image diffuse_shading(const render::SurfaceGeometry& geometry, const Lighting& lighting);

/// The detail layer D of `photo` (scene-linear RGB, the geometry's size) given its diffuse
/// shading S (see the file comment). 3 channels; 1 where there is no surface or S is ~0.
/// Throws mr::Error(size_mismatch) for images of different sizes.
Image photo_detail(const Image& photo, const Image& shading,
                   const render::SurfaceGeometry& geometry, const DetailOptions& options = {});

/// `photo` with each region k (labels(x, y) = k in 1..materials.size(), surface pixels only)
/// re-rendered with materials[k - 1]: D * diffuse_albedo * S + specular, or without `detail`
/// (null) the plain rendering. Composited with a linear ramp of `feather_px` pixels inside each
/// region's border (0: hard edges); pixels outside the regions and sky pixels are the photo's.
Image apply_materials(const Image& photo, const render::SurfaceGeometry& geometry,
                      const Lighting& lighting, const Image& shading, const Image& region_labels,
                      std::span<const Material> materials, const Image* detail,
                      double feather_px = 1.5);

/// Renders what apply_materials puts into region pixels, for one material at the listed pixels
/// (indices y * width + x) into `out` (3 channels, the geometry's size; other pixels untouched).
void render_with_detail(const render::SurfaceGeometry& geometry, const Lighting& lighting,
                        const Image& shading, const Image* detail, const Material& material,
                        std::span<const std::int32_t> pixels, Image& out);

}  // namespace mr::photo
