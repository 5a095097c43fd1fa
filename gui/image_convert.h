// Conversions between libmr images and what the GUI shows: scene-linear -> 8-bit sRGB QImage,
// box-filtered downscaling of photos (depth maps and the camera: mr::resize_nearest and
// mr::scale_camera, mr/working_size.h), and a colour map of a distance map.
#pragma once
#include <QImage>

#include "mr/camera.h"
#include "mr/color.h"
#include "mr/image.h"

namespace mrstudio {

/// Scene-linear RGB (first three channels; 1 channel: grey) to an 8-bit sRGB QImage (RGB888),
/// through the colour config's scene_linear -> srgb_texture conversion. `exposure` multiplies
/// first (for the in-scatter layer, say).
QImage to_display(const mr::Image& linear, const mr::ColorConfig& color, float exposure = 1.0f);

/// The size that fits `max_pixels` with the aspect ratio of width x height (never larger).
QSize fit_pixels(int width, int height, double max_pixels);

/// Box-filtered (area-averaged) downscale to width x height (same size: a copy). Channels kept.
mr::Image downscale_area(const mr::Image& image, int width, int height);

/// Distance map (1 channel, metres, +inf = sky) as a colour map: log distance from near (red)
/// through green to far (blue), sky light grey.
QImage depth_colormap(const mr::Image& distance_m);

}  // namespace mrstudio
