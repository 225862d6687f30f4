// progress.hpp: the terminal progress bar the volreel program draws for long work.
#pragma once

#include <chrono>
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

/// "1h02m", "3m07s", "12s".
std::string format_duration(double seconds);

}  // namespace volreel::cli
