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
// frame; as SkyMaskOptions::floating_min_sky_ring), and a cloud by its look or by its depth:
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
// A guessed horizon (FloatingCloudOptions::guessed_horizon): in an all-sky frame looking up the
// guess is lowered below the frame, and a cumulus cut off by the frame's bottom "stood" on it
// (kite's lower right cloud: a surface 60-70 m away). Nobody saw ground there: a bank of the sky's
// colours cut off only by the frame's bottom is sky too. Not a bank reaching a guessed line
// inside the frame (god_rays' backlit bank): it continues below the guess as the "ground" plane,
// so it would be the sky's veil above the line and nearly clear below it, a straight hard
// horizontal seam in haze (tried: god_rays haze 0.039 -> 0.509 %, dense 0 -> 0.168 % created
// edges); that needs the horizon itself lowered below the bank.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "mr/image.h"

namespace mr::photo {

struct FloatingCloudOptions {
  /// At least this fraction of the component's outline (pixels next to the sky, or on the frame's
  /// top, left or right border) is next to the sky.
  double min_sky_ring = 0.6;
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
};

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
