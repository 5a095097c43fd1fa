#include "render/vulkan/vulkan_backend.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <mutex>
#include <optional>
#include <vector>

#include "render/math.h"
#include "render/photo_fallback.h"
#include "render/vulkan/context.h"
#include "shaders/scattering_params.h"

namespace mr::render::vulkan {

namespace {

// SPIR-V compiled by glslc at build time (shaders/CMakeLists.txt).
const std::uint32_t kGridSpv[] =
#include "grid.comp.inc"
    ;
const std::uint32_t kResolveSpv[] =
#include "resolve.comp.inc"
    ;
const std::uint32_t kShadowVertSpv[] =
#include "shadow.vert.inc"
    ;
const std::uint32_t kShadowFragSpv[] =
#include "shadow.frag.inc"
    ;
const std::uint32_t kLayoutCheckSpv[] =
#include "layout_check.comp.inc"
    ;

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

constexpr int kComputeBindings = 13;  // 0..10 and 12 storage buffers, 11 the shadow atlas
constexpr int kMaxLamps = 16;         // shaders/scattering_common.glsl kMaxLamps
constexpr float kFar = 3.0e38f;       // cleared shadow-map texels: nothing there
// Shadow maps store each texel's surface depth plus its change across the texel, capped at this
// many texels' worth: enough against self-shadowing of points just in front of lit surfaces
// (surfaces themselves are looked up 1.5 texels off along their normal), small enough not to
// lift the shadow off points just behind an occluder (a cap of 10 texels lit 15 % of some rays
// that the CPU shades, in the half-plane test).
constexpr double kSlopeBiasTexels = 0.5;

using V3 = Vec3d;  // render/math.h
gpu::vec4 v4(const V3& v, double w = 0) { return {float(v[0]), float(v[1]), float(v[2]), float(w)}; }
gpu::vec4 v4(const Rgb& v, double w = 0) { return {v[0], v[1], v[2], float(w)}; }

// A matrix from its rows (r[i] = (a, b, c, d): clip_i = a x + b y + c z + d).
gpu::mat4 from_rows(const std::array<std::array<double, 4>, 4>& r) {
  gpu::mat4 m;
  for (int c = 0; c < 4; ++c) m.col[c] = {float(r[0][c]), float(r[1][c]), float(r[2][c]), float(r[3][c])};
  return m;
}

int grid_count(int n, int g) { return (n - 1) / g + 1 + ((n - 1) % g != 0 ? 1 : 0); }

VkShaderModule make_module(const Context& ctx, const std::uint32_t* code, std::size_t bytes) {
  VkShaderModuleCreateInfo ci = make<VkShaderModuleCreateInfo>(VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO);
  ci.codeSize = bytes;
  ci.pCode = code;
  VkShaderModule m = VK_NULL_HANDLE;
  check(ctx.vk.vkCreateShaderModule(ctx.device, &ci, nullptr, &m), "vkCreateShaderModule");
  return m;
}

template <class T>
Unique<T> own(const Context& ctx, T handle, typename Unique<T>::Deleter d) {
  return Unique<T>(ctx, handle, d);
}

void destroy_module(const Context& c, VkShaderModule h) { c.vk.vkDestroyShaderModule(c.device, h, nullptr); }
void destroy_set_layout(const Context& c, VkDescriptorSetLayout h) {
  c.vk.vkDestroyDescriptorSetLayout(c.device, h, nullptr);
}
void destroy_pipeline_layout(const Context& c, VkPipelineLayout h) {
  c.vk.vkDestroyPipelineLayout(c.device, h, nullptr);
}
void destroy_pipeline(const Context& c, VkPipeline h) { c.vk.vkDestroyPipeline(c.device, h, nullptr); }
void destroy_sampler(const Context& c, VkSampler h) { c.vk.vkDestroySampler(c.device, h, nullptr); }
void destroy_pool(const Context& c, VkCommandPool h) { c.vk.vkDestroyCommandPool(c.device, h, nullptr); }
void destroy_fence(const Context& c, VkFence h) { c.vk.vkDestroyFence(c.device, h, nullptr); }
void destroy_descriptor_pool(const Context& c, VkDescriptorPool h) {
  c.vk.vkDestroyDescriptorPool(c.device, h, nullptr);
}
void destroy_query_pool(const Context& c, VkQueryPool h) { c.vk.vkDestroyQueryPool(c.device, h, nullptr); }

Unique<VkDescriptorSetLayout> make_set_layout(const Context& ctx,
                                              const std::vector<VkDescriptorSetLayoutBinding>& b) {
  VkDescriptorSetLayoutCreateInfo ci = make<VkDescriptorSetLayoutCreateInfo>(VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO);
  ci.bindingCount = std::uint32_t(b.size());
  ci.pBindings = b.data();
  VkDescriptorSetLayout h = VK_NULL_HANDLE;
  check(ctx.vk.vkCreateDescriptorSetLayout(ctx.device, &ci, nullptr, &h), "vkCreateDescriptorSetLayout");
  return own(ctx, h, destroy_set_layout);
}

Unique<VkPipelineLayout> make_pipeline_layout(const Context& ctx, VkDescriptorSetLayout set,
                                              const VkPushConstantRange* push) {
  VkPipelineLayoutCreateInfo ci = make<VkPipelineLayoutCreateInfo>(VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO);
  ci.setLayoutCount = 1;
  ci.pSetLayouts = &set;
  ci.pushConstantRangeCount = push ? 1 : 0;
  ci.pPushConstantRanges = push;
  VkPipelineLayout h = VK_NULL_HANDLE;
  check(ctx.vk.vkCreatePipelineLayout(ctx.device, &ci, nullptr, &h), "vkCreatePipelineLayout");
  return own(ctx, h, destroy_pipeline_layout);
}

Unique<VkPipeline> make_compute_pipeline(const Context& ctx, VkPipelineLayout layout,
                                         const std::uint32_t* code, std::size_t bytes) {
  const auto module = own(ctx, make_module(ctx, code, bytes), destroy_module);
  VkComputePipelineCreateInfo ci = make<VkComputePipelineCreateInfo>(VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO);
  ci.stage = make<VkPipelineShaderStageCreateInfo>(VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO);
  ci.stage.stage = VK_SHADER_STAGE_COMPUTE_BIT;
  ci.stage.module = module.get();
  ci.stage.pName = "main";
  ci.layout = layout;
  VkPipeline h = VK_NULL_HANDLE;
  check(ctx.vk.vkCreateComputePipelines(ctx.device, VK_NULL_HANDLE, 1, &ci, nullptr, &h),
        "vkCreateComputePipelines");
  return own(ctx, h, destroy_pipeline);
}

void memory_barrier(const Context& ctx, VkCommandBuffer cmd, VkPipelineStageFlags src_stage,
                    VkAccessFlags src, VkPipelineStageFlags dst_stage, VkAccessFlags dst) {
  VkMemoryBarrier m = make<VkMemoryBarrier>(VK_STRUCTURE_TYPE_MEMORY_BARRIER);
  m.srcAccessMask = src;
  m.dstAccessMask = dst;
  ctx.vk.vkCmdPipelineBarrier(cmd, src_stage, dst_stage, 0, 1, &m, 0, nullptr, 0, nullptr);
}

void image_barrier(const Context& ctx, VkCommandBuffer cmd, VkImage image, VkImageAspectFlags aspect,
                   std::uint32_t layers, VkImageLayout from, VkImageLayout to,
                   VkPipelineStageFlags src_stage, VkAccessFlags src, VkPipelineStageFlags dst_stage,
                   VkAccessFlags dst) {
  VkImageMemoryBarrier m = make<VkImageMemoryBarrier>(VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER);
  m.srcAccessMask = src;
  m.dstAccessMask = dst;
  m.oldLayout = from;
  m.newLayout = to;
  m.srcQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  m.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  m.image = image;
  m.subresourceRange = {aspect, 0, 1, 0, layers};
  ctx.vk.vkCmdPipelineBarrier(cmd, src_stage, dst_stage, 0, 0, nullptr, 0, nullptr, 1, &m);
}

// Light-space frame of the sun: x, y across the rays, z = depth away from the sun.
struct SunFrame {
  V3 x, y, z;
};

struct Bounds3 {
  double lo[3] = {std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity(),
                  std::numeric_limits<double>::infinity()};
  double hi[3] = {-std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity(),
                  -std::numeric_limits<double>::infinity()};
  void add(const V3& p) {
    for (int i = 0; i < 3; ++i) {
      lo[i] = std::min(lo[i], p[i]);
      hi[i] = std::max(hi[i], p[i]);
    }
  }
  bool empty() const { return !(hi[0] >= lo[0]); }
};

// ---- the stages of a render ---------------------------------------------------------------------
// Backend::Impl::render runs them in order: pack_parameters (the scene into ScatterParams),
// plan_shadow_maps (sun cascades and lamp cube faces), plan_tiles (what fits the device's
// storage-buffer range), FrameResources (buffers, the shadow atlas, descriptor sets),
// render_shadow_maps (upload the scene, rasterize the mesh), then per tile upload_tile,
// dispatch_tile and read_back_tile, then the photo fallback and the timestamps.

// The frame's parameters and the switches every stage reads.
struct FramePlan {
  MarchPlan plan;
  int W = 0, H = 0;
  int g = 1;           // grid step
  int ngx = 0, ngy = 0;  // grid samples across and down
  bool sun = false, lights = false, shadows = false, normals = false, photo_fallback = false;
  gpu::ScatterParams p{};
  SunFrame frame{};
};

// Shadow maps: one layer per sun cascade and six per lamp, all `size` texels a side.
struct ShadowPlan {
  int size = 0;
  int n_cascades = 0;
  std::vector<gpu::ShadowLayer> layers;
  std::vector<gpu::GpuLamp> lamps;
  int n_layers() const { return int(layers.size()); }
};

// The image in tiles of tw x th pixels, each with the depth / normals region around it.
struct TileLayout {
  int tw = 0, th = 0, halo = 0;
  std::size_t region_max = 0, tile_max = 0, grid_max = 0;
  int tiles_x = 0, tiles_y = 0;
  int count() const { return tiles_x * tiles_y; }
};

// One tile's pixels [x0, x1) x [y0, y1), its depth region and its grid samples.
struct Tile {
  int index = 0;
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  int rx0 = 0, ry0 = 0, rx1 = 0, ry1 = 0;
  int i0 = 0, i1 = 0, j0 = 0, j1 = 0;
  gpu::ScatterParams tp{};
};

// A pixel the shadow maps shade, kept for the photo fallback: T with the sun seen, and its AO.
struct Shaded {
  int x, y;
  std::array<float, 3> t_sun_seen;
  float ao;
};

FramePlan pack_parameters(const CoreInputs& in, const TriangleMesh* mesh) {
  const FogScene& scene = *in.scene;
  const Camera& cam = *in.camera;
  const Medium& medium = scene.medium;
  const Lighting& lighting = scene.lighting;
  FramePlan f;
  f.plan = march_plan(scene.render);
  f.W = in.distance_m.width;
  f.H = in.distance_m.height;
  if (lighting.lamps.size() > std::size_t(kMaxLamps))
    throw Unavailable("the Vulkan backend renders at most " + std::to_string(kMaxLamps) + " lamps, the scene has " +
                      std::to_string(lighting.lamps.size()));
  f.sun = lighting.sun.has_value();
  f.lights = f.sun || !lighting.lamps.empty();
  const bool constant_source = !f.lights && medium.noise.amplitude <= 0;
  f.g = constant_source ? 1 : std::max(1, f.plan.grid_step);
  f.shadows = mesh && mesh->triangle_count() > 0 && scene.render.volumetric_shadows && f.lights;
  f.normals = in.normals.data != nullptr;
  // The surface term's photo fallback (render/photo_fallback.h, as on the CPU): the shaders
  // write each pixel's T with the sun seen, the host decides where the photo shows it.
  f.photo_fallback = PhotoFallback::wanted(scene, in.distance_m, in.normals, in.photo, f.shadows);

  gpu::ScatterParams& p = f.p;
  const auto [forward, right, up] = scene.pose.axes();
  const V3 origin = vec(scene.pose.position_m);
  p.origin = v4(origin);
  p.right = v4(vec(right));
  p.up = v4(vec(up));
  p.forward = v4(vec(forward));
  p.camera = {float(cam.focal_px), float(cam.cx), float(cam.cy), 0};
  f.ngx = grid_count(f.W, f.g);
  f.ngy = grid_count(f.H, f.g);
  std::uint32_t flags = 0;
  if (f.sun) flags |= gpu::kFlagSun;
  if (f.shadows) flags |= gpu::kFlagShadows | gpu::kFlagNeedsAo;
  if (scene.render.light_path_attenuation) flags |= gpu::kFlagLightPathAttenuation;
  if (medium.noise.amplitude > 0) flags |= gpu::kFlagNoise;
  if (constant_source) flags |= gpu::kFlagConstantSource;
  if (f.normals) flags |= gpu::kFlagNormals;
  if (f.photo_fallback) flags |= gpu::kFlagPhotoFallback;
  p.image = {f.W, f.H, f.g, int(lighting.lamps.size())};
  p.plan = {f.plan.steps, f.plan.lamp_steps, f.plan.sun_surface_rays, f.plan.ao_rays};
  p.flags = {flags, scene.render.seed, medium.noise.seed, std::uint32_t(std::max(0, medium.noise.octaves))};
  const Rgb& s = medium.sigma_t_per_m;
  p.sigma = v4(s, (double(s[0]) + s[1] + s[2]) / 3.0);
  p.albedo = v4(medium.albedo, medium.g);
  p.sky = v4(in.sky_radiance, std::min({s[0], s[1], s[2]}));
  auto clamp_height = [](double h) { return float(std::clamp(h, -1e30, 1e30)); };
  p.layer = {clamp_height(medium.layer_bottom_m), clamp_height(medium.layer_top_m),
             medium.height_fog ? float(medium.height_fog->base_height_m) : 0.0f,
             medium.height_fog ? float(medium.height_fog->scale_height_m) : 0.0f};
  p.noise = {float(medium.noise.amplitude), float(1.0 / medium.noise.scale_m), 0, 0};
  if (f.sun) {
    const V3 l = normalized(vec(lighting.sun->direction_to_sun));
    const V3 helper = std::fabs(l[1]) < 0.9 ? V3{0, 1, 0} : V3{1, 0, 0};
    const V3 u = normalized(cross(helper, l));
    const V3 v = cross(l, u);
    p.sun_dir = v4(l, std::tan(lighting.sun->angular_radius_deg * 3.14159265358979323846 / 180.0));
    p.sun_u = v4(u);
    p.sun_v = v4(v);
    p.sun_irradiance = v4(lighting.sun->irradiance, 1);
    f.frame = {u, v, {-l[0], -l[1], -l[2]}};
  }
  p.misc.x = float(scene.render.max_distance_m);
  p.misc.z = float(f.plan.ao_partial_rays);
  return f;
}

// Sun cascades fitted to slices of the view frustum and lamp cube faces, around the mesh; writes
// the cascade ends, the grid counts and the map size into f.p, and the lamps' first layers.
ShadowPlan plan_shadow_maps(const CoreInputs& in, const TriangleMesh* mesh, const BackendOptions& opt,
                            std::uint32_t max_image_dimension, FramePlan& f) {
  const FogScene& scene = *in.scene;
  const Camera& cam = *in.camera;
  const Lighting& lighting = scene.lighting;
  const int W = f.W, H = f.H;
  gpu::ScatterParams& p = f.p;
  const SunFrame& frame = f.frame;
  const V3 origin = vec(scene.pose.position_m);
  ShadowPlan s;
  int size = opt.shadow_map_size;
  if (size <= 0) {
    int side = 1;
    while (side < std::max(W, H)) side *= 2;
    // Texels per image pixel: 1 (draft), 2 (normal), 4 (final); 1024..4096 texels a side.
    const int scale = scene.render.quality == Quality::draft ? 1 : scene.render.quality == Quality::final ? 4 : 2;
    size = std::clamp(side * scale, 1024, 4096);
  }
  size = std::min<int>(size, int(max_image_dimension));
  s.size = size;
  std::vector<gpu::ShadowLayer>& layers = s.layers;
  int n_cascades = 0;
  if (f.shadows) {
    const std::size_t nv = mesh->vertex_count();
    const float* pos = mesh->positions.data();
    if (f.sun) {
      // The mesh in light space; cascades by view distance, each an orthographic map fitted to
      // its slice of the view frustum (within the mesh's extent), depth covering the whole mesh.
      Bounds3 mb;
      for (std::size_t i = 0; i < nv; ++i) {
        const V3 q{pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]};
        mb.add({dot(q, frame.x), dot(q, frame.y), dot(q, frame.z)});
      }
      double d_near = std::numeric_limits<double>::infinity(), d_far = 0;
      for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
          const double d = in.distance_m.at(x, y, 0);
          if (std::isfinite(d) && d > 0) {
            d_near = std::min(d_near, d);
            d_far = std::max(d_far, d);
          }
        }
      d_near = std::max(0.05, std::min(d_near, d_far));
      n_cascades = d_far > 0 ? std::clamp(int(std::ceil(std::log(d_far / d_near) / std::log(4.0))), 1, 4) : 1;
      std::vector<double> ends(std::size_t(n_cascades) + 1, 0.0);
      for (int c = 1; c <= n_cascades; ++c) {
        const double fr = double(c) / n_cascades;
        const double logarithmic = d_near * std::pow(d_far / d_near, fr);
        const double uniform = d_near + (d_far - d_near) * fr;
        ends[std::size_t(c)] = 0.8 * logarithmic + 0.2 * uniform;
      }
      const double z_pad = 0.01 * (mb.hi[2] - mb.lo[2]) + 0.01;
      const double z_lo = mb.lo[2] - z_pad, z_hi = mb.hi[2] + z_pad;
      for (int c = 0; c < n_cascades; ++c) {
        Bounds3 fb;
        const bool last = c + 1 == n_cascades;
        if (last) {
          fb = mb;  // the last cascade holds all of the mesh: every point beyond is covered
        } else {
          for (double t : {ends[std::size_t(c)], ends[std::size_t(c) + 1]})
            for (int j = 0; j <= 8; ++j)
              for (int i = 0; i <= 8; ++i) {
                const Vec3 w = scene.pose.ray_direction(cam, W * i / 8.0 - 0.5, H * j / 8.0 - 0.5);
                const V3 q{origin[0] + t * w.x, origin[1] + t * w.y, origin[2] + t * w.z};
                fb.add({dot(q, frame.x), dot(q, frame.y), 0});
              }
          for (int k = 0; k < 2; ++k) {  // within the mesh's extent
            fb.lo[k] = std::max(fb.lo[k], mb.lo[k]);
            fb.hi[k] = std::min(fb.hi[k], mb.hi[k]);
          }
          if (!(fb.hi[0] > fb.lo[0] && fb.hi[1] > fb.lo[1])) fb = mb;
        }
        double extent = std::max(fb.hi[0] - fb.lo[0], fb.hi[1] - fb.lo[1]);
        extent = extent * 1.05 + 1e-3;
        const double cx = 0.5 * (fb.lo[0] + fb.hi[0]), cy = 0.5 * (fb.lo[1] + fb.hi[1]);
        const double k = 2.0 / extent, kz = 1.0 / (z_hi - z_lo);
        gpu::ShadowLayer L{};
        L.view_proj = from_rows({{{k * frame.x[0], k * frame.x[1], k * frame.x[2], -k * cx},
                                  {k * frame.y[0], k * frame.y[1], k * frame.y[2], -k * cy},
                                  {kz * frame.z[0], kz * frame.z[1], kz * frame.z[2], -kz * z_lo},
                                  {0, 0, 0, 1}}});
        const double texel = extent / size;
        L.origin = {0, 0, 0, float(gpu::kLayerSun)};
        L.axis = v4(frame.z, texel);
        L.bounds = {float(z_lo), float(z_hi), float(kSlopeBiasTexels * texel), 0};
        layers.push_back(L);
        const float end = last ? 3e38f : float(ends[std::size_t(c) + 1]);
        switch (c) {
          case 0: p.cascade_end.x = end; break;
          case 1: p.cascade_end.y = end; break;
          case 2: p.cascade_end.z = end; break;
          default: p.cascade_end.w = end; break;
        }
      }
    }
    // Lamps: six cube faces each, perspective from the lamp, storing the distance from it.
    Bounds3 wb;
    for (std::size_t i = 0; i < nv; ++i) wb.add({pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]});
    for (const Lamp& lamp : lighting.lamps) {
      const V3 lp = vec(lamp.position_m);
      double far = 0;
      for (int corner = 0; corner < 8; ++corner) {
        const V3 q{corner & 1 ? wb.hi[0] : wb.lo[0], corner & 2 ? wb.hi[1] : wb.lo[1], corner & 4 ? wb.hi[2] : wb.lo[2]};
        const V3 d{q[0] - lp[0], q[1] - lp[1], q[2] - lp[2]};
        far = std::max(far, std::sqrt(dot(d, d)));
      }
      far = far * 1.01 + 1.0;
      const double near = 0.01;
      const double a = far / (far - near), b = -far * near / (far - near);
      for (int face = 0; face < 6; ++face) {
        V3 F{0, 0, 0};
        F[std::size_t(face / 2)] = face % 2 ? -1.0 : 1.0;
        const V3 U = std::fabs(F[1]) > 0.5 ? V3{0, 0, 1} : V3{0, 1, 0};
        const V3 R = cross(U, F);
        gpu::ShadowLayer L{};
        L.view_proj = from_rows({{{R[0], R[1], R[2], -dot(R, lp)},
                                  {U[0], U[1], U[2], -dot(U, lp)},
                                  {a * F[0], a * F[1], a * F[2], -a * dot(F, lp) + b},
                                  {F[0], F[1], F[2], -dot(F, lp)}}});
        L.origin = v4(lp, gpu::kLayerLamp);
        L.axis = v4(F, 2.0 / size);
        L.bounds = {float(near), float(far), float(kSlopeBiasTexels * far * 2.0 / size), 0};
        layers.push_back(L);
      }
    }
  }
  s.n_cascades = n_cascades;
  p.grid_count = {f.ngx, f.ngy, n_cascades, 0};
  p.misc.y = float(size);
  {
    std::size_t first = std::size_t(n_cascades);
    for (const Lamp& lamp : lighting.lamps) {
      gpu::GpuLamp gl{};
      gl.position = v4(vec(lamp.position_m), f.shadows ? double(first) : -1.0);
      first += 6;
      gl.intensity = v4(lamp.intensity_per_sr);
      const bool spot = lamp.outer_angle_deg < 180.0;
      gl.spot = v4(normalized(vec(lamp.spot_direction)), spot ? 1.0 : 0.0);
      gl.cone = {float(std::cos(lamp.inner_angle_deg * 3.14159265358979323846 / 180.0)),
                 float(std::cos(lamp.outer_angle_deg * 3.14159265358979323846 / 180.0)), 0, 0};
      s.lamps.push_back(gl);
    }
  }
  return s;
}

