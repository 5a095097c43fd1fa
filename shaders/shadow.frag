// Stores the layer's light depth (sun: along its axis; lamp: distance from the lamp) plus a
// slope-scaled bias: how much the surface's depth changes across one texel (capped), so that
// points on or just in front of a surface that faces the light are not shadowed by it.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "scattering_params.h"

layout(std430, set = 0, binding = 0) readonly buffer LayerBuffer { ShadowLayer layers[]; };
layout(push_constant) uniform Push { ShadowPush push; };
layout(location = 0) in vec3 world;
layout(location = 0) out float stored_depth;

void main() {
  const ShadowLayer L = layers[push.layer.x];
  const float d = L.origin.w == float(kLayerSun) ? dot(world, L.axis.xyz) : length(world - L.origin.xyz);
  stored_depth = d + min(fwidth(d), L.bounds.z);
}
