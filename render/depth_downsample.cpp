#include "render/depth_downsample.h"

#include <tbb/parallel_for.h>

#include <cmath>
#include <limits>
#include <string>

#include "mr/error.h"

namespace mr::render {

DownsampledDistance downsample_distance_nearest(ConstImageView distance_m, const Camera& camera,
                                                int factor) {
  if (factor < 1)
    throw Error(ErrorCode::invalid_argument,
                "downsample_distance_nearest: factor must be >= 1, got " + std::to_string(factor));
  if (distance_m.channels != 1 || distance_m.width != camera.width ||
      distance_m.height != camera.height)
    throw Error(ErrorCode::invalid_argument,
                "downsample_distance_nearest: need a 1-channel distance map of the camera's size " +
                    std::to_string(camera.width) + "x" + std::to_string(camera.height));
  DownsampledDistance out;
  out.camera = camera;
  out.camera.width = camera.width / factor;
  out.camera.height = camera.height / factor;
  out.camera.focal_px = camera.focal_px / factor;
  out.camera.cx = camera.cx / factor;
  out.camera.cy = camera.cy / factor;
  out.distance_m = Image::uninitialized(out.camera.width, out.camera.height, 1, {"Z"});
  const ImageView coarse = out.distance_m.view();
  const Camera& cc = out.camera;
  tbb::parallel_for(0, cc.height, [&](int j) {
    for (int i = 0; i < cc.width; ++i) {
      double nearest = std::numeric_limits<double>::infinity();
      int nx = -1, ny = -1;
      for (int y = j * factor; y < (j + 1) * factor; ++y)
        for (int x = i * factor; x < (i + 1) * factor; ++x) {
          const double d = distance_m.at(x, y, 0);
          if (d > 0 && std::isfinite(d) && d < nearest) {
            nearest = d;
            nx = x;
            ny = y;
          }
        }
      float value = std::numeric_limits<float>::infinity();
      if (nx >= 0) {
        // Planar depth z = d * dir_z of the fine pixel, re-expressed along the coarse ray.
        const double z = nearest * camera.ray_direction(nx, ny)[2];
        value = float(z / cc.ray_direction(i, j)[2]);
      }
      coarse.at(i, j, 0) = value;
    }
  });
  return out;
}

}  // namespace mr::render