// Tiles as large as the request, the cancel token and the storage-buffer range allow.
TileLayout plan_tiles(const CoreInputs& in, const FramePlan& f, const BackendOptions& opt, std::size_t range) {
  const int W = f.W, H = f.H, g = f.g;
  TileLayout t;
  // A cancellable render is split into tiles of at most kCancellableTilePixels (the same result,
  // tile by tile) so that a request waits for at most one small dispatch.
  constexpr std::size_t kCancellableTilePixels = std::size_t(1) << 16;
  const std::size_t wanted_tile = opt.max_tile_pixels ? opt.max_tile_pixels
                                  : in.cancel         ? kCancellableTilePixels
                                                      : std::size_t(-1);
  std::size_t tile_limit =
      std::min<std::size_t>(wanted_tile, range / (4 * sizeof(float) * gpu::kSampleVec4s));
  tile_limit = std::max<std::size_t>(tile_limit, 1);
  int tw = W, th = H;
  while (std::size_t(tw) * std::size_t(th) > tile_limit) {
    if (tw >= th) tw = (tw + 1) / 2;
    else th = (th + 1) / 2;
  }
  // The depth / normals region around a tile: the grid's halo, and as far as AO rays reach in
  // the image (a ray of length d / 4 from a point at distance d spans at most f / 3 pixels).
  int halo = 2 * g + 2;
  if (f.shadows && f.plan.ao_rays > 0) halo = std::max(halo, int(std::ceil(in.camera->focal_px / 3.0)) + 2);
  auto region_pixels = [&](int h) {
    return std::size_t(std::min(W, tw + 2 * h)) * std::size_t(std::min(H, th + 2 * h));
  };
  while (halo > 2 * g + 2 && region_pixels(halo) * 3 * sizeof(float) > range) halo = std::max(2 * g + 2, halo / 2);
  t.tw = tw;
  t.th = th;
  t.halo = halo;
  t.region_max = region_pixels(halo);
  t.tile_max = std::size_t(tw) * std::size_t(th);
  t.grid_max = std::size_t(std::min(f.ngx, (tw + g - 1) / g + 5)) * std::size_t(std::min(f.ngy, (th + g - 1) / g + 5));
  if (t.region_max * 3 * sizeof(float) > range || t.tile_max * 3 * sizeof(float) > range)
    throw Unavailable("tile of " + std::to_string(tw) + "x" + std::to_string(th) +
                      " does not fit the device's storage-buffer range");
  t.tiles_x = (W + tw - 1) / tw;
  t.tiles_y = (H + th - 1) / th;
  return t;
}

