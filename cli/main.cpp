// The `mr` command line: batch front end of libmr.
#include <unistd.h>

#include <csignal>

#include <CLI/CLI.hpp>
#include <atomic>
#include <cstdio>

#include "estimate_command.h"
#include "fog_command.h"
#include "material_command.h"
#include "mr/version.h"

namespace {

std::atomic<bool> g_interrupted{false};

// How long the first SIGTERM leaves the photos in flight to finish before the process exits.
constexpr unsigned kTermGraceSeconds = 10;

extern "C" void on_alarm(int) { _exit(128 + SIGTERM); }

extern "C" void on_signal(int signal) {
  // First Ctrl-C: finish the files in flight (their outputs are written atomically), start no
  // more. A second one kills the process the default way; temporary files are hidden dotfiles,
  // removed by the next run. SIGTERM (a service manager, `timeout`, `kill`) must always end the
  // run: the same, but if the files in flight take longer than kTermGraceSeconds (or a read
  // hangs) the process exits anyway. Only async-signal-safe calls here.
  g_interrupted = true;
  std::signal(SIGINT, SIG_DFL);
  std::signal(SIGTERM, SIG_DFL);
  if (signal == SIGTERM) {
    std::signal(SIGALRM, on_alarm);
    alarm(kTermGraceSeconds);
  }
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"mr: physically based fog for photographs (libmr " + std::string(mr::version()) + ")"};
  app.set_version_flag("--version", std::string("mr ") + mr::version());
  app.require_subcommand(1);
  mr::cli::FogCommandOptions fog_options;
  CLI::App* fog = mr::cli::add_fog_command(app, fog_options);
  mr::cli::EstimateCommandOptions estimate_options;
  CLI::App* estimate = mr::cli::add_estimate_command(app, estimate_options);
  mr::cli::MaterialCommandOptions material_options;
  CLI::App* material = mr::cli::add_material_command(app, material_options);
  // A usage error is one line, the last one printed: "ERROR: <problem>; see mr <command> --help".
  app.failure_message([](const CLI::App* failed, const CLI::Error& e) {
    std::string where = "mr";
    for (const CLI::App* sub : failed->get_subcommands()) where += " " + sub->get_name();
    return "ERROR: " + std::string(e.what()) + " (see " + where + " --help)\n";
  });
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : 2;  // usage errors exit 2
  }
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  // Anything the commands do not turn into their own one-line error (std::bad_alloc, a thread
  // that cannot be created, ...) still ends as one, never as an abort.
  try {
    if (fog->parsed()) return mr::cli::run_fog_command(fog_options, g_interrupted);
    if (estimate->parsed()) return mr::cli::run_estimate_command(estimate_options);
    if (material->parsed()) return mr::cli::run_material_command(material_options);
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "ERROR: out of memory (fewer threads with -j, or smaller photos)\n");
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "ERROR: %s\n", e.what());
    return 1;
  }
  return 2;
}
