// Private to libmr: the sky found automatically (issue 4 item 2). Per pixel of a working copy
// (about 0.5 MP, display-referred: scene-linear ^ (1 / 2.2)), a pixel is a sky candidate when it
// is above the horizon, has little texture (mean gradient magnitude over a small window below
// `max_texture` per pixel) and is blue-ish (B > R, B >= G, not dark, and saturated or pale: a
// dim, barely bluish grey is shade) or grey and bright (low saturation, luma at least
// `bright_fraction` of the above-horizon 95th percentile). The sky is the candidates'
// 8-connected components that touch the top border (blue ones elsewhere only when blue sky
// does; grey-bright ones also when surrounded by blue sky: clouds), cut back to what lies near
// its smooth core (issue 11: a textured rock face or concrete floor that touches the sky is not
// sky; SkyMaskOptions::core_texture_factor), joined by the clouds that stand on nothing (grey or
// sky-coloured regions above the horizon that reach neither it nor the frame's bottom: a
// backlit cloud's dark body; SkyMaskOptions::floating_max_saturation), with small enclosed holes
// (birds, specks: below `max_hole_fraction` of the image) filled; at full resolution its edges
// are refined with a guided filter (cv::ximgproc::guidedFilter, guide = the display-referred
// photo) and clipped to the horizon again. Never throws for any image content.
//
// Issue 11 item 4: the mask also comes as a soft matte (alpha): in a band along the mask's edges
// the guided filter's output, and where the two sides differ in colour each pixel unmixed
// against them (SkyMaskOptions::unmix_edges), so the sky's edge is where and as soft as the
// photo's; and
// sky seen through foliage (small sky-coloured gaps enclosed by textured structure, whose colour
// matches the open sky's) is sky, so that no billboard fills it and sunlight can pass.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "mr/annotations.h"
#include "mr/image.h"

