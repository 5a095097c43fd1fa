// Material style transfer (DESIGN.md section 5, seed 002 chapter 4): give regions of a photo the
// material look of a sample image. Candidate materials are fitted to the sample's segments by
// inverse rendering, an assignment of candidates to the target's regions is chosen by Tabu search
// on a style objective, and the regions are re-rendered under the photo's lighting.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>
#include "mr/camera.h"
#include "mr/cancel.h"
#include "mr/export.h"
#include "mr/image.h"
#include "mr/material_model.h"
#include "mr/scene.h"

namespace mr {

/// A material fitted to one segment of the sample image.
struct MR_API MaterialCandidate {
  Material material;
  int segment = -1;          ///< the segment's label in MaterialCandidates::segment_labels
  int pixel_count = 0;       ///< pixels the fit used
  double relative_rms = 0;   ///< RMS residual of the fit / mean radiance of the segment
};

/// What the sample image offered.
struct MR_API MaterialCandidates {
  std::vector<MaterialCandidate> candidates;  ///< distinct, well-fitted; at least one
  Image segment_labels;  ///< 1 channel, the sample's size: segment id per pixel, -1 = unused
  std::vector<std::string> notes;  ///< one line per decision, for a person to read
  /// Lines a person should see even when not reading the notes (also among the notes), e.g. that
  /// no segment fitted within max_relative_rms and looser fits were kept.
  std::vector<std::string> warnings;
};

struct MR_API MaterialTransferOptions {
  int max_candidates = 8;            ///< keep at most this many candidates (1..64)
  double superpixel_size_px = 0;     ///< segmentation scale; 0 = from the sample's size
  /// Candidates fitting worse are dropped. When no segment fits this well (common for real
  /// photos under a guessed light), the segments within 1.5 x the best fit's relative RMS are
  /// kept instead, with a warning (MaterialCandidates::warnings).
  double max_relative_rms = 0.25;
  double smoothness_weight = 0.1;    ///< weight of the material-gradient term (>= 0)
  /// Assignment search: with at most 65536 assignments (candidates^regions, e.g. 5 regions of
  /// 8 candidates) every one is evaluated (the global minimum, milliseconds); above, Tabu search:
  int tabu_max_iterations = 200;     ///< Tabu search: iterations at most
  int tabu_patience = 40;            ///< stop after this many iterations without a new best
  std::uint32_t seed = 1;            ///< equal seeds give identical results
  bool keep_detail = true;           ///< carry the photo's fine texture into the new material
  /// A region whose new material would render beyond the photo's white (1, or a float photo's
  /// 99.9th percentile) is exposed down as a whole until 99 % of it is within, as a camera
  /// exposing for it would record it: its texture and contrast kept, its lightness not (the
  /// sample's albedo is known only up to its guessed exposure). The search judges the
  /// candidates so exposed. false: the photo's own exposure, the excess left to the output's
  /// highlight roll-off. Ignored for a 3D scene (no photo).
  bool fit_photo_range = true;
  int threads = 0;                   ///< 0: all cores
  /// Optional, caller-owned (mr/cancel.h): requested, the call stops at its next step (or
  /// segment fit) with mr::Error(cancelled). Its progress callback hears, in order,
  /// "target geometry" (transfer only), "sample geometry", "segments" (each 0 then 1 of 1),
  /// "fit" (segments fitted of those fitted), then for a transfer "statistics" (candidates
  /// rendered), "search" and "apply" (0 then 1 of 1).
  const CancelToken* cancel = nullptr;
};

/// A photo (or sample) with what shading it needs: scene-linear RGB, the distance map (metres
/// along each pixel's ray; 0 or +inf = sky), the camera and the scene (pose and lighting; the
/// medium is ignored). Views: the images must outlive the call.
struct MR_API ShadedPhoto {
  const Image* photo = nullptr;
  const Image* distance_m = nullptr;
  Camera camera;
  FogScene scene;
};

/// Candidate materials from a sample image: segments it (superpixels merged by colour), fits the
/// BRDF of each segment by inverse rendering under the sample's lighting (Ceres), drops poorly
/// fitted ones (see max_relative_rms: loose fits are kept with a warning when nothing fits well)
/// and keeps the distinct ones. A sample larger than 0.5 MP is reduced by an integer factor
/// first (a pixel budget: the fits use 2000 pixels per segment); segment_labels are at the
/// sample's own size. Throws mr::Error(invalid_argument) for a sample with no
/// usable segment (too small, all sky, flat black, non-finite pixels everywhere, no fit at all;
/// the message says what was tried and what to do) and
/// mr::Error(size_mismatch) when the distance map or camera differ from the photo's size.
MR_API MaterialCandidates extract_material_candidates(const ShadedPhoto& sample,
                                               const MaterialTransferOptions& options = {});

struct MR_API MaterialTransferResult {
  Image image;  ///< the target photo with its regions re-materialed, scene-linear RGB
  MaterialCandidates candidates;
  std::vector<int> assignment;  ///< candidate index per region (region r = label r + 1)
  /// Per region: the factor its rendering was scaled by to stay within the photo's white
  /// (MaterialTransferOptions::fit_photo_range; 1: the photo's own exposure).
  std::vector<double> exposures;
  double objective = 0;         ///< the style objective of the assignment (lower is better)
  std::vector<double> best_objective_history;  ///< best-so-far per Tabu iteration
  std::vector<std::string> notes;
  std::vector<std::string> warnings;  ///< as MaterialCandidates::warnings (also among the notes)
};

/// Re-materials the regions of `target`. A target with `photo` null is a 3D scene given by its
/// distance map and camera alone (e.g. objects rendered to depth by another renderer): its
/// regions are rendered over black with the chosen materials (no photo detail: keep_detail is
/// ignored), everything else is black.
/// Region labels: `region_labels` is 1 channel of the target's size with
/// 0 = untouched and 1..n = region n (every id in 1..n must have pixels). A photo's regions are
/// taken as a brush's, a pixel or two off: their borders snap to the photo's edges and are
/// feathered (1 px; where the photo is plain across a border with an untouched surface the
/// feather goes on up to 6 px outside it, so a plain surface's untouched pixels next to a
/// region can change); a 3D scene's are exact. Throws
/// mr::Error(invalid_argument) for an empty region set, a region id with no pixels, or a region
/// entirely in the sky; mr::Error(size_mismatch) for labels of another size.
MR_API MaterialTransferResult transfer_material(const ShadedPhoto& sample, const ShadedPhoto& target,
                                         const Image& region_labels,
                                         const MaterialTransferOptions& options = {});

/// Region labels from a mask image file: either one channel of integer ids (0 = none; renumbered
/// 1..n in increasing order when there are gaps) or a colour image whose distinct non-black
/// colours are regions (numbered in order of first appearance, row by row); or, for a ".json"
/// file, an annotations document (mr/annotations.h) whose plane polygons are the regions (plane
/// i = region i + 1, later polygons paint over earlier ones). Throws mr::Error(io) if
/// unreadable, mr::Error(size_mismatch) if its size is not width x height,
/// mr::Error(invalid_argument) if it has no region (or a polygon covers no pixel).
MR_API Image load_region_labels(const std::filesystem::path& path, int width, int height);

/// The chosen materials as a JSON document (format "mr-materials", version 1): the candidates,
/// the assignment and the objective.
MR_API std::string material_result_to_json(const MaterialTransferResult& result);

}  // namespace mr
