// The facade of mr/material.h: candidate materials from a sample image, their assignment to the
// target's regions by Tabu search, and the re-rendering (DESIGN.md section 5).
#include "mr/material.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <numeric>
#include <opencv2/imgproc.hpp>

#include "mr/annotations.h"
#include "mr/cancel.h"
#include "mr/error.h"
#include "mr/io.h"
#include "photo/material/apply.h"
#include "photo/material/brdf_fit.h"
#include "photo/material/material_objective.h"
#include "photo/material/segments.h"
#include "photo/material/style.h"
#include "photo/material/tabu_search.h"
#include "render/depth_downsample.h"
#include "render/surface_shading.h"

namespace mr {

namespace {

// Two fitted materials closer than this (Euclidean over diffuse R, G, B, specular albedo and
// roughness, the parameter vector of the objective's smoothness term) are the same material
// fitted twice: the acceptance tolerances of the fit itself are 0.03 / 0.05 / 0.1, so a smaller
// gap is within its noise. The larger segment's fit is kept.
constexpr double kDuplicateMaterialDistance = 0.05;
// Radiance below this (scene-linear) is flat black: no shading to fit.
constexpr float kBlackRadiance = 1e-4f;
// Regions larger than this are capped when computing statistics for the search (every pixel is
// still re-rendered): the statistics are sums, so an even stride keeps them unbiased.
constexpr std::size_t kMaxStatisticsPixels = 200000;
// Rays per pixel for the sky's occlusion. A 3D-scene target is rendered as traced, where 16
// left visible grain under sky light, so it gets 64. A photo target's regions get their
// geometry averaged over a few pixels (photo::smooth_geometry_in_regions) and their diffuse
// part from the photo (D x shading), and a sample's fits average 2000 pixels each: 16 rays do
// there, a quarter of the tracing (most of the geometry's time).
constexpr int kSceneSkyRays = 64;
constexpr int kPhotoSkyRays = 16;
// A photo target's visibility is traced on about this many pixels (a larger photo's occluder
// mesh coarser by an integer factor; render::SurfaceGeometryOptions::traced_pixel_budget): its
// geometry is then averaged over 2-24 px in each region (smooth_geometry_in_regions), and the
// coarse pixels stay at most a third of that (2 px for the gallery's 1 MP photos, 5 for 12 MP,
// 8 from 32 MP on). The mesh, BVH and rays were most of a photo's time and memory (a 10.7 MP
// photo: 15 of 28 s, 3.2 GB; tuning dragonfly's slivered depth: 11 of 19 s at 1280 px), and
// the gallery's transfers meet the same bars with 0.5 MP (gallery/results/material37_tune.md).
// A 3D scene's visibility is exact and traced on every pixel.
constexpr std::size_t kPhotoTracedPixels = 500000;

std::size_t photo_traced_pixels(int width, int height) {
  const int max_factor = std::max(1, photo::region_smoothing_radius(width, height) / 3);
  const double pixels = double(width) * height;
  return std::max(kPhotoTracedPixels,
                  std::size_t(std::ceil(pixels / double(max_factor * max_factor))));
}
// At most this many segments per wanted candidate are fitted, each on this many pixels (a
// deterministic stride over the segment; five parameters, so 1000 pixels are plenty: the fits
// are most of the extraction's time, and 2000 gave the same candidates on the synthetic tests
// within their noise).
constexpr int kFittedSegmentsPerCandidate = 3;
constexpr int kFitPixels = 1000;
// When no segment fits within max_relative_rms (real photos under a guessed light: texture,
// small shadows and an approximate light all count as misfit), the segments fitting within this
// factor of the best fit are kept, with a warning, instead of failing.
constexpr double kLooseFitFactor = 1.5;
// Bound on a candidate's reflectance, max(diffuse) + F0: 1 (energy conservation of the additive
// Lambert + GGX model at normal incidence) with a margin for the GGX lobe's own energy loss at
// high roughness and for fit noise; the project's glossy test material has 0.6 + 0.5.
constexpr double kMaxReflectance = 1.2;
// Pixel budget of candidate extraction: a larger sample is reduced by an integer factor (the
// nearest surface per block for the distance map, the block mean for the photo) before its
// geometry is traced, segmented and fitted. The fits use kFitPixels per segment and the
// segmentation works at 0.5 MP anyway, so a 12 MP sample gives the same candidates at a
// fraction of the cost.
constexpr double kExtractionPixelBudget = 0.5e6;

std::string format(const char* fmt, auto... args) {
  char buffer[512];
  std::snprintf(buffer, sizeof buffer, fmt, args...);
  return buffer;
}

std::string size_text(int w, int h) {
  return std::to_string(w) + "x" + std::to_string(h);
}

double luminance(const float* p) {
  return 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
}

void validate_options(const MaterialTransferOptions& o) {
  auto bad = [](const std::string& what) {
    throw Error(ErrorCode::invalid_argument, "material transfer: " + what);
  };
  if (o.max_candidates < 1 || o.max_candidates > 64)
    bad("max_candidates must be in 1..64, got " + std::to_string(o.max_candidates));
  if (!(o.superpixel_size_px >= 0) || !std::isfinite(o.superpixel_size_px))
    bad("superpixel_size_px must be >= 0 (0: automatic)");
  if (!(o.max_relative_rms > 0) || !std::isfinite(o.max_relative_rms))
    bad("max_relative_rms must be > 0");
  if (!(o.smoothness_weight >= 0) || !std::isfinite(o.smoothness_weight))
    bad("smoothness_weight must be >= 0");
  if (o.tabu_max_iterations < 1) bad("tabu_max_iterations must be >= 1");
  if (o.tabu_patience < 1) bad("tabu_patience must be >= 1");
  if (o.threads < 0) bad("threads must be >= 0 (0: all cores)");
}

// Checks a ShadedPhoto and returns its RGB (first three channels): the photo itself when it has
// three (a 12 MP photo is 144 MB of floats), else a copy of them held in `owned`.
const Image& checked_rgb(const ShadedPhoto& p, const char* what, Image& owned) {
  if (!p.photo || !p.distance_m)
    throw Error(ErrorCode::invalid_argument,
                std::string(what) + ": photo and distance map are required");
  const Image& photo = *p.photo;
  if (photo.empty() || photo.channels() < 3)
    throw Error(ErrorCode::invalid_argument, std::string(what) +
                                                 ": the photo must be RGB, it has " +
                                                 std::to_string(photo.channels()) + " channels");
  if (p.distance_m->width() != photo.width() || p.distance_m->height() != photo.height())
    throw Error(ErrorCode::size_mismatch,
                std::string(what) + ": distance map is " +
                    size_text(p.distance_m->width(), p.distance_m->height()) + ", photo is " +
                    size_text(photo.width(), photo.height()));
  if (p.camera.width != photo.width() || p.camera.height != photo.height())
    throw Error(ErrorCode::size_mismatch,
                std::string(what) + ": camera is " + size_text(p.camera.width, p.camera.height) +
                    ", photo is " + size_text(photo.width(), photo.height()));
  const Lighting& l = p.scene.lighting;
  if (!l.sun && !l.sky_radiance && l.lamps.empty())
    throw Error(ErrorCode::invalid_argument,
                std::string(what) + ": the scene has no light (no sun, sky or lamp)");
  if (photo.channels() == 3) return photo;
  owned = photo.select_channels(std::array{0, 1, 2});
  return owned;
}

render::SurfaceGeometry geometry_of(const ShadedPhoto& p, const MaterialTransferOptions& o,
                                    int sky_rays, std::size_t traced_pixels = 0) {
  render::SurfaceGeometryOptions g;
  g.threads = o.threads;
  g.sky_rays = sky_rays;
  g.traced_pixel_budget = traced_pixels;
  return render::surface_geometry_from_depth(*p.distance_m, p.camera, p.scene.pose,
                                             p.scene.lighting, g);
}

double mean_surface_luminance(const Image& rgb, const Image& surface) {
  double sum = 0;
  std::size_t n = 0;
  for (int y = 0; y < rgb.height(); ++y)
    for (int x = 0; x < rgb.width(); ++x) {
      if (!(surface.at(x, y, 0) > 0)) continue;
      const double l = luminance(rgb.pixel(x, y));
      if (!std::isfinite(l)) continue;
      sum += std::max(0.0, l);
      ++n;
    }
  return n ? sum / double(n) : 0.0;
}

double parameter_distance(const Material& a, const Material& b) {
  double d = 0;
  for (int c = 0; c < 3; ++c) d += std::pow(double(a.diffuse_albedo[c]) - b.diffuse_albedo[c], 2);
  d += std::pow(double(a.specular_albedo) - b.specular_albedo, 2);
  d += std::pow(double(a.roughness) - b.roughness, 2);
  return std::sqrt(d);
}

std::string describe(const Material& m) {
  return format("diffuse (%.3f, %.3f, %.3f), specular %.3f, roughness %.3f", m.diffuse_albedo[0],
                m.diffuse_albedo[1], m.diffuse_albedo[2], m.specular_albedo, m.roughness);
}

template <class F>
auto in_arena(int threads, F&& f) {
  tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
  return arena.execute(std::forward<F>(f));
}

// Exposure reference for the style statistics: the light level, i.e. the mean luminance of a
// white Lambertian surface (the diffuse shading S) over the photo's surfaces. Both the sample and
// the target are normalised by their own light, so that the statistics compare materials (a
// surface of albedo 0.3 looks the same under either light) and a highlight is a pixel brighter than
// twice what an average white matte surface would show. Normalising by the photo's own mean
// luminance instead would make a region look brighter or darker by what the rest of the photo
// happens to hold (a bright new material under the target's light, in a dark photo, would count
// as all highlight).
double light_level(const render::SurfaceGeometry& geometry, const Lighting& lighting) {
  const Image shading = photo::diffuse_shading(geometry, lighting);
  return mean_surface_luminance(shading, geometry.surface);
}

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// What to do when the sample offers nothing to fit, for the error messages.
constexpr const char* kSampleAdvice =
    "; use a sample photo showing larger lit surfaces (a close-up of the material), or give its "
    "depth (--sample-depth) and light (--sample-scene, e.g. from `mr estimate`)";

// The sample reduced to the extraction pixel budget: the photo averaged over factor x factor
// blocks, the distance map keeping each block's nearest surface (render/depth_downsample.h), so
// a block that is part surface and part sky is surface; its photo mean then mixes sky in, which
// a segment's fit treats as one more textured pixel.
struct ReducedSample {
  Image rgb, distance_m;
  Camera camera;
  int factor = 1;
};

ReducedSample reduce_sample(const Image& rgb, const ShadedPhoto& sample) {
  ReducedSample r;
  const double pixels = double(rgb.width()) * rgb.height();
  r.factor = int(std::ceil(std::sqrt(pixels / kExtractionPixelBudget)));
  if (r.factor <= 1) return r;
  const render::DownsampledDistance d =
      render::downsample_distance_nearest(sample.distance_m->view(), sample.camera, r.factor);
  r.distance_m = d.distance_m;
  r.camera = d.camera;
  const int w = r.camera.width, h = r.camera.height, f = r.factor;
  r.rgb = Image(w, h, 3);
  tbb::parallel_for(0, h, [&](int y) {
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) {
        double sum = 0;
        for (int dy = 0; dy < f; ++dy)
          for (int dx = 0; dx < f; ++dx) sum += rgb.at(x * f + dx, y * f + dy, c);
        r.rgb.at(x, y, c) = float(sum / double(f * f));
      }
  });
  return r;
}

// One step of a transfer (progress, mr/cancel.h): (name, 0, 1) as it starts, after a check of
// the cancellation; (name, 1, 1) at end().
class Step {
 public:
  Step(const CancelToken* cancel, const char* name) : cancel_(cancel), name_(name) {
    throw_if_cancelled(cancel_, "material");
    report_progress(cancel_, name_, 0, 1);
  }
  void end() { report_progress(cancel_, name_, 1, 1); }

