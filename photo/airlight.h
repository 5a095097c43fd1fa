// Private to libmr: airlight (fog colour) estimated from a photo with the dark channel prior,
// and the neutral prior with a chroma bound that every automatic fog colour goes through.
#pragma once

#include <array>

#include "mr/image.h"

namespace mr::photo {

/// The colour of real fog (issue 11 item 5). Fog and mist droplets (radius 1-20 um) are much
/// larger than visible wavelengths, so Mie scattering by them is nearly wavelength-independent
/// and the fog takes the colour of the light that falls on it: the sun's and the sky's, i.e. a
/// daylight illuminant. The dehazing literature models the atmospheric light of real hazy photos
/// the same way, as the colour of the illumination (Narasimhan & Nayar 2002, "Vision and the
/// atmosphere"; Sulami et al. 2014, "Automatic recovery of the atmospheric light in hazy
/// images"; Berman et al. 2017, "Air-light estimation using haze-lines"), and the plain
/// brightest-pixel / dark-channel estimates are known to pick up bright objects' colours instead
/// (He et al. 2009 name white objects; a yellow wall or a blue sky does the same to the hue).
/// Daylight illuminants lie close to the Planckian locus, between a low sun (~4000 K) and the
/// shade under a blue sky (~10000 K). In CIE 1976 u'v' from D65 (x 0.3127, y 0.3290): 4000 K
/// (x 0.3805, y 0.3768) is 0.043 away toward warm, 10000 K (x 0.2807, y 0.2884) 0.029 toward
/// cool, and off the locus (green / magenta) illuminants stay within ~0.006 (the ANSI C78.377
/// tolerance; daylight sits ~0.003 above the Planckian). The bound: the fog colour's u'v' offset
/// from D65, split into a part along the locus (toward 4000 K when it leans warm, toward
/// 10000 K otherwise) and a part across it, is kept within those limits.
struct NeutralPrior {
  double warm_limit = 0.043;      ///< along the locus toward 4000 K (u'v')
  double cool_limit = 0.029;      ///< along the locus toward 10000 K (u'v')
  double off_locus_limit = 0.01;  ///< across the locus (u'v'), with margin over 0.006
  /// The neutral prior: below this fraction of each limit a colour is taken as it is (a
  /// plausible light), above it the offset is compressed smoothly toward the limit,
  /// k + (B - k) tanh((x - k) / (B - k)): continuous, monotonic, never beyond B. 1 gives a
  /// hard clamp at the limits (the bound alone).
  double knee_fraction = 0.5;
  /// And at most this CIELAB chroma C*ab (at Y = 1, D65 white; scaled toward D65 when above):
  /// that of the Planckian 4000 K, 33.6. CIE daylight D40 (which lies a little off the Planckian,
  /// toward green-yellow) has 36.1, the bound the gallery's measure (gallery/measures.py) states.
  double max_chroma_ab = 33.6;
};

/// The fog colour from an estimated light colour `rgb` (scene-linear Rec.709, D65 white), as
/// NeutralPrior describes: its Rec.709 luminance kept, its chromaticity moved toward D65 only
/// where it is beyond the knee. A colour within the knees comes back unchanged (bit for bit); a
/// colour whose luminance is not positive and finite gives black.
std::array<float, 3> neutral_fog_colour(const std::array<float, 3>& rgb,
                                        const NeutralPrior& prior = {});

/// CIELAB C*ab of a scene-linear Rec.709 colour scaled to Y = 1 (D65 white; 0 for black).
double chroma_ab(const std::array<float, 3>& rgb);

/// CIE 1976 u'v' distance of a scene-linear Rec.709 colour from D65 (0 for black).
double delta_uv_from_d65(const std::array<float, 3>& rgb);

struct DarkChannelOptions {
  /// Min-filter window as a fraction of the image's shorter side; He et al. use 15 px on
  /// ~600 px images (0.025). At least 3 px.
  double window_fraction = 0.025;
  double brightest_fraction = 0.001;  ///< fraction of dark-channel pixels to average (0.1 %)
  /// Larger photos are area-averaged down to about this many pixels first.
  double working_pixels = 1.0e6;
  /// Applied to the mean colour (neutral_fog_colour); false gives the raw dark-channel mean.
  bool apply_neutral_prior = true;
  NeutralPrior prior;
};

/// Mean colour of the photo's pixels with the brightest dark channel (He et al. 2009; Foggy
/// Cityscapes), through the neutral prior unless options say otherwise. `photo` is scene-linear
/// with >= 3 channels.
std::array<float, 3> estimate_airlight_dark_channel(ConstImageView photo,
                                                    const DarkChannelOptions& options = {});

}  // namespace mr::photo