// Tile (tx, ty): its pixels, depth region, grid samples and parameters.
Tile make_tile(const FramePlan& f, const TileLayout& layout, int tx, int ty, int index) {
  const int W = f.W, H = f.H, g = f.g;
  Tile t;
  t.index = index;
  t.x0 = tx * layout.tw;
  t.y0 = ty * layout.th;
  t.x1 = std::min(W, t.x0 + layout.tw);
  t.y1 = std::min(H, t.y0 + layout.th);
  t.rx0 = std::max(0, t.x0 - layout.halo);
  t.ry0 = std::max(0, t.y0 - layout.halo);
  t.rx1 = std::min(W, t.x1 + layout.halo);
  t.ry1 = std::min(H, t.y1 + layout.halo);
  // Grid samples the tile's pixels need: their cells' corners and those corners' neighbours.
  auto cell = [&](int v, int n_grid) { return std::max(0, std::min(v / g, n_grid - 2)); };
  t.i0 = std::max(0, cell(t.x0, f.ngx) - 1);
  t.i1 = std::min(f.ngx - 1, cell(t.x1 - 1, f.ngx) + 2);
  t.j0 = std::max(0, cell(t.y0, f.ngy) - 1);
  t.j1 = std::min(f.ngy - 1, cell(t.y1 - 1, f.ngy) + 2);
  t.tp = f.p;
  t.tp.region = {t.rx0, t.ry0, t.rx1 - t.rx0, t.ry1 - t.ry0};
  t.tp.tile = {t.x0, t.y0, t.x1 - t.x0, t.y1 - t.y0};
  t.tp.grid = {t.i0, t.j0, t.i1 - t.i0 + 1, t.j1 - t.j0 + 1};
  if (std::size_t(t.tp.grid.z) * std::size_t(t.tp.grid.w) > layout.grid_max)
    throw Error(ErrorCode::internal, "vulkan: grid buffer too small for a tile");
  return t;
}

// Grid samples inside the tile count as exact pixels (as on the CPU).
std::size_t grid_samples_in_tile(const FramePlan& f, const Tile& t) {
  std::size_t n = 0;
  for (int i = t.i0; i <= t.i1; ++i) {
    const int gxv = std::min(i * f.g, f.W - 1);
    if (gxv < t.x0 || gxv >= t.x1) continue;
    for (int j = t.j0; j <= t.j1; ++j) {
      const int gyv = std::min(j * f.g, f.H - 1);
      if (gyv >= t.y0 && gyv < t.y1) ++n;
    }
  }
  return n;
}

// After every tile (a pixel's neighbours may lie in another one): where the photo shows a
// shadow-mapped pixel as sunlit, its T with the sun seen. The same test as the CPU core's pass
// 3, on the sun visibility before any fallback.
void apply_photo_fallback(const CoreInputs& in, const std::vector<Shaded>& shaded, CoreOutputs& out) {
  const PhotoFallback fallback(*in.camera, *in.scene, in.distance_m, in.normals, in.photo, in.sky_radiance);
  const std::vector<float> disk = fallback.sun_disk_map(out.sun_visibility);
  const std::size_t W = std::size_t(in.distance_m.width);
  std::vector<unsigned char> sunlit(shaded.size(), 0);
  tbb::parallel_for(std::size_t(0), shaded.size(), [&](std::size_t k) {
    const Shaded& p = shaded[k];
    const float d = disk[std::size_t(p.y) * W + std::size_t(p.x)];
    sunlit[k] = d >= 0 && d < 1 && fallback.shows_sunlit(p.x, p.y, p.ao, disk.data());
  });
  for (std::size_t k = 0; k < shaded.size(); ++k) {
    if (!sunlit[k]) continue;
    const Shaded& p = shaded[k];
    for (int c = 0; c < 3; ++c) out.transmittance.at(p.x, p.y, c) = p.t_sun_seen[std::size_t(c)];
    out.sun_visibility.at(p.x, p.y, 0) = 1.0f;
  }
}

