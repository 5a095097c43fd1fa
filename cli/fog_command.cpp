#include "fog_command.h"

#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <mutex>
#include <optional>

#include "batch.h"
#include "mr/mr.h"
#include "output_safety.h"
#include "mr/scene_json.h"
#include "progress.h"
#include "mr/insert.h"
#include "mr/object_io.h"

namespace fs = std::filesystem;

namespace mr::cli {

namespace {

// Everything resolved from the options once, before the batch starts.
struct FogPlan {
  ColorConfig color = ColorConfig::builtin();
  FogScene scene;
  DepthOptions depth;
  PixelType pixel_type = PixelType::automatic;
};

enum class Outcome { done, skipped, failed };

struct Job {
  fs::path photo, depth, output, aovs_output;  // aovs_output empty: none / same as output
  std::string error;  // found while planning (an output that is an input, or shared): fails it
};

constexpr const char* kDepthExtensions[] = {".exr", ".tif", ".tiff", ".pfm", ".png"};

fs::path find_depth(const FogCommandOptions& o, const fs::path& photo) {
  if (!o.depth.empty() && o.depth != "auto")
    return is_pattern(o.depth) ? expand_pattern(o.depth, photo) : fs::path(o.depth);
  // Default: <dir>/<stem>_depth.<ext> with the first extension that exists.
  std::error_code ec;
  for (const char* ext : kDepthExtensions) {
    fs::path candidate = expand_pattern(std::string("{dir}/{stem}_depth") + ext, photo);
    if (fs::exists(candidate, ec)) return candidate;
  }
  return expand_pattern("{dir}/{stem}_depth.exr", photo);
}

FogPlan make_plan(const FogCommandOptions& o) {
  FogPlan plan;
  plan.color = ColorConfig::from_environment(o.ocio_config);
  for (const std::string* cs : {&o.input_colorspace, &o.output_colorspace})
    if (!cs->empty() && !plan.color.has_colorspace(*cs))
      throw Error(ErrorCode::invalid_argument,
                  "colour space '" + *cs + "' is not in OCIO config " + plan.color.source());
  if (!o.visibility.empty() && !o.density.empty())
    throw Error(ErrorCode::invalid_argument, "--visibility and --density are exclusive");
  FogScene& scene = plan.scene;
  if (!o.scene_path.empty()) scene = load_scene(o.scene_path);
  try {
    if (!o.density.empty()) {
      scene.medium.sigma_t_per_m = parse_rgb(o.density);
    } else if (!o.visibility.empty() || o.scene_path.empty()) {
      const float sigma = float(extinction_from_visibility(
          parse_distance_m(o.visibility.empty() ? "150m" : o.visibility)));
      scene.medium.sigma_t_per_m = {sigma, sigma, sigma};
    }
    if (o.airlight != "auto")
      scene.lighting.sky_radiance = parse_rgb(o.airlight);
    else if (o.scene_path.empty())
      scene.lighting.sky_radiance.reset();
    if (o.sky_light == "direction")
      scene.lighting.sky_by_direction = true;
    else if (o.sky_light == "uniform")
      scene.lighting.sky_by_direction = false;
    else if (o.sky_light != "auto")
      throw std::invalid_argument("--sky-light must be direction, uniform or auto, not '" +
                                  o.sky_light + "'");
    if (!o.albedo.empty()) scene.medium.albedo = parse_rgb(o.albedo);
    if (o.g) scene.medium.g = *o.g;
    if (!o.height_fog.empty()) {
      const auto v = parse_numbers(o.height_fog, 2, "--height-fog base,scale");
      scene.medium.height_fog = Medium::HeightFog{v[0], v[1]};
    }
    if (!o.layer.empty()) {
      const auto v = parse_numbers(o.layer, 2, "--layer bottom,top");
      scene.medium.layer_bottom_m = v[0];
      scene.medium.layer_top_m = v[1];
    }
    if (o.layer_top == "none") {
      if (o.layer.empty()) scene.medium.layer_top_m = std::numeric_limits<double>::infinity();
    } else if (o.layer_top != "auto") {
      if (!o.layer.empty()) throw std::invalid_argument("--layer and --layer-top are exclusive");
      scene.medium.layer_top_m = parse_distance_m(o.layer_top);
    }
    if (!o.noise.empty()) {
      const std::size_t n = std::count(o.noise.begin(), o.noise.end(), ',') + 1;
      const auto v = parse_numbers(o.noise, n, "--noise amplitude[,scale[,octaves[,seed]]]");
      if (n > 4) throw std::invalid_argument("--noise takes at most 4 numbers");
      scene.medium.noise.amplitude = v[0];
      if (n > 1) scene.medium.noise.scale_m = v[1];
      // Whole numbers in range before the casts (a double out of an int's range is UB).
      const auto whole = [&](double x, double lo, double hi, const std::string& name) {
        if (!(x >= lo && x <= hi && x == std::floor(x)))
          throw std::invalid_argument(
              "--noise '" + o.noise + "': " + name + " must be a whole number in " +
              std::to_string(std::uint32_t(lo)) + ".." + std::to_string(std::uint32_t(hi)));
        return x;
      };
      if (n > 2) scene.medium.noise.octaves = int(whole(v[2], 1, 8, "octaves"));
      if (n > 3) scene.medium.noise.seed = std::uint32_t(whole(v[3], 0, 4294967295.0, "seed"));
    }
    const bool sun_given = o.sun_azimuth_deg || o.sun_elevation_deg || !o.sun_direction.empty() ||
                           !o.sun_irradiance.empty() || o.sun_radius_deg;
    if (sun_given) {
      Sun sun = scene.lighting.sun.value_or(Sun{});
      if (!o.sun_direction.empty()) {
        const auto v = parse_numbers(o.sun_direction, 3, "--sun-dir x,y,z");
        sun.direction_to_sun = {v[0], v[1], v[2]};
      } else if (o.sun_azimuth_deg || o.sun_elevation_deg) {
        if (!o.sun_azimuth_deg || !o.sun_elevation_deg)
          throw std::invalid_argument("--sun-azimuth and --sun-elevation go together");
        if (!(std::abs(*o.sun_elevation_deg) <= 90))  // as in scene files
          throw std::invalid_argument("--sun-elevation must be in [-90, 90] degrees");
        sun.direction_to_sun =
            direction_from_azimuth_elevation(*o.sun_azimuth_deg, *o.sun_elevation_deg);
      }
      // No --sun-irradiance for a new sun, or 'auto': relative to each photo's exposure.
      if (o.sun_irradiance == "auto" || (o.sun_irradiance.empty() && !scene.lighting.sun)) {
        sun.irradiance_auto = true;
      } else if (!o.sun_irradiance.empty()) {
        sun.irradiance = parse_rgb(o.sun_irradiance);
        sun.irradiance_auto = false;
      }
      if (o.sun_radius_deg) sun.angular_radius_deg = *o.sun_radius_deg;
      scene.lighting.sun = sun;
    }
    for (const std::string& text : o.lamps) {
      // "x,y,z;R,G,B[;dx,dy,dz;inner,outer]"
      std::vector<std::string> parts;
      std::size_t pos = 0;
      while (pos <= text.size()) {
        std::size_t semi = text.find(';', pos);
        if (semi == std::string::npos) semi = text.size();
        parts.push_back(text.substr(pos, semi - pos));
        pos = semi + 1;
      }
      if ((parts.size() != 1 && parts.size() != 2 && parts.size() != 4) ||
          std::count(parts[0].begin(), parts[0].end(), ',') != 2)
        throw std::invalid_argument("--lamp '" + text +
                                    "': expected x,y,z;R,G,B[;dx,dy,dz;inner,outer] (R,G,B "
                                    "'auto' or left out: relative to the photo's exposure)");
      Lamp lamp;
      const auto p = parse_numbers(parts[0], 3, "--lamp position");
      lamp.position_m = {p[0], p[1], p[2]};
      // No intensity, or 'auto': relative to each photo's exposure (Lamp::intensity_auto).
      lamp.intensity_auto = parts.size() == 1 || parts[1] == "auto";
      if (!lamp.intensity_auto) lamp.intensity_per_sr = parse_rgb(parts[1]);
      if (parts.size() == 4) {
        const auto d = parse_numbers(parts[2], 3, "--lamp spot direction");
        const auto a = parse_numbers(parts[3], 2, "--lamp spot angles");
        lamp.spot_direction = {d[0], d[1], d[2]};
        lamp.inner_angle_deg = a[0];
        lamp.outer_angle_deg = a[1];
      }
      scene.lighting.lamps.push_back(lamp);
    }
  } catch (const std::invalid_argument& e) {
    throw Error(ErrorCode::invalid_argument, e.what());
  }
  if (o.camera_height_m) scene.pose.position_m.y = *o.camera_height_m;
  if (o.pitch_deg) scene.pose.pitch_deg = *o.pitch_deg;
  if (o.roll_deg) scene.pose.roll_deg = *o.roll_deg;
  if (o.yaw_deg) scene.pose.yaw_deg = *o.yaw_deg;
  // The command line's focal length wins over the scene's camera; a single --save-scene file
  // (not a pattern) is written before any photo is read, so it cannot record a focal length in
  // pixels of a photo and records no camera then. A pattern records each photo's.
  if (o.focal_px || o.fov_deg) scene.camera.reset();
  if (o.seed) scene.render.seed = *o.seed;
  if (o.march_steps) scene.render.march_steps = *o.march_steps;
  if (o.no_shadows) scene.render.volumetric_shadows = false;
  if (!o.quality.empty()) {
    if (o.quality == "draft")
      scene.render.quality = Quality::draft;
    else if (o.quality == "normal")
      scene.render.quality = Quality::normal;
    else if (o.quality == "final")
      scene.render.quality = Quality::final;
    else
      throw Error(ErrorCode::invalid_argument,
                  "--quality '" + o.quality + "': expected draft, normal or final");
  }
  if (!o.backend.empty()) {
    if (o.backend == "auto")
      scene.render.backend = Backend::automatic;
    else if (o.backend == "cpu")
      scene.render.backend = Backend::cpu;
    else if (o.backend == "vulkan")
      scene.render.backend = Backend::vulkan;
    else
      throw Error(ErrorCode::invalid_argument,
                  "--backend '" + o.backend + "': expected auto, cpu or vulkan");
  }
  if (!o.shadow_traversal.empty()) {
    if (o.shadow_traversal == "embree")
      scene.render.shadow_traversal = ShadowTraversal::embree;
    else if (o.shadow_traversal == "multi-index")
      scene.render.shadow_traversal = ShadowTraversal::multi_index;
    else
      throw Error(ErrorCode::invalid_argument, "--shadow-traversal '" + o.shadow_traversal +
                                                   "': expected embree or multi-index");
  }
  // Photos in parallel already use the cores; each render gets what its arena allows.
  validate_scene(scene);

  if (o.depth_kind == "distance")
    plan.depth.kind = DepthKind::distance;
  else if (o.depth_kind == "z")
    plan.depth.kind = DepthKind::planar_z;
  else if (o.depth_kind == "disparity")
    plan.depth.kind = DepthKind::disparity;
  else
    throw Error(ErrorCode::invalid_argument,
                "--depth-kind '" + o.depth_kind + "': expected distance, z or disparity");
  plan.depth.scale = o.depth_scale;
  if (!(o.sky_depth_m > 0))  // +inf allowed: no threshold
    throw Error(ErrorCode::invalid_argument, "--sky-depth must be positive metres (inf: none)");
  plan.depth.sky_depth_m = o.sky_depth_m;
  if (!(o.max_megapixels > 0) || !std::isfinite(o.max_megapixels))
    throw Error(ErrorCode::invalid_argument, "--max-megapixels must be positive");
  set_max_decoded_pixels(std::uint64_t(std::ceil(o.max_megapixels * 1e6)));
  plan.depth.baseline_m = o.baseline_m;
  plan.depth.doffs_px = o.doffs_px;
  if (plan.depth.kind == DepthKind::disparity && !(o.baseline_m > 0))
    throw Error(ErrorCode::invalid_argument, "--depth-kind disparity needs --baseline (metres)");
  if (!(o.depth_scale > 0) || !std::isfinite(o.depth_scale))
    throw Error(ErrorCode::invalid_argument, "--depth-scale must be positive");
  if (!o.annotations.empty() && o.depth != "auto")
    throw Error(ErrorCode::invalid_argument, "--annotations needs --depth auto");
  plan.pixel_type = parse_pixel_type(o.bit_depth);
  if (!o.format.empty() && !is_writable_image_extension("x." + o.format))
    throw Error(ErrorCode::invalid_argument,
                "--format '" + o.format + "' is not a writable image format");
  // Last, so that a usage error writes nothing; like the images, it never replaces an input.
  // A pattern is written per photo, once its scene is resolved (run_job); here only checked.
  if (!o.save_scene_path.empty() && is_pattern(o.save_scene_path)) {
    const std::vector<fs::path> photos = expand_inputs(o.inputs, {"_depth", "_disparity", "_aovs"});
    std::vector<std::pair<fs::path, fs::path>> targets;  // scene file, its photo
    for (const fs::path& photo : photos) {
      const fs::path target = expand_pattern(o.save_scene_path, photo);
      check_output_path(target);  // a FIFO, a link, a device: an error, not replaced
      for (const fs::path& input : {photo, find_depth(o, photo)})
        if (same_file(target, input))
          throw Error(ErrorCode::invalid_argument,
                      "--save-scene " + o.save_scene_path + ": " + target.string() +
                          " is an input file; refusing to overwrite it");
      for (const auto& [other, other_photo] : targets)
        if (other.lexically_normal() == target.lexically_normal())
          throw Error(ErrorCode::invalid_argument, "--save-scene " + o.save_scene_path + " gives " +
                                                       target.string() + " for both " +
                                                       other_photo.string() + " and " +
                                                       photo.string() + "; use {stem} or {name}");
      targets.emplace_back(target, photo);
    }
  } else if (!o.save_scene_path.empty()) {
    for (const fs::path& photo : expand_inputs(o.inputs))
      for (const fs::path& input : {photo, find_depth(o, photo)})
        if (same_file(o.save_scene_path, input))
          throw Error(
              ErrorCode::invalid_argument,
              "--save-scene " + o.save_scene_path + " is an input file; refusing to overwrite it");
    save_scene(o.save_scene_path, scene);
  }
  return plan;
}

// --focal-px / --fov, else the camera recorded in the --scene file (what `mr estimate` found),
// else EXIF or the default.
Camera make_camera(const FogCommandOptions& o, const FogScene& scene, const fs::path& photo_path,
                   int width, int height, const Metadata& metadata) {
  if (o.focal_px) return Camera::from_focal_px(width, height, *o.focal_px);
  if (o.fov_deg) return Camera::from_horizontal_fov(width, height, *o.fov_deg);
  if (scene.camera) {
    try {
      return camera_for_image(*scene.camera, width, height);
    } catch (const Error& e) {
      throw Error(e.code(), photo_path.string() + ": --scene " + o.scene_path + ": " + e.what() +
                                "; give --fov or --focal-px");
    }
  }
  return Camera::from_metadata(width, height, metadata);
}
Camera make_camera(const FogCommandOptions& o, const FogScene& scene, const fs::path& photo_path,
                   const Image& photo) {
  return make_camera(o, scene, photo_path, photo.width(), photo.height(), photo.metadata());
}

// The photo's annotations file (--annotations: one file, or a pattern whose file may be missing,
// meaning none), or nullopt.
std::optional<fs::path> annotations_path(const FogCommandOptions& o, const Job& job) {
  if (o.annotations.empty()) return std::nullopt;
  if (!is_pattern(o.annotations)) return fs::path(o.annotations);
  const fs::path path = expand_pattern(o.annotations, job.photo);
  std::error_code ec;
  return fs::exists(path, ec) ? std::optional<fs::path>(path) : std::nullopt;
}

// --depth auto without a depth file: the geometry from mr::estimate_scene (the photo's
// annotations file when there is one, else the automatic / level-camera estimate). The
// estimated pose (and sun, sky, when the annotations give them) replace the plan's; options on
// the command line still win. --camera-height also scales the estimated depth.
DepthMap estimate_depth(const FogCommandOptions& o, const Job& job,
                        const std::optional<fs::path>& annotations_file, const Image& photo,
                        const Camera& camera, FogScene& scene, const CancelToken* progress,
                        Image& sky_alpha) {
  try {
    Annotations annotations;
    if (annotations_file) annotations = load_annotations(*annotations_file);
    EstimateOptions options;
    options.cancel = progress;
    if (o.camera_height_m) options.default_camera_height_m = *o.camera_height_m;
    SceneEstimate est =
        estimate_scene(photo.channels() >= 3 ? photo : photo.select_channels(std::array{0, 0, 0}),
                       camera, annotations, options);
    scene.pose = est.scene.pose;
    if (o.camera_height_m) scene.pose.position_m.y = *o.camera_height_m;
    if (o.pitch_deg) scene.pose.pitch_deg = *o.pitch_deg;
    if (o.roll_deg) scene.pose.roll_deg = *o.roll_deg;
    if (o.yaw_deg) scene.pose.yaw_deg = *o.yaw_deg;
    const bool sun_given = o.sun_azimuth_deg || o.sun_elevation_deg || !o.sun_direction.empty() ||
                           !o.sun_irradiance.empty() || o.sun_radius_deg;
    if (est.scene.lighting.sun && !sun_given) scene.lighting.sun = est.scene.lighting.sun;
    // The estimate's sky radiance only where nothing set one: --airlight and a --scene file's
    // sky_radiance (e.g. a night look's dark sky) both win over it.
    if (est.scene.lighting.sky_radiance && !scene.lighting.sky_radiance)
      scene.lighting.sky_radiance = est.scene.lighting.sky_radiance;
    // Blockers stated in the photo's annotations replace the scene file's (they are this
    // photo's, in the world of its estimated pose).
    if (annotations.blockers) scene.blockers = est.scene.blockers;
    DepthMap depth;
    depth.distance_m = std::move(est.geometry.distance_m);
    depth.no_surface_pixels = est.geometry.sky_pixels;
    sky_alpha = std::move(est.geometry.sky_alpha);  // issue 11 item 4: fog() mixes along it
    return depth;
  } catch (const Error& e) {
    throw Error(e.code(),
                job.photo.string() + ": estimating the geometry (--depth auto): " + e.what());
  }
}

// The output's stored type: --bit-depth, or with auto the input's precision where the output
// format can hold it.
WriteOptions output_write_options(const FogCommandOptions& o, const FogPlan& plan, const Job& job,
                                  const ImageFileInfo& info) {
  WriteOptions write;
  write.color = &plan.color;
  write.colorspace = o.output_colorspace;
  write.pixel_type = plan.pixel_type;
  const std::string out_ext = job.output.extension().string();
  const bool exr_out = out_ext == ".exr" || out_ext == ".EXR";
  if (write.pixel_type == PixelType::automatic) {
    if (exr_out)
      write.pixel_type =
          info.pixel_type == PixelType::float32 ? PixelType::float32 : PixelType::half;
    else if (info.pixel_type == PixelType::uint16 &&
             (out_ext == ".png" || out_ext == ".tif" || out_ext == ".tiff"))
      write.pixel_type = PixelType::uint16;
  }
  // Display-referred (integer) outputs get the highlight roll-off by default (mr/color.h):
  // bright fog fades to white instead of clipping; float outputs stay linear and unclipped.
  const bool float_out = write.pixel_type == PixelType::half ||
                         write.pixel_type == PixelType::float32 ||
                         (write.pixel_type == PixelType::automatic &&
                          (exr_out || out_ext == ".hdr" || out_ext == ".HDR"));
  if (write.colorspace.empty() && !float_out) write.colorspace = plan.color.display_colorspace();
  return write;
}

// Sky statistics of a depth map, as warnings (NaN / negative values, all sky).
void warn_about_depth(Reporter& report, const FogCommandOptions& o, const std::string& depth_name,
                      std::size_t pixels, std::size_t no_surface, std::size_t invalid,
                      std::size_t sky_threshold, std::size_t clamped) {
  // Sky stored as 0 or +inf is the documented encoding; NaN or negative values are not, and an
  // all-sky map is almost certainly the wrong file or scale.
  auto percent = [&](std::size_t n) {
    char text[64];
    std::snprintf(text, sizeof text, "%.1f", 100.0 * double(n) / double(pixels));
    return std::string(text);
  };
  if (invalid > 0)
    report.warning(depth_name + ": " + std::to_string(invalid) + " pixels (" + percent(invalid) +
                   " %) are NaN or negative: treated as sky");
  if (clamped > 0)
    report.warning(depth_name + ": " + std::to_string(clamped) +
                   " pixels are farther than 10,000 km: clamped to it");
  if (o.verbose && sky_threshold > 0)
    report.info("note: " + depth_name + ": " + std::to_string(sky_threshold) +
                " pixels at or beyond --sky-depth are sky");
  if (no_surface == pixels)
    report.warning(depth_name + ": no pixel has a surface (all 0, inf or invalid): all sky");
}

// Streamers (their strip buffers) are reused from photo to photo: one per photo in flight.
class StreamerPool {
 public:
  std::unique_ptr<FogStreamer> acquire() {
    std::lock_guard lock(mutex_);
    if (free_.empty()) return std::make_unique<FogStreamer>();
    auto s = std::move(free_.back());
    free_.pop_back();
    return s;
  }
  void release(std::unique_ptr<FogStreamer> s) {
    std::lock_guard lock(mutex_);
    free_.push_back(std::move(s));
  }

