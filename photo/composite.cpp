#include "photo/composite.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace mr::photo {

void composite(ConstImageView photo, ConstImageView transmittance, ConstImageView inscatter,
               ImageView out) {
  tbb::parallel_for(tbb::blocked_range<int>(0, photo.height), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y < rows.end(); ++y)
      for (int x = 0; x < photo.width; ++x) {
        const float* i = photo.pixel(x, y);
        const float* t = transmittance.pixel(x, y);
        const float* r = inscatter.pixel(x, y);
        float* c = out.pixel(x, y);
        for (int k = 0; k < 3; ++k) c[k] = i[k] * t[k] + r[k];
        for (int k = 3; k < photo.channels; ++k) c[k] = i[k];
      }
  });
}

}  // namespace mr::photo
