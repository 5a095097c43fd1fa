// Private to libmr: the soft sky matte applied to the fog (issue 11 item 4).
//
// A pixel on the sky's edge shows partly a surface and partly the sky (the lens and the
// demosaicing blur every edge over a pixel or two; hair, leaves and antennas cover a fraction of
// it). Its depth can only be one of the two, so the fog rendered for it is either the surface's
// or the sky's and the fogged edge becomes a one-pixel step, sharper than the photo's own edge
// (a created edge), or, where the surface is near and the sky behind it deep in haze, a step
// far higher than the photo had. The matte says how much of each the pixel shows; the fog of a
// mixed pixel is the same mix of the fog in front of the surface and of the fog in front of the
// sky: T = (1 - a) T_surface + a T_sky, R = (1 - a) R_surface + a R_sky (the light reaching the
// camera from the two parts of the pixel, each attenuated and in-scattered along its own ray;
// C = I T + R then equals the matte mix of the two fogged parts up to the term
// a (1 - a) (I_surface - I_sky) (T_surface - T_sky), which vanishes at both ends of the edge).
// T_surface, R_surface: of the nearest pixel that is all surface (alpha 0); T_sky, R_sky: of the
// nearest pixel that is all sky (alpha 1); the matte is fractional only in a band a few pixels
// wide along the edge, so those neighbours see almost the same fog along almost the same ray.
#pragma once

#include <cstdint>
#include <vector>

#include "mr/image.h"

namespace mr::photo {

/// For every pixel of a w x h row-major grid, the row-major index of the nearest pixel (L2)
/// where `is_source` is non-zero; empty when no pixel is a source.
std::vector<std::int32_t> nearest_source(int w, int h, const std::vector<std::uint8_t>& is_source);

/// Replaces T and R (3 channels each, the matte's size) on every pixel whose `sky_alpha`
/// (1 channel, [0, 1], 1 = sky) is strictly between 0 and 1 by the matte mix above. Pixels with
/// alpha 0 or 1 (and NaN alpha) keep their values exactly. Does nothing when no pixel is all
/// sky or none is all surface. Returns the number of pixels mixed. Throws mr::Error
/// (size_mismatch) when the sizes differ, (invalid_argument) when the channel counts are wrong.
std::size_t apply_sky_matte(ConstImageView sky_alpha, ImageView transmittance, ImageView inscatter);

/// Issue 11 (created edges in haze, helper haze11b): the matte's ramp running past a sharp edge
/// into the surface. Along an edge where the sky and the surface differ plainly in brightness,
/// the guided filter's ramp runs a few pixels past the photo's own edge (a dark roof's first
/// rows under a white sky: alpha 0.07, 0.05, 0.01, 0.01 where the photo shows plain roof), and
/// SkyMask's unmixing keeps part of it wherever the pixel is off the line between the two
/// sides' colours (the roof's texture and hue). The fog mix then lays a faint band of the sky's
/// fog over the surface: a second edge one or two pixels beside the photo's. A surface-side
/// pixel (0 < alpha < 0.5) whose colour holds no more of the sky's than the surface beyond the
/// band (its projection a = (I - F).(B - F) / |B - F|^2 <= 0.1 in scene-linear light, F and B
/// the 3x3 means at the nearest all-surface and all-sky pixels, F within 4.5 px) shows no sky:
/// its alpha moves to max(a, 0), weighted by the step in display luma between B and F (none
/// below 0.03, fully at 0.08). Seeds: such pixels next to a sharp edge (alpha >= 0.9 within
/// 3.5 px, >= 0.5 within 2.5 px); from them the trim follows the ramp outward (to neighbours
/// whose alpha is no higher) for up to 6 px. Left alone: a soft edge (a blurred leaf: no
/// seed; trimming single pixels of a wide ramp leaves cliffs in the matte), a thin member
/// lying wholly in the band (no plain surface of its own within reach), and a hue edge with
/// little step in luma (a dark steel leg against a dark blue dusk sky: a crisp silhouette
/// against the haze's brighter, neutral sky would be a luma step the photo lacks). Only lowers
/// alpha (the binary sky is unchanged). `photo`: scene-linear RGB (or grey), the matte's size.
/// Returns the number of pixels lowered. Throws mr::Error(size_mismatch) when the sizes differ.
std::size_t trim_matte_spill(ConstImageView photo, std::vector<float>& alpha);

}  // namespace mr::photo
