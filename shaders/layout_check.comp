// For tests/vulkan_layout_test.cpp: copies every 16-byte member of the parameter structs, as
// GLSL sees them, into a flat buffer; the test compares with what C++ wrote.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "scattering_params.h"

layout(local_size_x = 1) in;
layout(std430, set = 0, binding = 0) readonly buffer ParamsBuffer { ScatterParams P; };
layout(std430, set = 0, binding = 1) readonly buffer LampBuffer { GpuLamp lamps[]; };
layout(std430, set = 0, binding = 2) readonly buffer LayerBuffer { ShadowLayer layers[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Out { vec4 o[]; };

void main() {
  int k = 0;
  o[k++] = P.origin; o[k++] = P.right; o[k++] = P.up; o[k++] = P.forward; o[k++] = P.camera;
  o[k++] = vec4(P.image); o[k++] = vec4(P.region); o[k++] = vec4(P.tile); o[k++] = vec4(P.grid);
  o[k++] = vec4(P.grid_count); o[k++] = vec4(P.plan); o[k++] = vec4(P.flags);
  o[k++] = P.sigma; o[k++] = P.albedo; o[k++] = P.sky; o[k++] = P.layer; o[k++] = P.noise;
  o[k++] = P.sun_dir; o[k++] = P.sun_u; o[k++] = P.sun_v; o[k++] = P.sun_irradiance;
  o[k++] = P.misc; o[k++] = P.cascade_end;
  for (int l = 0; l < 2; ++l) {
    o[k++] = lamps[l].position; o[k++] = lamps[l].intensity; o[k++] = lamps[l].spot; o[k++] = lamps[l].cone;
  }
  for (int l = 0; l < 2; ++l) {
    for (int c = 0; c < 4; ++c) o[k++] = layers[l].view_proj[c];
    o[k++] = layers[l].origin; o[k++] = layers[l].axis; o[k++] = layers[l].bounds; o[k++] = layers[l].pad;
  }
}
