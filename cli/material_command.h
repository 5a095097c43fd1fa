// `mr material`: give regions of a photo the material look of a sample image (issue 7).
#pragma once

#include <optional>
#include <string>

namespace CLI {
class App;
}

namespace mr::cli {

struct MaterialCommandOptions {
  std::string sample;          ///< --sample s.jpg
  std::string target;          ///< --target photo.jpg
  std::string regions;         ///< --regions masks.png | annotations.json
  std::string output;          ///< -o out.png
  std::string materials_json;  ///< --materials-json chosen.json; empty: none
  std::string sample_depth;    ///< file, or empty / "auto": {stem}_depth.*, else estimated
  std::string target_depth;
  std::string sample_scene;  ///< scene JSON (pose, lighting); empty: the default light
  std::string target_scene;
  std::optional<double> sample_fov_deg, target_fov_deg;
  std::optional<unsigned> seed;
  int max_candidates = 8;
  double smoothness = 0.1;
  bool no_detail = false;
  bool physical_exposure = false;
  std::string visibility;  ///< fog the result: "150m"; empty: no fog
  int threads = 0;
  bool overwrite = false;
  bool quiet = false;
  bool verbose = false;  ///< -v: progress notes when stderr is not a terminal
};

/// Adds the `material` subcommand to `app`; `options` must outlive parsing.
CLI::App* add_material_command(CLI::App& app, MaterialCommandOptions& options);

/// Runs it. Returns the exit code: 0 done, 1 the work failed (unreadable input, no usable sample
/// segment, an output not written), 2 bad options or regions (the message names them).
int run_material_command(const MaterialCommandOptions& options);

}  // namespace mr::cli