 private:
  const CancelToken* cancel_;
  const char* name_;
};

MaterialCandidates extract(const ShadedPhoto& sample, const MaterialTransferOptions& options,
                           double* light_level_out = nullptr) {
  const auto start = std::chrono::steady_clock::now();
  Step geometry_step(options.cancel, "sample geometry");
  Image owned_rgb;
  const Image& full_rgb = checked_rgb(sample, "sample", owned_rgb);
  const int full_w = full_rgb.width(), full_h = full_rgb.height();
  const ReducedSample reduced = reduce_sample(full_rgb, sample);
  ShadedPhoto working = sample;
  if (reduced.factor > 1) {
    working.photo = &reduced.rgb;
    working.distance_m = &reduced.distance_m;
    working.camera = reduced.camera;
  }
  const Image& rgb = reduced.factor > 1 ? reduced.rgb : full_rgb;
  const int w = rgb.width(), h = rgb.height();
  const render::SurfaceGeometry geometry = geometry_of(working, options, kPhotoSkyRays);
  const double geometry_s = seconds_since(start);
  geometry_step.end();
  const Lighting& lighting = sample.scene.lighting;
  if (light_level_out) *light_level_out = light_level(geometry, lighting);

  // Usable pixels: a surface, finite, not flat black.
  Image valid(w, h, 1);
  std::size_t surface_pixels = 0, usable_pixels = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      if (!(geometry.surface.at(x, y, 0) > 0)) continue;
      ++surface_pixels;
      const float* p = rgb.pixel(x, y);
      bool ok = true;
      for (int c = 0; c < 3; ++c) ok = ok && std::isfinite(p[c]);
      if (!ok || !(std::max({p[0], p[1], p[2]}) > kBlackRadiance)) continue;
      valid.at(x, y, 0) = 1;
      ++usable_pixels;
    }
  const std::string counts =
      std::to_string(w * h) + " pixels" +
      (reduced.factor > 1 ? format(" (reduced %d x from %s to the %.1f MP budget)", reduced.factor,
                                   size_text(full_w, full_h).c_str(), kExtractionPixelBudget / 1e6)
                          : std::string()) +
      ", " + std::to_string(surface_pixels) + " with a surface, " + std::to_string(usable_pixels) +
      " of them not black";
  if (usable_pixels == 0)
    throw Error(ErrorCode::invalid_argument,
                "sample: no usable segment: " + counts +
                    (surface_pixels == 0 ? " (all sky: the distance map has no surface)"
                                         : " (flat black)") +
                    kSampleAdvice);
  photo::SegmentOptions seg_options;
  seg_options.superpixel_size_px = options.superpixel_size_px / reduced.factor;
  Step segment_step(options.cancel, "segments");
  const photo::Segmentation seg = photo::segment_image(rgb, &valid, seg_options);
  segment_step.end();

