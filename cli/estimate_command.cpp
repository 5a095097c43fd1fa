#include "estimate_command.h"

#include <CLI/CLI.hpp>
#include <cstdio>
#include <filesystem>

#include "mr/annotations.h"
#include "mr/camera.h"
#include "mr/depth_network.h"
#include "mr/error.h"
#include "mr/estimate.h"
#include "mr/io.h"
#include "mr/scene_json.h"
#include "output_safety.h"
#include "progress.h"

namespace mr::cli {

namespace fs = std::filesystem;

CLI::App* add_estimate_command(CLI::App& app, EstimateCommandOptions& o) {
  CLI::App* cmd = app.add_subcommand(
      "estimate",
      "Estimate a fog scene (camera pose, sun) and a metric depth map from one photo and its "
      "annotations (docs/annotations.md)");
  cmd->add_option("photo", o.photo, "The photo")->required();
  // Without --fov / --focal-px: EXIF, else orthogonal vanishing points when confident, else 60.
  cmd->add_option("--annotations", o.annotations,
                  "Annotations JSON: horizon, camera height, planes, distance hints, shadow pairs");
  auto* fov = cmd->add_option("--fov", o.fov_deg,
                              "Horizontal field of view in degrees [default: EXIF, else from "
                              "orthogonal vanishing points when confident, else 60]")
                  ->check(CLI::Range(0.0, 180.0));
  cmd->add_option("--focal-px", o.focal_px, "Focal length in pixels")
      ->excludes(fov)
      ->check(CLI::PositiveNumber);
  cmd->add_option("-o,--output", o.scene_out, "Scene JSON to write (what `mr fog --scene` reads)")
      ->required();
  cmd->add_option("--depth-out", o.depth_out,
                  "Distance map to write (float EXR, channel Z, metres along the ray, +inf = sky)");
  cmd->add_option("--overlay", o.overlay_out,
                  "Debug picture to write: horizon, sky, depth colour map, annotations");
  cmd->add_option("--depth-network", o.depth_network,
                  "ONNX monocular depth network (MiDaS v2.1 small conventions: 256x256, RGB, "
                  "ImageNet mean/std, inverse depth); its map, fitted to the ground plane, "
                  "replaces the estimated depth")
      ->check(CLI::ExistingFile);
  cmd->add_flag("-q,--quiet", o.quiet, "Print only errors");
  cmd->add_flag("-v,--verbose", o.verbose,
                "Progress notes on stderr when it is not a terminal (on a terminal: a bar)");
  cmd->add_flag("--overwrite", o.overwrite,
                "Replace an existing --depth-out (a depth map is an input of mr fog; default: "
                "refuse)");
  return cmd;
}

int run_estimate_command(const EstimateCommandOptions& o) {
  // The report goes to stdout (buffered when piped): flushed before any error, so errors come
  // last.
  std::setvbuf(stdout, nullptr, _IOLBF, 0);
  // Outputs must not replace an input (the photo, the annotations, the network) or each other,
  // and are only ever regular files (a FIFO, a link, a device is an error, not replaced).
  std::error_code ec;
  std::vector<fs::path> inputs{o.photo};
  if (!o.annotations.empty()) inputs.emplace_back(o.annotations);
  if (!o.depth_network.empty()) inputs.emplace_back(o.depth_network);
  std::vector<std::vector<PlannedOutput>> outputs;
  for (const auto& [out, option] : {std::pair{&o.scene_out, "-o"}, {&o.depth_out, "--depth-out"},
                                    {&o.overlay_out, "--overlay"}})
    if (!out->empty()) outputs.push_back({{*out, option}});
  std::vector<std::string> problems = check_planned_outputs(inputs, outputs);
  for (const std::string& problem : problems)
    if (!problem.empty()) {
      std::fprintf(stderr, "ERROR: %s\n", problem.c_str());
      return 2;
    }
  // A depth map is what mr fog reads as an input: an existing one is replaced only when asked.
  if (!o.depth_out.empty() && !o.overwrite && fs::exists(o.depth_out, ec)) {
    std::fprintf(stderr,
                 "ERROR: %s: exists (a depth map mr fog reads); pass --overwrite to replace it\n",
                 o.depth_out.c_str());
    return 2;
  }
  if (!o.depth_out.empty() && !is_writable_image_extension(o.depth_out)) {
    std::fprintf(stderr, "ERROR: %s: not an image format that can be written\n",
                 o.depth_out.c_str());
    return 2;
  }
  if (!o.overlay_out.empty() && !is_writable_image_extension(o.overlay_out)) {
    std::fprintf(stderr, "ERROR: %s: not an image format that can be written\n",
                 o.overlay_out.c_str());
    return 2;
  }

  for (const auto& out : {o.scene_out, o.depth_out, o.overlay_out})
    if (!out.empty()) remove_stale_temporaries(fs::path(out).parent_path());
  Annotations annotations;
  if (!o.annotations.empty()) {
    try {
      annotations = load_annotations(o.annotations);
    } catch (const Error& e) {
      std::fprintf(stderr, "ERROR: %s\n", e.what());
      return 2;
    }
  }
  Image photo;
  try {
    photo = read_image(o.photo);
  } catch (const Error& e) {
    std::fprintf(stderr, "ERROR: %s\n", e.what());
    return 1;
  }
  SceneEstimate est;
  try {
    std::string focal_source = "given";
    Camera camera;
    if (o.focal_px) {
      camera = Camera::from_focal_px(photo.width(), photo.height(), *o.focal_px);
    } else if (o.fov_deg) {
      camera = Camera::from_horizontal_fov(photo.width(), photo.height(), *o.fov_deg);
    } else {
      const PhotoCamera pc = camera_for_photo(photo);
      camera = pc.camera;
      focal_source = pc.source;
      if (pc.source == "vanishing points") {
        char conf[32];
        std::snprintf(conf, sizeof conf, ", confidence %.2f", pc.confidence);
        focal_source += conf;
      }
    }
    {
      // Progress on stderr: a bar on a terminal, -v notes in a pipe; erased before the report.
      Reporter report(1, o.quiet, o.verbose);
      const PhotoProgress progress(report, o.photo, {{estimate_stages(), 1}});
      EstimateOptions options;
      options.cancel = progress.token();
      try {
        est = estimate_scene(photo, camera, annotations, options);
      } catch (...) {
        report.finish();
        throw;
      }
      report.finish();
    }
    // Recorded so that `mr fog --scene` renders with this focal length (the one found from the
    // vanishing points, say) rather than falling back to EXIF or the default.
    est.scene.camera = scene_camera(camera);
    std::optional<NetworkDepth> network_depth;
    if (!o.depth_network.empty()) {
      try {  // the network's and the fit's messages name the model
        const DepthNetwork network(o.depth_network);
        network_depth = estimate_network_depth(network, photo, camera, est.geometry);
      } catch (const Error& e) {
        std::fprintf(stderr, "ERROR: %s: %s\n", o.photo.c_str(), e.what());
        return 1;
      }
      est.geometry.distance_m = network_depth->fit.distance_m;
    }
    if (!o.quiet) {
      std::printf("%s: %dx%d, focal %.1f px (%.1f deg across; %s)\n", o.photo.c_str(), camera.width,
                  camera.height, camera.focal_px, camera.horizontal_fov_deg(),
                  focal_source.c_str());
      for (const auto& note : est.notes) std::printf("  %s\n", note.c_str());
      if (network_depth) {
        const DepthFit& f = network_depth->fit;
        std::printf(
            "  depth network: %s, 1/depth = %.4g * r %+.4g (1/m), inliers %zu/%zu ground "
            "pixels, residual %.2f%% RMS (inliers), %.2f%% median\n",
            o.depth_network.c_str(), f.scale, f.shift, f.inliers, f.reference_pixels,
            100 * f.rms_inlier_residual, 100 * f.median_abs_residual);
      }
    }
  } catch (const Error& e) {
    // Problems with the annotations name their JSON pointer; say which file they are in.
    const std::string source = o.annotations.empty() ? o.photo : o.annotations;
    std::fprintf(stderr, "ERROR: %s: %s\n", source.c_str(), e.what());
    return e.code() == ErrorCode::invalid_argument ? 2 : 1;
  }
  try {
    if (!o.depth_out.empty()) {
      WriteOptions w;
      w.pixel_type = PixelType::float32;
      w.colorspace = colorspace::raw;
      write_image(o.depth_out, est.geometry.distance_m, w);
    }
    if (!o.overlay_out.empty()) {
      Image overlay = render_estimate_overlay(photo, est, annotations);
      write_image(o.overlay_out, overlay);
    }
    save_scene(o.scene_out, est.scene);
  } catch (const Error& e) {
    std::fprintf(stderr, "ERROR: %s\n", e.what());
    return 1;
  }
  if (!o.quiet) {
    std::printf("  wrote %s", o.scene_out.c_str());
    if (!o.depth_out.empty()) std::printf(", %s", o.depth_out.c_str());
    if (!o.overlay_out.empty()) std::printf(", %s", o.overlay_out.c_str());
    std::printf("\n");
  }
  return 0;
}

}  // namespace mr::cli
