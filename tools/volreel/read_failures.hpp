// read_failures.hpp: the bricks and frames a playing command (render, bench play) could not read,
// each reported once, and the run's end that says it failed.
#pragma once

#include <cstdio>
#include <set>
#include <string>
#include <vector>

#include "volreel/datasets/volume.hpp"

namespace volreel::cli {

class ReadFailures {
 public:
  /// Prints each message not seen before as a warning (a brick that cannot be read fails again
  /// each time it is requested). `prefix` goes before it (a newline after a progress bar).
  void add(const std::vector<std::string>& messages, const char* prefix = "") {
    for (const std::string& e : messages)
      if (seen_.insert(e).second)
        std::fprintf(stderr, "%svolreel: warning: %s\n", prefix, e.c_str());
  }
  /// Throws InputError with the count when there was any: the run's output is of frames drawn
  /// without them (`what_was_made`, e.g. "the frames were drawn without them").
  void fail_if_any(const std::string& what_was_made) const {
    if (!seen_.empty())
      throw InputError(std::to_string(seen_.size()) +
                       " bricks or frames could not be read (see the warnings above, which name "
                       "them): " +
                       what_was_made);
  }

 private:
  std::set<std::string> seen_;
};

}  // namespace volreel::cli