  MaterialCandidates out;
  out.notes.push_back("sample: " + counts + "; " + std::to_string(seg.count) + " segments");
  if (seg.count == 0)
    throw Error(ErrorCode::invalid_argument,
                "sample: no usable segment: " + counts + ", none large enough (segments of at least " +
                    std::to_string(seg_options.min_segment_pixels) +
                    " pixels of one colour are fitted)" + kSampleAdvice);
  std::vector<std::vector<std::int32_t>> segment_pixels(seg.count);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float s = seg.labels.at(x, y, 0);
      if (s >= 0 && s < float(seg.count)) segment_pixels[int(s)].push_back(y * w + x);
    }
  struct Fitted {
    bool ok = false;
    photo::BrdfFit fit;
    std::string failure;
  };
  std::vector<Fitted> fits(seg.count);
  // Inverse rendering is most of the time: only the largest segments are fitted (the candidates
  // come from them anyway: larger segments win ties and duplicates), on a pixel sample each, in
  // parallel (one Ceres problem per segment).
  const int fitted_segments =
      std::min(seg.count, kFittedSegmentsPerCandidate * options.max_candidates);
  std::vector<int> by_size(seg.count);
  std::iota(by_size.begin(), by_size.end(), 0);
  std::stable_sort(by_size.begin(), by_size.end(), [&](int a, int b) {
    return segment_pixels[a].size() > segment_pixels[b].size();
  });
  for (int i = fitted_segments; i < seg.count; ++i)
    fits[by_size[i]].failure =
        "not fitted: smaller than the " + std::to_string(fitted_segments) + " largest segments";
  photo::BrdfFitOptions fit_options;
  fit_options.max_pixels = kFitPixels;
  const auto fit_start = std::chrono::steady_clock::now();
  throw_if_cancelled(options.cancel, "material");
  ProgressCounter fit_progress(options.cancel, "fit", std::size_t(fitted_segments));  // segments
  tbb::parallel_for(0, fitted_segments, [&](int i) {
    if (options.cancel && options.cancel->requested()) return;
    const int s = by_size[i];
    try {
      fits[s].fit = photo::fit_brdf(rgb, geometry, lighting, segment_pixels[s], fit_options);
      fits[s].ok = std::isfinite(fits[s].fit.relative_rms);
      if (!fits[s].ok) fits[s].failure = "not fitted: no finite residual";
    } catch (const Error& e) {
      fits[s].failure = std::string("not fitted: ") + e.what();
    }
    fit_progress.add(1);
  });
  throw_if_cancelled(options.cancel, "material");
  const double fit_s = seconds_since(fit_start);

  // Well fitted, then the largest first; a near-duplicate joins the candidate it duplicates.
  double best_rms = INFINITY;
  int fitted_ok = 0;
  for (const Fitted& f : fits)
    if (f.ok) best_rms = std::min(best_rms, f.fit.relative_rms), ++fitted_ok;
  if (fitted_ok == 0) {
    std::string reason;
    for (int s : by_size)
      if (!fits[s].failure.empty()) {
        reason = fits[s].failure;
        break;
      }
    throw Error(ErrorCode::invalid_argument,
                "sample: no usable segment: " + counts + "; " + std::to_string(fitted_segments) +
                    " of its " + std::to_string(seg.count) +
                    " segments were fitted by inverse rendering under the sample's light and none "
                    "gave a fit (the largest: " +
                    reason + ")" + kSampleAdvice);
  }
  // Real photos under a guessed light rarely fit within max_relative_rms (texture and small
  // shadows count as misfit): rather than fail, the best fits are kept, and a warning says how
  // loose they are.
  double accepted_rms = options.max_relative_rms;
  if (!(best_rms <= options.max_relative_rms)) {
    accepted_rms = kLooseFitFactor * best_rms;
    const std::string warning = format(
        "warning: no segment of the sample fits its light within relative RMS %.3f (best %.3f); "
        "kept the segments fitting within %.3f (%.1f x the best): the materials are approximate, "
        "the light assumed for the sample explains its look only loosely (give the sample's "
        "depth and light, e.g. a scene from `mr estimate`, for closer fits)",
        options.max_relative_rms, best_rms, accepted_rms, kLooseFitFactor);
    out.warnings.push_back(warning);
    out.notes.push_back(warning);
  }
  std::vector<int> order;
  for (int s = 0; s < seg.count; ++s) {
    if (!fits[s].ok) {
      out.notes.push_back(
          format("segment %d (%zu px): %s", s, segment_pixels[s].size(), fits[s].failure.c_str()));
      continue;
    }
    if (fits[s].fit.relative_rms > accepted_rms) {
      out.notes.push_back(format("segment %d (%zu px): dropped, relative RMS %.3f > %.3f", s,
                                 segment_pixels[s].size(), fits[s].fit.relative_rms,
                                 accepted_rms));
      continue;
    }
    order.push_back(s);
  }
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return segment_pixels[a].size() > segment_pixels[b].size();
  });
  std::vector<int> owner(seg.count, -1);  // segment -> the segment whose candidate it is shown by
  // A fit that reflects more than the light it receives (max diffuse + F0 above
  // kMaxReflectance) is a segment brighter than any surface under the light assumed for the
  // sample: rendered as is, it blows the target's regions out to white. When the typical fit
  // does (the median of the kept ones), the light was guessed too dim: it is taken brighter by
  // the median's excess, every fit darker by as much, and the sample's light level brighter with
  // it (its look, normalised by that level for the style statistics, is then measured under the
  // light its fits assume). A fit still above the bound after that (the sample's sky, a lamp, a
  // white coat in sun) is scaled down to it, hue and gloss kept.
  auto reflectance_of = [](const Material& m) {
    return std::max({m.diffuse_albedo[0], m.diffuse_albedo[1], m.diffuse_albedo[2]}) +
           double(m.specular_albedo);
  };
  double exposure = 1;
  if (!order.empty()) {
    std::vector<double> reflectances;
    for (int s : order) reflectances.push_back(reflectance_of(fits[s].fit.material));
    std::nth_element(reflectances.begin(), reflectances.begin() + reflectances.size() / 2,
                     reflectances.end());
    const double median = reflectances[reflectances.size() / 2];
    if (median > kMaxReflectance) {
      exposure = kMaxReflectance / median;
      if (light_level_out) *light_level_out /= exposure;
      out.notes.push_back(format(
          "exposure: the sample's fits reflect a median %.2f of its light (more than %.1f): its "
          "light taken %.2f x brighter, the fits %.2f x darker",
          median, kMaxReflectance, 1 / exposure, exposure));
    }
  }
  for (int s : order) {
    Material m = fits[s].fit.material;
    for (float& v : m.diffuse_albedo) v *= float(exposure);
    m.specular_albedo *= float(exposure);
    const double reflectance = reflectance_of(m);
    std::string scaled;
    if (reflectance > kMaxReflectance * (1 + 1e-6)) {  // (not the exposure's own rounding)
      const float k = float(kMaxReflectance / reflectance);
      for (float& v : m.diffuse_albedo) v *= k;
      m.specular_albedo *= k;
      scaled = format(" (fit reflected %.2f of its light: diffuse and specular x %.2f)",
                      reflectance, double(k));
    }
    int duplicate_of = -1;
    for (const MaterialCandidate& c : out.candidates)
      if (parameter_distance(c.material, m) < kDuplicateMaterialDistance) {
        duplicate_of = c.segment;
        break;
      }
    if (duplicate_of >= 0) {
      owner[s] = duplicate_of;
      out.notes.push_back(
          format("segment %d (%zu px): same material as segment %d (parameter distance < %.2f)", s,
                 segment_pixels[s].size(), duplicate_of, kDuplicateMaterialDistance));
      continue;
    }
    if (int(out.candidates.size()) >= options.max_candidates) {
      out.notes.push_back(format("segment %d (%zu px): dropped, %d candidates kept already", s,
                                 segment_pixels[s].size(), options.max_candidates));
      continue;
    }
    owner[s] = s;
    MaterialCandidate c;
    c.material = m;
    c.segment = s;
    c.pixel_count = fits[s].fit.pixels_used;
    c.relative_rms = fits[s].fit.relative_rms;
    out.candidates.push_back(c);
    out.notes.push_back(format("candidate %zu = segment %d (%zu px): %s, relative RMS %.3f%s",
                               out.candidates.size() - 1, s, segment_pixels[s].size(),
                               describe(m).c_str(), c.relative_rms, scaled.c_str()));
  }
  // Labels at the sample's own size (a reduced sample's blocks map back to their pixels; pixels
  // that are not usable at full size stay -1).
  out.segment_labels = Image(full_w, full_h, 1, {"Y"});
  for (float& v : out.segment_labels.pixels()) v = -1;
  if (reduced.factor <= 1) {
    for (int s = 0; s < seg.count; ++s)
      if (owner[s] >= 0)
        for (std::int32_t i : segment_pixels[s]) out.segment_labels.data()[i] = float(owner[s]);
  } else {
    const int f = reduced.factor;
    for (int y = 0; y < full_h; ++y)
      for (int x = 0; x < full_w; ++x) {
        const float d = sample.distance_m->at(x, y, 0);
        const float* p = full_rgb.pixel(x, y);
        if (!(std::isfinite(d) && d > 0) || !(std::max({p[0], p[1], p[2]}) > kBlackRadiance))
          continue;
        const int s = int(seg.labels.at(std::min(x / f, w - 1), std::min(y / f, h - 1), 0));
        if (s >= 0 && s < seg.count && owner[s] >= 0)
          out.segment_labels.at(x, y, 0) = float(owner[s]);
      }
  }
  out.notes.push_back(format("sample extraction %.1f s: geometry (%dx%d, sky and sun traced) %.1f s, "
                             "%d segment fits %.1f s",
                             seconds_since(start), w, h, geometry_s, fitted_segments, fit_s));
  return out;
}

