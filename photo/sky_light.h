// Private to libmr: sky light by direction (issue 11, "real photos, no help").
//
// Single scattering of the light arriving from every direction w' at a point of the fog, seen
// along the view direction w, is L_in(w) = integral over the sphere of L_env(w') p(w . w') dw'
// with p the Henyey-Greenstein phase (w' is the direction one looks in to see that light, as for
// the sun: render/physics/scattering.h). A uniform environment L_sky gives L_in = L_sky (p is
// normalised): the scattering core's isotropic sky light. Its sky term of R is
// albedo L_sky (1 - tau(0, D)) along every view ray, whatever the density (the source is
// constant along the ray, so the march telescopes), so a direction-dependent L_in(w) replaces
// it exactly by adding albedo (L_in(w) - L_sky) (1 - tau(0, D)) to R: the same closed form
// (render/medium.h, sky_only_inscatter) with the deviation in place of L_sky.
//
// The environment comes from the photo: the sky directions it shows take its sky's radiance,
// the sky directions it does not show are filled smoothly from the rows of sky it does show
// (the mean of each elevation row, interpolated between rows and held beyond them; L_sky with no
// sky at all), and every direction below the horizon takes the ground's upward radiance, the
// mean of the photo's surface pixels below the horizon. It is kept as a low-resolution
// latitude-longitude map of its deviation from L_sky (so a uniform environment gives exactly
// zero) and convolved with the phase function texel by texel (exact for the map, the kernel
// weights normalised to sum to 1): the convolved map is smooth at the scale of the phase lobe,
// and a pixel takes it bilinearly at its view direction.
#pragma once

#include <array>

#include "mr/camera.h"
#include "mr/image.h"
#include "mr/scene.h"

namespace cv {
class Mat;
}

