// Private to libmr: shading opaque surfaces seen in a photo with the microfacet BRDF of
// mr::Material (Lambert + GGX, Smith height-correlated G2, Schlick F; mr/material.h) under the
// scene's lights: the sun (with shadows from the occluder mesh), a uniform sky and point/spot
// lamps. Used to render re-materialed regions and, by photo/material/brdf_fit, for inverse
// rendering. One place for the BRDF: everything that evaluates it calls these functions.
#pragma once
#include <array>
#include <cstddef>
#include <span>
#include "mr/camera.h"
#include "mr/image.h"
#include "mr/material_model.h"
#include "mr/scene.h"
#include "render/math.h"

namespace mr::render {

/// GGX normal distribution D(h) for alpha = roughness^2 (integrates to 1 against n.h over the
/// hemisphere).
float ggx_distribution(float n_dot_h, float roughness);
/// Smith height-correlated masking-shadowing G2(l, v) for GGX.
float smith_g2(float n_dot_l, float n_dot_v, float roughness);
/// Schlick: F0 + (1 - F0) (1 - v.h)^5.
float schlick_fresnel(float f0, float v_dot_h);

/// f_r(l, v) * max(n.l, 0): reflected radiance per unit irradiance-perpendicular from direction
/// `l` toward `v` (all unit vectors, pointing away from the surface). 0 below either horizon.
Rgb brdf_cosine(const Material& material, const Vec3f& n, const Vec3f& l, const Vec3f& v);

/// Directional albedo of the GGX lobe under uniform light, split as E_spec = F0 * a + b
/// (exact for Schlick's Fresnel): the integral of the specular f_r cos over the hemisphere of
/// light directions for a viewer at n.v = `n_dot_v`. Tabulated on first use (thread-safe, ~0.2 s):
/// 96 x 50 nodes over (sqrt(n.v), roughness in [0.02, 1]), each integrated with 1024 fixed
/// Hammersley samples of GGX's visible normals (so a + b <= 1 by construction); bilinear in
/// between. Within 0.005 of a brute-force quadrature (tests/material_shading_test.cpp).
struct SpecularAlbedo {
  float scale = 0;  ///< a
  float bias = 0;   ///< b
};
SpecularAlbedo ggx_directional_albedo(float n_dot_v, float roughness);

/// Per-pixel geometry and light, computed once per photo and reused for every material.
/// Images are the camera's size; pixels without a surface (sky) have surface(x, y) = 0.
struct SurfaceGeometry {
  Image normal;  ///< 3 channels: unit world normal facing the camera
  /// 1 channel: metres along each pixel's ray, as given. With the camera and pose it gives a
  /// surface pixel's world position and its unit direction to the camera (surface_point),
  /// which are not stored: 24 bytes a pixel less on a large photo.
  Image distance_m;
  Camera camera;
  CameraPose pose;
  /// 1 channel in [0, 1]: the fraction of the sun's disk seen from the surface (above its
  /// tangent plane and past the occluder mesh); 0 with no sun or facing away from it.
  Image sun_visibility;
  /// 1 channel in [0, 1]: the share of the diffuse (cosine-weighted) light from a uniform sky
  /// that reaches the surface. The sky is the upper hemisphere (world +Y) at radiance L_sky; the
  /// lower hemisphere (ground, horizon haze) is dark. An unoccluded plane with unit normal n
  /// sees sky_visibility = (1 + n.y) / 2 exactly (1 for the ground, 1/2 for a wall); with
  /// shadows on, that closed form is multiplied by the fraction of cosine-distributed upward
  /// rays around n that escape the occluder mesh (SurfaceGeometryOptions::sky_rays).
  Image sky_visibility;
  Image surface;  ///< 1 channel: 1 where there is a surface, 0 in the sky
};

struct SurfaceGeometryOptions {
  bool shadows = true;  ///< trace sun and sky visibility against the occluder mesh (Embree)
  int threads = 0;      ///< 0: all cores
  int sky_rays = 16;    ///< rays per pixel for the sky's occlusion (with shadows; 0..256)
  int sun_rays = 8;     ///< rays per pixel over the sun's disk (1 when its radius is 0; 1..64)
  /// With shadows, at most this many pixels are traced (0: every pixel). A larger map's
  /// occluders (mesh, BVH) and rays are made at a factor f = ceil(sqrt(pixels / budget))
  /// coarser (the nearest surface of each f x f block, render/depth_downsample.h): each pixel
  /// keeps its own normal, tangent-plane test and sky closed form, and takes the share of its
  /// sun and sky rays that escape the occluders from the coarse pixels around it at its own
  /// distance. Shadow edges soften over about f pixels: for callers that smooth the visibility
  /// wider than that anyway (a photo target of material transfer).
  std::size_t traced_pixel_budget = 0;
};

/// The factor by which a w x h map's visibility is traced coarser under `traced_pixel_budget`
/// (SurfaceGeometryOptions; 1: every pixel).
int traced_visibility_factor(int width, int height, std::size_t traced_pixel_budget);

/// Builds SurfaceGeometry from a distance map (normals from render::estimate_normals; with
/// shadows, the occluder mesh of reconstruct_occluder_mesh in an Embree scene, shadow and sky
/// rays leaving the surface 1 mm + 1e-3 of its distance along its normal). Deterministic.
/// Throws like estimate_normals (size_mismatch, invalid_argument), and invalid_argument for
/// options out of range or a zero sun direction.
SurfaceGeometry surface_geometry_from_depth(const Image& distance_m, const Camera& camera,
                                            const CameraPose& pose, const Lighting& lighting,
                                            const SurfaceGeometryOptions& options = {});

/// Radiance reflected toward the camera at pixel (x, y) by `material` under `lighting`:
/// sun (irradiance * visibility * brdf_cosine, the sun's centre direction in the BRDF), sky
/// (uniform radiance L_sky: (diffuse albedo + F0 a + b) * L_sky * sky_visibility, the split sum
/// with one visibility for both lobes), lamps (intensity / r^2 * brdf_cosine, the scattering
/// core's smoothstep spot falloff, unshadowed). Lighting without a sky radiance gets no sky.
/// 0 where there is no surface.
Rgb shade_pixel(const Material& material, const SurfaceGeometry& geometry, const Lighting& lighting,
                int x, int y);

/// One pixel's geometry, read out of a SurfaceGeometry (for loops over many materials).
struct SurfacePoint {
  Vec3f normal{}, view{}, position_m{};
  float sun_visibility = 0, sky_visibility = 0;
  bool surface = false;
};
SurfacePoint surface_point(const SurfaceGeometry& geometry, int x, int y);

/// shade_pixel split by what it is linear in (Schlick's F is linear in F0):
///   radiance = diffuse_albedo * diffuse + F0 * specular_f0 + specular_bias   (per channel),
/// the three terms depending only on the geometry, the light and the roughness. Inverse
/// rendering uses it for exact derivatives in the albedos.
struct ShadingTerms {
  Rgb diffuse{}, specular_f0{}, specular_bias{};
};
ShadingTerms shading_terms(const SurfacePoint& point, const Lighting& lighting, float roughness);
/// shading_terms(...).diffuse alone, the same sums in the same order (so the same floats),
/// without the specular lobes' cost: what a Lambertian ratio (differential rendering's photo
/// side) needs.
Rgb diffuse_term(const SurfacePoint& point, const Lighting& lighting);
Rgb shade(const Material& material, const ShadingTerms& terms);

/// shade_pixel for every pixel with labels(x, y) = k >= 1 and k <= materials.size(), using
/// materials[k - 1]; other pixels of `out` (3 channels, the geometry's size) are left as they are.
/// Parallel (TBB).
void shade_regions(const SurfaceGeometry& geometry, const Lighting& lighting, const Image& labels,
                   std::span<const Material> materials, Image& out);

}  // namespace mr::render