// Integer region ids of a label image: the count n, with every id in 1..n checked to have pixels.
int checked_region_count(const Image& labels, int width, int height) {
  if (labels.empty()) throw Error(ErrorCode::invalid_argument, "region labels: empty image");
  if (labels.width() != width || labels.height() != height)
    throw Error(ErrorCode::size_mismatch, "region labels are " +
                                              size_text(labels.width(), labels.height()) +
                                              ", the target photo is " + size_text(width, height));
  if (labels.channels() != 1)
    throw Error(ErrorCode::invalid_argument,
                "region labels must have 1 channel, found " + std::to_string(labels.channels()));
  constexpr int kMaxRegions = 4096;
  int n = 0;
  for (float v : labels.pixels()) {
    if (!std::isfinite(v) || v < 0 || v != std::floor(v) || v > float(kMaxRegions))
      throw Error(
          ErrorCode::invalid_argument,
          format("region labels: value %g is not a region id (0..%d)", double(v), kMaxRegions));
    n = std::max(n, int(v));
  }
  if (n == 0)
    throw Error(ErrorCode::invalid_argument,
                "region labels: no region (every pixel is 0): nothing to re-material");
  std::vector<std::size_t> count(n + 1, 0);
  for (float v : labels.pixels()) ++count[int(v)];
  for (int k = 1; k <= n; ++k)
    if (count[k] == 0)
      throw Error(ErrorCode::invalid_argument, "region labels: region " + std::to_string(k) +
                                                   " has no pixels (ids must be 1.." +
                                                   std::to_string(n) + " without gaps)");
  return n;
}

