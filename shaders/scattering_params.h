// The ONE definition of the parameter blocks that the Vulkan scattering backend
// (render/vulkan/) hands to its shaders: included by the C++ host code and by the GLSL shaders
// (the common subset of both languages; #ifdef __cplusplus below maps the GLSL types).
//
// Layout rule, so that std430 (GLSL storage buffers) and the C++ struct layout agree without
// any padding games: every member is 16 bytes (vec4 / ivec4 / uvec4) or a mat4 (four vec4
// columns), and arrays live in their own storage buffers (runtime arrays of these structs).
// tests/vulkan_layout_test.cpp checks the agreement at run time: a shader copies every member
// back and the test compares it with what the C++ side wrote.
#ifndef MR_SHADERS_SCATTERING_PARAMS_H
#define MR_SHADERS_SCATTERING_PARAMS_H

#ifdef __cplusplus
#include <cstdint>
namespace mr::render::gpu {
struct vec4 {
  float x = 0, y = 0, z = 0, w = 0;
};
struct ivec4 {
  std::int32_t x = 0, y = 0, z = 0, w = 0;
};
struct uvec4 {
  std::uint32_t x = 0, y = 0, z = 0, w = 0;
};
struct mat4 {
  vec4 col[4];  ///< column-major, as GLSL
};
#define MR_CONST inline constexpr int
#else
#define MR_CONST const int
#endif

// Compute workgroups are kTile x kTile invocations.
MR_CONST kWorkgroupSize = 8;

// Shaft edges (render/scattering_cpu.cpp, Core::march and render_scattering_cpu's pass 2; the
// CPU core uses these same constants):
// where the sun visibility changes between two march samples, this many bisection steps (single
// shadow queries) locate the crossing, so each segment gets its exact lit part;
MR_CONST kEdgeBisections = 6;
// pixels of a cell that a shadow edge crosses are marched with this many times the steps,
MR_CONST kShaftRefinement = 4;
// and their crossings bisected this many times: their samples are 4 = 2^2 times closer, so two
// fewer steps locate a crossing as precisely (in distance) as the preset's march does. On
// tests/scattering_scenes.h's forest (640x360, bench/bench_forest_shafts.cpp) 6 -> 4 took 16 %
// of the shadow rays and left R's error against a 512-step reference unchanged (the refined
// pixels' 0.3349 -> 0.3342 %: their error is the samples' noise, not the crossings').
MR_CONST kShaftRefinementBisections = kEdgeBisections - 2;

// ScatterParams.flags.x bits.
MR_CONST kFlagSun = 1;                  // a sun lights the scene
MR_CONST kFlagShadows = 2;              // occluder geometry exists (shadow maps, AO)
MR_CONST kFlagLightPathAttenuation = 4; // fog dims light on its way in
MR_CONST kFlagNoise = 8;                // noise modulates the view ray's density
MR_CONST kFlagConstantSource = 16;      // sky light only: every pixel in closed form
MR_CONST kFlagNeedsAo = 32;             // ambient occlusion at exact samples
MR_CONST kFlagNormals = 64;             // the normals buffer is valid
MR_CONST kFlagPhotoFallback = 128;      // write each pixel's "sun seen" T and AO (binding 12)

// ShadowLayer.origin.w: how a shadow-map layer measures depth.
MR_CONST kLayerSun = 0;   // orthographic: depth = dot(x, axis.xyz) (axis = -direction to sun)
MR_CONST kLayerLamp = 1;  // one cube face of a lamp: depth = |x - origin.xyz|

// Per-pixel sample of the sparse grid pass, 3 x vec4: (R.rgb, shaft), (camera od.rgb, ao),
// (sun-disk visibility at the surface or -1, 0, 0, 0).
MR_CONST kSampleVec4s = 3;

struct ScatterParams {
  vec4 origin;    // camera position (xyz, metres)
  vec4 right;     // camera axes in the world (xyz): image +x
  vec4 up;        // image -y
  vec4 forward;   // view axis
  vec4 camera;    // focal_px, cx, cy, 0
  ivec4 image;    // full image width, height; grid step g; number of lamps
  ivec4 region;   // the depth/normals buffers cover pixels [x, x + z) x [y, y + w)
  ivec4 tile;     // this dispatch writes pixels [x, x + z) x [y, y + w)
  ivec4 grid;     // grid buffer: first global grid column i0, row j0; its width, height
  ivec4 grid_count;  // global grid columns, rows; number of sun cascades; 0
  ivec4 plan;     // march steps, lamp steps, sun rays at surfaces, AO rays
  uvec4 flags;    // kFlag* bits; render seed; noise seed; noise octaves
  vec4 sigma;     // extinction at density 1 (rgb, 1/m); w = mean of rgb
  vec4 albedo;    // single-scattering albedo (rgb); w = Henyey-Greenstein g
  vec4 sky;       // sky radiance (rgb); w = min of sigma rgb
  vec4 layer;     // layer bottom, top (clamped to +-1e30), height-fog base, scale (0: none)
  vec4 noise;     // amplitude, 1 / scale_m, 0, 0
  vec4 sun_dir;   // unit direction to the sun (xyz); w = tan(angular radius)
  vec4 sun_u;     // frame around the sun direction (xyz)
  vec4 sun_v;
  vec4 sun_irradiance;  // rgb
  vec4 misc;      // max_distance_m (0: automatic), shadow-map size (texels), AO rays where the
                  // plan's AO rays disagree (MarchPlan::ao_partial_rays), 0
  vec4 cascade_end;  // view distance where sun cascades 0..3 end (the last: +inf)
};

struct GpuLamp {
  vec4 position;   // xyz; w = first of its 6 shadow-map layers, -1: none
  vec4 intensity;  // rgb, per steradian
  vec4 spot;       // unit cone axis (xyz); w = 1 for a spot, 0 for a point lamp
  vec4 cone;       // cos(inner), cos(outer), 0, 0
};

struct ShadowLayer {
  mat4 view_proj;  // world -> clip (Vulkan: y down, depth 0..1)
  vec4 origin;     // lamp position (xyz); w = kLayerSun or kLayerLamp
  vec4 axis;       // sun: depth axis (xyz); lamp face: its forward axis. w = texel size
                   // (sun: metres; lamp: metres per metre of distance)
  vec4 bounds;     // near, far of the rasterized depth range; max slope bias (m); 0
  vec4 pad;
};

// Push constants of the shadow-map pipeline.
struct ShadowPush {
  ivec4 layer;  // x = layer index
};

#ifdef __cplusplus
}  // namespace mr::render::gpu
#endif

#endif  // MR_SHADERS_SCATTERING_PARAMS_H
