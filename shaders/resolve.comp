// Pass 2 + 3 of the Vulkan scattering core, per pixel of the tile: the pixel's sample (a grid
// sample; else interpolated from its cell's four samples with their gradients where all four
// are depth-continuous with it and the cell has no shadow edge or glow core; else marched
// exactly, with kShaftRefinement times the steps in a cell with a shadow edge), then the transmittance map T = tau(camera, surface) * S(surface) and the AOVs.
// As passes 2 and 3 of render_scattering_cpu.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "scattering_common.glsl"
#include "render/physics/resolve.h"

layout(local_size_x = kWorkgroupSize, local_size_y = kWorkgroupSize) in;

layout(std430, set = 0, binding = 6) writeonly buffer TOut { float out_transmittance[]; };
layout(std430, set = 0, binding = 7) writeonly buffer ROut { float out_inscatter[]; };
layout(std430, set = 0, binding = 8) writeonly buffer VOut { float out_sun_visibility[]; };
layout(std430, set = 0, binding = 9) writeonly buffer OdOut { float out_optical_depth[]; };
layout(std430, set = 0, binding = 10) buffer Counters { uint exact_count; uint interpolated_count; };
// With kFlagPhotoFallback: per pixel, T as it would be with the sun seen at the surface (rgb)
// and the AO (w); the host's photo fallback (render/photo_fallback.h) takes it where the photo
// shows a pixel the shadow maps shade as sunlit, as the CPU core does.
layout(std430, set = 0, binding = 12) writeonly buffer SunlitOut { vec4 out_sunlit[]; };

shared uint wg_exact, wg_interpolated;

int grid_x(int i) { return min(i * P.image.z, P.image.x - 1); }
int grid_y(int j) { return min(j * P.image.z, P.image.y - 1); }

// Value c of a grid sample: R (0..2), camera optical depth (3..5), ambient occlusion (6).
float sample_value(int i, int j, int c) {
  const int k = kSampleVec4s * ((j - P.grid.y) * P.grid.z + (i - P.grid.x));
  if (c < 3) return grid_samples[k][c];
  if (c < 6) return grid_samples[k + 1][c - 3];
  return grid_samples[k + 1].w;
}
float sample_shaft(int i, int j) {
  return grid_samples[kSampleVec4s * ((j - P.grid.y) * P.grid.z + (i - P.grid.x))].w;
}
float sample_sun_disk(int i, int j) {
  return grid_samples[kSampleVec4s * ((j - P.grid.y) * P.grid.z + (i - P.grid.x)) + 2].x;
}

// Gradient of grid sample (i, j)'s value c along one grid axis (central where both grid
// neighbours are continuous with it, one-sided where one is, else flat).
float gradient(int i, int j, bool along_x, int c) {
  const int x = grid_x(i), y = grid_y(j);
  const float d = depth_at(x, y);
  const float v = sample_value(i, j, c);
  const int n = along_x ? P.grid_count.x : P.grid_count.y;
  const int k = along_x ? i : j;
  float slope_sum = 0.0;
  int slopes = 0;
  for (int side = -1; side <= 1; side += 2) {
    if ((side < 0 && k == 0) || (side > 0 && k + 1 >= n)) continue;
    const int ni = along_x ? i + side : i, nj = along_x ? j : j + side;
    const int nx = grid_x(ni), ny = grid_y(nj);
    if (!depth_continuous(depth_at(nx, ny), d)) continue;
    add_slope(slope_sum, slopes, v, sample_value(ni, nj, c), along_x ? float(nx - x) : float(ny - y));
  }
  return mean_slope(slope_sum, slopes);
}

