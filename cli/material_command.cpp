#include "material_command.h"

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numbers>
#include <vector>


#include "batch.h"
#include "mr/material.h"
#include "mr/mr.h"
#include "output_safety.h"
#include "progress.h"

namespace fs = std::filesystem;

namespace mr::cli {

namespace {

constexpr const char* kDepthExtensions[] = {".exr", ".tif", ".tiff", ".pfm", ".png"};

// The default light when no scene JSON is given: a sun behind-left of the camera (azimuth
// yaw - 135 deg) 45 deg above the horizon plus a uniform grey sky, the sun's irradiance 2 pi
// times the sky's radiance (a sunny day: a level surface gets 1.41 L from the sun and L from the
// sky). The level is an exposure guess in the spirit of grey world: the 90th percentile of the
// photo's surface luminance is taken to be a level surface of albedo 0.8, i.e.
// L = p90 / (0.8 * 2.41) (the brightest surfaces are near-white, and do not clip the fitted
// albedos).
constexpr double kSunAzimuthFromViewDeg = -135, kSunElevationDeg = 45;
constexpr double kSunToSkyRatio = 2 * std::numbers::pi;
constexpr double kBrightSurfaceAlbedo = 0.8;
constexpr double kBrightSurfacePercentile = 0.9;

struct LoadedPhoto {
  Image photo;
  Image distance_m;
  Camera camera;
  FogScene scene;
  std::string depth_note, light_note;
};

// "a.json" -> annotations; anything else -> none.
bool is_json(const std::string& path) {
  std::string ext = fs::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  return ext == ".json";
}

double bright_surface_luminance(const Image& photo, const Image& distance_m) {
  std::vector<float> l;
  l.reserve(photo.pixel_count());
  for (int y = 0; y < photo.height(); ++y)
    for (int x = 0; x < photo.width(); ++x) {
      const float d = distance_m.at(x, y, 0);
      if (!(d > 0) || !std::isfinite(d)) continue;
      const float* p = photo.pixel(x, y);
      l.push_back(0.2126f * p[0] + 0.7152f * p[1] + 0.0722f * p[2]);
    }
  if (l.empty()) return 0;
  const std::size_t k = std::size_t(kBrightSurfacePercentile * double(l.size() - 1));
  std::nth_element(l.begin(), l.begin() + k, l.end());
  return l[k];
}

// The default sun and sky at sky radiance `sky` (the sun's irradiance kSunToSkyRatio * sky).
Lighting default_lighting_at(float sky, const CameraPose& pose) {
  Lighting l;
  Sun sun;
  sun.direction_to_sun =
      direction_from_azimuth_elevation(pose.yaw_deg + kSunAzimuthFromViewDeg, kSunElevationDeg);
  const float e = float(kSunToSkyRatio) * sky;
  sun.irradiance = {e, e, e};
  l.sun = sun;
  l.sky_radiance = Rgb{sky, sky, sky};
  return l;
}

Lighting default_lighting(const Image& photo, const Image& distance_m, const CameraPose& pose,
                          std::string& note) {
  const double bright = bright_surface_luminance(photo, distance_m);
  const double level_factor =
      kSunToSkyRatio * std::sin(kSunElevationDeg * std::numbers::pi / 180) / std::numbers::pi + 1;
  const float sky = float(std::max(bright, 1e-4) / (kBrightSurfaceAlbedo * level_factor));
  Lighting l = default_lighting_at(sky, pose);
  const float e = float(kSunToSkyRatio) * sky;
  char text[256];
  std::snprintf(text, sizeof text,
                "default light: sun behind-left of the camera (azimuth %.0f, elevation %.0f deg), "
                "irradiance %.4g; "
                "sky radiance %.4g (exposure: 90th percentile of surface luminance %.4g = albedo "
                "%.2f, level)",
                pose.yaw_deg + kSunAzimuthFromViewDeg, kSunElevationDeg, double(e), double(sky),
                bright, kBrightSurfaceAlbedo);
  note = text;
  return l;
}

LoadedPhoto load_photo(const std::string& path, const std::string& depth_option,
                       const std::string& scene_path, std::optional<double> fov_deg,
                       const Annotations* annotations, const CancelToken* progress) {
  LoadedPhoto p;
  p.photo = read_image(path);
  if (p.photo.channels() < 3) p.photo = p.photo.select_channels(std::array{0, 0, 0});
  p.camera = fov_deg ? Camera::from_horizontal_fov(p.photo.width(), p.photo.height(), *fov_deg)
                     : Camera::from_metadata(p.photo.width(), p.photo.height(), p.photo.metadata());
  if (!scene_path.empty()) p.scene = load_scene(scene_path);
  fs::path depth_file;
  if (!depth_option.empty() && depth_option != "auto") {
    depth_file = depth_option;
  } else {
    std::error_code ec;
    for (const char* ext : kDepthExtensions) {
      const fs::path candidate = expand_pattern(std::string("{dir}/{stem}_depth") + ext, path);
      if (fs::exists(candidate, ec)) {
        depth_file = candidate;
        break;
      }
    }
  }
  if (!depth_file.empty()) {
    p.distance_m = read_depth(depth_file, p.camera).distance_m;
    p.depth_note = "depth " + depth_file.string() +
                   (scene_path.empty() ? "; pose: level camera 1.6 m above the ground"
                                       : "; pose from " + scene_path);
  } else {
    // As `mr fog --depth auto`: the geometry estimated from the photo (and its annotations).
    EstimateOptions options;
    options.cancel = progress;
    const SceneEstimate est =
        estimate_scene(p.photo, p.camera, annotations ? *annotations : Annotations{}, options);
    p.distance_m = est.geometry.distance_m;
    if (scene_path.empty()) p.scene.pose = est.scene.pose;
    p.depth_note = std::string("depth estimated from the photo") +
                   (annotations ? " and its annotations" : "") + " (no " +
                   fs::path(path).stem().string() +
                   "_depth file), horizon: " + to_string(est.geometry.horizon_source);
  }
  if (scene_path.empty()) {
    p.scene.lighting = default_lighting(p.photo, p.distance_m, p.scene.pose, p.light_note);
  } else {
    p.light_note = "lighting from " + scene_path;
    if (!p.scene.lighting.sky_radiance) p.light_note += " (no sky radiance in it: no sky light)";
  }
  return p;
}

// A 3D scene target (no photo): its distance map, the camera from --fov (else 60 degrees) at
// the map's size, the scene JSON's pose and light, else a level camera and the default light at
// sky radiance 1.
LoadedPhoto load_scene_target(const std::string& depth_path, const std::string& scene_path,
                              std::optional<double> fov_deg) {
  LoadedPhoto p;
  const ImageFileInfo info = probe_image(depth_path);
  p.camera = Camera::from_horizontal_fov(info.width, info.height, fov_deg.value_or(60.0));
  p.distance_m = read_depth(depth_path, p.camera).distance_m;
  p.depth_note = "3D scene: distance map " + depth_path + " (no photo; regions over black)";
  if (!scene_path.empty()) {
    p.scene = load_scene(scene_path);
    p.light_note = "pose and lighting from " + scene_path;
  } else {
    p.scene.lighting = default_lighting_at(1.0f, p.scene.pose);
    p.light_note = "default light at sky radiance 1 (sun behind-left of the camera, 45 deg up)";
  }
  return p;
}

}  // namespace

CLI::App* add_material_command(CLI::App& app, MaterialCommandOptions& o) {
  CLI::App* cmd = app.add_subcommand(
      "material",
      "Give regions of a photo the material look of a sample image: BRDFs fitted to the sample's "
      "segments, assigned to the regions by a search (every assignment, or Tabu search for many "
      "regions), re-rendered under the photo's light");
  cmd->add_option("--sample", o.sample, "Sample image with the wanted look")->required();
  cmd->add_option("--target", o.target,
                  "Photo whose regions get the look (without it: --target-depth is a 3D scene's "
                  "distance map, rendered over black)");
  cmd->add_option(
         "--regions", o.regions,
         "Regions of the target: a mask image (one channel of ids 1..n, 0 = none; or distinct "
         "non-black colours) or an annotations JSON (each plane polygon one region)")
      ->required();
  cmd->add_option("-o,--output", o.output,
                  "Output image (format from the extension; 8/16-bit: the changed pixels through "
                  "the highlight roll-off, the rest as the photo; EXR: scene-linear)")
      ->required();
  cmd->add_option("--materials-json", o.materials_json,
                  "Write the candidates and the chosen materials here");
  cmd->add_option(
      "--sample-depth", o.sample_depth,
      "Sample's distance map [default: {dir}/{stem}_depth.{exr,tif,tiff,pfm,png}, else estimated]");
  cmd->add_option("--target-depth", o.target_depth,
                  "Target's distance map [default: as --sample-depth]");
  cmd->add_option(
      "--sample-scene", o.sample_scene,
      "Scene JSON for the sample (pose, lighting) [default: level camera, default light]");
  cmd->add_option("--target-scene", o.target_scene,
                  "Scene JSON for the target (e.g. from `mr estimate`)");
  cmd->add_option("--sample-fov", o.sample_fov_deg,
                  "Sample's horizontal field of view, degrees [default: EXIF, else 60]")
      ->check(CLI::Range(0.0, 180.0));
  cmd->add_option("--fov", o.target_fov_deg,
                  "Target's horizontal field of view, degrees [default: EXIF, else 60]")
      ->check(CLI::Range(0.0, 180.0));
  cmd->add_option("--seed", o.seed, "Tabu search seed (many regions only) [default: 1]");
  cmd->add_option("--max-candidates", o.max_candidates,
                  "Candidate materials kept from the sample (1..64)")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  cmd->add_option("--smoothness", o.smoothness,
                  "Weight of the material-gradient term between neighbouring regions")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_flag("--no-detail", o.no_detail,
                "Do not carry the photo's fine texture into the new material");
  cmd->add_flag("--physical-exposure", o.physical_exposure,
                "Render each region at the photo's own exposure even where the new material "
                "goes beyond the photo's white (default: such a region is exposed down as a "
                "whole until 99 % of it is within, keeping its texture)");
  cmd->add_option("--visibility", o.visibility,
                  "Also fog the result: meteorological visibility, e.g. 150m");
  cmd->add_option("-j,--threads", o.threads, "Worker threads [default: all cores]")
      ->check(CLI::Range(0, kMaxThreads));
  cmd->add_flag("--overwrite", o.overwrite, "Replace existing outputs (default: refuse)");
  cmd->add_flag("-q,--quiet", o.quiet, "Print only errors");
  cmd->add_flag("-v,--verbose", o.verbose,
                "Progress notes on stderr when it is not a terminal (on a terminal: a bar)");
  return cmd;
}

int run_material_command(const MaterialCommandOptions& o) {
  // The report goes to stdout (buffered when piped), errors to stderr: flush the report first,
  // so that the error is the last line a user or a script's `tail` sees, and the only one.
  auto fail = [](int code, const std::string& message) {
    std::fflush(stdout);
    std::fprintf(stderr, "ERROR: %s\n", message.c_str());
    return code;
  };
  // Outputs: writable formats, never an input (with the depth maps found beside the photos,
  // which mr fog reads too; not even with --overwrite), only regular files, never silently
  // replaced.
  std::vector<std::string> inputs = {o.sample,       o.target,       o.regions,     o.sample_depth,
                                     o.target_depth, o.sample_scene, o.target_scene};
  for (const auto& [photo, depth] : {std::pair{&o.sample, &o.sample_depth}, {&o.target, &o.target_depth}})
    if (!photo->empty() && (depth->empty() || *depth == "auto"))
      for (const char* ext : kDepthExtensions)
        inputs.push_back(expand_pattern(std::string("{dir}/{stem}_depth") + ext, *photo).string());
  for (const std::string* out : {&o.output, &o.materials_json}) {
    if (out->empty()) continue;
    for (const std::string& in : inputs)
      if (!in.empty() && in != "auto" && same_file(*out, in))
        return fail(2, *out + ": is an input file; refusing to overwrite it");
    try {
      check_output_path(*out);
    } catch (const Error& e) {
      return fail(2, e.what());
    }
    std::error_code ec;
    if (!o.overwrite && fs::exists(*out, ec))
      return fail(2, *out + ": exists (pass --overwrite to replace it)");
    remove_stale_temporaries(fs::path(*out).parent_path());
  }
  if (!is_writable_image_extension(o.output))
    return fail(2, o.output + ": not an image format that can be written");
  if (!o.materials_json.empty() && same_file(o.materials_json, o.output))
    return fail(2, "--materials-json and -o name the same file");
  double sigma = 0;
  if (!o.visibility.empty()) {
    try {
      sigma = extinction_from_visibility(parse_distance_m(o.visibility));
    } catch (const std::exception& e) {
      return fail(2, "--visibility '" + o.visibility + "': " + e.what());
    }
  }

  const bool scene_target = o.target.empty();
  if (scene_target && (o.target_depth.empty() || o.target_depth == "auto"))
    return fail(2, "--target (a photo) or --target-depth (a 3D scene's distance map) is required");

  const auto start = std::chrono::steady_clock::now();
  // Progress on stderr: a bar on a terminal, -v notes in a pipe. The shares: measured on the
  // test scenes, the fits are most of a transfer; an estimated depth adds its steps.
  Reporter report(1, o.quiet, o.verbose);
  const PhotoProgress progress(report, scene_target ? o.target_depth : o.target,
                               {{estimate_stages(), 1},
                                {{"target geometry"}, 1},
                                {{"sample geometry"}, 1},
                                {{"segments"}, 1},
                                {{"fit"}, 4},
                                {{"statistics"}, 1},
                                {{"search"}, 1},
                                {{"apply"}, 1}});
  LoadedPhoto sample, target;
  Image labels;
  try {
    std::optional<Annotations> annotations;
    if (is_json(o.regions)) annotations = load_annotations(o.regions);
    target = scene_target ? load_scene_target(o.target_depth, o.target_scene, o.target_fov_deg)
                          : load_photo(o.target, o.target_depth, o.target_scene, o.target_fov_deg,
                                       annotations ? &*annotations : nullptr, progress.token());
    sample = load_photo(o.sample, o.sample_depth, o.sample_scene, o.sample_fov_deg, nullptr,
                        progress.token());
    labels = load_region_labels(o.regions, target.camera.width, target.camera.height);
  } catch (const Error& e) {
    report.finish();
    const bool usage =
        e.code() == ErrorCode::invalid_argument || e.code() == ErrorCode::size_mismatch;
    return fail(usage ? 2 : 1, e.what());
  }
  if (!o.quiet) {
    report.finish();  // the bar is redrawn by the next report
    std::printf("sample %s: %dx%d; %s\n  %s\n", o.sample.c_str(), sample.photo.width(),
                sample.photo.height(), sample.depth_note.c_str(), sample.light_note.c_str());
    std::printf("target %s: %dx%d; %s\n  %s\n",
                scene_target ? o.target_depth.c_str() : o.target.c_str(), target.camera.width,
                target.camera.height, target.depth_note.c_str(), target.light_note.c_str());
  }
  MaterialTransferOptions options;
  options.max_candidates = o.max_candidates;
  options.smoothness_weight = o.smoothness;
  options.keep_detail = !o.no_detail;
  options.fit_photo_range = !o.physical_exposure;
  options.threads = o.threads;
  if (o.seed) options.seed = *o.seed;
  options.cancel = progress.token();
  MaterialTransferResult result;
  try {
    const ShadedPhoto s{&sample.photo, &sample.distance_m, sample.camera, sample.scene};
    const ShadedPhoto t{scene_target ? nullptr : &target.photo, &target.distance_m, target.camera,
                        target.scene};
    result = transfer_material(s, t, labels, options);
    report.finish();
  } catch (const Error& e) {
    report.finish();
    // The library's messages say which input they are about; name its file.
    const std::string message = e.what();
    const bool regions = message.starts_with("region");
    const std::string& file = regions ? o.regions
                              : message.starts_with("target")
                                  ? (scene_target ? o.target_depth : o.target)
                                  : o.sample;
    return fail(regions ? 2 : 1, file + ": " + message);
  }
  try {
    Image out = std::move(result.image);
    if (sigma > 0) {
      FogScene fog_scene = target.scene;
      fog_scene.medium.sigma_t_per_m = {float(sigma), float(sigma), float(sigma)};
      fog_scene.render.threads = o.threads;
      out = fog(out, target.distance_m, target.camera, fog_scene).composite;
    }
    WriteOptions write;
    write.overwrite = true;  // checked above
    // Display-referred (integer) outputs through the highlight roll-off, as `mr fog` and
    // `mr insert` write them (DESIGN.md section 7): a light material on a surface the photo shows
    // dark and brightly lit (sunlit patches in shaded foliage) comes out above the photo's white
    // and would clip flat under plain sRGB. Only the pixels the transfer changed are rolled off:
    // the rest of the photo stays exactly as it was (its own highlights included), unless fog
    // changed every pixel. Float outputs stay linear and unclipped. A 16-bit photo stays 16-bit
    // (a PNG output was 8-bit).
    const PhotoOutputEncoding encoding =
        photo_output_encoding(o.output, scene_target ? fs::path() : fs::path(o.target));
    const ColorConfig color = ColorConfig::from_environment();
    const bool rolloff = color.display_colorspace() == std::string(colorspace::srgb_rolloff);
    write.color = &color;
    write.pixel_type = encoding.pixel_type;
    if (encoding.display_referred && rolloff) {
      if (sigma > 0 || scene_target) {
        write.colorspace = colorspace::srgb_rolloff;
      } else {
        const Image& photo = target.photo;
        for (int y = 0; y < out.height(); ++y)
          for (int x = 0; x < out.width(); ++x) {
            bool changed = false;
            for (int c = 0; c < 3; ++c) changed = changed || out.at(x, y, c) != photo.at(x, y, c);
            if (changed)
              for (int c = 0; c < 3; ++c)
                out.at(x, y, c) = float(highlight_rolloff(out.at(x, y, c)));
          }
      }
    }
    write_image(o.output, out, write);
    result.image = Image();
    if (!o.materials_json.empty())
      mr::write_text_file(o.materials_json, material_result_to_json(result));
  } catch (const Error& e) {
    return fail(1, e.what());
  }
  if (!o.quiet) {
    for (const std::string& note : result.notes) std::printf("  %s\n", note.c_str());
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::printf("wrote %s%s%s in %.1f s\n", o.output.c_str(), o.materials_json.empty() ? "" : ", ",
                o.materials_json.c_str(), seconds);
  }
  return 0;
}

}  // namespace mr::cli
