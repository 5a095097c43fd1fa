// Pass 1 of the Vulkan scattering core: exact samples on the sparse grid (every g-th pixel and
// the last row / column), as pass 1 of render_scattering_cpu.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "scattering_common.glsl"

layout(local_size_x = kWorkgroupSize, local_size_y = kWorkgroupSize) in;

void main() {
  const ivec2 id = ivec2(gl_GlobalInvocationID.xy);
  if (id.x >= P.grid.z || id.y >= P.grid.w) return;
  const int i = P.grid.x + id.x, j = P.grid.y + id.y;
  const int x = min(i * P.image.z, P.image.x - 1), y = min(j * P.image.z, P.image.y - 1);
  PixelSample s = march(x, y, P.plan.x);
  s.ao = ambient_occlusion_at(x, y);
  const int k = kSampleVec4s * (id.y * P.grid.z + id.x);
  grid_samples[k] = vec4(s.inscatter, s.shaft);
  grid_samples[k + 1] = vec4(s.camera_od, s.ao);
  grid_samples[k + 2] = vec4(sun_disk_visibility(x, y), 0.0, 0.0, 0.0);
}
