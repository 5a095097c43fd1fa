// Private to libmr: clouds the sky mask left out are sky, not surfaces (issue 11, the sun bank
// look).
//
// The sky mask keeps a cloud's smooth body but not always its wisps: a cumulus' textured rim, a
// veil of cirrus over blue sky fail its texture test, and so do a cloud's detached fragments
// that touch the frame. What is left above the horizon goes on the far billboard (46 m at a
// 1.6 m camera height), and the photo-guided refinement then pulls each such fragment toward
// the sky's inverse distance wherever the photo has no edge between them: fragments at hundreds
// of metres to 100 km, but finite. A finite pixel is a surface of the occluder mesh: under a low
// sun (8 degrees, the sun bank look) those fragments hung in the sky as occluders, cast
// fragmented shafts fanning from the clouds, and made the render slow (grazing shadow rays
// through the fragments: kite at 640 px, 2.9 us a ray against 0.63 us with them as sky; 10.4 s
// against 1.6 s CPU). A cloud is kilometres away and far above any fog layer we render: it is
// sky, seen through the fog along the sky's path like the sky around it (the sky-through-fog
// layer; the fog over it is then the sky's, so it creates no edge in dense fog or haze), and it
// shades no fog in the photo's frame that the estimate could place.
//
// Which fragments: a connected component (8-connected) of surface pixels above the horizon that
// is held up by nothing (no pixel of it has the horizon or the frame's bottom directly below:
// a tree, a mast, a building or a mountain stands on the ground, and keeps occluding), mostly
// ringed by sky rather than by the frame (a bridge deck or an eave seen from below spans the
// frame; as SkyMaskOptions::floating_min_sky_ring; a quarter of it for a component of the sky's
// colours or joined to the sky, below), and a cloud by its look or by its depth:
// cloud-coloured (grey, a mean display-referred saturation of at most `max_saturation`, or
// mostly of a blue sky's colours: a thin cloud over blue sky) and not foliage (less than half of
// it the vegetation mask's, when given: a backlit branch reaching into the frame is grey too),
// or joined to the sky by the refinement itself (its median distance at least
// `min_distance_ratio` times the far billboard's on the same rays: the photo shows no edge
// between it and the sky; a sunset cloud is neither grey nor blue). A kite, a balloon or a
// bird is saturated and has its own edges: it keeps its distance and occludes. The component
// becomes sky: distance +inf, matte 1 (libmr/src/estimate.cpp), and so does the matte of the
// sky pixels in the blurred band along its outline whose nearest all-surface pixel was the
// cloud's: photo/sky_matte.h would otherwise mix the fog of some surface far away into them.
//
// Cut off by the frame (FloatingCloudOptions::min_sky_ring_sky_like): a cumulus filling a
// corner of the frame or a deck of cloud along its top is ringed more by the frame than by the
// sky, and was held to be an eave; on the far billboard under the sun bank's low sun it cast
// specks and streaks into the fogged sky, and in haze it stayed unveiled under the veiled sky
// (tests/sky_light_test.cpp, a corner cumulus: sun bank 0.028 %, haze 0.19 % created edges). A
// structure seen from below against the sky is in its own shade and has an edge against the
// sky; a component mostly of a blue sky's colours (and not foliage) or joined to the sky by the
// refinement needs only a quarter of its outline next to the sky.
//
// Joined clouds (FloatingCloudOptions::min_overhang_*): a cumulus high in the sky joined
// (8-connected, through a band of cloud) to a cloud that sits on the horizon was held up with
// it: a surface on the far billboard, casting shafts fanning from it under the sun bank's low
// sun (tests/sky_light_test.cpp: sun bank 0.30 %, haze 0.22 % created edges, none of it sky).
// Of a component held up by the horizon, what rests on it is each column's run of the
// component's pixels upward from where it meets the horizon; a thick, cloud-coloured part of
// the sky's colours hanging beside those runs is judged as a floating cloud. A tree's crown is
// foliage; a cornice, a jib, a cable, a bridge deck is thin, grey or in its own shade.
//
// A cloud bank low over land on a known horizon (FloatingCloudOptions::min_bank_pixel_ratio):
// what rests on the horizon stays a surface on the far billboard, nearly clear in haze under
// the veiled sky (the same scene: 0.030 % created edges) and an occluder under the sun bank.
// When it is grey, of a blue sky's colours and the refinement joined it to the sky (no edge
// between them; a wall, a ship or a ridge keeps its edge), it is sky: with the horizon known
// the land under it is far (the ground plane), so no seam (0.0036 %). Not under a guessed
// horizon: the guess may cut the bank, which then runs on below it as the ground plane (see
// CloudBankOptions::lower_to_land).
//
// A guessed horizon (FloatingCloudOptions::guessed_horizon): in an all-sky frame looking up the
// guess is lowered below the frame, and a cumulus cut off by the frame's bottom "stood" on it
// (kite's lower right cloud: a surface 60-70 m away). Nobody saw ground there: a bank of the sky's
// colours cut off only by the frame's bottom is sky too. Not a bank reaching a guessed line
// inside the frame (god_rays' backlit bank): it continues below the guess as the "ground" plane,
// so it would be the sky's veil above the line and nearly clear below it, a straight hard
// horizontal seam in haze (tried: god_rays haze 0.039 -> 0.509 %, dense 0 -> 0.168 % created
// edges); that needs the horizon itself lowered below the bank.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "mr/annotations.h"
#include "mr/image.h"