 private:
  std::mutex mutex_;
  std::vector<std::unique_ptr<FogStreamer>> free_;
};

// Sky light only (no sun, lamps or noise): every pixel is a closed form, so the photo streams
// through decode -> fog -> encode in strips (mr/fog_stream.h) with the same result as the
// full-frame path below. With the sky radiance 'auto' the photo is decoded whole first (the
// dark channel prior needs all of it); the fog and the encoding still stream. nullopt: the job
// needs the full-frame path (AOVs, an estimated geometry, a forced Vulkan backend, or what
// FogStreamer declines: unusual files, and the bad inputs whose errors that path reports).
std::optional<Outcome> run_streamed(const FogCommandOptions& o, const FogPlan& plan,
                                    const Job& job, Reporter& report) {
  if (!is_sky_only(plan.scene) || plan.scene.render.backend == Backend::vulkan || o.aovs)
    return std::nullopt;
  if (!plan.scene.objects.empty()) return std::nullopt;  // objects: the full-frame path
  const PhotoProgress progress(report, job.photo.string(), {{{"render"}, 1}});
  std::error_code ec;
  if (o.depth == "auto" && !fs::exists(job.depth, ec)) return std::nullopt;
  static StreamerPool pool;
  std::unique_ptr<FogStreamer> streamer = pool.acquire();
  FogScene scene = plan.scene;  // what --save-scene records ('auto' sky stays 'auto')
  FogScene render_scene = scene;
  Image photo;
  StreamFogRequest request;
  if (!scene.lighting.sky_radiance) {
    ReadOptions read;
    read.colorspace = o.input_colorspace;
    read.color = &plan.color;
    photo = read_image(job.photo, read);
    if (photo.channels() < 3) return std::nullopt;
    render_scene.lighting.sky_radiance = estimate_airlight(photo);
    request.photo_image = &photo;
  }
  // Sky light by direction: its low-resolution map from the whole photo and depth, read once
  // here; the fog and the encoding still stream, sampling the map per pixel.
  SkyLight sky_light;
  if (scene.lighting.sky_by_direction.value_or(false)) {
    if (photo.empty()) {
      ReadOptions read;
      read.colorspace = o.input_colorspace;
      read.color = &plan.color;
      photo = read_image(job.photo, read);
      if (photo.channels() < 3) return std::nullopt;
      request.photo_image = &photo;
    }
    std::error_code size_ec;
    if (!fs::exists(job.depth, size_ec)) return std::nullopt;
    const Camera camera = make_camera(o, plan.scene, job.photo, photo);
    const DepthMap depth = read_depth(job.depth, camera, plan.depth);
    if (depth.distance_m.width() != photo.width() || depth.distance_m.height() != photo.height())
      return std::nullopt;  // the full-frame path reports it
    sky_light = sky_light_from_photo(photo, depth.distance_m, camera, render_scene,
                                     *render_scene.lighting.sky_radiance);
    request.sky_light = &sky_light;
  }
  request.photo = job.photo;
  request.depth = job.depth;
  request.output = job.output;
  request.depth_options = plan.depth;
  request.scene = &render_scene;
  request.camera = [&](int width, int height, const Metadata& metadata) {
    return make_camera(o, plan.scene, job.photo, width, height, metadata);
  };
  request.color = &plan.color;
  request.software = kOutputSoftware;  // marks the output as ours (output_safety.h)
  request.input_colorspace = o.input_colorspace;
  request.write = output_write_options(o, plan, job, probe_image(job.photo));
  const StreamFogResult result = streamer->fog_file(request, progress.token());
  pool.release(std::move(streamer));
  if (!result.streamed) return std::nullopt;
  warn_about_depth(report, o, job.depth.string(),
                   std::size_t(result.width) * std::size_t(result.height), result.no_surface_pixels,
                   result.invalid_pixels, result.sky_threshold_pixels, result.clamped_pixels);
  if (!o.save_scene_path.empty() && is_pattern(o.save_scene_path)) {
    scene.camera = scene_camera(result.camera);
    const fs::path target = expand_pattern(o.save_scene_path, job.photo);
    if (target.has_parent_path()) fs::create_directories(target.parent_path(), ec);  // as -o
    save_scene(target, scene);
  }
  return Outcome::done;
}

// The depth map's size from its header against the photo's as displayed (read_image turns the
// photo by its EXIF Orientation, read_depth the map by its own), before either is decoded.
void check_depth_size(const Job& job, const ImageFileInfo& photo) {
  const ImageFileInfo depth = probe_image(job.depth);
  auto shown = [](const ImageFileInfo& i) {
    return i.orientation >= 5 ? std::pair{i.height, i.width} : std::pair{i.width, i.height};
  };
  const auto [pw, ph] = shown(photo);
  const auto [dw, dh] = shown(depth);
  if (pw != dw || ph != dh)
    throw Error(ErrorCode::size_mismatch,
                job.depth.string() + ": depth map is " + std::to_string(dw) + "x" +
                    std::to_string(dh) + ", photo " + job.photo.string() + " is " +
                    std::to_string(pw) + "x" + std::to_string(ph));
}

Outcome run_job(const FogCommandOptions& o, const FogPlan& plan, const Job& job, Reporter& report,
                [[maybe_unused]] const std::atomic<bool>& interrupted) {
  if (!job.error.empty()) throw Error(ErrorCode::invalid_argument, job.error);
  std::error_code ec;
  const bool want_aovs_file = !job.aovs_output.empty();
  if (!o.overwrite && fs::exists(job.output, ec) &&
      (!want_aovs_file || fs::exists(job.aovs_output, ec)))
    return Outcome::skipped;
  for (const fs::path* out : {&job.output, &job.aovs_output}) {
    if (out->empty()) continue;
    for (const fs::path* in : {&job.photo, &job.depth})
      if (same_file(*out, *in))
        throw Error(ErrorCode::invalid_argument, job.photo.string() + ": output " + out->string() +
                                                     " is an input file; refusing to overwrite it");
  }
  // -v: the moment a photo's work starts (a test sends its signals on it).
  if (o.verbose) report.info("note: " + job.photo.string() + ": rendering");
  if (const std::optional<Outcome> streamed = run_streamed(o, plan, job, report)) return *streamed;
  ReadOptions read;
  read.colorspace = o.input_colorspace;
  read.color = &plan.color;
  // Sizes from the headers first: a wrong-size depth map fails before anything is decoded.
  const ImageFileInfo info = probe_image(job.photo);
  if (o.depth != "auto" || fs::exists(job.depth, ec)) check_depth_size(job, info);
  Image photo = read_image(job.photo, read);
  photo.metadata().set("Software", kOutputSoftware);  // marks the outputs as ours
  FogScene scene = plan.scene;
  const bool estimated = o.depth == "auto" && !fs::exists(job.depth, ec);
  // Estimating the geometry, a photo without EXIF focal length may get it from its vanishing
  // points (camera_for_photo); a supplied depth map keeps the documented default.
  // Issue 11: a camera-size photo is estimated, fogged and softened at a working size (the size
  // the estimate was tuned at), and its fog brought to the photo's size by guided upsampling.
  // Annotations (pixel positions) and objects (placed by pixel) keep the photo's own size.
  const std::optional<fs::path> annotations_file =
      estimated ? annotations_path(o, job) : std::nullopt;
  const std::optional<WorkingSize> working =
      estimated && !annotations_file && plan.scene.objects.empty()
          ? working_size(photo.width(), photo.height(), o.working_size)
          : std::nullopt;
  const Image working_photo =
      working ? working_copy(photo, working->width, working->height) : Image();
  const Image& work = working ? working_photo : photo;
  const Camera camera =
      estimated && !o.focal_px && !o.fov_deg && !plan.scene.camera
          ? scale_camera(camera_for_photo(work).camera, photo.width(), photo.height())
          : make_camera(o, plan.scene, job.photo, photo);
  const Camera work_camera =
      working ? scale_camera(camera, working->width, working->height) : camera;
  scene.camera = scene_camera(camera);  // what --save-scene records for this photo
  // Progress inside the photo (a bar on a terminal, -v notes in a pipe): the estimate's steps,
  // the occluders (with a sun or lamps) and the render, weighted by their usual shares of time.
  const bool lights = scene.lighting.sun || !scene.lighting.lamps.empty();
  const PhotoProgress progress(report, job.photo.string(),
                               {{estimate_stages(), estimated ? 1.0 : 0.0},
                                {{"occluders"}, lights ? 1.0 : 0.0},
                                {{"render"}, 2}});
  Image sky_alpha;  // the estimate's soft sky matte (empty for a depth file)
  DepthMap depth = estimated ? estimate_depth(o, job, annotations_file, work, work_camera, scene,
                                              progress.token(), sky_alpha)
                             : read_depth(job.depth, camera, plan.depth);
  // Issue 11 item 4: an estimated scene's fog lies in a layer with a top, so the sky is seen
  // through it (clouds and sunsets attenuated, not painted over) and the sun enters it from
  // above. Only where nothing gave the fog a top or a height profile.
  if (estimated && o.layer_top == "auto" && o.layer.empty() && !scene.medium.height_fog &&
      std::isinf(scene.medium.layer_top_m))
    scene.medium.layer_top_m = default_layer_top_m(scene.medium);
  // Issue 11: the estimated scene's fog is lit by the photo's own sky by direction unless the
  // scene file or --sky-light chose, or a sky radiance was given (--airlight, the scene file:
  // e.g. a night look's dark sky is not the photo's daylight sky).
  if (estimated && !scene.lighting.sky_by_direction && !plan.scene.lighting.sky_radiance)
    scene.lighting.sky_by_direction = true;
  const std::string depth_name =
      estimated ? job.photo.string() + " (estimated depth)" : job.depth.string();
  warn_about_depth(report, o, depth_name, depth.distance_m.pixel_count(), depth.no_surface_pixels,
                   depth.invalid_pixels, depth.sky_threshold_pixels, depth.clamped_pixels);
  // Issue 16: the scene document's objects are composited into the photo first (mr/insert.h);
  // then they take part in the fog like the photo's surfaces: their distance where they are in
  // front, their triangles among the shadow casters (shafts).
  if (!scene.objects.empty()) {
    const fs::path document =
        is_pattern(o.scene_path) ? expand_pattern(o.scene_path, job.photo) : fs::path(o.scene_path);
    std::vector<InsertObject> objects;
    for (const SceneObject& so : scene.objects) {
      InsertObject io;
      io.mesh = resolve_object_mesh(so, document.parent_path());
      for (const std::string& w : io.mesh.warnings) report.warning(w);
      io.placement = so.placement;
      io.material = so.material;
      objects.push_back(std::move(io));
    }
    InsertOptions insert_options;
    insert_options.threads = o.threads;
    InsertResult inserted = insert_objects(photo, depth.distance_m, camera, scene, objects,
                                           insert_options, progress.token());
    photo = std::move(inserted.clear_composite);
    depth.distance_m = std::move(inserted.distance_m);
    for (Blockers::Polygon& p : object_shadow_polygons(objects))
      scene.blockers.polygons.push_back(std::move(p));
  }
  ScatteringLayers aovs;
  FogLayers layers =
      fog(work, depth.distance_m, sky_alpha, work_camera, scene, &aovs, progress.token());
  // Issue 11 item 3: a guessed depth's steps where the photo has no edge become seams in the
  // fog; softened there (a depth file's fog, and shafts' edges under a sun or lamps, are kept).
  if (estimated && !lights && o.seams == "soften") {
    const SeamSoftening s = soften_fog_seams(work, layers);
    if (o.verbose && s.rounds > 0)
      report.info("note: " + job.photo.string() + ": softened the fog's seams at " +
                  std::to_string(s.pixels_changed) + " pixels (" +
                  std::to_string(s.created_before) + " created-edge pixels before, " +
                  std::to_string(s.created_after) + " after, " + std::to_string(s.rounds) +
                  " rounds)");
  }
  if (working) {
    if (o.verbose)
      report.info("note: " + job.photo.string() + ": estimated and fogged at " +
                  std::to_string(work.width()) + "x" + std::to_string(work.height()) +
                  ", brought to " + std::to_string(photo.width()) + "x" +
                  std::to_string(photo.height()) + " (--working-size)");
    layers = upsample_fog_layers(photo, working_photo, layers, o.aovs);
    if (o.aovs) {  // the other layers each working pixel's value (distances are not mixed)
      depth.distance_m = resize_nearest(depth.distance_m, photo.width(), photo.height());
      for (Image* aov : {&aovs.sun_visibility, &aovs.optical_depth})
        if (!aov->empty()) *aov = resize_nearest(*aov, photo.width(), photo.height());
    }
    for (CompletedBlocker& b : aovs.completed_blockers) {  // (-v notes: the photo's pixels)
      const double s = b.edge == CompletedBlocker::Edge::top
                           ? double(photo.width()) / work.width()
                           : double(photo.height()) / work.height();
      b.first_px = int(std::lround(b.first_px * s));
      b.last_px = int(std::lround(b.last_px * s));
    }
  }
  // The Vulkan fall-back, once per run: a warning when a GPU failed; on a machine without a
  // usable GPU the CPU is the expected choice, a note in verbose mode only.
  if (!aovs.backend_notice.empty() && (aovs.backend_notice_is_warning || o.verbose)) {
    static std::once_flag noticed;
    std::call_once(noticed, [&] {
      if (aovs.backend_notice_is_warning)
        report.warning(aovs.backend_notice);
      else
        report.info("note: " + aovs.backend_notice);
    });
  }
  // What the render guessed beyond the frame (issue 13): worth a look when a shaft seems wrong.
  if (o.verbose)
    for (const CompletedBlocker& b : aovs.completed_blockers) {
      const char* edge = b.edge == CompletedBlocker::Edge::top    ? "top"
                         : b.edge == CompletedBlocker::Edge::left ? "left"
                                                                  : "right";
      char text[256];
      std::snprintf(text, sizeof text,
                    "note: %s: a structure cut by the %s edge (pixels %d-%d) continued %s%s, "
                    "confidence %.1f",
                    job.photo.string().c_str(), edge, b.first_px, b.last_px,
                    b.vertical ? "up" : "along its plane", b.prism ? " as a box" : "",
                    b.confidence);
      std::string line = text;
      if (b.vertical) {
        std::snprintf(text, sizeof text, " (to %.1f m)", b.top_m);
        line.insert(line.find(", confidence"), text);
      }
      report.info(line);
    }
  // Interrupted (Ctrl-C) while this photo rendered: it is finished and written all the same
  // (the README's promise); only photos not yet started are left.

  const WriteOptions write = output_write_options(o, plan, job, info);
  const std::string out_ext = job.output.extension().string();
  const bool exr_out = out_ext == ".exr" || out_ext == ".EXR";
  // R,G,B + transmittance.RGB + inscatter.RGB + depth.Z + sun_visibility.Y + optical_depth.RGB
  auto write_layers = [&](const fs::path& path, PixelType type) {
    const Image composite_rgb = layers.composite.select_channels(std::array{0, 1, 2});
    const ExrLayer exr[] = {{"", &composite_rgb},
                            {"transmittance", &layers.transmittance},
                            {"inscatter", &layers.inscatter},
                            {"depth", &depth.distance_m, true},
                            {"sun_visibility", &aovs.sun_visibility, true},
                            {"optical_depth", &aovs.optical_depth, true}};
    write_exr_layers(path, exr, photo.metadata(), type);
  };
  if (o.aovs && exr_out) {
    if (!o.output_colorspace.empty())
      report.warning(job.output.string() +
                     ": layered EXR output is scene-linear; --output-colorspace ignored");
    write_layers(job.output,
                 write.pixel_type == PixelType::float32 ? PixelType::float32 : PixelType::half);
  } else {
    write_image(job.output, layers.composite, write);
    if (want_aovs_file) write_layers(job.aovs_output, PixelType::half);
  }
  // The scene this photo was rendered with (with --depth auto: its estimated pose, sun, sky).
  if (!o.save_scene_path.empty() && is_pattern(o.save_scene_path)) {
    const fs::path target = expand_pattern(o.save_scene_path, job.photo);
    if (target.has_parent_path()) fs::create_directories(target.parent_path(), ec);  // as -o
    save_scene(target, scene);
  }
  return Outcome::done;
}

}  // namespace

CLI::App* add_fog_command(CLI::App& app, FogCommandOptions& o) {
  CLI::App* cmd = app.add_subcommand(
      "fog", "Fog photos using their depth maps: single scattering of sun, sky and lamps");
  cmd->add_option("inputs", o.inputs,
                  "Photos: files, folders or globs (in folders and globs, *_depth, *_disparity "
                  "and *_aovs files are not photos)")
      ->required();
  cmd->add_option(
      "--depth", o.depth,
      "Depth map: a pattern with {dir} {stem} {name} {ext}, or one file for all "
      "[default: {dir}/{stem}_depth.{exr,tif,tiff,pfm,png}, first that exists]; 'auto': "
      "that search, and where it finds nothing the geometry is estimated from the photo");
  cmd->add_option(
      "--annotations", o.annotations,
      "With --depth auto: annotations JSON (docs/annotations.md), a pattern like --depth "
      "(a photo without its file: automatic)");
  cmd->add_option("--depth-kind", o.depth_kind, "distance (along the ray), z (planar) or disparity")
      ->capture_default_str();
  cmd->add_option("--depth-scale", o.depth_scale,
                  "Multiplies stored depth values (integer files: raw codes), e.g. 0.001 for mm")
      ->capture_default_str();
  cmd->add_option("--baseline", o.baseline_m, "Stereo baseline in metres (disparity maps)");
  cmd->add_option("--doffs", o.doffs_px, "Disparity offset in pixels (Middlebury 'doffs')");
  auto* fov =
      cmd->add_option("--fov", o.fov_deg,
                      "Horizontal field of view in degrees [default: EXIF, else 60; with an "
                      "estimated depth (--depth auto): EXIF, else from orthogonal vanishing "
                      "points when confident, else 60]");
  cmd->add_option("--focal-px", o.focal_px, "Focal length in pixels")->excludes(fov);
  auto* vis = cmd->add_option(
      "--visibility", o.visibility,
      "Meteorological visibility, e.g. 150m or 1.2km (sigma = 3.912 / V) [default: 150m]");
  cmd->add_option("--density", o.density, "Extinction coefficient in 1/m: one value or R,G,B")
      ->excludes(vis);
  cmd->add_option("--airlight", o.airlight,
                  "Fog colour, scene-linear: 'auto' (dark channel prior), one value or R,G,B")
      ->capture_default_str();
  cmd->add_option("-o,--out-dir", o.out_dir, "Output folder (created if missing)")
      ->capture_default_str();
  cmd->add_option("--suffix", o.suffix, "Appended to each output's name")->capture_default_str();
  cmd->add_option("--format", o.format,
                  "Output format by extension: jpg, png, tif, exr, ... [default: the input's]");
  cmd->add_option("--bit-depth", o.bit_depth,
                  "8, 16, half, float or auto (the input's where possible)")
      ->capture_default_str();
  cmd->add_flag("--aovs", o.aovs,
                "Also write layers R,G,B + transmittance.RGB + inscatter.RGB + depth.Z "
                "(into the output if it is .exr, else into <name>_aovs.exr)");
  cmd->add_option("-j,--threads", o.threads, "Worker threads [default: all cores]")
      ->check(CLI::Range(0, kMaxThreads));
  cmd->add_flag("-q,--quiet", o.quiet, "Print errors and the summary only");
  cmd->add_flag("-v,--verbose", o.verbose,
                "Also print notes: each photo as it renders, its progress (stages and fractions, "
                "when stderr is not a terminal), the backend chosen, files cleaned up");
  cmd->add_option("--sky-depth", o.sky_depth_m,
                  "Stored depth values (times --depth-scale) at or above this are sky, metres; "
                  "reads Blender's 1e10, 1e6 and 65504 as sky; inf: none")
      ->capture_default_str();
  cmd->add_option("--max-megapixels", o.max_megapixels,
                  "Refuse photos and depth maps larger than this when decoded (checked from "
                  "the header)")
      ->capture_default_str();
  cmd->add_flag("--overwrite", o.overwrite, "Redo photos whose outputs exist (default: skip them)");
  cmd->add_option("--scene", o.scene_path,
                  "Scene JSON (docs/scene.md); options below override it (its camera, from mr "
                  "estimate, sets the focal length unless --fov or --focal-px is given)");
  cmd->add_option(
      "--save-scene", o.save_scene_path,
      "Write the resolved scene JSON here; a pattern with {dir} {stem} {name} {ext}: one "
      "per photo, the scene it was rendered with (its camera; --depth auto: its estimated "
      "pose, sun and sky)");
  cmd->add_option("--quality", o.quality, "draft, normal or final [default: normal]");
  cmd->add_option(
      "--backend", o.backend,
      "auto, cpu or vulkan [default: auto: Vulkan on a GPU, else the CPU with a notice]");
  cmd->add_option("--shadow-traversal", o.shadow_traversal,
                  "CPU shadow rays: embree or multi-index (seed 004's kd-tree; same answers, "
                  "see README 'Shadow-ray traversal') [default: embree]");
  cmd->add_option("--sun-azimuth", o.sun_azimuth_deg,
                  "Sun azimuth, degrees (0 = the camera's forward at yaw 0, 90 = right)");
  cmd->add_option("--sun-elevation", o.sun_elevation_deg,
                  "Sun elevation above the horizon, degrees");
  cmd->add_option("--sun-dir", o.sun_direction, "Direction to the sun x,y,z (world: +Y up)");
  cmd->add_option("--sun-irradiance", o.sun_irradiance,
                  "Sun irradiance above the fog: v, R,G,B or 'auto' [default: auto: pi x the "
                  "photo's bright-surface luminance, so the sun matches the exposure]");
  cmd->add_option("--sun-radius", o.sun_radius_deg,
                  "Sun's angular radius, degrees (soft shafts) [default: 0.27]");
  cmd->add_option("--lamp", o.lamps,
                  "A lamp: x,y,z[;R,G,B] (position m; intensity per sr; none or 'auto': "
                  "relative to the photo's exposure), spot: add ;dx,dy,dz;inner,outer "
                  "(degrees). Repeatable");
  cmd->add_option("--height-fog", o.height_fog,
                  "Exponential height fog: base,scale (m); density exp(-(y - base) / scale)");
  cmd->add_option("--layer", o.layer, "Fog only between heights bottom,top (m)");
  cmd->add_option("--layer-top", o.layer_top,
                  "The fog's top (height above the ground: 60m, 1.5km), 'none', or 'auto': with "
                  "--depth auto estimating the geometry and no --layer / --height-fog / scene "
                  "top, half the visibility within 30 m..2 km (the sky is seen through the fog)")
      ->default_str("auto");
  cmd->add_option("--sky-light", o.sky_light,
                  "The sky light in the fog: 'direction' (each view ray takes the photo's own "
                  "sky around its direction, phase-weighted, the ground below the horizon: "
                  "sunsets and sky gradients survive haze), 'uniform' (one sky radiance), or "
                  "'auto': the scene's, else direction when --depth auto estimates the geometry and "
                  "no --airlight or scene sky radiance is given")
      ->default_str("auto");
  cmd->add_option("--seams", o.seams,
                  "With --depth auto estimating the geometry and no sun or lamps: 'soften' the "
                  "fog where the guessed depth makes edges the photo does not have (a smooth fog "
                  "there instead of a seam), or 'keep' them")
      ->check(CLI::IsMember({"soften", "keep"}))
      ->default_str("soften");
  cmd->add_option("--working-size", o.working_size,
                  "With --depth auto estimating the geometry (no annotations, no objects): a "
                  "photo larger than this (its longer side, px) is estimated, fogged and softened "
                  "at this size, and the fog brought to the photo's size by guided upsampling "
                  "(its edges follow the photo's); 0: at the photo's own size")
      ->check(CLI::Range(0, 1000000))
      ->capture_default_str();
  cmd->add_option("--albedo", o.albedo, "Single-scattering albedo: v or R,G,B [default: 1]");
  cmd->add_option("--g", o.g, "Henyey-Greenstein asymmetry in (-1, 1) [default: 0]");
  cmd->add_option("--noise", o.noise, "Wisps: amplitude[,scale m[,octaves[,seed]]]");
  cmd->add_option("--camera-height", o.camera_height_m,
                  "Camera height above the ground, m [default: 1.6]");
  cmd->add_option("--pitch", o.pitch_deg, "Camera pitch, degrees (positive looks up)");
  cmd->add_option("--roll", o.roll_deg, "Camera roll, degrees");
  cmd->add_option("--yaw", o.yaw_deg, "Camera yaw, degrees");
  cmd->add_option("--seed", o.seed, "Jitter / noise seed");
  cmd->add_option("--march-steps", o.march_steps, "View-ray steps (overrides the quality preset)");
  cmd->add_flag("--no-shadows", o.no_shadows, "No volumetric shadows (lights are never blocked)");
  cmd->add_option("--ocio-config", o.ocio_config,
                  "OpenColorIO config [default: $OCIO, else the built-in one]");
  cmd->add_option(
      "--input-colorspace", o.input_colorspace,
      "Colour space of the photos [default: sRGB for 8/16-bit, scene-linear for float]");
  cmd->add_option(
      "--output-colorspace", o.output_colorspace,
      "Colour space of the outputs [default: 8/16-bit: srgb_rolloff (sRGB with a highlight "
      "roll-off above 0.8 linear) where the config has it, else sRGB; float: scene-linear]");
  return cmd;
}

int run_fog_command(const FogCommandOptions& o, const std::atomic<bool>& interrupted) {
  const auto start = std::chrono::steady_clock::now();
  FogPlan plan;
  try {
    plan = make_plan(o);
  } catch (const Error& e) {
    std::fprintf(stderr, "ERROR: %s\n", e.what());
    return 2;
  }
  for (const std::string& warning : scene_warnings(plan.scene))
    std::fprintf(stderr, "WARNING: %s\n", warning.c_str());

  // Jobs: photo -> depth, outputs. Depth maps named on the command line are not photos.
  std::vector<std::string> input_warnings;
  std::vector<fs::path> photos =
      expand_inputs(o.inputs, {"_depth", "_disparity", "_aovs"}, &input_warnings);
  if (!o.quiet)
    for (const std::string& w : input_warnings) std::fprintf(stderr, "WARNING: %s\n", w.c_str());
  std::vector<Job> jobs;
  {
    std::vector<fs::path> depths;
    for (const auto& p : photos) depths.push_back(find_depth(o, p));
    const fs::path out_dir(o.out_dir);
    for (std::size_t i = 0; i < photos.size(); ++i) {
      const fs::path& p = photos[i];
      bool is_depth = false;
      for (const auto& d : depths)
        is_depth = is_depth || p.lexically_normal() == d.lexically_normal();
      // Our own earlier outputs in the same folder are not inputs; a user's photo named like one
      // (c_fog.jpg beside c.jpg) is: only files marked by mr fog (output_safety.h) are ours.
      const bool is_output = p.stem().string().ends_with(o.suffix) && !o.suffix.empty() &&
                             same_file(p.parent_path().empty() ? "." : p.parent_path(), out_dir) &&
                             written_by_mr_fog(p);
      if (is_depth || is_output) continue;
      const std::string ext = o.format.empty() ? p.extension().string() : "." + o.format;
      Job job{p, depths[i], out_dir / (p.stem().string() + o.suffix + ext), {}, {}};
      if (o.aovs && ext != ".exr" && ext != ".EXR")
        job.aovs_output = out_dir / (p.stem().string() + o.suffix + "_aovs.exr");
      jobs.push_back(std::move(job));
    }
    // Outputs are never an input of the run (a photo, a depth map) and never shared by two
    // photos (d1/x.jpg and d2/x.jpg into one folder; x.jpg and x.png with one --format): such
    // photos fail here, before anything renders, rather than one output silently replacing
    // another or an input.
    std::vector<fs::path> inputs;
    for (const Job& job : jobs) inputs.insert(inputs.end(), {job.photo, job.depth});
    if (!o.scene_path.empty()) inputs.emplace_back(o.scene_path);
    std::vector<std::vector<PlannedOutput>> outputs;
    for (const Job& job : jobs) {
      std::vector<PlannedOutput> own{{job.output, job.photo.string()}};
      if (!job.aovs_output.empty()) own.push_back({job.aovs_output, job.photo.string()});
      if (!o.save_scene_path.empty() && is_pattern(o.save_scene_path))
        own.push_back({expand_pattern(o.save_scene_path, job.photo), job.photo.string()});
      outputs.push_back(std::move(own));
    }
    const std::vector<std::string> errors = check_planned_outputs(inputs, outputs);
    for (std::size_t i = 0; i < jobs.size(); ++i) jobs[i].error = errors[i];
  }
  if (jobs.empty()) {
    std::fprintf(stderr, "ERROR: no input photos found in: %s\n",
                 CLI::detail::join(o.inputs, " ").c_str());
    return 2;
  }
  std::error_code ec;
  fs::create_directories(o.out_dir, ec);
  if (!fs::is_directory(o.out_dir, ec)) {
    std::fprintf(stderr, "ERROR: %s: cannot create output folder\n", o.out_dir.c_str());
    return 2;
  }
  // Hidden temporaries of runs that were killed (kill -9) before they could remove them.
  for (const fs::path& stale : remove_stale_temporaries(o.out_dir))
    if (o.verbose) std::fprintf(stderr, "note: removed %s (left by a killed run)\n", stale.c_str());

  Reporter report(jobs.size(), o.quiet, o.verbose);
  std::atomic<std::size_t> done{0}, skipped{0}, failed{0}, interrupted_jobs{0};
  std::mutex failures_mutex;
  std::vector<std::string> failures;
  // -j is at most kMaxThreads (the parser), and photos in flight beyond 4 per core only cost
  // memory and threads (each holds a photo; thread creation can fail under a memory limit).
  const int cores = tbb::this_task_arena::max_concurrency();
  const int threads = o.threads > 0 ? std::min(o.threads, 4 * cores) : cores;
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
  tbb::task_arena arena(threads);
  arena.execute([&] {
    // Photos in parallel (grain 1) overlap one photo's decode with another's compute.
    tbb::parallel_for(std::size_t(0), jobs.size(), [&](std::size_t i) {
      const Job& job = jobs[i];
      if (interrupted) {
        ++interrupted_jobs;
        return;
      }
      Outcome outcome;
      try {
        outcome = run_job(o, plan, job, report, interrupted);
        if (outcome == Outcome::failed) ++interrupted_jobs;
      } catch (const std::exception& e) {
        // mr::Error names the file; anything else (bad_alloc) gets the photo's name.
        std::string msg =
            dynamic_cast<const Error*>(&e) ? e.what() : job.photo.string() + ": " + e.what();
        report.error(msg);
        std::lock_guard lock(failures_mutex);
        failures.push_back(std::move(msg));
        outcome = Outcome::failed;
        ++failed;
      }
      if (outcome == Outcome::done) ++done;
      if (outcome == Outcome::skipped) ++skipped;
      report.advance(job.photo.filename().string());
    });
  });
  report.finish();

  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::fprintf(stderr, "mr fog: %zu done, %zu skipped (outputs exist), %zu failed", done.load(),
               skipped.load(), failed.load());
  if (interrupted_jobs)
    std::fprintf(stderr, ", %zu not started (interrupted)", interrupted_jobs.load());
  std::fprintf(stderr, " in %.1f s; outputs in %s\n", seconds, o.out_dir.c_str());
  if (!failures.empty() && failures.size() < jobs.size() && !o.quiet) {
    std::fprintf(stderr, "failed:\n");
    for (const auto& f : failures) std::fprintf(stderr, "  %s\n", f.c_str());
  }
  if (interrupted) return 130;
  return failed ? 1 : 0;
}

}  // namespace mr::cli
