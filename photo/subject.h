// Private to libmr: a subject standing in the bottom band of a photo (issue 11: a person sitting
// on a beach, her feet out of the frame; a portrait filling the bottom of the frame).
//
// The ground mask (photo/sky_mask.h, estimate_ground_mask) says when the colour of the bottom
// band rose far above the horizon in most of its columns (GroundMask::standing_subject): a
// subject, not the ground, fills it. This finds the subject's pixels. It is what runs up each
// column from the bottom row, neither sky nor ground-coloured, to above the horizon (a head and
// neck), and what joins those runs neither sky nor ground-coloured and not far above the horizon
// (shoulders, arms, a lap: their columns' runs are cut short by the ground between the knees or
// beside the subject). Above that band only the rising runs count, so the far land a head
// touches (dunes, people on a beach) stays apart. GrabCut (Rother et al. 2004, cv::grabCut) then
// settles the pixels that are only joined to the subject: the runs are definitely the subject,
// sky and the ground-coloured pixels definitely not, and what only joins them (a patch of sand
// darker than the modelled sand, the subject's arm) goes with the colours it is most like.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "mr/annotations.h"
#include "mr/image.h"

namespace mr::photo {

struct GroundMask;

struct StandingSubjectOptions {
  /// A column's run rises when it reaches this fraction of the height above the horizon (the
  /// ground mask's subject_min_rise_fraction).
  double min_rise_fraction = 0.05;
  /// The run goes on over at most max(2, height x this) ground-coloured pixels (teeth, a
  /// highlight) and stops at the next.
  double max_gap_fraction = 0.005;
  /// Above that band, what is neither sky nor ground-coloured within this fraction of the
  /// width of a rising run is a candidate too (hair falling beside a face), for GrabCut to keep
  /// or drop.
  double reach_fraction = 0.04;
  /// A colour (16 levels a channel) is the far land's when at least this fraction of the far
  /// land's pixels beside the head have it (and at least 3).
  double far_colour_fraction = 0.002;
  /// GrabCut on a copy of at most this many pixels (its cost grows with them); 0: off.
  double grabcut_pixels = 0.1e6;
  int grabcut_iterations = 3;
};

struct StandingSubject {
  /// Row-major at the photo's size, 1 = the subject; empty when none was found.
  std::vector<std::uint8_t> pixels;
};

/// `photo` scene-linear (>= 1 channel); `horizon` two points of it (pixel centres); `sky` and
/// `ground` (ground.coloured, ground.ground) at the photo's size. Returns an empty subject when
/// `ground` is not valid or found no standing subject, or when no run rises. Never throws for
/// any image content.
StandingSubject find_standing_subject(ConstImageView photo,
                                      const std::array<PixelPoint, 2>& horizon,
                                      const std::vector<std::uint8_t>& sky,
                                      const GroundMask& ground,
                                      const StandingSubjectOptions& options = {});

}  // namespace mr::photo
