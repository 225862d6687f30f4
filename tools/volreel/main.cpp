// main.cpp: the volreel program — generate datasets, compare volumes and images, benchmark
// codecs. Every subcommand has --help.
#include <cstdio>
#include <exception>
#include <new>

#include <CLI/CLI.hpp>

#include "commands.hpp"
#include "mpi_ranks.hpp"
#include "progress.hpp"

int main(int argc, char** argv) {
  // Line by line also into a pipe or file, so that a log of `2>&1` keeps the report's lines and
  // the notes and errors on stderr in the order they were written.
  std::setvbuf(stdout, nullptr, _IOLBF, BUFSIZ);
  // Under mpirun, MPI for `encode`'s ranks (mpi_ranks.hpp); otherwise nothing.
  volreel::cli::MpiSession mpi(argc, argv);
  CLI::App app{"volreel " VOLREEL_VERSION
               ": encode time-varying simulation volumes into a compact, GPU-decodable form and "
               "explore them\n"
               "like a video. Run `volreel COMMAND --help` for the options of each command."};
  app.require_subcommand(1);
  app.set_version_flag("--version", "volreel " VOLREEL_VERSION);
  volreel::cli::add_gen_command(app);
  volreel::cli::add_compare_command(app);
  volreel::cli::add_bench_command(app);
  volreel::cli::add_train_command(app);
  volreel::cli::add_encode_command(app);
  volreel::cli::add_info_command(app);
  volreel::cli::add_verify_command(app);
  volreel::cli::add_decode_command(app);
#ifdef VOLREEL_HAVE_VULKAN
  volreel::cli::add_play_command(app);
  volreel::cli::add_render_command(app);
#endif
  try {
    try {
      volreel::cli::refuse_unknown_command(app, argc, argv);
    } catch (const std::exception& e) {  // a mistake on the command line: status 2
      std::fprintf(stderr, "volreel: error: %s\n", e.what());
      return 2;
    }
    app.parse(argc, argv);
  } catch (const CLI::RuntimeError& e) {  // a command's own exit status, its message printed
    return e.get_exit_code();
  } catch (const CLI::ParseError& e) {
    // --help and --version as CLI11 prints them; a mistake on the command line as every other
    // error, with exit status 2 (a usage error, as for most Unix tools).
    if (e.get_exit_code() == 0) return app.exit(e);
    std::fprintf(stderr,
                 "volreel: error: %s\nRun `volreel --help` or `volreel COMMAND --help` "
                 "for the options.\n",
                 e.what());
    return 2;
  } catch (const volreel::cli::Interrupted&) {
    std::fprintf(stderr, "volreel: interrupted; nothing half-written was left\n");
    volreel::cli::end_by_stop_signal();
    return 130;
  } catch (const volreel::cli::TargetMissed& e) {
    std::fprintf(stderr, "volreel: %s\n", e.what());
    return volreel::cli::target_missed_status;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr,
                 "volreel: error: out of memory: the input or the options ask for more memory than "
                 "this machine can give (check the dimensions in the input's manifest or "
                 "series.json and the sizes given as options)\n");
    volreel::cli::MpiSession::abort_job(1);
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "volreel: error: %s\n", e.what());
    volreel::cli::MpiSession::abort_job(1);
    return 1;
  }
  return 0;
}