// T's surface factor S (DESIGN.md section 3) at a surface pixel; also the sun visibility, and
// S_sun_seen: S with the sun's disk fully seen (the photo fallback's value).
// known_sun_disk: the pixel's sun_disk_visibility when already known (interpolation), else -1.
void surface_term(int x, int y, float ao, float known_sun_disk, out vec3 S, out vec3 S_sun_seen,
                  out float sun_visibility) {
  S = vec3(1.0);
  S_sun_seen = vec3(1.0);
  sun_visibility = 1.0;
  const float distance = depth_at(x, y);
  const bool sun = has_flag(kFlagSun);
  const int n_lamps = min(P.image.w, kMaxLamps);
  if (is_sky(distance) || !(sun || n_lamps > 0) || !has_flag(kFlagNormals)) return;
  const vec3 n = normal_at(x, y);
  if (dot(n, n) < 0.5) return;
  const bool shadows = has_flag(kFlagShadows), lpa = has_flag(kFlagLightPathAttenuation);
  const vec3 sigma = P.sigma.xyz;
  const vec3 x0 = P.origin.xyz + ray_dir(x, y) * distance;
  const float offset = 1e-3 + 1e-3 * distance;  // off the surface for shadow lookups
  vec3 direct = vec3(0.0), direct_fogged = vec3(0.0);
  vec3 sun_seen = vec3(0.0), sun_seen_fogged = vec3(0.0);  // the sun's share with visible = 1
  if (sun) {
    const float cos_i = dot(n, P.sun_dir.xyz);
    float visible = 0.0;
    if (cos_i > 0.0) visible = known_sun_disk >= 0.0 ? known_sun_disk : sun_disk_visibility(x, y);
    sun_visibility = visible;
    const float od_sun = lpa ? sun_path_optical_depth(medium_shape(), x0, P.sun_dir.xyz) : 0.0;
    const vec3 tau_sun = transmittance(sigma, od_sun);
    const vec3 e_seen = P.sun_irradiance.xyz * max(0.0, cos_i);
    add_surface_light(direct, direct_fogged, e_seen * visible, tau_sun);
    add_surface_light(sun_seen, sun_seen_fogged, e_seen - e_seen * visible, tau_sun);
  }
  for (int l = 0; l < n_lamps; ++l) {
    const GpuLamp lamp = lamps[l];
    const TowardLamp to_lamp = toward_lamp(x0, lamp.position.xyz);
    const float r2 = to_lamp.r2, r = to_lamp.r;
    if (r < 1e-6) continue;
    const vec3 lv = to_lamp.l;
    const float cos_i = dot(n, lv);
    if (cos_i <= 0.0) continue;
    const float spot = spot_factor(lamp, -lv);
    if (spot <= 0.0) continue;
    if (shadows && !lamp_lit(lamp, x0, n, r, offset, 0.0)) continue;
    const float od_lamp = lpa ? optical_depth(ray_density(x0, lv), 0.0, r) : 0.0;
    add_surface_light(direct, direct_fogged, lamp.intensity.xyz * spot * cos_i / r2,
                      transmittance(sigma, od_lamp));
  }
  S = surface_factor(direct, direct_fogged, P.sky.xyz, ao);
  S_sun_seen = surface_factor(direct + sun_seen, direct_fogged + sun_seen_fogged, P.sky.xyz, ao);
}