// Each plane polygon of the annotations is one region (a later polygon paints over an earlier
// one). Annotation coordinates put (0, 0) at the centre of the top-left pixel, as OpenCV does;
// 4 bits of sub-pixel precision.
Image region_labels_from_annotations(const Annotations& annotations, const std::string& name,
                                     int width, int height) {
  if (width <= 0 || height <= 0)
    throw Error(ErrorCode::invalid_argument, name + ": bad photo size");
  if (annotations.planes.empty())
    throw Error(ErrorCode::invalid_argument,
                name + ": region annotations have no plane polygon (/planes is empty)");
  cv::Mat labels(height, width, CV_32F, cv::Scalar(0));
  constexpr int kShift = 4;
  for (std::size_t i = 0; i < annotations.planes.size(); ++i) {
    std::vector<cv::Point> points;
    for (const PixelPoint& p : annotations.planes[i].polygon)
      points.emplace_back(int(std::lround(p[0] * (1 << kShift))),
                          int(std::lround(p[1] * (1 << kShift))));
    const std::vector<std::vector<cv::Point>> polygons{points};
    cv::fillPoly(labels, polygons, cv::Scalar(double(i + 1)), cv::LINE_8, kShift);
  }
  Image out(width, height, 1, {"Y"});
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) out.at(x, y, 0) = labels.at<float>(y, x);
  std::vector<bool> present(annotations.planes.size() + 1, false);
  for (float v : out.pixels()) present[std::size_t(v)] = true;
  for (std::size_t i = 0; i < annotations.planes.size(); ++i)
    if (!present[i + 1])
      throw Error(ErrorCode::invalid_argument,
                  name + ": /planes/" + std::to_string(i) + "/polygon: covers no pixel of the " +
                      size_text(width, height) +
                      " photo (outside it, or painted over by a later polygon)");
  return out;
}

}  // namespace

MaterialCandidates extract_material_candidates(const ShadedPhoto& sample,
                                               const MaterialTransferOptions& options) {
  validate_options(options);
  return in_arena(options.threads, [&] { return extract(sample, options); });
}

