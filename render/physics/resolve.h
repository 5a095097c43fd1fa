// The gradient-accelerated resolve (seed 002 ch. 2, DESIGN.md section 3), shared by the CPU core
// (render/scattering_cpu.cpp, pass 2) and the Vulkan shaders (shaders/resolve.comp): exact
// samples on a sparse grid; every other pixel from its cell's four samples and their
// image-space gradients where all four are depth-continuous with it and the cell has no shadow
// edge or glow core, else marched exactly. In the common subset of C++ and GLSL
// (render/physics/types.h).
#ifndef MR_RENDER_PHYSICS_RESOLVE_H
#define MR_RENDER_PHYSICS_RESOLVE_H

#include "render/physics/medium.h"

MR_PHYSICS_BEGIN

/// Values a grid sample carries for interpolation: R (3), the camera's optical depth (3), AO.
MR_CONSTANT int kResolveValues = 7;
/// A cell whose samples' sun-lit fractions differ by more than this has a shadow edge.
MR_CONSTANT Float kShaftEdge = 0.2;
/// ...and one whose in-scatter (r + g + b) differs by more than this factor a glow core.
MR_CONSTANT Float kGlowRatio = 1.25;

/// Whether depth a may be interpolated from a sample at depth b: within b / 10; sky only with
/// sky.
MR_FN bool depth_continuous(Float a, Float b) {
  if (is_sky(a) || is_sky(b)) return is_sky(a) && is_sky(b);
  return abs(a - b) <= 0.1 * b;
}

/// Whether a cell's pixels need their own march (with kShaftRefinement times the steps): a
/// shadow boundary crosses it, or the in-scatter changes too fast across it (a lamp's core) for
/// gradients to follow.
MR_FN bool cell_has_edge(Float shaft_min, Float shaft_max, Float lum_min, Float lum_max) {
  return shaft_max - shaft_min > kShaftEdge || lum_max > kGlowRatio * lum_min + 1e-12;
}

/// Adds the slope toward a grid neighbour `dist` pixels away (negative: before) that is
/// depth-continuous with the sample.
MR_FN void add_slope(MR_INOUT(Float) slope_sum, MR_INOUT(int) slopes, Float value,
                     Float neighbour_value, Float dist) {
  slope_sum += (neighbour_value - value) / dist;
  ++slopes;
}
/// A sample's gradient along one grid axis: central where both neighbours are continuous with
/// it, one-sided where one is, else flat.
MR_FN Float mean_slope(Float slope_sum, int slopes) {
  return slopes > 0 ? slope_sum / Float(slopes) : 0.0;
}

/// Bilinear weight of corner k (0: (x0, y0), 1: (x1, y0), 2: (x0, y1), 3: (x1, y1)) at
/// fractional position (fx, fy) in the cell.
MR_FN Float corner_weight(int k, Float fx, Float fy) {
  const Float wx = (k == 0 || k == 2) ? 1.0 - fx : fx;
  const Float wy = k < 2 ? 1.0 - fy : fy;
  return wx * wy;
}

/// A corner's value extended to a pixel (dx, dy) away along its gradients.
MR_FN Float extrapolate(Float value, Float grad_x, Float grad_y, Float dx, Float dy) {
  return value + grad_x * dx + grad_y * dy;
}

MR_PHYSICS_END

#endif  // MR_RENDER_PHYSICS_RESOLVE_H
