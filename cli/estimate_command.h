// `mr estimate`: a fog scene (camera pose, light) and a metric depth map from one photo and its
// annotations (docs/annotations.md).
#pragma once

#include <optional>
#include <string>

namespace CLI {
class App;
}

namespace mr::cli {

struct EstimateCommandOptions {
  std::string photo;
  std::string annotations;  ///< --annotations a.json; empty: none
  std::optional<double> fov_deg;
  std::optional<double> focal_px;
  std::string scene_out;    ///< -o scene.json
  std::string depth_out;    ///< --depth-out d.exr
  std::string overlay_out;  ///< --overlay o.png
  std::string depth_network;  ///< --depth-network model.onnx; empty: none
  bool quiet = false;
  bool verbose = false;    ///< -v: progress notes when stderr is not a terminal
  bool overwrite = false;  ///< replace an existing --depth-out (an input of mr fog)
};

/// Adds the `estimate` subcommand to `app`; `options` must outlive parsing.
CLI::App* add_estimate_command(CLI::App& app, EstimateCommandOptions& options);

/// Runs it. Returns the exit code: 0 done, 1 the photo could not be read or an output not
/// written, 2 bad options or annotations (the message names the file and the JSON pointer).
int run_estimate_command(const EstimateCommandOptions& options);

}  // namespace mr::cli