MaterialTransferResult transfer_material(const ShadedPhoto& sample, const ShadedPhoto& target,
                                         const Image& region_labels_in,
                                         const MaterialTransferOptions& options) {
  validate_options(options);
  // A target without a photo is a 3D scene given by its distance map (objects rendered by any
  // renderer): its regions are rendered over black, with no photo detail to keep.
  const bool scene_only = target.photo == nullptr;
  Image blank;
  if (scene_only) {
    if (!target.distance_m)
      throw Error(ErrorCode::invalid_argument,
                  "target: a photo or a distance map (for a 3D scene) is required");
    if (target.camera.width != target.distance_m->width() ||
        target.camera.height != target.distance_m->height())
      throw Error(ErrorCode::size_mismatch,
                  "target: camera is " + size_text(target.camera.width, target.camera.height) +
                      ", distance map is " +
                      size_text(target.distance_m->width(), target.distance_m->height()));
    blank = Image(target.camera.width, target.camera.height, 3);
  }
  ShadedPhoto target_checked = target;
  if (scene_only) target_checked.photo = &blank;
  Image owned_target_rgb;
  const Image& target_rgb = checked_rgb(target_checked, "target", owned_target_rgb);
  const int w = target_rgb.width(), h = target_rgb.height();
  const int regions = checked_region_count(region_labels_in, w, h);
  return in_arena(options.threads, [&] {
    const auto start = std::chrono::steady_clock::now();
    Step target_step(options.cancel, "target geometry");
    const std::size_t traced_pixels = scene_only ? 0 : photo_traced_pixels(w, h);
    render::SurfaceGeometry traced =
        geometry_of(target, options, scene_only ? kSceneSkyRays : kPhotoSkyRays, traced_pixels);
    const double target_geometry_s = seconds_since(start);
    const int traced_factor = render::traced_visibility_factor(w, h, traced_pixels);
    target_step.end();
    const Lighting& lighting = target.scene.lighting;
    // Thin unlabelled seams between or inside regions (masks from depth or painted by hand)
    // join their nearest region, so no line of the old material is left between new pixels.
    // A photo's regions then snap to its edges (photo/material/apply.h); a 3D scene's masks are
    // exact.
    const Image region_labels =
        scene_only ? photo::close_region_gaps(region_labels_in, traced)
                   : photo::snap_regions_to_edges(
                         photo::close_region_gaps(region_labels_in, traced), target_rgb, traced);
    // A photo's geometry is estimated: its pixel-scale junk would show as lines in the new
    // material's shading (photo/material/apply.h); a 3D scene's is exact and kept.
    const render::SurfaceGeometry geometry =
        scene_only ? std::move(traced)
                   : photo::smooth_geometry_in_regions(std::move(traced), region_labels);
    std::vector<std::vector<std::int32_t>> region_pixels(regions);
    std::vector<std::size_t> sky_in_region(regions, 0);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const int k = int(region_labels.at(x, y, 0));
        if (k == 0) continue;
        if (geometry.surface.at(x, y, 0) > 0)
          region_pixels[k - 1].push_back(y * w + x);
        else
          ++sky_in_region[k - 1];
      }
    for (int r = 0; r < regions; ++r)
      if (region_pixels[r].empty())
        throw Error(ErrorCode::invalid_argument,
                    "region " + std::to_string(r + 1) + ": all its " +
                        std::to_string(sky_in_region[r]) +
                        " pixels are sky (no depth): there is no surface to re-material");

    MaterialTransferResult result;
    double sample_light = 0;
    result.candidates = extract(sample, options, &sample_light);
    const std::vector<MaterialCandidate>& candidates = result.candidates.candidates;
    const int m = int(candidates.size());

    // The sample's look: its used segments, normalised by its light (light_level).
    Image owned_sample_rgb;
    const Image& sample_rgb = checked_rgb(sample, "sample", owned_sample_rgb);
    std::vector<std::int32_t> sample_pixels;
    for (std::size_t i = 0; i < sample_rgb.pixel_count(); ++i)
      if (result.candidates.segment_labels.data()[i] >= 0) sample_pixels.push_back(std::int32_t(i));
    if (!(sample_light > 0))
      throw Error(ErrorCode::invalid_argument,
                  "sample: its light reaches none of its surfaces (all unlit)");
    const photo::StyleStatistics sample_stats =
        photo::style_statistics(sample_rgb, sample_pixels, sample_light);

    // The target's detail layer and per region x candidate statistics of what would be shown.
    const auto detail_start = std::chrono::steady_clock::now();
    Image model_shading = photo::diffuse_shading(geometry, lighting);
    const double target_reference = mean_surface_luminance(model_shading, geometry.surface);
    const Image* detail_used = nullptr;
    Image detail;
    if (options.keep_detail && !scene_only) {
      photo::DetailOptions detail_options;
      detail_options.region_labels = &region_labels;
      detail = photo::photo_detail(target_rgb, model_shading, geometry, detail_options);
      detail_used = &detail;
    }
    // With detail, D x the floored shading reproduces the photo where the model's shading is
    // untrustworthy (photo_detail); without, the plain rendering.
    const Image shading = detail_used ? photo::floored_shading(std::move(model_shading), geometry)
                                      : std::move(model_shading);
    const double detail_s = seconds_since(detail_start);
    const auto search_start = std::chrono::steady_clock::now();
    if (!(target_reference > 0))
      throw Error(ErrorCode::invalid_argument,
                  "target: its light reaches none of its surfaces (all unlit)");
    std::vector<std::vector<std::int32_t>> stats_pixels(regions);
    for (int r = 0; r < regions; ++r) {
      const std::size_t stride =
          (region_pixels[r].size() + kMaxStatisticsPixels - 1) / kMaxStatisticsPixels;
      for (std::size_t i = 0; i < region_pixels[r].size(); i += std::max<std::size_t>(stride, 1))
        stats_pixels[r].push_back(region_pixels[r][i]);
    }
    std::vector<std::int32_t> all_stats_pixels;
    for (const auto& p : stats_pixels)
      all_stats_pixels.insert(all_stats_pixels.end(), p.begin(), p.end());
    std::vector<std::vector<photo::StyleStatistics>> region_stats(
        regions, std::vector<photo::StyleStatistics>(m));
    // The statistics are of what will be shown: a candidate exposed down to the photo's white
    // (photo::region_range_fit over its statistics pixels) is judged so.
    const float white_level =
        scene_only || !options.fit_photo_range ? 0.0f : photo::photo_white_level(target_rgb);
    {
      Image rendered(w, h, 3);
      throw_if_cancelled(options.cancel, "material");
      report_progress(options.cancel, "statistics", 0, std::size_t(m));  // candidates rendered
      for (int c = 0; c < m; ++c) {
        throw_if_cancelled(options.cancel, "material");
        photo::render_with_detail(geometry, lighting, shading, detail_used, candidates[c].material,
                                  all_stats_pixels, rendered);
        tbb::parallel_for(0, regions, [&](int r) {
          // Scaling the pixels by the exposure is dividing the reference by it.
          region_stats[r][c] = photo::style_statistics(
              rendered, stats_pixels[r],
              target_reference / photo::region_range_fit(rendered, stats_pixels[r], white_level));
        });
        report_progress(options.cancel, "statistics", std::size_t(c) + 1, std::size_t(m));
      }
    }
    std::vector<Material> materials;
    for (const MaterialCandidate& c : candidates) materials.push_back(c.material);
    const photo::MaterialObjective objective(sample_stats, region_stats, materials,
                                             photo::region_adjacency(region_labels, regions),
                                             options.smoothness_weight);
    photo::TabuOptions tabu;
    tabu.max_iterations = options.tabu_max_iterations;
    tabu.patience = options.tabu_patience;
    tabu.seed = options.seed;
    Step search_step(options.cancel, "search");
    const photo::TabuResult search = photo::minimise_assignment(
        regions, m, [&](std::span<const int> a) { return objective(a); }, tabu);
    result.assignment = search.assignment;
    result.objective = search.objective;
    result.best_objective_history = search.best_history;

    std::vector<Material> assigned;
    for (int r = 0; r < regions; ++r) assigned.push_back(materials[result.assignment[r]]);
    const double search_s = seconds_since(search_start);
    search_step.end();
    Step apply_step(options.cancel, "apply");
    // A photo's region borders are approximate (a brush's): where the photo is plain across one
    // with an untouched surface, the feather goes on outside it, and the specks its mixed
    // border pixels make are taken out; a 3D scene's masks are exact.
    photo::CompositeOptions composite;
    composite.smooth_feather_px = scene_only ? 0.0 : 3.0;
    composite.despeckle_borders = !scene_only;
    composite.white_level = white_level;
    photo::DespeckleStats despeckled;
    std::vector<float> exposures;
    result.image =
        photo::apply_materials(target_rgb, geometry, lighting, shading, region_labels, assigned,
                               detail_used, composite, &despeckled, &exposures);
    result.exposures.assign(exposures.begin(), exposures.end());
    apply_step.end();

    // Style distance of the regions to the sample, before and after (whole composite).
    const photo::StyleStatistics before =
        photo::style_statistics(target_rgb, all_stats_pixels, target_reference);
    const photo::StyleStatistics after =
        photo::style_statistics(result.image, all_stats_pixels, target_reference);
    result.notes = result.candidates.notes;
    result.warnings = result.candidates.warnings;
    result.notes.push_back(
        search.exhaustive
            ? format("target: %d regions, %zu candidates; every assignment evaluated (%ld)",
                     regions, candidates.size(), search.evaluations)
            : format("target: %d regions, %zu candidates; Tabu search: %zu iterations, %ld "
                     "evaluations",
                     regions, candidates.size(), search.best_history.size(), search.evaluations));
    for (int r = 0; r < regions; ++r) {
      std::string line = format("region %d (%zu px): candidate %d", r + 1, region_pixels[r].size(),
                                result.assignment[r]);
      if (sky_in_region[r]) line += format(" (%zu sky pixels left as they are)", sky_in_region[r]);
      if (exposures[std::size_t(r)] < 1)
        line += format("; exposed down %.1f stops to stay within the photo's white",
                       -std::log2(double(exposures[std::size_t(r)])));
      result.notes.push_back(line);
    }
    if (scene_only)
      result.notes.push_back(
          format("style distance of the rendered regions to the sample: %.4f (objective %.4f)",
                 photo::style_distance(sample_stats, after), result.objective));
    else {
      const double distance_before = photo::style_distance(sample_stats, before);
      const double distance_after = photo::style_distance(sample_stats, after);
      result.notes.push_back(format(
          "style distance of the regions to the sample: before %.4f, after %.4f (objective %.4f)",
          distance_before, distance_after, result.objective));
      // The search picks the best of the candidates; with few and loose ones (a sample that is
      // mostly sky) the best can still move the regions away from the sample's look.
      if (distance_after > distance_before) {
        const std::string warning = format(
            "warning: the result is further from the sample's look than the photo was (style "
            "distance %.2f -> %.2f): none of the %zu candidate materials suits these regions "
            "(use a sample with larger surfaces of the wanted material, or give its depth and "
            "light)",
            distance_before, distance_after, candidates.size());
        result.warnings.push_back(warning);
        result.notes.push_back(warning);
      }
    }
    if (composite.despeckle_borders)
      result.notes.push_back(format(
          "region borders despeckled (specks and 1-pixel teeth the composite made where the "
          "photo has none): %zu changes in %d passes, %zu pixels within %d px of a border",
          despeckled.changed, despeckled.passes, despeckled.band_pixels, photo::kDespeckleBandPx));
    result.notes.push_back(format(
        "transfer %.1f s: target geometry (%dx%d, sky and sun traced%s) %.1f s, detail layer %.1f "
        "s, statistics and search %.1f s",
        seconds_since(start), w, h,
        traced_factor > 1 ? format(" at 1/%d resolution", traced_factor).c_str() : "",
        target_geometry_s, detail_s, search_s));
    return result;
  });
}