// The frame's device resources: parameter, scene and per-tile buffers, staging memory both ways,
// the shadow atlas, timestamp queries and the two descriptor sets. Freed (RAII) when the render
// returns or throws; the device is idle then (every submission is waited for).
struct FrameResources {
  const Context& ctx;
  Buffer params_buf, lamps_buf, layers_buf, depth_buf, normals_buf, grid_buf;
  Buffer t_buf, r_buf, v_buf, od_buf, counters_buf, sunlit_buf;
  Buffer vertex_buf, index_buf;
  Buffer staging_up, down;
  Image2D atlas;
  std::optional<Image2D> depth_attachment;
  // Timestamps: 3 for the scene, 4 per tile.
  bool timed = false;
  std::uint32_t n_queries = 0;
  Unique<VkQueryPool> queries;
  Unique<VkDescriptorPool> descriptor_pool;
  VkDescriptorSet sets[2] = {VK_NULL_HANDLE, VK_NULL_HANDLE};  // compute, shadow maps

  FrameResources(const Context& context, VkDescriptorSetLayout compute_set, VkDescriptorSetLayout shadow_set,
                 VkSampler sampler, const FramePlan& f, const ShadowPlan& s, const TileLayout& tiles,
                 const TriangleMesh* mesh)
      : ctx(context) {
    const VkBufferUsageFlags storage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT;
    const VkBufferUsageFlags readback = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_SRC_BIT |
                                        VK_BUFFER_USAGE_TRANSFER_DST_BIT;
    const int n_layers = s.n_layers();
    params_buf = Buffer(ctx, sizeof(gpu::ScatterParams), storage, false);
    lamps_buf = Buffer(ctx, std::max<std::size_t>(1, s.lamps.size()) * sizeof(gpu::GpuLamp), storage, false);
    layers_buf = Buffer(ctx, std::max(1, n_layers) * sizeof(gpu::ShadowLayer), storage, false);
    depth_buf = Buffer(ctx, tiles.region_max * sizeof(float), storage, false);
    normals_buf = Buffer(ctx, f.normals ? tiles.region_max * 3 * sizeof(float) : 16, storage, false);
    grid_buf = Buffer(ctx, tiles.grid_max * gpu::kSampleVec4s * 4 * sizeof(float), VK_BUFFER_USAGE_STORAGE_BUFFER_BIT,
                      false);
    t_buf = Buffer(ctx, tiles.tile_max * 3 * sizeof(float), readback, false);
    r_buf = Buffer(ctx, tiles.tile_max * 3 * sizeof(float), readback, false);
    v_buf = Buffer(ctx, tiles.tile_max * sizeof(float), readback, false);
    od_buf = Buffer(ctx, tiles.tile_max * 3 * sizeof(float), readback, false);
    counters_buf = Buffer(ctx, 4 * sizeof(std::uint32_t), readback, false);
    sunlit_buf = Buffer(ctx, f.photo_fallback ? tiles.tile_max * 4 * sizeof(float) : 16, readback, false);
    std::size_t mesh_bytes = 0;
    if (f.shadows) {
      vertex_buf = Buffer(ctx, mesh->vertex_count() * 3 * sizeof(float),
                          VK_BUFFER_USAGE_VERTEX_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT, false);
      index_buf = Buffer(ctx, mesh->indices.size() * sizeof(std::uint32_t),
                         VK_BUFFER_USAGE_INDEX_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT, false);
      mesh_bytes = vertex_buf.size + index_buf.size;
    }
    const std::size_t scene_bytes = lamps_buf.size + layers_buf.size + mesh_bytes;
    const std::size_t tile_up_bytes = sizeof(gpu::ScatterParams) + depth_buf.size + normals_buf.size;
    staging_up = Buffer(ctx, std::max(scene_bytes, tile_up_bytes), VK_BUFFER_USAGE_TRANSFER_SRC_BIT, true);
    const std::size_t down_bytes =
        t_buf.size + r_buf.size + v_buf.size + od_buf.size + counters_buf.size + sunlit_buf.size;
    down = Buffer(ctx, down_bytes, VK_BUFFER_USAGE_TRANSFER_DST_BIT, true);
    const std::uint32_t atlas_side = n_layers > 0 ? std::uint32_t(s.size) : 1u;
    atlas = Image2D(ctx, VK_FORMAT_R32_SFLOAT, atlas_side, atlas_side, std::uint32_t(std::max(1, n_layers)),
                    VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT | VK_IMAGE_USAGE_SAMPLED_BIT, VK_IMAGE_ASPECT_COLOR_BIT);
    if (n_layers > 0)
      depth_attachment.emplace(ctx, VK_FORMAT_D32_SFLOAT, atlas_side, atlas_side, 1,
                               VK_IMAGE_USAGE_DEPTH_STENCIL_ATTACHMENT_BIT, VK_IMAGE_ASPECT_DEPTH_BIT);

    timed = ctx.timestamp_valid_bits > 0;
    n_queries = 3 + 4 * std::uint32_t(tiles.count());
    if (timed) {
      VkQueryPoolCreateInfo qci = make<VkQueryPoolCreateInfo>(VK_STRUCTURE_TYPE_QUERY_POOL_CREATE_INFO);
      qci.queryType = VK_QUERY_TYPE_TIMESTAMP;
      qci.queryCount = n_queries;
      VkQueryPool q = VK_NULL_HANDLE;
      check(ctx.vk.vkCreateQueryPool(ctx.device, &qci, nullptr, &q), "vkCreateQueryPool");
      queries = own(ctx, q, destroy_query_pool);
    }
    write_descriptor_sets(compute_set, shadow_set, sampler);
  }

  void stamp(VkCommandBuffer cmd, std::uint32_t index, VkPipelineStageFlagBits stage) const {
    if (timed) ctx.vk.vkCmdWriteTimestamp(cmd, stage, queries.get(), index);
  }

 private:
  // The compute set (all passes, all tiles) and the shadow-map set.
  void write_descriptor_sets(VkDescriptorSetLayout compute_set, VkDescriptorSetLayout shadow_set, VkSampler sampler) {
    VkDescriptorPoolSize pool_sizes[] = {{VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 13},
                                         {VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, 1}};
    VkDescriptorPoolCreateInfo dpci = make<VkDescriptorPoolCreateInfo>(VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO);
    dpci.maxSets = 2;
    dpci.poolSizeCount = 2;
    dpci.pPoolSizes = pool_sizes;
    VkDescriptorPool dp = VK_NULL_HANDLE;
    check(ctx.vk.vkCreateDescriptorPool(ctx.device, &dpci, nullptr, &dp), "vkCreateDescriptorPool");
    descriptor_pool = own(ctx, dp, destroy_descriptor_pool);
    const VkDescriptorSetLayout set_layouts[2] = {compute_set, shadow_set};
    VkDescriptorSetAllocateInfo dsai = make<VkDescriptorSetAllocateInfo>(VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO);
    dsai.descriptorPool = dp;
    dsai.descriptorSetCount = 2;
    dsai.pSetLayouts = set_layouts;
    check(ctx.vk.vkAllocateDescriptorSets(ctx.device, &dsai, sets), "vkAllocateDescriptorSets");
    const VkBuffer buffers[11] = {params_buf.handle, lamps_buf.handle, layers_buf.handle, depth_buf.handle,
                                  normals_buf.handle, grid_buf.handle, t_buf.handle, r_buf.handle,
                                  v_buf.handle, od_buf.handle, counters_buf.handle};
    VkDescriptorBufferInfo infos[13];
    VkWriteDescriptorSet writes[14];
    for (int i = 0; i < 11; ++i) {
      infos[i] = {buffers[i], 0, VK_WHOLE_SIZE};
      writes[i] = make<VkWriteDescriptorSet>(VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET);
      writes[i].dstSet = sets[0];
      writes[i].dstBinding = std::uint32_t(i);
      writes[i].descriptorCount = 1;
      writes[i].descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
      writes[i].pBufferInfo = &infos[i];
    }
    const VkDescriptorImageInfo image_info{sampler, atlas.all_layers, VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL};
    writes[11] = make<VkWriteDescriptorSet>(VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET);
    writes[11].dstSet = sets[0];
    writes[11].dstBinding = 11;
    writes[11].descriptorCount = 1;
    writes[11].descriptorType = VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER;
    writes[11].pImageInfo = &image_info;
    infos[11] = {layers_buf.handle, 0, VK_WHOLE_SIZE};
    writes[12] = make<VkWriteDescriptorSet>(VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET);
    writes[12].dstSet = sets[1];
    writes[12].dstBinding = 0;
    writes[12].descriptorCount = 1;
    writes[12].descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
    writes[12].pBufferInfo = &infos[11];
    infos[12] = {sunlit_buf.handle, 0, VK_WHOLE_SIZE};
    writes[13] = make<VkWriteDescriptorSet>(VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET);
    writes[13].dstSet = sets[0];
    writes[13].dstBinding = 12;
    writes[13].descriptorCount = 1;
    writes[13].descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
    writes[13].pBufferInfo = &infos[12];
    ctx.vk.vkUpdateDescriptorSets(ctx.device, 14, writes, 0, nullptr);
  }
};

}  // namespace

