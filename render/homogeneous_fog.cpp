#include "render/homogeneous_fog.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cmath>

namespace mr::render {

void render_homogeneous_sky(ConstImageView distance_m, const HomogeneousSkyMedium& medium,
                            ImageView transmittance, ImageView inscatter) {
  tbb::parallel_for(tbb::blocked_range<int>(0, distance_m.height), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y < rows.end(); ++y) {
      const float* d = distance_m.row(y);
      float* t = transmittance.row(y);
      float* r = inscatter.row(y);
      for (int x = 0; x < distance_m.width; ++x) {
        const float dist = d[x * distance_m.channels];
        float tau = 1.0f;
        for (int c = 0; c < 3; ++c) {
          // exp(-sigma * inf) = 0 for sigma > 0; sigma = 0 means clear air (T = 1) even for sky.
          // Grey fog (the common case) needs one exp per pixel, not three.
          if (c == 0 || medium.sigma_t_per_m[c] != medium.sigma_t_per_m[c - 1])
            tau = medium.sigma_t_per_m[c] > 0 ? std::exp(-medium.sigma_t_per_m[c] * dist) : 1.0f;
          t[x * transmittance.channels + c] = tau;
          r[x * inscatter.channels + c] = medium.albedo[c] * medium.sky_radiance[c] * (1.0f - tau);
        }
      }
    }
  });
}

}  // namespace mr::render
