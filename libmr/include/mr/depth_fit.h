// Relative -> metric depth (issue 4, item 4): a monocular network's relative map (inverse depth /
// disparity-like, or affine depth) fitted with a scale and a shift to metric reference distances
// on some of the pixels (the ground plane of mr::estimate_geometry, annotated distance hints, a
// sparse lidar, ...).
//
//   mr::GeometryEstimate g = mr::estimate_geometry(camera, annotations);
//   mr::DepthFitOptions o;
//   o.camera = camera;                           // the network's map is planar (z-like)
//   mr::DepthFit fit = mr::fit_relative_depth(network_output, g.distance_m, o);
//   mr::fog(photo, fit.distance_m, camera, scene);
#pragma once

#include <cstddef>
#include <optional>

#include "mr/camera.h"
#include "mr/export.h"
#include "mr/image.h"

namespace mr {

/// What the relative map's values are, up to an unknown scale s > 0 and shift t.
enum class RelativeDepthKind {
  /// Inverse depth / disparity-like (MiDaS, DPT, Depth Anything): larger is nearer;
  /// 1 / depth = s * r + t. Fitted on the relative error of the inverse depth,
  /// (s r + t) * d_ref - 1 (= d_ref / d - 1), linear in s and t.
  inverse_depth,
  /// Affine depth: larger is farther; depth = s * r + t. Fitted on the relative error of the
  /// depth, (s r + t) / d_ref - 1.
  depth,
};

struct MR_API DepthFitOptions {
  RelativeDepthKind kind = RelativeDepthKind::inverse_depth;
  /// When set, the relative map is planar (z-depth-like, as monocular networks output: the
  /// fit is done on z = distance / camera.z_to_distance) and the result is converted back to
  /// distance along the ray. Unset: the relative map is of distance along the ray. The
  /// camera's size must be the map's.
  std::optional<Camera> camera;
  /// Fewer usable reference pixels than this is an error.
  std::size_t min_reference_pixels = 16;
  /// Cauchy loss scale on the relative residual (0.05 = 5 %): the final iterations' weights
  /// are 1 / (1 + (e / scale)^2). Earlier iterations use a larger scale from the residuals'
  /// median absolute deviation, so a bad start (or plain least squares) converges. A final
  /// refinement uses Tukey's biweight (outliers get no weight) with the cut-off
  /// max(loss_scale, 4.685 x the residuals' robust standard deviation).
  double loss_scale = 0.05;
  /// A reference pixel is an inlier when its relative residual |e| is below this.
  double inlier_threshold = 0.1;
  /// Starting scale and shift; unset: unweighted least squares.
  std::optional<double> initial_scale, initial_shift;
  int max_iterations = 100;
};

struct MR_API DepthFit {
  /// One channel "Z": metres along each pixel's ray. +inf where the fitted depth is not
  /// positive (inverse depth: s r + t <= 0, i.e. beyond infinity: sky).
  Image distance_m;
  double scale = 0, shift = 0;  ///< s and t of RelativeDepthKind, in 1/m (inverse) or m (depth)
  /// Root mean square of the relative residuals over the inliers, and their median over all
  /// reference pixels (both dimensionless: 0.02 = 2 %).
  double rms_inlier_residual = 0, median_abs_residual = 0;
  std::size_t reference_pixels = 0;  ///< usable reference pixels
  std::size_t inliers = 0;           ///< of those, with |residual| < inlier_threshold
  std::size_t non_positive_pixels = 0;  ///< pixels set to +inf in distance_m
  int iterations = 0;
};

/// Fits `relative` (one channel, or the first, of any size equal to the reference's) to the
/// metric distances in `reference_distance_m` (one channel, or the first; metres along the
/// ray): a pixel is a reference where the value is finite and positive (+inf and 0, the sky
/// encodings, are not references). Robust: iteratively reweighted least squares with a Cauchy
/// loss, then Tukey's biweight, so a few percent of outliers (in either map) do not bias the fit.
/// Throws mr::Error: size_mismatch (maps or camera of different sizes); invalid_argument for a
/// relative value that is NaN or infinite, a NaN or negative reference, fewer than
/// options.min_reference_pixels references, relative values that do not vary over them,
/// absurd options, or a fit with scale <= 0 (the map's convention is the other one, or the
/// reference contradicts it) -- each message says which.
MR_API DepthFit fit_relative_depth(const Image& relative, const Image& reference_distance_m,
                            const DepthFitOptions& options = {});

}  // namespace mr
