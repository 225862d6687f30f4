// progress.hpp: the terminal progress bar the volreel program draws for long work.
#pragma once

#include <chrono>
#include <stdexcept>
#include <string>

#include "volreel/datasets/volume.hpp"

namespace volreel::cli {

/// A progress bar on stderr: redrawn in place on a terminal (at most 10 times a second), or a
/// plain line every 10 % / 10 s when stderr is a file or pipe (CI logs stay short).
class ProgressBar {
 public:
  ProgressBar(std::string label, std::string unit);
  ~ProgressBar();
  ProgressBar(const ProgressBar&) = delete;
  ProgressBar& operator=(const ProgressBar&) = delete;

  void update(const ProgressUpdate& update);
  /// Print the final state and a newline.
  void finish();
  /// Adapter for library calls that take a Progress.
  Progress progress();

 private:
  std::string label_, unit_;
  bool terminal_;
  bool finished_ = false;
  ProgressUpdate last_;
  std::chrono::steady_clock::time_point start_, last_draw_;
  double last_logged_fraction_ = -1;
  void draw(bool final);
};

/// Ctrl-C (SIGINT) and SIGTERM for a command whose output an interruption would leave
/// half-written (gen, bench rd, bench stream), while one is alive: the first signal asks the work
/// to stop at its next progress update, where Interrupted unwinds it so that what it was writing is
/// removed as on any error; a second signal ends the process at once. A signal ignored when it is
/// made (a background job's SIGINT) stays ignored; the handlers before are restored when it goes.
class StopOnSignal {
 public:
  StopOnSignal();
  ~StopOnSignal();
  StopOnSignal(const StopOnSignal&) = delete;
  StopOnSignal& operator=(const StopOnSignal&) = delete;
};

/// What a progress update throws after a StopOnSignal's signal (main catches it: exit 130).
struct Interrupted : std::runtime_error {
  Interrupted() : std::runtime_error("interrupted") {}
};

/// After an Interrupted has unwound the work: ends the process by the signal that stopped it (a
/// shell running volreel in a loop then stops too); returns if none came.
void end_by_stop_signal();

/// Throws Interrupted when a StopOnSignal's signal came, on the thread that made it and outside
/// any OpenMP parallel region (an exception must not leave one); otherwise nothing.
void stop_if_interrupted();

/// "1h02m", "3m07s", "12s".
std::string format_duration(double seconds);

}  // namespace volreel::cli
