#include "photo/composite.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace mr::photo {

void composite(ConstImageView photo, ConstImageView transmittance, ConstImageView inscatter,
               ImageView out) {
  tbb::parallel_for(tbb::blocked_range<int>(0, photo.height), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y < rows.end(); ++y)
      for (int x = 0; x < photo.width; ++x) {
        composite_pixel(photo.pixel(x, y), transmittance.pixel(x, y), inscatter.pixel(x, y),
                        out.pixel(x, y), photo.channels);
      }
  });
}

}  // namespace mr::photo