namespace mr::photo {

struct SkyMaskOptions {
  /// Issue 11: found inside a frame border (photo/frame_border.h; a scanned print's edge),
  /// which is never sky. false: the whole frame.
  bool inside_frame_border = true;
  double working_pixels = 0.5e6;
  double max_texture = 0.012;  ///< mean |gradient| of the display-referred luma per pixel
  /// The sky keeps only what lies within `core_grow` texture windows (through the sky) of its
  /// core: pixels whose roughness over three windows (mean gradient magnitude less the magnitude
  /// of the mean gradient: 0 on a smooth ramp such as a cloud's soft edge) is at most
  /// `core_texture_factor` x the sky's 5th percentile of it (its noise floor), within
  /// [min_core_texture, max_texture], in patches at least two windows across. 0: off (every
  /// candidate that passed `max_texture` counts).
  double core_texture_factor = 4.0;
  double min_core_texture = 0.003;
  double core_grow = 2.0;
  /// ... and each core patch must hold a patch (two windows across) at most this rough: a sky
  /// is smooth down to the camera's noise somewhere, snow's grain or a concrete slab nowhere
  /// (when such a surface is all the "sky", its own 5th percentile sets the limit above). 0: off.
  double max_core_floor = 0.003;
  /// Blue candidates not touching the top border (touching a side one, or larger than 0.2 % of
  /// the image) are sky only when blue sky touches the top border. false: always.
  bool detached_needs_top_sky = true;
  /// Under a blue sky, a grey-bright component not touching the top border (a cloud whose edge
  /// is too steep for the texture test) is sky when at least this fraction of the pixels around
  /// it are within two texture windows of the blue sky. > 1: off.
  double cloud_min_sky_ring = 0.9;
  /// Clouds: what is above the horizon, not sky and reaches neither the horizon nor the
  /// frame's bottom (stands on nothing), is sky when its mean saturation is at most this (or
  /// most of it has the sky's colours), its mean per-pixel gradient is at most `max_texture`
  /// (or it is bright white: a cumulus), and at least `floating_min_sky_ring` of its outline
  /// pixels touch the sky rather than the frame. 0: off.
  double floating_max_saturation = 0.2;
  double floating_min_sky_ring = 0.6;
  double bright_fraction = 0.6;     ///< grey sky: luma >= this x the bright reference
  double max_hole_fraction = 5e-4;  ///< enclosed non-sky specks filled up to this image fraction
  /// Sky seen through foliage: enclosed sky-coloured components up to this image fraction whose
  /// mean colour is within `gap_max_sigma` (Mahalanobis, display-referred RGB) of the open sky's
  /// and at least `gap_min_luma` x its median luma. 0: off.
  double max_gap_fraction = 3e-3;
  double gap_max_sigma = 3.0;
  double gap_min_luma = 0.8;
  /// Both the gaps above and the openings of a lattice (below) must be as smooth as the open
  /// sky: their median per-pixel gradient away from the structure around them (or their
  /// smoothest tenth's, when too narrow) at most this x the open sky's median, clamped to
  /// [min_core_texture, max_texture]: snow or ground seen between branches carries its texture.
  /// 0: off.
  double opening_max_texture_ratio = 4.0;
  /// Sky seen through a lattice or between cables: a sky-coloured component (the gap test's
  /// colour bounds) that touches the sky across structure narrower than `thin_member_width` x
  /// the working image's diagonal (a morphological opening of that diameter removes it) is sky
  /// when that thin structure bounds at least `thin_min_bounded` of the pixels around it (within
  /// about a member's width) and structure that is not thin at most `thin_max_thick` of the
  /// structure there. One that reaches the horizon is sky only where the sky's colour does not
  /// go on below it: at most `thin_max_ground_sky` of the pixels around it below the horizon
  /// have the sky's colour (the mask ends at the horizon, so an opening that continues below
  /// it would end in a line across the lattice; one whose tower stands on land or a cloud bank
  /// there ends where the photo's opening ends; issue 11, helper haze16); negative: every
  /// opening that reaches the horizon is refused (the rule before). That refusal is for an
  /// opening cut across, which members bound below the horizon too: where less than
  /// `thin_min_ground_members` of those pixels around it lack the sky's colour and the sky's
  /// colour goes on at most `thin_max_band_fraction` of the height below it (the median over
  /// the columns where it meets the horizon), nothing but the band the horizon was drawn in lies
  /// below it (bridge's triangle of sky between cable stays, its guessed horizon lowered into
  /// the pale band over the far shore: 0.4 % and 2.8 %; rocket's left tower 14 %; a white
  /// house's siding taken for sky, which goes on below: 10 %), and it is judged as any other
  /// opening; thin_min_ground_members 0: the refusal as before. Only under a blue sky.
  /// thin_member_width 0: off.
  double thin_member_width = 0.008;
  double thin_min_bounded = 0.25;
  double thin_max_thick = 0.2;
  double thin_max_ground_sky = 0.5;
  double thin_min_ground_members = 0.05;
  double thin_max_band_fraction = 0.05;
  /// Along the mask's edges, unmix each pixel against the colours on both sides (the two-colour
  /// matting model) where the sides differ, so the matte sits on the photo's edge and is as wide
  /// as it (issue 11 item 4); false: the guided filter's output alone.
  bool unmix_edges = true;
};

struct SkyMask {
  int width = 0, height = 0;
  std::vector<std::uint8_t> sky;  ///< row-major, 1 = sky (alpha >= 0.5)
  /// Row-major soft matte in [0, 1]: 1 sky, 0 not; fractional only along the mask's edges, where
  /// the guided filter follows the photo's own edge (soft where the photo's edge is soft); 0 at
  /// and below the horizon.
  std::vector<float> alpha;
  std::size_t pixels = 0;      ///< sky pixels
  std::size_t gap_pixels = 0;  ///< of them, sky seen through foliage or a lattice (gaps)
};

/// The sky of `photo` (scene-linear, >= 1 channel), only above the horizon through the two
/// points (pixel-centre coordinates, the photo's pixels).
SkyMask estimate_sky_mask(ConstImageView photo, const std::array<PixelPoint, 2>& horizon,
                          const SkyMaskOptions& options = {});

/// Issue 11: a close-up's background (a bee on a flower, a bird on a trunk) is blurred smooth
/// by the shallow depth of field, and a smooth lavender, green-grey or pale grey bokeh passes
/// the sky tests above. Seen through the whole fog layer it becomes a flat, hard-edged patch of
/// fog colour next to a subject one to three metres away. In a close-up (the caller decides,
/// photo/geometry.h estimate_defocus) what the mask calls sky is kept only with a clear sky's
/// evidence: the component (of the matte's support, alpha > 0, 8-connected) reaches the top
/// border along at least `min_top_fraction` of the frame's width, and its mean display-referred
/// colour is a clear sky's blue: hue within [min_hue_deg, max_hue_deg] (a daylight sky in sRGB
/// is about 200-230 degrees; lavender and violet bokeh 250-290) and saturation at least
/// `min_saturation` (a pale blue-grey or white backdrop is not enough). The rest becomes surface
/// (sky 0, alpha 0): in a close-up it stands at the scene's bounded depth with the subject, and
/// the fog over the whole background is as smooth as the photo. Dropping a real sky costs only a
/// lighter fog over it; keeping bokeh as sky cuts a hard patch into the photo.
struct CloseUpSkyOptions {
  double min_top_fraction = 0.15;
  double min_hue_deg = 185, max_hue_deg = 245;
  double min_saturation = 0.2;
  /// A component that runs along at least this share of the top border is kept whatever its
  /// colour (an overcast strip of sky across the frame's top). Above 1: never (a close-up).
  double keep_open_top_fraction = 2.0;
};
struct CloseUpSky {
  std::size_t kept_pixels = 0;     ///< sky pixels (alpha >= 0.5) left as sky
  std::size_t dropped_pixels = 0;  ///< sky pixels made surface
};
/// Updates `mask` (sky, alpha, pixels; gap_pixels scaled by what is left) in place; `photo`:
/// scene-linear, the mask's size. Never throws for any image content; a mask of another size is
/// left alone.
CloseUpSky keep_evident_sky(ConstImageView photo, SkyMask& mask,
                            const CloseUpSkyOptions& options = {});

/// Issue 11 (free: a ceiling lit by its lamps, seen from below). A smooth, pale ceiling passes
/// the sky tests as an overcast sky does, and a frame that is all "sky" is veiled flat, its
/// subject a metre away vanishing in dense fog. A sky holds one light source at most (the sun);
/// a ceiling holds its lamps. The lamps: 8-connected components of the pixels clipped in every
/// channel (scene-linear >= `min_clipped`) under `sky` (row-major, the photo's size), each at
/// least `min_area_fraction` of the frame and compact (its area at least `min_solidity` of its
/// convex hull's: a lamp's disc or globe, cut by the frame or not, not a cloud's thin silver
/// lining). Returns how many there are. Never throws for any image content (0 for a sky of
/// another size).
struct LampsInSkyOptions {
  double min_clipped = 0.95;
  double min_area_fraction = 0.01;
  double min_solidity = 0.75;
};
int count_lamps_in_sky(ConstImageView photo, const std::vector<std::uint8_t>& sky,
                       const LampsInSkyOptions& options = {});

/// Ground-coloured pixels (issue 4 item 2: where structures meet the ground). The ground's
/// colour is modelled from the bottom band of the photo (the lowest `band_fraction` of the rows,
/// the middle `band_width_fraction` of the columns (walls and kerbs line the sides), at least
/// `min_depression_fraction` of the height below the horizon, not sky): mean and covariance of
/// the display-referred RGB after a 5x5 median filter (texture out, edges kept), refit three
/// times without the samples beyond 2.5 sigma of the previous fit (markings, a wall reaching
/// into the band), the covariance floored at `min_sigma`^2. A pixel below the horizon is
/// ground-coloured when its Mahalanobis distance to that model is below `max_sigma`; isolated
/// non-ground specks (3x3 opening) are ground too.
struct GroundMaskOptions {
  double band_fraction = 0.1;
  double band_width_fraction = 0.5;
  double min_depression_fraction = 0.05;
  double min_sigma = 0.03;
  double max_sigma = 4.0;
  int min_samples = 50;
  /// A subject standing in the band (issue 11): a column "rises" when the modelled colour runs
  /// up from the frame's bottom to more than `subject_min_rise_fraction` of the height above
  /// the horizon. When more than `max_subject_fraction` of the band's columns rise and at least
  /// `min_ground_width_fraction` of all columns do not, the model is refit from the bottom band
  /// in the columns that do not rise. max_subject_fraction >= 1: off.
  double subject_min_rise_fraction = 0.05;
  double max_subject_fraction = 0.5;
  double min_ground_width_fraction = 0.1;
};

struct GroundMask {
  bool valid = false;  ///< false: too few ground samples (ground then unknown: all 0)
  int width = 0, height = 0;
  std::vector<std::uint8_t> ground;  ///< row-major, 1 = ground-coloured, below the horizon
  /// Only with standing_subject (else empty): row-major, 1 = in the ground's colour model (the
  /// refit one) and not sky, above the horizon as well as below it, without the opening
  /// `ground` gets.
  std::vector<std::uint8_t> coloured;
  /// The band's colour rose above the horizon in most of its columns: a subject standing in
  /// front of the camera filled it, and the model was refit from the ground beside it.
  bool standing_subject = false;
};

/// Never throws for any image content; `sky` (row-major, the photo's size, or empty) is left out
/// of the samples.
GroundMask estimate_ground_mask(ConstImageView photo, const std::array<PixelPoint, 2>& horizon,
                                const std::vector<std::uint8_t>& sky,
                                const GroundMaskOptions& options = {});

}  // namespace mr::photo
