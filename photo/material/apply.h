// Private to libmr: re-rendering regions of a photo with new materials while keeping the photo's
// fine detail (issue 7, step 5).
//
// The split (an intrinsic-image decomposition in its simplest form, not a learned one):
//   photo I = A * S + specular,  S = shading of a unit-albedo Lambert surface under the photo's
//   lights (sun with shadows, sky, lamps; render/surface_shading.h), so A = I / S is the photo's
//   apparent albedo, with everything the lighting model does not explain folded into it.
//   A's luminance (plus a noise floor) is split in log space by a robust local mean over each
//   region's own pixels (a normalised tent filter, re-weighted twice against pixels far from it,
//   so a window does not pull a wall's base down into a halo): log A = log A_smooth + log D.
//   A_smooth is the material's base, which the new material replaces; D is the texture and the
//   shading the model misses (mortar lines, grain, leaves, small unmodelled shadows), which is
//   kept, in luminance only (one value for the three channels):
//   new = D * diffuse_albedo * S + min(1, Y(D)) * specular(new material),
//   so the diffuse part has the photo's texture and small-scale shading in the new colour. (Per
//   channel, tried first, a channel the photo barely records, e.g. the green and blue of a red
//   saucer, put its JPEG and sensor noise into D as coloured grain; and colour variation inside
//   a region stayed relative to the old colour.) The noise floor keeps D near 1 where the photo
//   is too dark to record texture (a black silhouette): there D is the photo's noise. (An
//   edge-aware split, tried first, put real photos' strong texture into A_smooth, where it was
//   replaced by a flat pastel colour.)
// Limits: the photo's own highlights are part of A (a glossy original leaves bright blobs in D
// when they are smaller than the filter radius, and in A_smooth otherwise, where they are
// replaced); large-scale errors of the lighting estimate (a wrong sun direction, shadows of things
// the depth map lacks) are larger than the filter and get replaced by the model's shading.
#pragma once
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>
#include "mr/image.h"
#include "mr/material_model.h"
#include "mr/scene.h"
#include "render/surface_shading.h"

