// Automatic fog on camera-size photos (issue 11): the estimate, the render and the seam
// softening run on a copy of the photo at a working size, and the fog's T and R are brought to
// the photo's own size by guided upsampling, their steps following the full-size photo's
// outlines (photo/fog_upsample.h says how). The estimate's rules were tuned, and judged on
// held-out photos, at 1280 px across (gallery/); a 24 MP original now gets the estimate of its
// 1280 px copy, in a fraction of the time and memory.
#pragma once

#include <optional>

#include "mr/camera.h"
#include "mr/export.h"
#include "mr/fog.h"
#include "mr/image.h"

namespace mr {

/// `mr fog --depth auto`'s default working size: the longer side, in pixels.
inline constexpr int kDefaultWorkingLongSidePx = 1280;

struct MR_API WorkingSize {
  int width = 0, height = 0;
};

/// The size a `width` x `height` photo is worked on at when its longer side may be at most
/// `long_side_px` (the aspect ratio kept, each side rounded, at least 1), or nullopt when the
/// photo is not larger than that (or `long_side_px` <= 0: no limit). Throws
/// mr::Error(invalid_argument) for a size that is not positive.
MR_API std::optional<WorkingSize> working_size(int width, int height, int long_side_px);

/// The photo (scene-linear) reduced to `width` x `height` the way the estimate's tuning photos
/// were: its colour channels sRGB-encoded (the IEC 61966-2-1 curve, continued beyond 0..1 so
/// that an HDR photo's highlights survive), averaged over each output pixel's area
/// (cv::INTER_AREA), decoded again; other channels averaged as they are. Reduced in linear light
/// instead, thin dark structures against a bright sky come out lighter, and the estimate of a
/// tuning photo changed with it (gallery/tune bridge: a clear window in dense fog). Channel
/// names and metadata are kept. Throws mr::Error(invalid_argument) for an empty image or a size
/// that is not positive.
MR_API Image working_copy(const Image& photo, int width, int height);

/// `image` resized to `width` x `height` by taking, for each output pixel, the input pixel under
/// its centre (cv::INTER_NEAREST_EXACT; for maps whose values must not be mixed: distances with
/// +inf sky, the sun's visibility). Throws as working_copy.
MR_API Image resize_nearest(const Image& image, int width, int height);

/// The camera of the same photo stored at `width` x `height`: focal length and principal point
/// scaled with the sides. Throws mr::Error(invalid_argument) for a size that is not positive.
MR_API Camera scale_camera(const Camera& camera, int width, int height);

/// The fog rendered on `working_photo` (`working`: its layers, as mr::fog returned them, the
/// seams already softened) brought to `photo`'s own size by guided upsampling: composite,
/// transmittance and inscatter at the photo's size (with `keep_layers` false only the
/// composite; T and R are left empty, saving 2 x 12 bytes a pixel); `airlight` copied. Throws
/// mr::Error(size_mismatch) when the layers are not the working photo's size,
/// (invalid_argument) when the working photo is larger than the photo or has fewer than 3
/// channels.
MR_API FogLayers upsample_fog_layers(const Image& photo, const Image& working_photo,
                                     const FogLayers& working, bool keep_layers = true);

}  // namespace mr
