// `mr fog`: fog a batch of photos with their depth maps.
#pragma once

#include <atomic>
#include <optional>
#include <string>
#include <vector>

#include "mr/working_size.h"  // kDefaultWorkingLongSidePx

namespace CLI {
class App;
}

namespace mr::cli {

struct FogCommandOptions {
  std::vector<std::string> inputs;
  std::string depth;  ///< pattern with {dir} {stem} {name} {ext}, or one file; empty: search;
                      ///< "auto": search, and estimate the geometry where nothing is found
  std::string annotations;  ///< --depth auto: annotations JSON pattern (missing file: none)
  std::string depth_kind = "distance";
  double depth_scale = 1.0;
  double baseline_m = 0;
  double doffs_px = 0;
  std::optional<double> fov_deg;
  std::optional<double> focal_px;
  std::string visibility;  ///< "150m"
  std::string density;     ///< extinction 1/m, "0.02" or "R,G,B"
  std::string airlight = "auto";
  std::string out_dir = "fogged";
  std::string suffix = "_fog";
  std::string format;  ///< output extension without dot; empty: the input's
  std::string bit_depth = "auto";
  bool aovs = false;
  int threads = 0;  ///< 0: all cores
  bool quiet = false;
  bool verbose = false;  ///< -v: notes (per photo, the backend choice)
  bool overwrite = false;
  double sky_depth_m = 65504.0;  ///< --sky-depth: stored depth >= this is sky (mr::DepthOptions)
  double max_megapixels = 250;   ///< --max-megapixels: decoded-size limit of photos and depth
  // The physical model (issue 3); an empty string / nullopt leaves the scene's value.
  std::string scene_path;       ///< --scene scene.json
  std::string save_scene_path;  ///< --save-scene: write the resolved scene
  std::string quality;
  std::string backend;  ///< --backend auto|cpu|vulkan
  std::string shadow_traversal;  ///< --shadow-traversal embree|multi-index (issue 17)
  std::optional<double> sun_azimuth_deg, sun_elevation_deg;
  std::string sun_direction;    ///< "x,y,z"
  std::string sun_irradiance;   ///< "v", "R,G,B" or "auto" (empty: auto unless --scene has a sun)
  std::optional<double> sun_radius_deg;
  std::vector<std::string> lamps;  ///< "x,y,z;R,G,B[;dx,dy,dz;inner,outer]"
  std::string height_fog;       ///< "base,scale"
  std::string layer;            ///< "bottom,top"
  /// "auto" (default): with an estimated geometry (--depth auto) and no top given, the fog's
  /// top from its visibility (mr::default_layer_top_m); "none": no top; else a distance.
  std::string layer_top = "auto";
  /// The fog's sky light (mr/sky_light.h): "direction" (the photo's sky by direction),
  /// "uniform" (one sky radiance), "auto": the scene file's, else by direction when the geometry
  /// is estimated (--depth auto) with the sky radiance 'auto', uniform otherwise.
  std::string sky_light = "auto";
  /// With an estimated geometry (--depth auto) and no sun or lamps: "soften" (default) the fog's
  /// seams where the guessed depth makes edges the photo lacks (mr::soften_fog_seams), or
  /// "keep" them. A depth file's fog is never softened.
  std::string seams = "soften";
  /// With --depth auto estimating the geometry: the longer side (px) the photo is estimated,
  /// rendered and softened at, the fog then brought to the photo's size by guided upsampling
  /// (mr/working_size.h); 0: the photo's own size. Not used with annotations or objects.
  int working_size = kDefaultWorkingLongSidePx;
  std::string albedo;
  std::optional<double> g;
  std::string noise;            ///< "amplitude[,scale[,octaves[,seed]]]"
  std::optional<double> camera_height_m, pitch_deg, roll_deg, yaw_deg;
  std::optional<unsigned> seed;
  std::optional<int> march_steps;
  bool no_shadows = false;
  std::string ocio_config;
  std::string input_colorspace;
  std::string output_colorspace;
};

/// Adds the `fog` subcommand to `app`; `options` must outlive parsing.
CLI::App* add_fog_command(CLI::App& app, FogCommandOptions& options);

/// Runs the batch. Returns the exit code: 0 all done or skipped, 1 some failed, 2 bad options,
/// 130 interrupted. Checks `interrupted` between files.
int run_fog_command(const FogCommandOptions& options, const std::atomic<bool>& interrupted);

}  // namespace mr::cli
