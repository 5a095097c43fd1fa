// Private to libmr: a coarser distance map for the occluder mesh, so that the mesh (and its
// Embree BVH, whose build time grows with the triangle count) is cheaper where the quality
// preset allows (DESIGN.md section 3, "Occluder geometry").
#pragma once

#include "mr/camera.h"
#include "mr/image.h"
#include "mr/scene.h"

namespace mr::render {

struct DownsampledDistance {
  Image distance_m;  ///< 1 channel, +inf = sky
  Camera camera;     ///< the coarse pixel grid: same view, focal and principal point / factor
};

/// Reduces a distance map by an integer factor, keeping in each factor x factor block the
/// NEAREST surface (so thin foreground occluders such as poles and branches survive, widened by
/// less than one coarse pixel, instead of vanishing as they would under subsampling or being
/// smeared into the background as under averaging). The nearest pixel's planar depth is carried
/// to the coarse pixel's centre ray (exact for surfaces facing the camera; elsewhere the coarse
/// surface sits at most one fine pixel's depth step nearer). A block of sky stays sky. The
/// coarse grid covers floor(w / factor) x floor(h / factor) blocks; leftover border pixels are
/// dropped. Throws mr::Error(invalid_argument) for factor < 1 or a distance map that is not
/// 1 channel of the camera's size.
DownsampledDistance downsample_distance_nearest(ConstImageView distance_m, const Camera& camera,
                                                int factor);

}  // namespace mr::render
