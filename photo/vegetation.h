// Private to libmr: trees and foliage in the automatic estimate (issue 11 item 3: "trees as a
// canopy/trunk volume with gaps where the photo shows sky through them, so sun shafts can
// pass").
//
// Without it, everything above the horizon that the sky mask does not call sky is one
// structure: a forest's canopy, its trunks and the sky seen between them and through the leaves
// become one gap-free far billboard, and the sun behind the trees leaves the whole fog in front
// of them in shadow: the shafts between trunks that sun + fog are wanted for cannot appear.
//
// What is found here, on the display-referred photo (scene-linear ^ (1 / 2.2)), only when the
// sky mask holds an open blue sky (at least `min_sky_fraction` of the image; else nothing):
// - vegetation: pixels that are textured at a fine scale (the mean |gradient| of the luma over a
//   small window at least `min_texture`), of foliage colour (blue the weakest channel and a
//   little saturation: green, yellow, red, brown, bark; or dark: foliage in shade) and not
//   sky-coloured (a textured patch of the sky's own hue and brightness is a cloud edge);
// - sky seen through vegetation: pixels above the horizon that the sky mask left out but whose
//   colour is the open sky's (chromaticity within `gap_max_chroma` of the mask's median sky
//   chromaticity, luma within [gap_min_luma, gap_max_luma] x its median) and that are smooth,
//   in 8-connected components of which at least `gap_min_vegetation_ring` of the surrounding
//   ring (`ring_px` wide) is green foliage (a rusty lattice rings sky too). Unlike the sky mask's gaps (small, enclosed, blue sky
//   only) these may be large and open to the side: the sky seen under a canopy between trunks,
//   the pale sky of an overcast day through branches.
// Both only under a blue open sky (`min_sky_blueness`): a grey or white sky's colour matched
// skin and pale walls ringed by hair or texture on the tuning photos, and a rusty lattice tower
// under a grey sky was taken for a tree (more created edges in haze). Trees under an overcast
// sky are left to the structures' usual rule.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "mr/annotations.h"
#include "mr/image.h"

namespace mr::photo {

struct VegetationOptions {
  int texture_window_px = 7;     ///< box window of the texture measure
  double min_texture = 0.025;    ///< mean |gradient| of the display-referred luma per pixel
  double min_sky_fraction = 0.002;
  double gap_max_chroma = 0.035;  ///< distance in (r, g) chromaticity (r = R / (R + G + B))
  double gap_min_luma = 0.65, gap_max_luma = 1.6;  ///< x the open sky's median luma
  double gap_max_texture = 0.06;  ///< a gap pixel's own 3x3 mean |gradient| (edges excluded)
  double max_shade_luma = 0.12;   ///< darker than this counts as foliage colour (shade)
  double min_saturation = 0.04;   ///< max - min of the display-referred channels
  /// Gaps only under a blue sky: its chromaticity b = B / (R + G + B) at least this above r, g.
  double min_sky_blueness = 0.04;
  int ring_px = 3;
  double gap_min_vegetation_ring = 0.5;
  /// A structure of the automatic estimate is a tree when at least this fraction of its pixels
  /// is green foliage (used by mr::estimate_geometry; a rusty lattice tower is textured and of
  /// a foliage colour, but not green).
  double tree_min_fraction = 0.35;
};

struct Vegetation {
  int width = 0, height = 0;
  /// Row-major: 2 = green foliage (G >= R), 1 = other foliage colours, bark, shade; 0 = none.
  std::vector<std::uint8_t> vegetation;
  std::vector<std::uint8_t> sky_gap;     ///< row-major, 1 = sky seen through vegetation, not in
                                         ///< the sky mask given
  std::size_t vegetation_pixels = 0, gap_pixels = 0;
};

/// `photo`: scene-linear, >= 1 channel; `sky`: the sky mask (row-major, the photo's size);
/// `horizon`: two points of the horizon (pixel-centre coordinates). Never throws for any image
/// content; throws mr::Error(size_mismatch) when `sky` is not the photo's size.
Vegetation estimate_vegetation(ConstImageView photo, const std::array<PixelPoint, 2>& horizon,
                               const std::vector<std::uint8_t>& sky,
                               const VegetationOptions& options = {});

}  // namespace mr::photo