namespace mr::photo {

struct FloatingCloudOptions {
  /// At least this fraction of the component's outline (pixels next to the sky, or on the frame's
  /// top, left or right border) is next to the sky.
  double min_sky_ring = 0.6;
  /// ... or at least this fraction when the component is mostly of a blue sky's colours (B > R,
  /// B >= G) and not foliage, or joined to the sky (as `min_distance_ratio`): a cumulus
  /// filling a corner of the frame, a deck of cloud along its top (issue 11, the sun bank's
  /// streak fans; see the file comment).
  double min_sky_ring_sky_like = 0.25;
  /// Cloud-coloured: a mean display-referred saturation ((max - min) / max of the channels, on
  /// scene-linear ^ (1 / 2.2)) of at most this, or more than half of its pixels bluish (B > R,
  /// B >= G); and less than half of it foliage.
  double max_saturation = 0.2;
  /// Or joined to the sky: its median of distance / the far billboard's distance on the same
  /// ray is at least this.
  double min_distance_ratio = 10.0;
  /// The horizon is a guess (the level fall-back, or a cue of very low confidence, possibly
  /// lowered below the sky it cut; issue 11): then the frame's bottom holds up nothing that
  /// stands on no ground seen (no `standing` pixel) when the horizon is at or below it (the
  /// component reaches nothing else), the component is mostly of a blue sky's colours (B > R,
  /// B >= G) and not foliage, and it is a bank, not a post: at least `min_bank_fraction` of
  /// the frame's pixels, on the frame's bottom along at least `min_bank_contact` of its width.
  bool guessed_horizon = false;
  double min_bank_fraction = 0.0025;
  double min_bank_contact = 0.02;
  /// The cloud bank a guessed horizon was lowered under (CloudBank::bank), row-major w x h, or
  /// empty. A component at least half of whose pixels are the bank's is a cloud when it is
  /// cloud-coloured (as above) and touches the sky, held up or not, however much of its outline
  /// is on the frame: the horizon step found it ringed by sky and the ground only below it.
  /// Of such a component, only what stands on the horizon and is not the bank's (a building, a
  /// ridge, a tree rising from the land into the bank: 8-connected parts of it that reach the
  /// horizon or the frame's bottom and are at least `min_standing_fraction` of the frame) stays
  /// a surface; the bank's lit rims and other small textured parts inside it go with it (specks
  /// left standing on the frame's bottom were created edges in haze: god_rays 0.010 %).
  std::vector<std::uint8_t> bank;
  double min_standing_fraction = 5e-4;
  /// Joined clouds (issue 11, the sun bank's streak fans): of a component held up by the
  /// horizon (or the frame's bottom), what does not rest on it (not on a column of the
  /// component's pixels rising from where it meets the horizon) and is 8-connected is judged
  /// on its own: a cloud when at least `min_overhang_fraction` of the frame, a body at least
  /// `min_overhang_radius_px` and `min_overhang_radius_fraction` of the frame's smaller side
  /// from its outline at its thickest (a cornice, a crane's jib, a cable or a branch is thin)
  /// over at least `min_overhang_body_fraction` of its area (crossing cables are that thick only
  /// where they cross: bridge's white cable stays, 6 %, went into the sky and vanished in haze;
  /// a disc twice that radius is 25 % body; the tuning half's one other such part 31 %),
  /// not foliage, grey (a mean saturation of at most `max_saturation`) and of a sky's colours
  /// (and smooth, below) or joined to the sky (as `min_distance_ratio`), with at least
  /// `min_sky_ring` of its outline next to the sky (the seam with what holds it up counts as not),
  /// solid (the sky it encloses at most `max_overhang_holes` of its area: not a lattice), and what
  /// holds it up (the component's pixels that rest on the horizon) cloud-coloured and not foliage
  /// (as a floating component). 0: off.
  double min_overhang_fraction = 5e-4;
  double min_overhang_radius_px = 3;
  double min_overhang_radius_fraction = 0.01;
  double min_overhang_body_fraction = 0.15;
  double max_overhang_holes = 0.1;
  /// A part of the sky's colours but not joined to the sky is a cloud only when also as smooth
  /// as one: a mean per-pixel gradient of the display-referred luma (Sobel / 8) of at most
  /// `overhang_max_texture` (SkyMaskOptions::max_texture), or bright white (a mean display luma
  /// of at least `overhang_min_white_luma`: a cumulus' sunlit detail); not a structure in a
  /// bluish-grey scene (snow, concrete and steel under an overcast sky: airport_snow).
  double overhang_max_texture = 0.012;
  double overhang_min_white_luma = 0.6;
  /// A cloud bank low over land on a known horizon (not `guessed_horizon`; issue 11, the sun
  /// bank's dark column under it): the pixels of a held-up component that rest on the horizon
  /// (as above) are sky when, together, they are at least `min_overhang_fraction` of the frame,
  /// grey (as `max_saturation`), mostly of a blue sky's colours, less than half foliage and
  /// joined to the sky by the refinement (median ratio at least `min_distance_ratio`); of them,
  /// those at least this times the far billboard's distance (a spire or a mast rising into the
  /// bank keeps its edge against it and its distance). 0: off.
  double min_bank_pixel_ratio = 2.0;
};

/// Issue 11: a cloud bank on a guessed horizon line (see find_cloud_bank).
struct CloudBankOptions {
  /// Cloud-like, per pixel (display-referred: scene-linear ^ (1 / 2.2)): not sky, not
  /// foliage-coloured (G above both R and B), grey (saturation at most `max_saturation`) or
  /// bluish (B > R, B >= G), and smooth: the mean |gradient| of the luma over a
  /// `texture_window`-pixel square at most `max_texture` (a cloud bank's body is far smoother
  /// than land, rock, a facade or foliage at the same distance).
  double max_saturation = 0.3;
  double max_texture = 0.008;
  int texture_window = 9;
  /// The bank sits on the guess: at the guessed line the bank (cloud-like, not sky) is found in
  /// at least `min_bank_at_guess` of the columns, bank or sky in at least `min_open_at_guess`.
  double min_bank_at_guess = 0.25;
  double min_open_at_guess = 0.6;
  /// Ringed by sky: sky is at least this fraction of the pixels above the guess.
  double min_sky_above = 0.02;
  /// A bank's upper outline under the sky is ragged; a sea's or a flat plain's horizon is a
  /// straight line (a calm grey sea filling the frame below the guess is smooth and bluish as
  /// well): in the columns where the bank is at the guess with sky above it, the lowest sky
  /// row's residuals from their least-squares line must have an interquartile range of at
  /// least this fraction of the height.
  double min_outline_spread = 0.02;
  /// Below the guess, each column is followed down through bank or sky until `stop_run`
  /// rows in a row are neither (the land); the lowered line is the median of those rows over
  /// the columns where bank or sky is at the guess. It must be at least `min_drop_fraction`
  /// of the height below the guess, and the band between the guess and it at least
  /// `min_band_fill` bank or sky.
  int stop_run = 3;
  double min_drop_fraction = 0.02;
  double min_band_fill = 0.75;
  /// Ground evidence: a line inside the frame has land below it: of the `ground_band_fraction`
  /// of the height under it (at least 4 rows), at least `min_ground_below` is neither bank nor
  /// sky. (A line at the frame's bottom: an all-sky frame, a bank filling it below the guess.)
  double ground_band_fraction = 0.03;
  double min_ground_below = 0.6;
  /// Lower a guess to land inside the frame at all. Off: only a bank that fills the frame below
  /// the guess (no land under it: an all-sky frame) moves the horizon, to the frame's bottom.
  /// Tried on a synthetic storm bank over hilly land (tests/cloud_bank_test.cpp): the bank
  /// becomes sky, but the land under it is a ground plane 10-100 m away from a 1.6 m camera
  /// (the refinement carries its near values up to the skyline), nearly clear in haze under
  /// the veil: created edges 0.0000 -> 0.90 % along the skyline. A bank over land needs the
  /// land at its skyline far as well; until then it keeps the old behaviour.
  bool lower_to_land = false;
};

struct CloudBank {
  /// Rows by which to lower the guess (same roll; 0: no bank, or no evidence for one).
  double drop_px = 0;
  /// Row-major w x h, 1 on the bank's pixels (cloud-like, not sky) above the lowered line;
  /// empty when drop_px is 0.
  std::vector<std::uint8_t> bank;
};

/// Issue 11: a cloud bank on a guessed horizon. Under the level fall-back (or a weak cue) in a
/// sky photo, a bank of cloud running across the guessed line is above the line a structure
/// on the far billboard and below it the "ground" plane: in haze its outline against the
/// veiled sky becomes a created edge, and under a sun it casts streak fans. Making the bank sky
/// above the guess alone cuts a straight seam along the guess (the bank continues below it as
/// ground, nearly clear in haze: tried, god_rays haze 0.039 -> 0.509 %). Where the evidence
/// supports it, the horizon belongs below the bank: below the frame when the bank fills the
/// frame below the guess (or, with CloudBankOptions::lower_to_land, where the photo's land
/// starts: a textured, non-cloud band under it).
/// `photo`: scene-linear, >= 3 channels; `guess`: the guessed horizon (pixel-centre
/// coordinates); `sky`: the sky mask found without the horizon's clip (row-major, the photo's
/// size). Never throws for any image content; sizes that do not match give no bank.
CloudBank find_cloud_bank(ConstImageView photo, const std::array<PixelPoint, 2>& guess,
                          const std::vector<std::uint8_t>& sky,
                          const CloudBankOptions& options = {});

/// `photo`: scene-linear, >= 3 channels, w x h; `distance_ratio`: row-major w x h, each pixel's
/// distance over the far billboard's distance on its ray (+inf for the sky; what is not finite
/// and positive is sky); `above`: 1 where the pixel is above the horizon; `foliage`: non-zero on
/// vegetation (photo/vegetation.h), or empty; `standing`: non-zero on the pixels that stand on
/// the ground where they meet it, or empty (read only with `options.guessed_horizon`). Returns a
/// row-major w x h mask, 1 on the pixels of the components that are floating clouds (see the file
/// comment); all 0 when there are none. Sizes that do not match give an all-0 mask. Never throws
/// for any image content.
std::vector<std::uint8_t> floating_clouds(ConstImageView photo,
                                          const std::vector<float>& distance_ratio,
                                          const std::vector<std::uint8_t>& above,
                                          const std::vector<std::uint8_t>& foliage,
                                          const std::vector<std::uint8_t>& standing,
                                          const FloatingCloudOptions& options = {});

}  // namespace mr::photo
