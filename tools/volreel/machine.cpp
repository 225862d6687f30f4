// machine.cpp: what benchmarks print about the machine and the build they ran on.
#include <omp.h>

#include <fstream>
#include <string>
#include <thread>

#include "commands.hpp"

namespace volreel::cli {

std::string describe_machine() {
  std::string model = "unknown CPU";
  std::ifstream cpuinfo("/proc/cpuinfo");
  for (std::string line; std::getline(cpuinfo, line);)
    if (line.rfind("model name", 0) == 0) {
      model = line.substr(line.find(':') + 2);
      break;
    }
  std::string build = VOLREEL_BUILD_TYPE;
  if (!std::string(VOLREEL_SANITIZERS).empty()) build += " + sanitizers " VOLREEL_SANITIZERS;
  return model + ", " + std::to_string(std::thread::hardware_concurrency()) +
         " hardware threads, " + std::to_string(omp_get_max_threads()) +
         " OpenMP threads; volreel " VOLREEL_VERSION ", " + build + " build";
}

std::uint64_t peak_resident_bytes() {
  std::ifstream status("/proc/self/status");
  for (std::string line; std::getline(status, line);)
    if (line.rfind("VmHWM:", 0) == 0) return std::stoull(line.substr(6)) * 1024;  // in kB
  return 0;
}

}  // namespace volreel::cli
