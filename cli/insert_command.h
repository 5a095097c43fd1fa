// `mr insert`: put 3D objects into a batch of photos (issue 16).
#pragma once

#include <atomic>
#include <optional>
#include <string>
#include <vector>

namespace CLI {
class App;
}

namespace mr::cli {

struct InsertCommandOptions {
  std::vector<std::string> inputs;
  std::vector<std::string> objects;    ///< model files or primitive:NAME, one per object
  std::vector<std::string> at;         ///< "X,Y" image positions (one per object, or one for all)
  std::vector<std::string> positions;  ///< "x,y,z" world positions (metres)
  std::vector<double> scales;          ///< per object, or one for all; default 1
  std::vector<double> rotates_deg;     ///< yaw per object, or one for all; default 0
  std::string up = "world";            ///< --at: world | normal
  std::string depth;        ///< pattern / file; empty: {dir}/{stem}_depth.*; "auto": estimate
  std::string scene_path;   ///< pattern or file; its lighting, pose, medium and objects
  std::optional<double> fov_deg, focal_px;
  std::optional<double> sun_azimuth_deg, sun_elevation_deg;
  std::string sun_irradiance;  ///< "v", "R,G,B" or "auto"
  std::string sky;             ///< "v", "R,G,B" or "auto"
  std::string visibility;      ///< fog: "150m" (empty: no fog unless --fog)
  bool fog = false;            ///< fog with the scene's medium
  std::string quality = "full";  ///< full | preview
  std::string out_dir = "inserted";
  std::string suffix = "_insert";
  std::string format;  ///< output extension without dot; empty: the input's
  bool aovs = false;   ///< also <stem><suffix>_aovs.exr: matte, shadow, difference, depth
  bool overwrite = false;
  bool quiet = false, verbose = false;
  int threads = 0;
};

CLI::App* add_insert_command(CLI::App& app, InsertCommandOptions& options);
int run_insert_command(const InsertCommandOptions& options, const std::atomic<bool>& interrupted);

}  // namespace mr::cli
