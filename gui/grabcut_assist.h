// The GrabCut assist of the polygon tools: a rough polygon drawn around an object is snapped to
// the object's outline with OpenCV's GrabCut (the polygon's inside is "probably object", a band
// outside it "background"), then simplified back to a polygon.
#pragma once
#include <QImage>
#include <vector>

#include "mr/annotations.h"

namespace mrstudio {

/// The object inside `rough` (>= 3 points, photo pixel coordinates, annotations.h convention)
/// in `photo` (8-bit display image of the photo). Returns the outline of the largest connected
/// object region, simplified to within `tolerance_px`; throws mr::Error(invalid_argument) when
/// the polygon is degenerate or GrabCut finds no object in it. Runs for tens to hundreds of
/// milliseconds: call it off the UI thread.
std::vector<mr::PixelPoint> snap_polygon_grabcut(const QImage& photo,
                                                 const std::vector<mr::PixelPoint>& rough,
                                                 double tolerance_px = 1.5, int iterations = 4);

}  // namespace mrstudio
