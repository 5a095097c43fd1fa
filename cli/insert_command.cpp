// `mr insert`: 3D objects into a batch of photos (issue 16), through mr::insert_objects
// (mr/insert.h). Per photo: its depth map (a file found by pattern, or --depth auto: estimated),
// its scene document (a pattern gives each photo its own: pose, light, medium, objects), the
// objects of the document and of the command line, the render, and the outputs written
// atomically; one bad photo is reported (naming its file) and the batch goes on.
#include "insert_command.h"

#include <CLI/CLI.hpp>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "batch.h"
#include "mr/annotations.h"
#include "mr/color.h"
#include "mr/depth.h"
#include "mr/error.h"
#include "mr/estimate.h"
#include "mr/fog.h"
#include "mr/insert.h"
#include "mr/io.h"
#include "mr/object_io.h"
#include "mr/objects.h"
#include "mr/scene_json.h"
#include "output_safety.h"

namespace fs = std::filesystem;

namespace mr::cli {

namespace {

// The n-th of a per-object list: its own entry, else the single entry given for all.
template <class T>
std::optional<T> nth(const std::vector<T>& values, std::size_t i) {
  if (values.empty()) return std::nullopt;
  return values.size() == 1 ? values[0] : values.at(i);
}

fs::path find_depth(const InsertCommandOptions& o, const fs::path& photo) {
  if (!o.depth.empty() && o.depth != "auto") return is_pattern(o.depth) ? expand_pattern(o.depth, photo) : fs::path(o.depth);
  std::error_code ec;
  for (const char* ext : {".exr", ".tif", ".tiff", ".pfm", ".png"}) {
    const fs::path p = photo.parent_path() / (photo.stem().string() + "_depth" + ext);
    if (fs::exists(p, ec)) return p;
  }
  return photo.parent_path() / (photo.stem().string() + "_depth.exr");
}

struct Job {
  fs::path photo, output, aovs_output;
};

Camera make_camera(const InsertCommandOptions& o, const FogScene& scene, const Image& photo) {
  if (o.focal_px) return Camera::from_focal_px(photo.width(), photo.height(), *o.focal_px);
  if (o.fov_deg) return Camera::from_horizontal_fov(photo.width(), photo.height(), *o.fov_deg);
  if (scene.camera) return camera_for_image(*scene.camera, photo.width(), photo.height());
  return Camera::from_metadata(photo.width(), photo.height(), photo.metadata());
}

void run_job(const InsertCommandOptions& o, const Job& job) {
  // The scene: this photo's document (a pattern) or the one for all, else defaults.
  FogScene scene;
  fs::path document_dir = job.photo.parent_path();
  if (!o.scene_path.empty()) {
    const fs::path path = is_pattern(o.scene_path) ? expand_pattern(o.scene_path, job.photo) : fs::path(o.scene_path);
    scene = load_scene(path);
    document_dir = path.parent_path();
  }
  Image photo = read_image(job.photo);
  photo.metadata().set("Software", kOutputSoftware);
  const Camera camera = make_camera(o, scene, photo);
  Image distance;
  if (o.depth == "auto") {
    try {
      SceneEstimate est = estimate_scene(photo, camera, Annotations{}, EstimateOptions{});
      scene.pose = est.scene.pose;
      if (!scene.lighting.sun && est.scene.lighting.sun) scene.lighting.sun = est.scene.lighting.sun;
      if (!scene.lighting.sky_radiance && est.scene.lighting.sky_radiance)
        scene.lighting.sky_radiance = est.scene.lighting.sky_radiance;
      distance = std::move(est.geometry.distance_m);
    } catch (const Error& e) {
      throw Error(e.code(), job.photo.string() + ": estimating the geometry (--depth auto): " + e.what());
    }
  } else {
    distance = read_depth(find_depth(o, job.photo), camera, DepthOptions{}).distance_m;
  }
  // The light: the command line over the document.
  if (o.sun_azimuth_deg || o.sun_elevation_deg) {
    Sun sun = scene.lighting.sun.value_or(Sun{});
    sun.direction_to_sun = direction_from_azimuth_elevation(o.sun_azimuth_deg.value_or(180),
                                                            o.sun_elevation_deg.value_or(45));
    if (!scene.lighting.sun) sun.irradiance_auto = true;
    scene.lighting.sun = sun;
  }
  if (!o.sun_irradiance.empty()) {
    if (!scene.lighting.sun) throw Error(ErrorCode::invalid_argument, "--sun-irradiance needs a sun (--sun-azimuth/--sun-elevation or the scene's)");
    scene.lighting.sun->irradiance_auto = o.sun_irradiance == "auto";
    if (o.sun_irradiance != "auto") scene.lighting.sun->irradiance = parse_rgb(o.sun_irradiance);
  }
  if (!o.sky.empty()) {
    if (o.sky == "auto")
      scene.lighting.sky_radiance.reset();
    else
      scene.lighting.sky_radiance = parse_rgb(o.sky);
  }
  if (!o.visibility.empty()) {
    const float sigma = float(extinction_from_visibility(parse_distance_m(o.visibility)));
    scene.medium.sigma_t_per_m = {sigma, sigma, sigma};
  }

  // The objects: the document's, then the command line's.
  std::vector<InsertObject> objects;
  for (std::size_t i = 0; i < scene.objects.size(); ++i) {
    InsertObject obj;
    obj.mesh = resolve_object_mesh(scene.objects[i], document_dir);
    obj.placement = scene.objects[i].placement;
    obj.material = scene.objects[i].material;
    objects.push_back(std::move(obj));
  }
  for (std::size_t i = 0; i < o.objects.size(); ++i) {
    const std::string& spec = o.objects[i];
    InsertObject obj;
    obj.mesh = spec.rfind(kPrimitivePrefix, 0) == 0 ? make_primitive(spec.substr(std::string(kPrimitivePrefix).size()))
                                                    : load_object_mesh(spec);
    for (const std::string& warning : obj.mesh.warnings) std::fprintf(stderr, "warning: %s\n", warning.c_str());
    const double scale = nth(o.scales, i).value_or(1.0), yaw = nth(o.rotates_deg, i).value_or(0.0);
    if (const auto pos = nth(o.positions, i)) {
      const std::vector<double> v = parse_numbers(*pos, 3, "--position");
      obj.placement.position_m = {v[0], v[1], v[2]};
      obj.placement.scale = scale;
      obj.placement.yaw_deg = yaw;
    } else if (const auto at = nth(o.at, i)) {
      const std::vector<double> v = parse_numbers(*at, 2, "--at");
      PlaceAtPixelOptions place;
      place.up = o.up == "normal" ? PlaceAtPixelOptions::Up::surface_normal : PlaceAtPixelOptions::Up::world;
      place.scale = scale;
      place.yaw_deg = yaw;
      try {
        obj.placement = place_at_pixel(camera, scene.pose, distance, v[0], v[1], place);
      } catch (const Error& e) {
        throw Error(e.code(), job.photo.string() + ": --at " + *at + ": " + e.what());
      }
    } else {
      throw Error(ErrorCode::invalid_argument, "--object " + spec + ": give --at X,Y or --position x,y,z");
    }
    objects.push_back(std::move(obj));
  }
  if (objects.empty())
    throw Error(ErrorCode::invalid_argument, job.photo.string() + ": no objects (--object, or the scene's objects)");

  InsertOptions options = o.quality == "preview" ? InsertOptions::preview() : InsertOptions{};
  options.fog = o.fog || !o.visibility.empty();
  options.threads = o.threads;
  const InsertResult r = insert_objects(photo, distance, camera, scene, objects, options);
  if (o.verbose)
    std::fprintf(stderr, "note: %s: %zu triangles, mesh %.2f s, render %.2f s, fog %.2f s\n", job.photo.string().c_str(),
                 r.timings.triangles, r.timings.mesh_s, r.timings.render_s, r.timings.fog_s);
  WriteOptions write;
  write.overwrite = true;  // existing outputs were checked above (skipped without --overwrite)
  // Display-referred (integer) outputs through the highlight roll-off, as `mr fog` writes them
  // (DESIGN.md section 7): a sunlit white object, lit relative to the photo's exposure, comes
  // out at or above the photo's white and would clip flat under plain sRGB. Float outputs stay
  // linear and unclipped. A 16-bit photo stays 16-bit (a PNG output was 8-bit).
  const PhotoOutputEncoding encoding = photo_output_encoding(job.output, job.photo);
  const ColorConfig color = ColorConfig::from_environment();
  write.pixel_type = encoding.pixel_type;
  if (encoding.display_referred) {
    write.color = &color;
    write.colorspace = color.display_colorspace();
  }
  Image composite = r.composite;
  composite.metadata() = photo.metadata();
  write_image(job.output, composite, write);
  if (!job.aovs_output.empty()) {
    const Image rgb = r.composite.select_channels(std::array{0, 1, 2});
    const Image shadow = r.shadow, difference = r.difference;
    std::vector<ExrLayer> layers = {{"", &rgb},
                                    {"matte", &r.matte, true},
                                    {"shadow", &shadow, true},
                                    {"difference", &difference},
                                    {"depth", &r.distance_m, true}};
    if (!r.transmittance.empty()) {
      layers.push_back({"transmittance", &r.transmittance});
      layers.push_back({"inscatter", &r.inscatter});
    }
    write_exr_layers(job.aovs_output, layers, photo.metadata(), PixelType::half);
  }
}

}  // namespace

CLI::App* add_insert_command(CLI::App& app, InsertCommandOptions& o) {
  CLI::App* cmd = app.add_subcommand(
      "insert", "Insert 3D objects into photos: lit by their light, shadowing and shadowed, hidden by their foreground");
  cmd->add_option("inputs", o.inputs, "Photos: files, folders or globs")->required();
  cmd->add_option("--object", o.objects, "A model file (.glb, .gltf, .obj) or primitive:sphere|box|plane|cylinder; repeat for several");
  cmd->add_option("--at", o.at, "X,Y: stand the object on the surface seen at this image position (one per object, or one for all)");
  cmd->add_option("--position", o.positions, "x,y,z: the object's origin in the world (metres, +Y up, ground y = 0)");
  cmd->add_option("--scale", o.scales, "Uniform scale (one per object, or one for all) [default: 1]");
  cmd->add_option("--rotate", o.rotates_deg, "Yaw in degrees about the object's up axis (one per object, or one for all)");
  cmd->add_option("--up", o.up, "With --at: 'world' (upright) or 'normal' (the surface's normal)")
      ->check(CLI::IsMember({"world", "normal"}));
  cmd->add_option("--depth", o.depth, "Depth map: a pattern with {dir} {stem} {name} {ext}, one file, or 'auto' (estimate) [default: {dir}/{stem}_depth.*]");
  cmd->add_option("--scene", o.scene_path, "Scene document (a pattern gives each photo its own): pose, light, medium, objects");
  cmd->add_option("--fov", o.fov_deg, "Horizontal field of view in degrees");
  cmd->add_option("--focal-px", o.focal_px, "Focal length in pixels");
  cmd->add_option("--sun-azimuth", o.sun_azimuth_deg, "Sun azimuth in degrees (0 = +Z, the view; 90 = +X)");
  cmd->add_option("--sun-elevation", o.sun_elevation_deg, "Sun elevation in degrees");
  cmd->add_option("--sun-irradiance", o.sun_irradiance, "v, R,G,B or auto (relative to the photo's exposure)");
  cmd->add_option("--sky", o.sky, "Sky radiance: v, R,G,B or auto (estimated from the photo)");
  cmd->add_option("--visibility", o.visibility, "Fog the result: meteorological visibility (e.g. 150m)");
  cmd->add_flag("--fog", o.fog, "Fog the result with the scene document's medium");
  cmd->add_option("--quality", o.quality, "full (16 rays per pixel) or preview")->check(CLI::IsMember({"full", "preview"}));
  cmd->add_option("-o,--out-dir", o.out_dir, "Output folder [default: inserted]");
  cmd->add_option("--suffix", o.suffix, "Output name suffix [default: _insert]");
  cmd->add_option("--format", o.format, "Output format (extension without dot) [default: the input's]");
  cmd->add_flag("--aovs", o.aovs, "Also write <stem><suffix>_aovs.exr: matte, shadow, difference, depth (and T, R with fog)");
  cmd->add_flag("--overwrite", o.overwrite, "Replace existing outputs");
  cmd->add_option("-j,--threads", o.threads, "Threads (0: all cores)")->check(CLI::Range(0, kMaxThreads));
  cmd->add_flag("-q,--quiet", o.quiet, "No progress lines");
  cmd->add_flag("-v,--verbose", o.verbose, "Notes per photo");
  return cmd;
}

int run_insert_command(const InsertCommandOptions& o, const std::atomic<bool>& interrupted) {
  if (o.objects.empty() && o.scene_path.empty()) {
    std::fprintf(stderr, "ERROR: nothing to insert: give --object (or a --scene with objects) (see mr insert --help)\n");
    return 2;
  }
  if (!o.positions.empty() && !o.at.empty()) {
    std::fprintf(stderr, "ERROR: give --at or --position, not both (see mr insert --help)\n");
    return 2;
  }
  for (const auto* list : {&o.at, &o.positions})
    if (list->size() > 1 && list->size() != o.objects.size()) {
      std::fprintf(stderr, "ERROR: give one --at/--position per --object, or one for all (see mr insert --help)\n");
      return 2;
    }
  std::vector<std::string> warnings;
  const std::vector<fs::path> photos = expand_inputs(o.inputs, {"_depth", "_disparity", "_aovs", o.suffix}, &warnings);
  for (const std::string& w : warnings) std::fprintf(stderr, "warning: %s\n", w.c_str());
  std::error_code ec;
  fs::create_directories(o.out_dir, ec);
  std::vector<Job> jobs;
  std::vector<std::vector<PlannedOutput>> planned;
  for (const fs::path& p : photos) {
    Job job;
    job.photo = p;
    const std::string ext = o.format.empty() ? p.extension().string() : "." + o.format;
    job.output = fs::path(o.out_dir) / (p.stem().string() + o.suffix + ext);
    if (o.aovs) job.aovs_output = fs::path(o.out_dir) / (p.stem().string() + o.suffix + "_aovs.exr");
    std::vector<PlannedOutput> outs = {{job.output, p.string()}};
    if (o.aovs) outs.push_back({job.aovs_output, p.string()});
    planned.push_back(outs);
    jobs.push_back(job);
  }
  const std::vector<std::string> problems = check_planned_outputs(photos, planned);
  int failed = 0, done = 0, skipped = 0;
  for (std::size_t i = 0; i < jobs.size(); ++i) {
    if (interrupted) break;
    const Job& job = jobs[i];
    if (!problems[i].empty()) {
      std::fprintf(stderr, "error: %s: %s\n", job.photo.string().c_str(), problems[i].c_str());
      ++failed;
      continue;
    }
    if (!o.overwrite && fs::exists(job.output, ec) && (job.aovs_output.empty() || fs::exists(job.aovs_output, ec))) {
      ++skipped;
      continue;
    }
    try {
      run_job(o, job);
      ++done;
      if (!o.quiet) std::fprintf(stderr, "%s -> %s\n", job.photo.string().c_str(), job.output.string().c_str());
    } catch (const std::exception& e) {
      const std::string message = e.what();
      // Errors name the file: prefix the photo unless the message already names it.
      if (message.find(job.photo.string()) == std::string::npos)
        std::fprintf(stderr, "error: %s: %s\n", job.photo.string().c_str(), message.c_str());
      else
        std::fprintf(stderr, "error: %s\n", message.c_str());
      ++failed;
    }
  }
  if (!o.quiet) std::fprintf(stderr, "%d inserted, %d skipped, %d failed\n", done, skipped, failed);
  return failed > 0 ? 1 : 0;
}

}  // namespace mr::cli