// ------------------------------------------------------------------------------------------------

struct Backend::Impl {
  Context ctx;
  Unique<VkDescriptorSetLayout> compute_set, shadow_set;
  Unique<VkPipelineLayout> compute_layout, shadow_layout;
  Unique<VkPipeline> grid, resolve, shadow;
  Unique<VkSampler> sampler;
  Unique<VkCommandPool> pool;
  Unique<VkFence> fence;
  VkCommandBuffer cmd = VK_NULL_HANDLE;
  std::mutex mutex;

  explicit Impl(const ContextOptions& options) : ctx(options) {
    VkSamplerCreateInfo sci = make<VkSamplerCreateInfo>(VK_STRUCTURE_TYPE_SAMPLER_CREATE_INFO);
    sci.magFilter = VK_FILTER_NEAREST;
    sci.minFilter = VK_FILTER_NEAREST;
    sci.mipmapMode = VK_SAMPLER_MIPMAP_MODE_NEAREST;
    sci.addressModeU = sci.addressModeV = sci.addressModeW = VK_SAMPLER_ADDRESS_MODE_CLAMP_TO_EDGE;
    sci.maxLod = 0;
    VkSampler s = VK_NULL_HANDLE;
    check(ctx.vk.vkCreateSampler(ctx.device, &sci, nullptr, &s), "vkCreateSampler");
    sampler = own(ctx, s, destroy_sampler);

    VkCommandPoolCreateInfo pci = make<VkCommandPoolCreateInfo>(VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO);
    pci.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
    pci.queueFamilyIndex = ctx.queue_family;
    VkCommandPool p = VK_NULL_HANDLE;
    check(ctx.vk.vkCreateCommandPool(ctx.device, &pci, nullptr, &p), "vkCreateCommandPool");
    pool = own(ctx, p, destroy_pool);
    VkCommandBufferAllocateInfo cai = make<VkCommandBufferAllocateInfo>(VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO);
    cai.commandPool = pool.get();
    cai.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
    cai.commandBufferCount = 1;
    check(ctx.vk.vkAllocateCommandBuffers(ctx.device, &cai, &cmd), "vkAllocateCommandBuffers");
    VkFenceCreateInfo fci = make<VkFenceCreateInfo>(VK_STRUCTURE_TYPE_FENCE_CREATE_INFO);
    VkFence f = VK_NULL_HANDLE;
    check(ctx.vk.vkCreateFence(ctx.device, &fci, nullptr, &f), "vkCreateFence");
    fence = own(ctx, f, destroy_fence);
  }

  // Pipelines are built on first use: Backend::automatic only probes the device, and on a
  // CPU-only machine renders on the CPU without paying for shader compilation.
  void ensure_pipelines() {
    if (grid.get()) return;
    std::vector<VkDescriptorSetLayoutBinding> b;
    for (int i = 0; i < kComputeBindings; ++i)
      b.push_back({std::uint32_t(i),
                   i == 11 ? VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER : VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1,
                   VK_SHADER_STAGE_COMPUTE_BIT, nullptr});
    compute_set = make_set_layout(ctx, b);
    compute_layout = make_pipeline_layout(ctx, compute_set.get(), nullptr);
    grid = make_compute_pipeline(ctx, compute_layout.get(), kGridSpv, sizeof(kGridSpv));
    resolve = make_compute_pipeline(ctx, compute_layout.get(), kResolveSpv, sizeof(kResolveSpv));

    shadow_set = make_set_layout(
        ctx, {{0, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, VK_SHADER_STAGE_VERTEX_BIT | VK_SHADER_STAGE_FRAGMENT_BIT,
               nullptr}});
    const VkPushConstantRange push{VK_SHADER_STAGE_VERTEX_BIT | VK_SHADER_STAGE_FRAGMENT_BIT, 0,
                                   sizeof(gpu::ShadowPush)};
    shadow_layout = make_pipeline_layout(ctx, shadow_set.get(), &push);
    shadow = make_shadow_pipeline();

  }

  ~Impl() {
    if (ctx.device) ctx.vk.vkDeviceWaitIdle(ctx.device);
  }

  Unique<VkPipeline> make_shadow_pipeline() {
    const auto vert = own(ctx, make_module(ctx, kShadowVertSpv, sizeof(kShadowVertSpv)), destroy_module);
    const auto frag = own(ctx, make_module(ctx, kShadowFragSpv, sizeof(kShadowFragSpv)), destroy_module);
    VkPipelineShaderStageCreateInfo stages[2] = {
        make<VkPipelineShaderStageCreateInfo>(VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO),
        make<VkPipelineShaderStageCreateInfo>(VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO)};
    stages[0].stage = VK_SHADER_STAGE_VERTEX_BIT;
    stages[0].module = vert.get();
    stages[0].pName = "main";
    stages[1].stage = VK_SHADER_STAGE_FRAGMENT_BIT;
    stages[1].module = frag.get();
    stages[1].pName = "main";
    const VkVertexInputBindingDescription binding{0, 3 * sizeof(float), VK_VERTEX_INPUT_RATE_VERTEX};
    const VkVertexInputAttributeDescription attribute{0, 0, VK_FORMAT_R32G32B32_SFLOAT, 0};
    VkPipelineVertexInputStateCreateInfo vi = make<VkPipelineVertexInputStateCreateInfo>(VK_STRUCTURE_TYPE_PIPELINE_VERTEX_INPUT_STATE_CREATE_INFO);
    vi.vertexBindingDescriptionCount = 1;
    vi.pVertexBindingDescriptions = &binding;
    vi.vertexAttributeDescriptionCount = 1;
    vi.pVertexAttributeDescriptions = &attribute;
    VkPipelineInputAssemblyStateCreateInfo ia = make<VkPipelineInputAssemblyStateCreateInfo>(VK_STRUCTURE_TYPE_PIPELINE_INPUT_ASSEMBLY_STATE_CREATE_INFO);
    ia.topology = VK_PRIMITIVE_TOPOLOGY_TRIANGLE_LIST;
    VkPipelineViewportStateCreateInfo vp = make<VkPipelineViewportStateCreateInfo>(VK_STRUCTURE_TYPE_PIPELINE_VIEWPORT_STATE_CREATE_INFO);
    vp.viewportCount = 1;
    vp.scissorCount = 1;
    VkPipelineRasterizationStateCreateInfo rs = make<VkPipelineRasterizationStateCreateInfo>(VK_STRUCTURE_TYPE_PIPELINE_RASTERIZATION_STATE_CREATE_INFO);
    rs.polygonMode = VK_POLYGON_MODE_FILL;
    rs.cullMode = VK_CULL_MODE_NONE;  // the mesh is a shell seen from both sides
    rs.frontFace = VK_FRONT_FACE_COUNTER_CLOCKWISE;
    rs.lineWidth = 1.0f;
    VkPipelineMultisampleStateCreateInfo ms = make<VkPipelineMultisampleStateCreateInfo>(VK_STRUCTURE_TYPE_PIPELINE_MULTISAMPLE_STATE_CREATE_INFO);
    ms.rasterizationSamples = VK_SAMPLE_COUNT_1_BIT;
    VkPipelineDepthStencilStateCreateInfo ds = make<VkPipelineDepthStencilStateCreateInfo>(VK_STRUCTURE_TYPE_PIPELINE_DEPTH_STENCIL_STATE_CREATE_INFO);
    ds.depthTestEnable = VK_TRUE;
    ds.depthWriteEnable = VK_TRUE;
    ds.depthCompareOp = VK_COMPARE_OP_LESS;
    VkPipelineColorBlendAttachmentState att{};
    att.colorWriteMask = VK_COLOR_COMPONENT_R_BIT;
    VkPipelineColorBlendStateCreateInfo cb = make<VkPipelineColorBlendStateCreateInfo>(VK_STRUCTURE_TYPE_PIPELINE_COLOR_BLEND_STATE_CREATE_INFO);
    cb.attachmentCount = 1;
    cb.pAttachments = &att;
    const VkDynamicState dyn_states[] = {VK_DYNAMIC_STATE_VIEWPORT, VK_DYNAMIC_STATE_SCISSOR};
    VkPipelineDynamicStateCreateInfo dyn = make<VkPipelineDynamicStateCreateInfo>(VK_STRUCTURE_TYPE_PIPELINE_DYNAMIC_STATE_CREATE_INFO);
    dyn.dynamicStateCount = 2;
    dyn.pDynamicStates = dyn_states;
    const VkFormat color_format = VK_FORMAT_R32_SFLOAT;
    VkPipelineRenderingCreateInfo rendering = make<VkPipelineRenderingCreateInfo>(VK_STRUCTURE_TYPE_PIPELINE_RENDERING_CREATE_INFO);
    rendering.colorAttachmentCount = 1;
    rendering.pColorAttachmentFormats = &color_format;
    rendering.depthAttachmentFormat = VK_FORMAT_D32_SFLOAT;
    VkGraphicsPipelineCreateInfo ci = make<VkGraphicsPipelineCreateInfo>(VK_STRUCTURE_TYPE_GRAPHICS_PIPELINE_CREATE_INFO);
    ci.pNext = &rendering;
    ci.stageCount = 2;
    ci.pStages = stages;
    ci.pVertexInputState = &vi;
    ci.pInputAssemblyState = &ia;
    ci.pViewportState = &vp;
    ci.pRasterizationState = &rs;
    ci.pMultisampleState = &ms;
    ci.pDepthStencilState = &ds;
    ci.pColorBlendState = &cb;
    ci.pDynamicState = &dyn;
    ci.layout = shadow_layout.get();
    VkPipeline h = VK_NULL_HANDLE;
    check(ctx.vk.vkCreateGraphicsPipelines(ctx.device, VK_NULL_HANDLE, 1, &ci, nullptr, &h),
          "vkCreateGraphicsPipelines");
    return own(ctx, h, destroy_pipeline);
  }