namespace mr::photo {

/// A latitude-longitude map (3 channels): column c covers azimuths (c / W) 360 - 180 to
/// ((c + 1) / W) 360 - 180 degrees (azimuth 0 = +Z, 90 = +X, as mr::direction_from_azimuth_
/// elevation), row r elevations 90 - (r / H) 180 to 90 - ((r + 1) / H) 180 (row 0 at the
/// zenith). H even, so the horizon is a texel boundary.
/// The unit world direction of the point (col, row) in texel units (texel centres at + 0.5).
Vec3 latlong_direction(int width, int height, double col, double row);
/// The solid angle of a texel of row `row` (steradians).
double latlong_texel_solid_angle(int width, int height, int row);
/// Bilinear sample of a lat-long map at a world direction (azimuth wraps, elevation clamps at
/// the first and last rows' centres).
std::array<double, 3> sample_latlong(const Image& map, const Vec3& direction);

/// The phase convolution of a lat-long map (any size, H even) onto an out_width x out_height
/// lat-long map: out(w) = sum_i env_i p_HG(g, w . w_i) dOmega_i / sum_i p_HG(g, w . w_i)
/// dOmega_i over the input texels' centres w_i, with their solid angles.
Image convolve_henyey_greenstein(const Image& env, double g, int out_width, int out_height);

/// The environment's resolution for a phase lobe (texels small against the lobe's half-width,
/// capped), and the convolved map's.
struct LatLongSizes {
  int env_width, env_height, out_width, out_height;
};
LatLongSizes latlong_sizes_for(double g);

/// The environment of a photo as the deviation from `sky_radiance` (lat-long, `width` x
/// `height`): sky pixels are those whose distance is_sky (+inf), seen from `pose` by `camera`
/// (see the file comment for the fill). The photo: scene-linear, >= 3 channels, the camera's
/// size; `distance_m`: 1 channel, the same size.
Image environment_deviation(ConstImageView photo, ConstImageView distance_m, const Camera& camera,
                            const CameraPose& pose, const std::array<float, 3>& sky_radiance,
                            int width, int height);

/// True when every value of the map is exactly 0 (a uniform environment: no correction).
bool all_zero(const Image& map);

/// A Gaussian blur of standard deviation `sigma_px` in place (edges replicated), for the scale's
/// wide blurs (1-1.5 % of the frame: 60 px at 12 MP, where cv::GaussianBlur's ~6 sigma taps per
/// pixel and pass took 11.7 of the scale's 22 s): from 4 px on, three box filters (O(1) per
/// pixel) of odd widths next to the Gaussian's (Kovesi, "Fast almost-Gaussian filtering", 2010)
/// and an exact Gaussian of the variance they leave (a few px), so the variance is the
/// Gaussian's; below 4 px, the exact Gaussian. Any depth and channel count cv::blur takes.
void wide_gaussian_blur(cv::Mat& image, double sigma_px);

/// Issue 11 (helper haze14): the sky's brightness where the photo shows it. The phase-convolved
/// map above is smooth at the scale of the phase lobe (tens of degrees) and, through the neutral
/// prior, of a daylight colour: in haze, where the sky behind a near surface is seen through the
/// whole layer (T ~ 0), a deep blue sky (dark in luma) turned into a flat, much brighter grey,
/// and a leaf or a steel strut whose edge against it was mostly hue became a luma step the
/// photo did not have. The light the haze scatters toward the camera along a direction is what
/// the photo's sky shows there, so the sky term's light along each pixel's ray is scaled to the
/// brightness of the photo's own sky around the pixel: s = (Y'_local / Y'(L_in(w)))^2.2, Y' the
/// display luma (Rec.709 weights on gamma-2.2 encoded values: a neutral grey of a blue sky's
/// luminance looks brighter than the blue), Y'_local an edge-aware average of the sky's display
/// luma (a normalized convolution with the domain
/// transform's recursive filter, Gastal and Oliveira 2011, guided by the display-referred
/// photo after a median that removes thin structures taken for sky: the core of the sky feeds
/// it, surface pixels and the mixed pixels along the sky's edge never do, and a photo edge,
/// such as a dark cloud's rim against its bright glow, stops it). Near a surface the scale only
/// ever darkens (at most 1): a glow, white clouds or a pale structure taken for sky there keep
/// the flat light. Deep in the sky (from 10 % of the frame away from the nearest surface pixel,
/// not within 3 %, a smoothstep between) the light follows the sky's own display luma pixel by
/// pixel instead: darker as it is, and brighter by 0.7 of its excess over the flat light (up to
/// 1.5 above the flat light's luma), so white clouds, glows and sunlit rays stay visible,
/// attenuated, with rims no sharper than the photo's (issue 11: kite's white clouds had become
/// grey patches at the mean sky's luma).
/// Dark or bright structures narrower than 3 % of the frame taken for sky (a launch tower's
/// lattice, cables, a facade's windows: haze15) stand off a grey closing or opening of the sky's
/// luma by more than 10 % and do not feed the average either.
/// Surface pixels take the scale of the nearest sound sky (the fog in front of a far hill is the
/// same light as the sky's just above it), smoothed, fading to 1 with their distance from any
/// sky pixel (a lattice's steel between sky-coloured openings keeps the sky's scale). The scale
/// is a scalar, so the fog's colour (its chroma) is the map's.
/// `photo`: scene-linear, >= 3 channels; `distance_m`: 1 channel, the same size (is_sky:
/// sky); `deviation`: the convolved (and bounded) map of L_in - sky_radiance. Returns a
/// 1-channel map of the photo's size, or an empty image when every scale is exactly 1.
/// `tint` (optional): set to the 3-channel factor on the scaled light that moves its colour half
/// way toward the hue of the photo's own sky around the pixel (the same edge-aware average of
/// the sky's display colour, normalised to unit luma) at the same display luma, spread and faded
/// over surfaces as the scale is; empty when every factor is exactly 1.
Image sky_brightness_scale(ConstImageView photo, ConstImageView distance_m, const Camera& camera,
                           const CameraPose& pose, const Image& deviation,
                           const std::array<float, 3>& sky_radiance, Image* tint = nullptr);

}  // namespace mr::photo