Image load_region_labels(const std::filesystem::path& path, int width, int height) {
  std::string extension = path.extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  if (extension == ".json")
    return region_labels_from_annotations(load_annotations(path), path.string(), width, height);
  ReadOptions read;
  read.to_scene_linear = false;  // ids and colours as stored (integer files normalised to [0, 1])
  const ImageFileInfo info = probe_image(path);
  const Image mask = read_image(path, read);
  const std::string name = path.string();
  if (mask.width() != width || mask.height() != height)
    throw Error(ErrorCode::size_mismatch, name + ": region mask is " +
                                              size_text(mask.width(), mask.height()) +
                                              ", the photo is " + size_text(width, height));
  Image labels(width, height, 1, {"Y"});
  // Integer files are read normalised: back to their codes.
  const double code_scale = info.pixel_type == PixelType::uint8    ? 255.0
                            : info.pixel_type == PixelType::uint16 ? 65535.0
                                                                   : 1.0;
  const int colour_channels = std::min(mask.channels(), 3);
  const bool has_alpha = mask.channels() == 2 || mask.channels() == 4;
  if (colour_channels == 1 || (mask.channels() == 2)) {
    for (int y = 0; y < height; ++y)
      for (int x = 0; x < width; ++x) {
        const double code = std::round(double(mask.at(x, y, 0)) * code_scale);
        if (has_alpha && !(mask.at(x, y, 1) > 0.5f)) continue;
        if (!std::isfinite(code) || code < 0 ||
            std::abs(double(mask.at(x, y, 0)) * code_scale - code) > 1e-3)
          throw Error(ErrorCode::invalid_argument,
                      name + format(": pixel (%d, %d) holds %g, not a region id (0 = none, 1..n)",
                                    x, y, double(mask.at(x, y, 0)) * code_scale));
        labels.at(x, y, 0) = float(code);
      }
    // Ids as given, but without gaps (transfer_material requires 1..n all present).
    std::map<int, int> renumber;
    for (float v : labels.pixels())
      if (v > 0) renumber[int(v)] = 0;
    int next = 1;
    for (auto& [id, to] : renumber) to = next++;
    for (float& v : labels.pixels())
      if (v > 0) v = float(renumber[int(v)]);
  } else {
    std::map<std::array<long, 3>, int> ids;
    for (int y = 0; y < height; ++y)
      for (int x = 0; x < width; ++x) {
        const float* p = mask.pixel(x, y);
        if (has_alpha && !(p[3] > 0.5f)) continue;
        std::array<long, 3> key;
        for (int c = 0; c < 3; ++c)
          key[c] = std::lround(double(p[c]) * (code_scale > 1 ? code_scale : 65535.0));
        if (key[0] == 0 && key[1] == 0 && key[2] == 0) continue;
        auto [it, inserted] = ids.emplace(key, int(ids.size()) + 1);
        labels.at(x, y, 0) = float(it->second);
        if (ids.size() > 1024)
          throw Error(
              ErrorCode::invalid_argument,
              name +
                  ": region mask has more than 1024 distinct colours: not a mask (a lossy format "
                  "such as JPEG blurs mask colours; use PNG)");
      }
  }
  bool any = false;
  for (float v : labels.pixels()) any = any || v > 0;
  if (!any)
    throw Error(ErrorCode::invalid_argument,
                name + ": region mask has no region (every pixel is 0 / black)");
  return labels;
}