  void begin() {
    check(ctx.vk.vkResetCommandBuffer(cmd, 0), "vkResetCommandBuffer");
    VkCommandBufferBeginInfo bi = make<VkCommandBufferBeginInfo>(VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO);
    bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    check(ctx.vk.vkBeginCommandBuffer(cmd, &bi), "vkBeginCommandBuffer");
  }

  void submit_and_wait() {
    check(ctx.vk.vkEndCommandBuffer(cmd), "vkEndCommandBuffer");
    VkSubmitInfo si = make<VkSubmitInfo>(VK_STRUCTURE_TYPE_SUBMIT_INFO);
    si.commandBufferCount = 1;
    si.pCommandBuffers = &cmd;
    VkFence f = fence.get();
    check(ctx.vk.vkQueueSubmit(ctx.queue, 1, &si, f), "vkQueueSubmit");
    check(ctx.vk.vkWaitForFences(ctx.device, 1, &f, VK_TRUE, std::numeric_limits<std::uint64_t>::max()),
          "vkWaitForFences");
    check(ctx.vk.vkResetFences(ctx.device, 1, &f), "vkResetFences");
  }

  void render(const CoreInputs& in, const TriangleMesh* mesh, CoreOutputs& out, const BackendOptions& opt,
              BackendTimings* timings);
  // The stages of render() (see "the stages of a render" above).
  double render_shadow_maps(const CoreInputs& in, const FramePlan& f, const ShadowPlan& s, FrameResources& r,
                            const TriangleMesh* mesh);
  double upload_tile(const CoreInputs& in, const FramePlan& f, const Tile& t, FrameResources& r);
  void dispatch_tile(const FramePlan& f, const Tile& t, FrameResources& r);
  double read_back_tile(const FramePlan& f, const Tile& t, const FrameResources& r, CoreOutputs& out,
                        std::vector<Shaded>& shaded, std::size_t& exact, std::size_t& interpolated);
  void read_timestamps(const FrameResources& r, int n_tiles, BackendTimings& timings);
  std::vector<float> echo_layout(const void* params, std::size_t params_bytes, const void* lamps,
                                 std::size_t lamps_bytes, const void* layers, std::size_t layers_bytes,
                                 std::size_t out_vec4s);
};

// ------------------------------------------------------------------------------------------------

void Backend::Impl::render(const CoreInputs& in, const TriangleMesh* mesh, CoreOutputs& out,
                           const BackendOptions& opt, BackendTimings* timings) {
  std::lock_guard lock(mutex);
  // Cancellation: checked here, after the shadow maps and before each tile (each tile waits for
  // its own fence, so a throw leaves the device idle and RAII frees the resources).
  throw_if_cancelled(in.cancel, "render_scattering (vulkan)");
  ensure_pipelines();
  const auto& limits = ctx.properties.limits;
  FramePlan f = pack_parameters(in, mesh);
  const ShadowPlan shadow_plan = plan_shadow_maps(in, mesh, opt, limits.maxImageDimension2D, f);
  const TileLayout layout = plan_tiles(in, f, opt, limits.maxStorageBufferRange);
  FrameResources r(ctx, compute_set.get(), shadow_set.get(), sampler.get(), f, shadow_plan, layout, mesh);

  double host_up = render_shadow_maps(in, f, shadow_plan, r, mesh);
  throw_if_cancelled(in.cancel, "render_scattering (vulkan)");

  double host_down = 0;
  std::size_t exact = 0, interpolated = 0;
  std::vector<Shaded> shaded;  // the photo fallback's candidates
  int tile_index = 0;
  report_progress(in.cancel, "render", 0, std::size_t(layout.count()));  // mr/cancel.h: tiles
  for (int ty = 0; ty < layout.tiles_y; ++ty)
    for (int tx = 0; tx < layout.tiles_x; ++tx, ++tile_index) {
      const Tile tile = make_tile(f, layout, tx, ty, tile_index);
      throw_if_cancelled(in.cancel, "render_scattering (vulkan)");
      host_up += upload_tile(in, f, tile, r);
      dispatch_tile(f, tile, r);
      host_down += read_back_tile(f, tile, r, out, shaded, exact, interpolated);
      report_progress(in.cancel, "render", std::size_t(tile_index) + 1, std::size_t(layout.count()));
    }
  if (f.photo_fallback) {
    const auto t_host = Clock::now();
    apply_photo_fallback(in, shaded, out);
    host_down += seconds_since(t_host);
  }
  out.exact_pixels = exact;
  out.interpolated_pixels = interpolated;
  out.shadow_rays = 0;  // shadow-map lookups are not counted

  if (timings) {
    *timings = BackendTimings{};
    timings->host_upload_s = host_up;
    timings->host_download_s = host_down;
    timings->tiles = layout.count();
    timings->shadow_layers = shadow_plan.n_layers();
    timings->shadow_map_size = shadow_plan.n_layers() > 0 ? shadow_plan.size : 0;
    if (r.timed) read_timestamps(r, layout.count(), *timings);
  }
}

// Uploads the lamps, the shadow layers and the mesh, and rasterizes the mesh into every layer of
// the shadow atlas. Returns the host's staging time.
double Backend::Impl::render_shadow_maps(const CoreInputs& in, const FramePlan& f, const ShadowPlan& s,
                                         FrameResources& r, const TriangleMesh* mesh) {
  const int n_layers = s.n_layers();
  const int size = s.size;
  const auto t_host = Clock::now();
  {
    auto* dst = static_cast<char*>(r.staging_up.mapped);
    std::size_t off = 0;
    auto put = [&](const void* src, std::size_t bytes) {
      if (bytes) std::memcpy(dst + off, src, bytes);
      off += bytes;
    };
    std::vector<char> zeros(std::max(r.lamps_buf.size, r.layers_buf.size), 0);
    put(s.lamps.empty() ? zeros.data() : static_cast<const void*>(s.lamps.data()), r.lamps_buf.size);
    put(s.layers.empty() ? zeros.data() : static_cast<const void*>(s.layers.data()), r.layers_buf.size);
    if (f.shadows) {
      put(mesh->positions.data(), r.vertex_buf.size);
      put(mesh->indices.data(), r.index_buf.size);
    }
  }
  const double host_up = seconds_since(t_host);
  begin();
  if (r.timed) ctx.vk.vkCmdResetQueryPool(cmd, r.queries.get(), 0, r.n_queries);
  r.stamp(cmd, 0, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT);
  {
    VkDeviceSize off = 0;
    auto copy = [&](const Buffer& b) {
      if (!b.handle) return;
      const VkBufferCopy region{off, 0, b.size};
      ctx.vk.vkCmdCopyBuffer(cmd, r.staging_up.handle, b.handle, 1, &region);
      off += b.size;
    };
    copy(r.lamps_buf);
    copy(r.layers_buf);
    if (f.shadows) {
      copy(r.vertex_buf);
      copy(r.index_buf);
    }
  }
  memory_barrier(ctx, cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
                 VK_PIPELINE_STAGE_VERTEX_INPUT_BIT | VK_PIPELINE_STAGE_VERTEX_SHADER_BIT |
                     VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT | VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                 VK_ACCESS_VERTEX_ATTRIBUTE_READ_BIT | VK_ACCESS_INDEX_READ_BIT | VK_ACCESS_SHADER_READ_BIT);
  r.stamp(cmd, 1, VK_PIPELINE_STAGE_TRANSFER_BIT);
  if (n_layers > 0) {
    image_barrier(ctx, cmd, r.atlas.handle, VK_IMAGE_ASPECT_COLOR_BIT, r.atlas.layers, VK_IMAGE_LAYOUT_UNDEFINED,
                  VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, 0,
                  VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT, VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT);
    const VkViewport viewport{0, 0, float(size), float(size), 0, 1};
    const VkRect2D scissor{{0, 0}, {std::uint32_t(size), std::uint32_t(size)}};
    auto bind_shadow_state = [&] {
      ctx.vk.vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_GRAPHICS, shadow.get());
      ctx.vk.vkCmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_GRAPHICS, shadow_layout.get(), 0, 1, &r.sets[1], 0,
                                     nullptr);
      ctx.vk.vkCmdSetViewport(cmd, 0, 1, &viewport);
      ctx.vk.vkCmdSetScissor(cmd, 0, 1, &scissor);
      const VkDeviceSize zero = 0;
      ctx.vk.vkCmdBindVertexBuffers(cmd, 0, 1, &r.vertex_buf.handle, &zero);
      ctx.vk.vkCmdBindIndexBuffer(cmd, r.index_buf.handle, 0, VK_INDEX_TYPE_UINT32);
    };
    bind_shadow_state();
    for (int l = 0; l < n_layers; ++l) {
      if (in.cancel && l > 0) {
        // Cancellable: one submission per layer (a 4096^2 layer is a long draw on a software
        // device), checked in between.
        submit_and_wait();
        throw_if_cancelled(in.cancel, "render_scattering (vulkan)");
        begin();
        bind_shadow_state();
      }
      // The depth attachment is reused by every layer: wait for the previous layer's tests.
      image_barrier(ctx, cmd, r.depth_attachment->handle, VK_IMAGE_ASPECT_DEPTH_BIT, 1, VK_IMAGE_LAYOUT_UNDEFINED,
                    VK_IMAGE_LAYOUT_DEPTH_ATTACHMENT_OPTIMAL,
                    VK_PIPELINE_STAGE_EARLY_FRAGMENT_TESTS_BIT | VK_PIPELINE_STAGE_LATE_FRAGMENT_TESTS_BIT,
                    VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_WRITE_BIT,
                    VK_PIPELINE_STAGE_EARLY_FRAGMENT_TESTS_BIT | VK_PIPELINE_STAGE_LATE_FRAGMENT_TESTS_BIT,
                    VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_READ_BIT | VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_WRITE_BIT);
      VkRenderingAttachmentInfo color = make<VkRenderingAttachmentInfo>(VK_STRUCTURE_TYPE_RENDERING_ATTACHMENT_INFO);
      color.imageView = r.atlas.layer_views[std::size_t(l)];
      color.imageLayout = VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL;
      color.loadOp = VK_ATTACHMENT_LOAD_OP_CLEAR;
      color.storeOp = VK_ATTACHMENT_STORE_OP_STORE;
      color.clearValue.color.float32[0] = kFar;
      VkRenderingAttachmentInfo depth = make<VkRenderingAttachmentInfo>(VK_STRUCTURE_TYPE_RENDERING_ATTACHMENT_INFO);
      depth.imageView = r.depth_attachment->layer_views[0];
      depth.imageLayout = VK_IMAGE_LAYOUT_DEPTH_ATTACHMENT_OPTIMAL;
      depth.loadOp = VK_ATTACHMENT_LOAD_OP_CLEAR;
      depth.storeOp = VK_ATTACHMENT_STORE_OP_DONT_CARE;
      depth.clearValue.depthStencil = {1.0f, 0};
      VkRenderingInfo ri = make<VkRenderingInfo>(VK_STRUCTURE_TYPE_RENDERING_INFO);
      ri.renderArea = scissor;
      ri.layerCount = 1;
      ri.colorAttachmentCount = 1;
      ri.pColorAttachments = &color;
      ri.pDepthAttachment = &depth;
      ctx.vk.vkCmdBeginRendering(cmd, &ri);
      const gpu::ShadowPush push{{l, 0, 0, 0}};
      ctx.vk.vkCmdPushConstants(cmd, shadow_layout.get(), VK_SHADER_STAGE_VERTEX_BIT | VK_SHADER_STAGE_FRAGMENT_BIT,
                                0, sizeof(push), &push);
      ctx.vk.vkCmdDrawIndexed(cmd, std::uint32_t(mesh->indices.size()), 1, 0, 0, 0);
      ctx.vk.vkCmdEndRendering(cmd);
    }
    image_barrier(ctx, cmd, r.atlas.handle, VK_IMAGE_ASPECT_COLOR_BIT, r.atlas.layers,
                  VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL, VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL,
                  VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT, VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT,
                  VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_READ_BIT);
  } else {
    image_barrier(ctx, cmd, r.atlas.handle, VK_IMAGE_ASPECT_COLOR_BIT, r.atlas.layers, VK_IMAGE_LAYOUT_UNDEFINED,
                  VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, 0,
                  VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_READ_BIT);
  }
  r.stamp(cmd, 2, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT);
  submit_and_wait();
  return host_up;
}

