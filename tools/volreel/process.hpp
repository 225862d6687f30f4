// process.hpp: finding and running another program (no shell) — ffmpeg for `volreel render
// --video`.
#pragma once

#include <string>
#include <vector>

namespace volreel::cli {

/// The executable's full path if `name` is on PATH, else empty.
std::string find_on_path(const std::string& name);

/// Runs a program with arguments (no shell); returns its exit status, or -1 if it did not start.
int run_program(const std::string& program, const std::vector<std::string>& args);

}  // namespace volreel::cli