void main() {
  if (gl_LocalInvocationIndex == 0u) {
    wg_exact = 0u;
    wg_interpolated = 0u;
  }
  barrier();
  const ivec2 id = ivec2(gl_GlobalInvocationID.xy);
  const bool in_tile = id.x < P.tile.z && id.y < P.tile.w;
  if (in_tile) {
    const int x = P.tile.x + id.x, y = P.tile.y + id.y;
    const int W = P.image.x, H = P.image.y, g = P.image.z;
    const int ngx = P.grid_count.x, ngy = P.grid_count.y;
    const bool on_x = x % g == 0 || x == W - 1, on_y = y % g == 0 || y == H - 1;
    PixelSample s;
    s.shaft = 1.0;
    float sun_disk = -1.0;
    bool exact = false;
    int exact_steps = P.plan.x;  // the preset's march steps; more where a shaft's edge crosses the cell
    if (on_x && on_y) {
      const int i = x == W - 1 ? ngx - 1 : x / g, j = y == H - 1 ? ngy - 1 : y / g;
      s.inscatter = vec3(sample_value(i, j, 0), sample_value(i, j, 1), sample_value(i, j, 2));
      s.camera_od = vec3(sample_value(i, j, 3), sample_value(i, j, 4), sample_value(i, j, 5));
      s.ao = sample_value(i, j, 6);
      sun_disk = sample_sun_disk(i, j);
    } else if (ngx < 2 || ngy < 2) {
      exact = true;
    } else {
      const int i = min(x / g, ngx - 2), j = min(y / g, ngy - 2);
      const ivec2 corner[4] = ivec2[4](ivec2(i, j), ivec2(i + 1, j), ivec2(i, j + 1), ivec2(i + 1, j + 1));
      const float d = depth_at(x, y);
      bool ok = true;
      for (int k = 0; k < 4 && ok; ++k)
        ok = depth_continuous(d, depth_at(grid_x(corner[k].x), grid_y(corner[k].y)));
      // A shadow boundary crosses the cell, or the in-scatter changes too fast across it.
      float shaft_min = 1.0, shaft_max = 0.0, lum_min = INF, lum_max = 0.0;
      for (int k = 0; k < 4; ++k) {
        const float sh = sample_shaft(corner[k].x, corner[k].y);
        shaft_min = min(shaft_min, sh);
        shaft_max = max(shaft_max, sh);
        const float lum = sample_value(corner[k].x, corner[k].y, 0) +
                          sample_value(corner[k].x, corner[k].y, 1) +
                          sample_value(corner[k].x, corner[k].y, 2);
        lum_min = min(lum_min, lum);
        lum_max = max(lum_max, lum);
      }
      const bool shadow_edge = cell_has_edge(shaft_min, shaft_max, lum_min, lum_max);
      if (shadow_edge) ok = false;
      if (!ok) {
        exact = true;
        // A shaft's edge crosses the cell: its pixels get finer steps, or thin slivers of
        // shadow that one step misses or catches would show as grain (as on the CPU).
        if (shadow_edge) exact_steps = P.plan.x * kShaftRefinement;
      } else {
        const int x0 = grid_x(i), x1 = grid_x(i + 1), y0 = grid_y(j), y1 = grid_y(j + 1);
        const float fx = float(x - x0) / float(x1 - x0), fy = float(y - y0) / float(y1 - y0);
        float acc[kResolveValues] = float[kResolveValues](0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        for (int k = 0; k < 4; ++k) {
          const float weight = corner_weight(k, fx, fy);
          const float dx = float(x - grid_x(corner[k].x)), dy = float(y - grid_y(corner[k].y));
          for (int c = 0; c < kResolveValues; ++c)
            acc[c] += weight * extrapolate(sample_value(corner[k].x, corner[k].y, c),
                                           gradient(corner[k].x, corner[k].y, true, c),
                                           gradient(corner[k].x, corner[k].y, false, c), dx, dy);
        }
        s.inscatter = max(vec3(0.0), vec3(acc[0], acc[1], acc[2]));
        s.camera_od = max(vec3(0.0), vec3(acc[3], acc[4], acc[5]));
        s.ao = clamp(acc[6], 0.0, 1.0);
        // The surface's sun visibility is a step function: taken from the cell's samples only
        // where all four agree, else looked up (as on the CPU).
        const float disk0 = sample_sun_disk(i, j);
        if (disk0 >= 0.0 && sample_sun_disk(i + 1, j) == disk0 && sample_sun_disk(i, j + 1) == disk0 &&
            sample_sun_disk(i + 1, j + 1) == disk0)
          sun_disk = disk0;
        atomicAdd(wg_interpolated, 1u);
      }
    }
    if (exact) {
      s = march(x, y, exact_steps);
      s.ao = ambient_occlusion_at(x, y);
      atomicAdd(wg_exact, 1u);
    }
    vec3 od = s.camera_od;
    if (!has_flag(kFlagNoise)) od = camera_optical_depth(x, y);
    vec3 S, S_sun_seen;
    float sun_visible;
    surface_term(x, y, s.ao, sun_disk, S, S_sun_seen, sun_visible);
    const vec3 T = exp(-od) * S;
    const int o = (id.y * P.tile.z + id.x);
    for (int c = 0; c < 3; ++c) {
      out_transmittance[3 * o + c] = T[c];
      out_inscatter[3 * o + c] = s.inscatter[c];
      out_optical_depth[3 * o + c] = od[c];
    }
    out_sun_visibility[o] = sun_visible;
    if (has_flag(kFlagPhotoFallback)) out_sunlit[o] = vec4(exp(-od) * S_sun_seen, s.ao);
  }
  barrier();
  if (gl_LocalInvocationIndex == 0u) {
    atomicAdd(exact_count, wg_exact);
    atomicAdd(interpolated_count, wg_interpolated);
  }
}
