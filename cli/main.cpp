// The `mr` command line: batch front end of libmr.
#include <malloc.h>
#include <unistd.h>

#include <csignal>
#include <ctime>

#include <CLI/CLI.hpp>
#include <atomic>
#include <cstdio>

#include "estimate_command.h"
#include "fog_command.h"
#include "insert_command.h"
#include "material_command.h"
#include "mr/io.h"
#include "mr/version.h"

namespace {

std::atomic<bool> g_interrupted{false};

// How long the first SIGTERM leaves the photos in flight to finish before the process exits.
constexpr unsigned kTermGraceSeconds = 10;
// A tool that signals a process and then its process group (GNU `timeout`, some supervisors)
// delivers one request twice within microseconds; a repeat from the same sending process within
// a second (a loaded machine may run the handlers far apart) is that request, not a second Ctrl-C.
constexpr long kSameRequestNs = 1'000'000'000;

volatile std::sig_atomic_t g_signals = 0;
volatile pid_t g_first_sender = 0;
volatile bool g_first_from_process = false;
timespec g_first_time{};

[[noreturn]] void end_now(int signal) {
  mr::remove_unfinished_outputs();  // finished outputs stay; partial ones go
  _exit(128 + signal);
}

extern "C" void on_alarm(int) {
  end_now(SIGTERM);
}

extern "C" void on_signal(int signal, siginfo_t* info, void*) {
  // First Ctrl-C: finish the files in flight (their outputs are written atomically), start no
  // more. A second one ends the process at once, removing the temporaries of the outputs in
  // flight. SIGTERM (a service manager, `timeout`, `kill`) must always end the run: the same,
  // but if the files in flight take longer than kTermGraceSeconds (or a read hangs) the process
  // exits anyway. Only async-signal-safe calls here.
  timespec now{};
  clock_gettime(CLOCK_MONOTONIC, &now);
  const bool from_process = info != nullptr && info->si_code == SI_USER;
  if (g_signals > 0) {
    const long elapsed_ns =
        (now.tv_sec - g_first_time.tv_sec) * 1'000'000'000L + (now.tv_nsec - g_first_time.tv_nsec);
    if (from_process && g_first_from_process && info->si_pid == g_first_sender &&
        elapsed_ns < kSameRequestNs)
      return;
    end_now(signal);
  }
  g_signals = 1;
  g_first_time = now;
  g_first_from_process = from_process;
  g_first_sender = from_process ? info->si_pid : 0;
  g_interrupted = true;
  if (signal == SIGTERM) {
    std::signal(SIGALRM, on_alarm);
    alarm(kTermGraceSeconds);
  }
}

// A photo's stages allocate and free full-frame buffers one after another (12 MP: 48-144 MB
// each). glibc serves every block over 32 MiB with a fresh mmap and returns it with munmap, so
// the kernel faults and zeroes each one in again, page by page: an automatic fog of a 12 MP
// photo spent about 22 s of its 60 s in the kernel (3.3 M page faults). A batch process keeps what
// it frees for the next buffer instead: all blocks from the heap, none trimmed back to the OS (the
// heap stays at the run's peak, which the process reached anyway). Output unchanged; the library
// leaves this to its host (mr-studio keeps glibc's defaults: a long-lived editor should give memory
// back).
void keep_freed_memory_for_reuse() {
#if defined(__GLIBC__)
  mallopt(M_MMAP_MAX, 0);
  mallopt(M_TRIM_THRESHOLD, -1);
#endif
}

void install_signal_handlers() {
  struct sigaction action {};
  action.sa_sigaction = on_signal;
  action.sa_flags = SA_SIGINFO | SA_RESTART;
  sigemptyset(&action.sa_mask);
  sigaddset(&action.sa_mask, SIGINT);  // one handler at a time: the state above is not atomic
  sigaddset(&action.sa_mask, SIGTERM);
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
}

}  // namespace

int main(int argc, char** argv) {
  keep_freed_memory_for_reuse();
  CLI::App app{"mr: physically based fog for photographs (libmr " + std::string(mr::version()) +
               ")"};
  app.set_version_flag("--version", std::string("mr ") + mr::version());
  app.require_subcommand(1);
  mr::cli::FogCommandOptions fog_options;
  CLI::App* fog = mr::cli::add_fog_command(app, fog_options);
  mr::cli::EstimateCommandOptions estimate_options;
  CLI::App* estimate = mr::cli::add_estimate_command(app, estimate_options);
  mr::cli::MaterialCommandOptions material_options;
  CLI::App* material = mr::cli::add_material_command(app, material_options);
  mr::cli::InsertCommandOptions insert_options;
  CLI::App* insert = mr::cli::add_insert_command(app, insert_options);
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
  install_signal_handlers();
  // Anything the commands do not turn into their own one-line error (std::bad_alloc, a thread
  // that cannot be created, ...) still ends as one, never as an abort.
  try {
    if (fog->parsed()) return mr::cli::run_fog_command(fog_options, g_interrupted);
    if (estimate->parsed()) return mr::cli::run_estimate_command(estimate_options);
    if (material->parsed()) return mr::cli::run_material_command(material_options);
    if (insert->parsed()) return mr::cli::run_insert_command(insert_options, g_interrupted);
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "ERROR: out of memory (fewer threads with -j, or smaller photos)\n");
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "ERROR: %s\n", e.what());
    return 1;
  }
  return 2;
}
