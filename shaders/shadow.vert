// Shadow maps: the occluder mesh rasterized into one layer of the shadow atlas (a cascade of
// the sun's orthographic maps or one cube face of a lamp).
#version 450
#extension GL_GOOGLE_include_directive : require
#include "scattering_params.h"

layout(std430, set = 0, binding = 0) readonly buffer LayerBuffer { ShadowLayer layers[]; };
layout(push_constant) uniform Push { ShadowPush push; };
layout(location = 0) in vec3 position;
layout(location = 0) out vec3 world;

void main() {
  world = position;
  gl_Position = layers[push.layer.x].view_proj * vec4(position, 1.0);
}