namespace mr::photo {

struct DetailOptions {
  /// Radius of the base's smoothing (a tent of two box filters, support 4 r + 1); 0: 8 % of the
  /// image's short side, 8..256. Texture and shading finer than about r are kept in D.
  int radius_px = 0;
  /// Optional (null = all surfaces are one group): 1 channel, the photo's size; the base is
  /// smoothed over each region's own pixels (label 0 is one more group), so that no albedo of a
  /// neighbouring region or of the sky leaks across a border into D.
  const Image* region_labels = nullptr;
  float min_detail = 1.0f / 32;  ///< D is clamped to [min_detail, max_detail] (a safety only:
  float max_detail = 32.0f;      ///< with the shading floor D x S reproduces the photo)
  /// Added to the photo's luminance before the split, as a share of its surfaces' 99th
  /// percentile luminance (0.003: about code 10 of 255 of an sRGB photo exposed to white), so
  /// that D is not the relative noise of near-black pixels. 0: none.
  double noise_floor = 0.003;
  /// The photo's coding noise (8-bit quantisation, JPEG's blocks), in display codes of 255 at
  /// its bright surfaces' level (the noise floor's). The luminance, display encoded (gamma 2.2,
  /// that level at 255), goes through a bilateral filter (range sigma 2.5 x this, spatial sigma
  /// 2 px) for the calmed detail (channel kCalmDetailChannel): steps larger than the range (the
  /// photo's edges, folds) stay in it, the blocks and grain do not. Only where that noise
  /// outweighs a 7 % texture (below code 2.2 x this / 0.07, 63 for 2 codes): a pixel keeps the
  /// share code / 63 of its departure from the filtered value, and mid-tones their few codes of
  /// real texture (grass, plaster). Only for a photo decoded from 8-bit sRGB codes (its values
  /// on them): a 16-bit or float original has no such noise. 0, or another photo: the calmed
  /// detail is D.
  double coding_noise_codes = 2.0;
  /// D fades to 1 over this many pixels at each group's border (the border pixel itself gets
  /// 1 / (border_px + 1) of its log D): border pixels mix the region with its neighbour. 0: none.
  int border_px = 2;
};

/// Unit-albedo diffuse shading S (3 channels, the geometry's size; 0 where there is no surface):
/// render::shading_terms(...).diffuse, exactly the part of the rendering that scales with the
/// diffuse albedo (no Fresnel-at-grazing specular, which a {diffuse 1, F0 0} render would add).
Image diffuse_shading(const render::SurfaceGeometry& geometry, const Lighting& lighting);

/// `shading` raised to 5 % of its mean over the surfaces where it is lower (grazing or deep
/// shadow in the model: at depth edges of an estimated geometry mostly wrong). photo_detail
/// divides by it, so D x floored shading is the photo's radiance over the base everywhere; the
/// rendering with detail must use it too.
/// Taken by value and floored in place: pass it moved when it is not needed again.
Image floored_shading(Image shading, const render::SurfaceGeometry& geometry);

/// The geometry with normals (renormalised), sun and sky visibility averaged over each region's
/// own surface pixels (label > 0) with a tent of radius `radius_px` (0: 3 % of the short side,
/// 2..24). A distance map estimated from one photo has junk at the pixel scale (normals flipping
/// at the edges of its columns, 1-pixel shadow slivers): rendered as is, a new material's
/// specular lobe turns it into bright and dark lines, and its texture is no longer the photo's.
/// (At 1 %, the gallery's tuning half kept the photo's texture, correlation >= 0.9, in 20 of 35
/// transfers; at 3 %, 25, none worse.) Used for photo targets only; a 3D-scene target's geometry
/// is exact.
/// The geometry is taken by value and smoothed in place: pass it moved when it is not needed
/// again (a large photo's peak memory).
render::SurfaceGeometry smooth_geometry_in_regions(render::SurfaceGeometry geometry,
                                                   const Image& region_labels, int radius_px = 0);
/// smooth_geometry_in_regions' default radius for a width x height photo: 3 % of the short
/// side, 2..24 px.
int region_smoothing_radius(int width, int height);

/// Region labels with thin gaps closed: label-0 surface pixels in gaps up to 2 x gap_px wide
/// between or inside regions (a morphological closing of their union) join the nearest region.
/// Masks painted or derived from depth leave such seams; left as the photo, each would show as
/// a line or specks of the old material between re-rendered pixels. Sky pixels are not added.
Image close_region_gaps(const Image& region_labels, const render::SurfaceGeometry& geometry,
                        int gap_px = 2);

/// Region labels whose borders follow the photo's edges. Classes: the unlabelled surface (0) and
/// each region; a pixel is trusted when its whole (2 radius_px + 1)^2 window is of its class.
/// An untrusted surface pixel (near a border) moves to the class whose local colour (mean and
/// variance of its trusted pixels within 3 radius_px, display-encoded; at least a full trusted
/// window's worth of them) is clearly closer (squared
/// distance over the variance under a quarter of its own class's). A mask painted or segmented a
/// few pixels off an object's edge leaves slivers of the neighbour inside a region: their D,
/// measured against the region's base, would show in the new material as a darker or lighter line
/// where the photo has a plain edge. Where the photo shows no edge, or a texture spans both sides,
/// the mask's border stays; a moved pixel with fewer than 3 of its 8 neighbours in its new class
/// (a lone flip: noise, clutter) goes back. Sky pixels keep their label (they stay the photo's
/// whatever it is).
/// Gaps: unlabelled surface pixels in a gap between or inside regions up to 4 radius_px wide (a
/// closing of their union) have no colour of their own (the unlabelled class's is measured
/// outside the gaps). Such a pixel joins one of the two regions with the most trusted pixels
/// within 3 radius_px + 2 radius_px when their colours explain its own: within one's spread,
/// a mix of the two (a penumbra or soft border left out between two painted regions), or
/// nearer to one than half the step between them. Otherwise (a pole, a seam) it stays.
/// radius_px 0: unchanged. Each class's window sums are made in strips of `strip_rows` rows of
/// its box (a large photo's memory; the result does not depend on it, >= 1).
Image snap_regions_to_edges(const Image& region_labels, const Image& photo,
                            const render::SurfaceGeometry& geometry, int radius_px = 4,
                            int strip_rows = 256);

/// Channels of photo_detail's layer: 0-2 D (equal), then D of the luminance with its coding
/// noise filtered out, then the base albedo (luminance) D is measured against.
constexpr int kCalmDetailChannel = 3, kBaseAlbedoChannel = 4, kDetailChannels = 5;

/// The detail layer D of `photo` (scene-linear RGB, the geometry's size) given its diffuse
/// shading S (see the file comment), kDetailChannels channels; D 1 where there is no surface or
/// S is ~0. render_with_detail keeps of the photo's coding noise (D over the calmed D) the share
/// 1 / k^(1 / 2.2) where a material's diffuse albedo is k > 1 times the base (the amplification
/// of display codes): a new material much lighter than a dark surface would show the photo's
/// coding noise k^(1 / 2.2) times larger than the old one did (a black shirt's 8 x 8 JPEG blocks
/// in a white one). Throws mr::Error(size_mismatch) for images of different sizes.
Image photo_detail(const Image& photo, const Image& shading,
                   const render::SurfaceGeometry& geometry, const DetailOptions& options = {});

/// What the despeckling of despeckle_region_borders() changed.
struct DespeckleStats {
  std::size_t band_pixels = 0;  ///< pixels within kDespeckleBandPx of a region's border
  std::size_t changed = 0;      ///< changes made, over all passes (a pixel may count twice)
  int passes = 0;               ///< passes that changed something
};

/// How apply_materials composites the re-rendered regions into the photo.
struct CompositeOptions {
  /// Sigma of the Gaussian that softens each region's indicator (0: hard edges, and none of
  /// the options below).
  double feather_px = 1.0;
  /// With more than feather_px: the feather goes on outside a region over the untouched
  /// surface, as far as the photo is plain (see apply_materials).
  double smooth_feather_px = 3.0;
  /// Last, despeckle_region_borders().
  bool despeckle_borders = true;
  /// Above 0, the photo's white (photo_white_level): a region whose rendering would reach
  /// beyond it is exposed down as a whole (region_range_fit). 0: every region at the photo's
  /// own exposure, however far beyond white (a 3D scene; `mr material --physical-exposure`).
  float white_level = 0;
};

/// The most a re-materialled region may reach, in the photo's units: 1, an 8-bit photo's white,
/// or for a photo that records brighter values (a float original) the 99.9th percentile of its
/// pixels' brightest channel (finite values; over an even subsample of 2^20 pixels for a larger
/// photo).
float photo_white_level(const Image& photo);

/// Percentile of a region's brightest channels that region_range_fit brings to white: 1 % of a
/// region may be sheen or glints beyond it, left to the output's highlight roll-off.
constexpr double kRangeFitPercentile = 99;

/// The exposure, in (0, 1], that brings a region's rendering within the photo's range:
/// white_level over the kRangeFitPercentile-th percentile of `brightest` (each pixel's
/// brightest channel) where that lies above white_level, else 1 (also for no pixels or a
/// white_level of 0). Why: a light material on a dark surface in strong light renders many
/// times beyond the photo's white, and the roll-off of an 8-bit file then flattens its texture
/// (tuning scenetext01's trees: 29 % of a region above white, its 99th percentile 15 x white).
/// The sample's albedo is known only up to its guessed exposure, and a camera exposing for the
/// new material would record it so. One factor for the whole region keeps the texture and
/// contrast, which are ratios. `brightest` is reordered.
float region_range_fit(std::span<float> brightest, float white_level);
/// The same over the listed pixels of a rendering (RGB; non-finite pixels left out): the factor
/// the assignment search judges a candidate's region by.
float region_range_fit(const Image& rendered, std::span<const std::int32_t> pixels,
                       float white_level);

/// `photo` with each region k (labels(x, y) = k in 1..materials.size(), surface pixels only)
/// re-rendered with materials[k - 1]: D * diffuse_albedo * S + specular (D calmed where the
/// material is lighter than the photo's, see photo_detail), or without `detail`
/// (null) the plain rendering. Composited with soft weights, each region's indicator blurred by
/// a Gaussian of sigma `options.feather_px` (0: hard edges), the photo filling the rest, sky
/// pixels counting as outside: two regions' border blends their renderings, a region's border
/// with the photo ramps inside the region. Pixels outside the regions and sky pixels are the
/// photo's, except (1) the 1-pixel edge of an object beside a region, a mix of the object and
/// its background whose object share (read from the colour line between them, where they differ
/// by a third or more) takes the new colour, (2) with `smooth_feather_px` > `feather_px`, the
/// untouched surface within 2 x smooth_feather_px of a region, which takes the region's
/// indicator blurred by a Gaussian of that sigma times how plain the photo is that far around
/// (1 where no step of the blurred log luminance between neighbours exceeds 0.05, 0 from 0.2;
/// the least over the reach): a border ragged by a pixel or two through a plain surface leaves
/// no teeth, and nothing crosses the photo's edges, and (3) the despeckled border band (what
/// it changed into `*despeckled` when given). With `options.white_level`, each region's
/// rendering is first scaled by its region_range_fit over the region's own pixels (an even
/// subsample of 2^20 of a larger region; the factors into `*exposures` when given, one per
/// region). With `detail`, pass floored_shading().
Image apply_materials(const Image& photo, const render::SurfaceGeometry& geometry,
                      const Lighting& lighting, const Image& shading, const Image& region_labels,
                      std::span<const Material> materials, const Image* detail,
                      const CompositeOptions& options = {}, DespeckleStats* despeckled = nullptr,
                      std::vector<float>* exposures = nullptr);

/// Pixels within this distance of a region's border (a 7 x 7 window holding another label, and
/// a region pixel) are despeckled: the narrow feather's reach.
constexpr int kDespeckleBandPx = 3;
/// A 1-pixel jump of log 0.15 (16 %) in a border pixel is plainly visible at 100 %; the photo's
/// own jumps under log 0.1 (its noise, JPEG ringing) are calm.
constexpr float kSpeckJump = 0.15f;
constexpr float kPhotoCalm = 0.1f;
/// Log values are of value + this share of the photo's bright surfaces' level (as the detail
/// layer's noise floor, DetailOptions::noise_floor; about sRGB code 10 of 255 for a photo
/// exposed to white): near black, a step of a code or two is the 8-bit coding's, invisible.
/// Without it the photo's near-black grain hid, as "the photo's own specks", the visible
/// specks a light material left along a dark region's border (gallery/tune astronaut).
constexpr float kSpeckNoiseFloor = 0.003f;

/// Takes out, in `out` (the composite of `photo`, 3 channels, the photo's size), the 1-pixel
/// specks, lines and teeth that the compositing makes along the regions' borders where the photo
/// has none: a border pixel mixes the region with what lies beyond it, so rendered as the region
/// it comes out a peak or a trough between its neighbours (a dark rim of a saucer's edge in the
/// new material; a tooth of a ragged border). In the band around the borders (kDespeckleBandPx;
/// labels as apply_materials reads them: a region id on a surface pixel, else 0):
///  (1) a pixel whose log value, in some channel, lies beyond both its neighbours along an axis
///      (horizontal or vertical) by more than kSpeckJump in `out` but by less than kPhotoCalm
///      in the photo becomes the mix of its two new neighbours along that axis with the weights
///      that make the photo's pixel from the photo's neighbours (its share along the colour line
///      between them, clamped to [0, 1]; the mean where they are equal), then is clamped per
///      channel into each axis's range of its new neighbours widened by kPhotoCalm;
///  (2) a pixel whose log value lies more than kSpeckJump from the median of its 3 x 3
///      neighbourhood in `out` but less than kPhotoCalm in the photo takes that median (per
///      channel): a 1-pixel tooth or notch of a ragged border.
/// Passes run until none changes anything, at most 10: a few pixels can alternate between the
/// two fixes as their neighbours change (coffee's regions: 1802 changes in the first pass, 65
/// in the tenth, of 29044 band pixels; settling them on their neighbours' median, tried, left
/// as many specks). A pixel the photo shows as a speck is never touched, so the photo's own
/// detail stays.
DespeckleStats despeckle_region_borders(const Image& photo, const render::SurfaceGeometry& geometry,
                                        const Image& region_labels, int regions, Image& out);

/// Renders what apply_materials puts into region pixels, for one material at the listed pixels
/// (indices y * width + x) into `out` (3 channels, the geometry's size; other pixels untouched).
/// `detail`: photo_detail's layer, or 3 channels of D taken as they are.
void render_with_detail(const render::SurfaceGeometry& geometry, const Lighting& lighting,
                        const Image& shading, const Image* detail, const Material& material,
                        std::span<const std::int32_t> pixels, Image& out);
/// The same, into `rgb` (3 floats per listed pixel, in their order; its size 3 x pixels): a
/// band's rendering without a frame-sized image.
void render_with_detail(const render::SurfaceGeometry& geometry, const Lighting& lighting,
                        const Image& shading, const Image* detail, const Material& material,
                        std::span<const std::int32_t> pixels, std::span<float> rgb);

}  // namespace mr::photo