// The tile's parameters, depth and normals region into staging memory. Returns the host's time.
double Backend::Impl::upload_tile(const CoreInputs& in, const FramePlan& f, const Tile& t, FrameResources& r) {
  const auto t_host = Clock::now();
  auto* dst = static_cast<char*>(r.staging_up.mapped);
  std::memcpy(dst, &t.tp, sizeof(t.tp));
  float* dd = reinterpret_cast<float*>(dst + sizeof(t.tp));
  const int rw = t.rx1 - t.rx0;
  for (int y = t.ry0; y < t.ry1; ++y)
    std::memcpy(dd + std::size_t(y - t.ry0) * rw, in.distance_m.pixel(t.rx0, y), std::size_t(rw) * sizeof(float));
  float* nd = reinterpret_cast<float*>(dst + sizeof(t.tp) + r.depth_buf.size);
  if (f.normals)
    for (int y = t.ry0; y < t.ry1; ++y)
      std::memcpy(nd + std::size_t(y - t.ry0) * rw * 3, in.normals.pixel(t.rx0, y),
                  std::size_t(rw) * 3 * sizeof(float));
  return seconds_since(t_host);
}

// Copies the staged tile to the device, runs the grid and resolve passes, copies the results to
// the read-back buffer, and waits.
void Backend::Impl::dispatch_tile(const FramePlan& f, const Tile& t, FrameResources& r) {
  const std::size_t region_px = std::size_t(t.rx1 - t.rx0) * std::size_t(t.ry1 - t.ry0);
  const std::uint32_t q = 3 + 4 * std::uint32_t(t.index);
  begin();
  r.stamp(cmd, q, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT);
  {
    VkBufferCopy c{0, 0, sizeof(t.tp)};
    ctx.vk.vkCmdCopyBuffer(cmd, r.staging_up.handle, r.params_buf.handle, 1, &c);
    c = {sizeof(t.tp), 0, region_px * sizeof(float)};
    ctx.vk.vkCmdCopyBuffer(cmd, r.staging_up.handle, r.depth_buf.handle, 1, &c);
    if (f.normals) {
      c = {sizeof(t.tp) + r.depth_buf.size, 0, region_px * 3 * sizeof(float)};
      ctx.vk.vkCmdCopyBuffer(cmd, r.staging_up.handle, r.normals_buf.handle, 1, &c);
    }
    ctx.vk.vkCmdFillBuffer(cmd, r.counters_buf.handle, 0, VK_WHOLE_SIZE, 0);
  }
  memory_barrier(ctx, cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
                 VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT);
  r.stamp(cmd, q + 1, VK_PIPELINE_STAGE_TRANSFER_BIT);
  ctx.vk.vkCmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, compute_layout.get(), 0, 1, &r.sets[0], 0,
                                 nullptr);
  const std::uint32_t wg = gpu::kWorkgroupSize;
  ctx.vk.vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, grid.get());
  ctx.vk.vkCmdDispatch(cmd, (std::uint32_t(t.tp.grid.z) + wg - 1) / wg, (std::uint32_t(t.tp.grid.w) + wg - 1) / wg,
                       1);
  memory_barrier(ctx, cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
                 VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_READ_BIT);
  ctx.vk.vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, resolve.get());
  ctx.vk.vkCmdDispatch(cmd, (std::uint32_t(t.x1 - t.x0) + wg - 1) / wg, (std::uint32_t(t.y1 - t.y0) + wg - 1) / wg,
                       1);
  memory_barrier(ctx, cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
                 VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_READ_BIT);
  r.stamp(cmd, q + 2, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT);
  const std::size_t px = std::size_t(t.x1 - t.x0) * std::size_t(t.y1 - t.y0);
  {
    VkDeviceSize off = 0;
    auto copy_back = [&](const Buffer& b, std::size_t bytes) {
      const VkBufferCopy c{0, off, bytes};
      ctx.vk.vkCmdCopyBuffer(cmd, b.handle, r.down.handle, 1, &c);
      off += b.size;
    };
    copy_back(r.t_buf, px * 3 * sizeof(float));
    copy_back(r.r_buf, px * 3 * sizeof(float));
    copy_back(r.v_buf, px * sizeof(float));
    copy_back(r.od_buf, px * 3 * sizeof(float));
    copy_back(r.counters_buf, r.counters_buf.size);
    if (f.photo_fallback) copy_back(r.sunlit_buf, px * 4 * sizeof(float));
  }
  memory_barrier(ctx, cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT, VK_PIPELINE_STAGE_HOST_BIT,
                 VK_ACCESS_HOST_READ_BIT);
  r.stamp(cmd, q + 3, VK_PIPELINE_STAGE_TRANSFER_BIT);
  submit_and_wait();
}

// The tile's T, R and AOVs into `out`, its counts, and (photo fallback) its shadow-mapped pixels.
// Returns the host's time.
double Backend::Impl::read_back_tile(const FramePlan& f, const Tile& t, const FrameResources& r, CoreOutputs& out,
                                     std::vector<Shaded>& shaded, std::size_t& exact, std::size_t& interpolated) {
  const auto t_host = Clock::now();
  const char* src = static_cast<const char*>(r.down.mapped);
  const int cw = t.x1 - t.x0;
  auto unpack = [&](const ImageView& view, std::size_t offset, int channels) {
    const float* p = reinterpret_cast<const float*>(src + offset);
    for (int y = t.y0; y < t.y1; ++y)
      std::memcpy(view.pixel(t.x0, y), p + std::size_t(y - t.y0) * cw * channels,
                  std::size_t(cw) * channels * sizeof(float));
  };
  unpack(out.transmittance, 0, 3);
  unpack(out.inscatter, r.t_buf.size, 3);
  unpack(out.sun_visibility, r.t_buf.size + r.r_buf.size, 1);
  unpack(out.optical_depth, r.t_buf.size + r.r_buf.size + r.v_buf.size, 3);
  std::uint32_t counts[4];
  std::memcpy(counts, src + r.t_buf.size + r.r_buf.size + r.v_buf.size + r.od_buf.size, sizeof(counts));
  if (f.photo_fallback) {
    // Only pixels the shadow maps shade can change: keep their "sun seen" T and AO.
    const float* sunlit = reinterpret_cast<const float*>(src + r.t_buf.size + r.r_buf.size + r.v_buf.size +
                                                         r.od_buf.size + r.counters_buf.size);
    for (int y = t.y0; y < t.y1; ++y)
      for (int x = t.x0; x < t.x1; ++x) {
        if (!(out.sun_visibility.at(x, y, 0) < 1.0f)) continue;
        const float* v = sunlit + 4 * (std::size_t(y - t.y0) * cw + std::size_t(x - t.x0));
        shaded.push_back({x, y, {v[0], v[1], v[2]}, v[3]});
      }
  }
  const double seconds = seconds_since(t_host);
  exact += counts[0] + grid_samples_in_tile(f, t);
  interpolated += counts[1];
  return seconds;
}