std::string material_result_to_json(const MaterialTransferResult& result) {
  using nlohmann::ordered_json;
  auto material_json = [](const Material& m) {
    return ordered_json{
        {"diffuse_albedo", {m.diffuse_albedo[0], m.diffuse_albedo[1], m.diffuse_albedo[2]}},
        {"specular_albedo", m.specular_albedo},
        {"roughness", m.roughness}};
  };
  ordered_json doc;
  doc["format"] = "mr-materials";
  doc["version"] = 1;
  ordered_json candidates = ordered_json::array();
  for (std::size_t i = 0; i < result.candidates.candidates.size(); ++i) {
    const MaterialCandidate& c = result.candidates.candidates[i];
    candidates.push_back(ordered_json{{"index", i},
                                      {"material", material_json(c.material)},
                                      {"sample_segment", c.segment},
                                      {"pixel_count", c.pixel_count},
                                      {"relative_rms", c.relative_rms}});
  }
  doc["candidates"] = candidates;
  ordered_json regions = ordered_json::array();
  for (std::size_t r = 0; r < result.assignment.size(); ++r) {
    const int c = result.assignment[r];
    ordered_json entry{{"region", r + 1}, {"candidate", c}};
    if (c >= 0 && std::size_t(c) < result.candidates.candidates.size())
      entry["material"] = material_json(result.candidates.candidates[c].material);
    if (r < result.exposures.size()) entry["exposure"] = result.exposures[r];
    regions.push_back(entry);
  }
  doc["regions"] = regions;
  doc["objective"] = result.objective;
  doc["best_objective_history"] = result.best_objective_history;
  doc["notes"] = result.notes;
  return doc.dump(1) + "\n";
}

}  // namespace mr
