// The CLI's rules for what it writes: outputs are regular files that are never an input of the
// run and never shared by two photos; leftovers of killed runs are cleaned up.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "mr/io.h"

namespace mr::cli {

/// The "Software" tag `mr fog` writes into its outputs, and the test for it: a file named like
/// an output (<stem><suffix>.<ext>) in the output folder is only taken for an earlier output
/// when its header carries this tag; otherwise it is a photo (an input of the run).
inline constexpr const char* kOutputSoftware = "mr fog (libmr)";
bool written_by_mr_fog(const std::filesystem::path& path);


/// One file a run will write, and whose file it is (the photo, or the option that names it).
struct PlannedOutput {
  std::filesystem::path path;
  std::string owner;
};

/// For a run's outputs, grouped per job: a message per job, empty when its outputs are safe,
/// else why not: an output that is one of `inputs` (by name, or the same file under another
/// name: links), an output that another job also writes (every job that shares it fails; no
/// output is silently lost or overwritten), an output that exists and is not a regular file.
std::vector<std::string> check_planned_outputs(
    const std::vector<std::filesystem::path>& inputs,
    const std::vector<std::vector<PlannedOutput>>& outputs_per_job);

/// Removes the hidden temporary files our atomic writes leave when a run is killed (kill -9, a
/// crash, a power cut): names ".<stem>.mr-tmp-<pid>-<n>[.<ext>]" in `folder` whose process is
/// gone, or that are older than a day (the pid was reused). Returns the names removed.
std::vector<std::filesystem::path> remove_stale_temporaries(const std::filesystem::path& folder);

/// How `mr insert` and `mr material` encode a photo's output (DESIGN.md section 7), as `mr fog`
/// does: integer formats display-referred (the config's display colour space: the highlight
/// roll-off where it has it), 16-bit where the photo is 16-bit and the format holds it (PNG,
/// TIFF); float formats (EXR, HDR, PFM) scene-linear. `photo` empty: no photo file (8-bit).
struct PhotoOutputEncoding {
  bool display_referred = false;
  PixelType pixel_type = PixelType::automatic;
};
PhotoOutputEncoding photo_output_encoding(const std::filesystem::path& output,
                                          const std::filesystem::path& photo);

/// The most threads -j accepts (more is a usage error: each thread holds a photo in memory).
inline constexpr int kMaxThreads = 256;

}  // namespace mr::cli