// Device time per stage from the timestamp queries: the scene upload, the shadow maps, and per
// tile its upload, passes and read-back.
void Backend::Impl::read_timestamps(const FrameResources& r, int n_tiles, BackendTimings& timings) {
  std::vector<std::uint64_t> ts(r.n_queries);
  check(ctx.vk.vkGetQueryPoolResults(ctx.device, r.queries.get(), 0, r.n_queries, ts.size() * sizeof(std::uint64_t),
                                     ts.data(), sizeof(std::uint64_t), VK_QUERY_RESULT_64_BIT | VK_QUERY_RESULT_WAIT_BIT),
        "vkGetQueryPoolResults");
  const double period = double(ctx.properties.limits.timestampPeriod) * 1e-9;
  const std::uint64_t mask =
      ctx.timestamp_valid_bits >= 64 ? ~std::uint64_t(0) : ((std::uint64_t(1) << ctx.timestamp_valid_bits) - 1);
  auto span = [&](std::uint32_t a, std::uint32_t b) { return double((ts[b] - ts[a]) & mask) * period; };
  timings.gpu_upload_s = span(0, 1);
  timings.gpu_shadow_maps_s = span(1, 2);
  for (int t = 0; t < n_tiles; ++t) {
    const std::uint32_t q = 3 + 4 * std::uint32_t(t);
    timings.gpu_upload_s += span(q, q + 1);
    timings.gpu_scatter_s += span(q + 1, q + 2);
    timings.gpu_download_s += span(q + 2, q + 3);
  }
}

std::vector<float> Backend::Impl::echo_layout(const void* params, std::size_t params_bytes, const void* lamps,
                                              std::size_t lamps_bytes, const void* layers, std::size_t layers_bytes,
                                              std::size_t out_vec4s) {
  std::lock_guard lock(mutex);
  std::vector<VkDescriptorSetLayoutBinding> b;
  for (std::uint32_t i = 0; i < 4; ++i)
    b.push_back({i, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, VK_SHADER_STAGE_COMPUTE_BIT, nullptr});
  const auto set_layout = make_set_layout(ctx, b);
  const auto layout = make_pipeline_layout(ctx, set_layout.get(), nullptr);
  const auto pipeline = make_compute_pipeline(ctx, layout.get(), kLayoutCheckSpv, sizeof(kLayoutCheckSpv));
  const std::size_t out_bytes = out_vec4s * 4 * sizeof(float);
  Buffer bufs[4] = {Buffer(ctx, params_bytes, VK_BUFFER_USAGE_STORAGE_BUFFER_BIT, true),
                    Buffer(ctx, lamps_bytes, VK_BUFFER_USAGE_STORAGE_BUFFER_BIT, true),
                    Buffer(ctx, layers_bytes, VK_BUFFER_USAGE_STORAGE_BUFFER_BIT, true),
                    Buffer(ctx, out_bytes, VK_BUFFER_USAGE_STORAGE_BUFFER_BIT, true)};
  std::memcpy(bufs[0].mapped, params, params_bytes);
  std::memcpy(bufs[1].mapped, lamps, lamps_bytes);
  std::memcpy(bufs[2].mapped, layers, layers_bytes);
  std::memset(bufs[3].mapped, 0, out_bytes);
  VkDescriptorPoolSize ps{VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 4};
  VkDescriptorPoolCreateInfo dpci = make<VkDescriptorPoolCreateInfo>(VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO);
  dpci.maxSets = 1;
  dpci.poolSizeCount = 1;
  dpci.pPoolSizes = &ps;
  VkDescriptorPool dp = VK_NULL_HANDLE;
  check(ctx.vk.vkCreateDescriptorPool(ctx.device, &dpci, nullptr, &dp), "vkCreateDescriptorPool");
  const auto pool_owner = own(ctx, dp, destroy_descriptor_pool);
  VkDescriptorSet set = VK_NULL_HANDLE;
  VkDescriptorSetLayout sl = set_layout.get();
  VkDescriptorSetAllocateInfo ai = make<VkDescriptorSetAllocateInfo>(VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO);
  ai.descriptorPool = dp;
  ai.descriptorSetCount = 1;
  ai.pSetLayouts = &sl;
  check(ctx.vk.vkAllocateDescriptorSets(ctx.device, &ai, &set), "vkAllocateDescriptorSets");
  VkDescriptorBufferInfo infos[4];
  VkWriteDescriptorSet writes[4];
  for (int i = 0; i < 4; ++i) {
    infos[i] = {bufs[i].handle, 0, VK_WHOLE_SIZE};
    writes[i] = make<VkWriteDescriptorSet>(VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET);
    writes[i].dstSet = set;
    writes[i].dstBinding = std::uint32_t(i);
    writes[i].descriptorCount = 1;
    writes[i].descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
    writes[i].pBufferInfo = &infos[i];
  }
  ctx.vk.vkUpdateDescriptorSets(ctx.device, 4, writes, 0, nullptr);
  begin();
  memory_barrier(ctx, cmd, VK_PIPELINE_STAGE_HOST_BIT, VK_ACCESS_HOST_WRITE_BIT, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                 VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT);
  ctx.vk.vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline.get());
  ctx.vk.vkCmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, layout.get(), 0, 1, &set, 0, nullptr);
  ctx.vk.vkCmdDispatch(cmd, 1, 1, 1);
  memory_barrier(ctx, cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT, VK_PIPELINE_STAGE_HOST_BIT,
                 VK_ACCESS_HOST_READ_BIT);
  submit_and_wait();
  std::vector<float> result(out_vec4s * 4);
  std::memcpy(result.data(), bufs[3].mapped, out_bytes);
  return result;
}

// ------------------------------------------------------------------------------------------------

Backend::Backend(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Backend::~Backend() = default;

namespace {
// The process's one backend (devices and compiled pipelines are expensive), and why it could
// not be made: for any device, and for hardware devices only (Backend::automatic's probe).
std::mutex g_shared_mutex;
std::unique_ptr<Backend> g_shared;
std::optional<std::string> g_failure, g_hardware_failure;

ContextOptions options_from_environment() {
  ContextOptions options;
  if (const char* v = std::getenv("MR_VULKAN_VALIDATION")) options.validation = std::string(v) == "1";
  if (const char* v = std::getenv("MR_VULKAN_DEVICE")) options.device_filter = v;
  return options;
}

std::string without_prefix(std::string what) {
  if (what.rfind("vulkan: ", 0) == 0) what = what.substr(8);
  return what;
}
}  // namespace

Backend& Backend::shared() {
  std::lock_guard lock(g_shared_mutex);
  if (g_shared) return *g_shared;
  if (g_failure) throw Unavailable(*g_failure);
  try {
    g_shared.reset(new Backend(std::make_unique<Impl>(options_from_environment())));
  } catch (const Unavailable& e) {
    g_failure = without_prefix(e.what());
    throw;
  }
  return *g_shared;
}

Backend& Backend::shared_hardware() {
  std::lock_guard lock(g_shared_mutex);
  if (g_shared) {
    if (g_shared->device().cpu_implementation)
      throw Unavailable("only a software device (" + g_shared->device().name + ")");
    return *g_shared;
  }
  if (g_failure) throw Unavailable(*g_failure);
  if (g_hardware_failure) throw Unavailable(*g_hardware_failure);
  ContextOptions options = options_from_environment();
  options.reject_cpu_implementation = true;
  try {
    g_shared.reset(new Backend(std::make_unique<Impl>(options)));
  } catch (const Unavailable& e) {
    g_hardware_failure = without_prefix(e.what());  // a later shared() may still use lavapipe
    throw;
  }
  return *g_shared;
}

const DeviceInfo& Backend::device() const { return impl_->ctx.info; }

void Backend::render(const CoreInputs& in, const TriangleMesh* mesh, CoreOutputs& out, const BackendOptions& options,
                     BackendTimings* timings) {
  impl_->render(in, mesh, out, options, timings);
}

std::string Backend::name() const { return "vulkan: " + device().name; }

void Backend::prepare_occluders(const CoreInputs& in, Occluders& occluders, FrameTimings& timings) {
  build_occluder_mesh(in, 1, occluders, timings);
}

void Backend::render(const CoreInputs& in, Occluders& occluders, CoreOutputs& out, FrameTimings& timings) {
  const auto t = Clock::now();
  BackendTimings bt;
  render(in, &occluders.mesh, out, {}, &bt);
  timings.upload_s = bt.gpu_upload_s + bt.host_upload_s;
  timings.shadow_maps_s = bt.gpu_shadow_maps_s;
  timings.gpu_scatter_s = bt.gpu_scatter_s;
  timings.download_s = bt.gpu_download_s + bt.host_download_s;
  timings.tiles = bt.tiles;
  timings.scatter_s = seconds_since(t);
}

std::size_t Backend::validation_messages() const { return impl_->ctx.validation_count.load(); }
std::string Backend::validation_log() const {
  std::lock_guard lock(impl_->ctx.log_mutex);
  return impl_->ctx.validation_log;
}
bool Backend::validation_enabled() const { return impl_->ctx.validation; }

std::vector<float> echo_parameter_layout(const void* params, std::size_t params_bytes, const void* lamps,
                                         std::size_t lamps_bytes, const void* layers, std::size_t layers_bytes,
                                         std::size_t out_vec4s) {
  return Backend::shared().impl_->echo_layout(params, params_bytes, lamps, lamps_bytes, layers,
                                                         layers_bytes, out_vec4s);
}

}  // namespace mr::render::vulkan
