// Private to libmr: the frame around a photo that is not the scene (issue 11: a scanned print's
// dark edge along the top, a grey strip down a side, a letterbox bar).
//
// Fog belongs to the scene, not to the paper or the scanner's lid: such a border is left as it
// is, and the sky is found in the picture inside it (a dark top edge kept the sky from touching
// the frame's top, and lent its darkness to the sky light of the rows under it: a dark line
// under the edge in haze).
#pragma once

#include "mr/image.h"

namespace mr::photo {

struct FrameBorderOptions {
  /// A border is at most this fraction of the frame's height (top, bottom) or width (sides).
  double max_fraction = 0.03;
  /// A border line: at least `uniform_fraction` of its pixels (the middle 90 % of the line)
  /// within `uniform_codes` (display-referred 8-bit, every channel) of the first line's median
  /// (a scan's dark edge is uneven: shadows of the print's curl, 5th-95th percentile 46-116).
  int uniform_codes = 24;
  double uniform_fraction = 0.6;
  /// The border's colour is near neutral (paper, film base, a scanner's lid): max - min of its
  /// median's channels at most this.
  int max_chroma_codes = 30;
  /// The picture starts within `max_transition` lines after the border (a scan's blurred edge),
  /// at a line where at most `content_like_fraction` of the pixels are of the border's colour;
  /// lines within those whose median still steps by more than `uniform_codes` to the next line's
  /// are the blurred edge's too.
  int max_transition = 2;
  double content_like_fraction = 0.3;
};

struct FrameBorder {
  int top = 0, bottom = 0, left = 0, right = 0;  ///< lines of border on each side

  bool any() const { return top > 0 || bottom > 0 || left > 0 || right > 0; }
  bool contains(int x, int y, int width, int height) const {
    return y < top || y >= height - bottom || x < left || x >= width - right;
  }
  /// The picture inside the border.
  Rect inside(int width, int height) const {
    return {left, top, width - left - right, height - top - bottom};
  }
};

/// `photo` scene-linear (>= 1 channel). No border (all 0) for photos under 16 x 16 pixels or
/// whose edges are picture. Never throws for any image content.
FrameBorder find_frame_border(ConstImageView photo, const FrameBorderOptions& options = {});

}  // namespace mr::photo
