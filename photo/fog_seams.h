// Private to libmr: the fog's seams softened where the depth was guessed (issue 11 item 3).
//
// An estimated depth map has steps the photo does not explain: a cloud split between sky and
// a structure, a billboard's edge across a hillside, a column of the ground lifted. Fog turns
// each into an edge the photo did not have (C = I T + R with T and R stepping where I is
// smooth): a seam or a window, the artifact a photographer rejects first. Where the depth is the
// user's own (a depth file), such an edge is the scene's and is kept; where it was guessed,
// the fog there is unknown anyway, and a smooth fog is the plausible answer.
//
// What is done: the pixels where the fogged image has an edge the photo does not have are found
// with the gallery's created-edge measure (gallery/measures.py: luma of the display-encoded
// colour, Gaussian blur of 1 px, central differences; the fogged gradient more than twice the
// photo's and above 0.01 luma a pixel), on the image as the caller displays it (SeamDisplay).
// Around them (a feathered band of the smoother's reach) T and R are replaced by an edge-aware
// smoothing of them guided by the photo (cv::ximgproc's fast global smoother, a weighted
// least-squares fit, Min et al. 2014, on the photo with its fine texture removed by rolling
// guidance, Zhang et al. 2014): where the photo is flat or only finely textured the fog becomes
// smooth (the step is spread into a ramp), while at an object's outline the fog keeps its step.
// Tried first and dropped (gallery/results/seams_tune.md): a guided filter (its local linear
// model copied a roof's texture into T, which deepened it: new created edges), the domain
// transform (strictly edge-stopping: it kept a far city's textured skyline cut out), and the
// smoother at a wider colour range or on the raw photo (the global fit leaked into a kite in a
// wide sky and veiled it). The same filter acts on T and R, so a fog whose R is A (1 - T) keeps
// that relation. Up to 3 rounds, each 4x smoother; a round is kept only if it weakens the
// created edges: the sum over their pixels of the squared excess of the fogged gradient over
// the measure's threshold falls (a step spread into a ramp is fainter even where the ramp keeps
// more pixels above the floor than the step had, as on a small frame). Pixels away from any
// created edge keep T and R exactly.
#pragma once

#include <cstddef>

#include "mr/image.h"

namespace mr::photo {

struct SeamSoftening {
  std::size_t created_before = 0;  ///< created-edge pixels of the composite before
  std::size_t created_after = 0;   ///< ... and after
  std::size_t pixels_changed = 0;  ///< pixels whose T or R changed
  int rounds = 0;                  ///< filter rounds run (0: nothing to soften)
};

/// How the photo and the fogged image are displayed, per channel from scene-linear to the
/// encoded values whose luma the measure takes (e.g. the sRGB encoding; for the fog the output's
/// highlight roll-off first). Non-finite inputs never reach them.
struct SeamDisplay {
  float (*photo)(float linear);
  float (*fogged)(float linear);
};

/// Softens T and R (3 channels each, the photo's size) where I T + R has edges the photo
/// (scene-linear, >= 3 channels; a 4th is ignored) lacks, as above. Non-finite values in the
/// photo count as black; pixels whose T or R is not finite are left as they are and do not feed
/// the filter. Throws mr::Error(size_mismatch) when sizes differ, (invalid_argument) when T or
/// R has other than 3 channels or the photo fewer than 3.
SeamSoftening soften_fog_seams(ConstImageView photo, ImageView transmittance, ImageView inscatter,
                               const SeamDisplay& display);

}  // namespace mr::photo
