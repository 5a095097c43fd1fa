// Private to libmr: people near the camera, found by their faces (issue 11: a couple at a
// canyon's rim whose horizon no cue found; a portrait in a studio).
//
// The depth of a portrait cannot come from the ground: the ground under the person is out of
// the frame, and the horizon is often guessed from the person's own outline (a jacket's zip
// taken for a vertical). A face says both that someone is there and how far: an adult's face is
// about 0.16 m across in the box a frontal-face detector draws, so it stands at focal_px x
// 0.16 / box width (Viola and Jones 2001; OpenCV's cascade haarcascade_frontalface_alt, from
// Debian's opencv-data). The person's pixels are the face and what runs down from it to the
// frame's bottom (head, hair, shoulders, a body), settled by GrabCut (Rother et al. 2004) from
// a prior of head and body drawn from the face box: the face and the chest under it certain,
// sky and the far sides certain background.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "mr/image.h"

namespace mr::photo {

struct PeopleOptions {
  /// The face box's width on an adult, metres (the cascade's box spans the cheeks and a little
  /// more: 0.14-0.18 m).
  double face_width_m = 0.16;
  /// Smallest face, as a fraction of the photo's shorter side (smaller ones are far, and the
  /// detector's false faces are mostly small).
  double min_face_fraction = 0.04;
  /// The detector's votes a face needs (cv::CascadeClassifier::detectMultiScale minNeighbors).
  int min_neighbors = 3;
  /// The fraction of the face box's centre that must have a skin colour (YCrCb, Cr 133-180,
  /// Cb 77-135; Chai and Ngan 1999, widened for low sun and shade). A black-and-white photo has
  /// no people (GrabCut separates them by colour).
  double min_skin_fraction = 0.3;
  /// GrabCut on a copy of at most this many pixels around each person; 0: the prior as it is.
  double grabcut_pixels = 0.1e6;
  int grabcut_iterations = 3;
  /// The cascade file; empty: the one Debian's opencv-data installs (MR_FACE_CASCADE).
  std::string cascade_path;
};

struct Person {
  /// The face box: x, y, width, height in pixels.
  std::array<int, 4> face{};
  /// Planar depth (metres along the optical axis) of the face, from its width.
  double depth_m = 0;
};

struct People {
  std::vector<Person> persons;  ///< nearest first
  /// Row-major at the photo's size: 0 = no one, k = persons[k - 1] (a nearer person's pixels
  /// over a farther one's); empty when no one was found.
  std::vector<std::uint8_t> pixels;
  /// False when the cascade file could not be read (no opencv-data): nothing was searched.
  bool searched = false;
};

/// `photo` scene-linear (>= 1 channel), `focal_px` > 0 its camera's focal length, `sky` at the
/// photo's size (1 = sky; empty: none). At most 255 people. Never throws for any image content.
People find_people(ConstImageView photo, double focal_px, const std::vector<std::uint8_t>& sky,
                   const PeopleOptions& options = {});

// People standing on the ground, found by their whole figure (issue 11: people wading in a sea
// under a horizon level with their heads, their backs to the camera or their faces too small for
// the face detector). Below the horizon the ground plane gives each row its own distance, so
// such a person ran from the ground's distance at their feet up to the far sea's at their head:
// heads lost in dense fog while legs stayed plain. A standing person is at one distance, that
// of the ground where their feet are. Found by Dalal and Triggs' people detector (HOG,
// OpenCV's default people SVM), segmented by GrabCut from a body prior drawn in the window,
// and kept only where the geometry agrees: a foot on ground-coloured pixels and a figure
// 0.9-2.1 m tall at that foot's distance (the detector also fires on towers, windows and
// rockets; none of those stands on the ground at a person's height).
struct StandingOptions {
  /// The detector's SVM margin a window needs (detectMultiScale hitThreshold).
  double hit_threshold = 0.0;
  /// Searched on a copy whose shorter side is this many pixels (scaled 0.25-1.5x). The
  /// window's person is about 96 px tall, so the smallest person found is 96 / 600 = 16 % of
  /// the shorter side; smaller ones are far, where the ground's distance varies little over
  /// their height.
  int search_short_side_px = 600;
  /// The height a figure must have at its foot's distance, metres (a child to a tall adult).
  double min_height_m = 0.9;
  double max_height_m = 2.1;
  /// GrabCut on a copy of at most this many pixels around each person.
  double grabcut_pixels = 0.05e6;
  int grabcut_iterations = 3;
  /// At most this many of the detector's windows are segmented, nearest (lowest) first: a
  /// crowd's far people stand where the ground plane puts them (each window costs a GrabCut,
  /// ~30 ms here).
  int max_windows = 32;
};

struct StandingPerson {
  /// The detector's window: x, y, width, height in pixels.
  std::array<int, 4> window{};
  /// Horizontal forward distance of the ground at the person's feet, metres.
  double forward_m = 0;
  /// The figure's height at that distance, metres.
  double height_m = 0;
};

struct StandingPeople {
  std::vector<StandingPerson> persons;  ///< nearest first
  /// Row-major at the photo's size: 0 = no one, k = persons[k - 1]; empty when none was found.
  std::vector<std::uint8_t> pixels;
};

/// The horizontal forward distance (metres) of the ground seen at pixel column x, row y; 0
/// where that pixel is not ground (above the horizon, not of the ground's colour).
using GroundForward = std::function<double(int x, int y)>;

/// `photo` scene-linear (>= 1 channel), `focal_px` > 0, `sky` and `taken` (pixels already given
/// to someone, e.g. find_people's) at the photo's size or empty. A black-and-white photo has
/// none (GrabCut separates by colour). At most 255. Never throws for any image content.
StandingPeople find_standing_people(ConstImageView photo, double focal_px,
                                    const std::vector<std::uint8_t>& sky,
                                    const std::vector<std::uint8_t>& taken,
                                    const GroundForward& ground_forward,
                                    const StandingOptions& options = {});

/// The cascade find_people reads by default (the build's MR_FACE_CASCADE).
const char* default_face_cascade();

}  // namespace mr::photo
