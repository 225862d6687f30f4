// memory.cpp: the memory this process may use (see memory.hpp).
#include "volreel/format/memory.hpp"

#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <string>

namespace volreel::format::detail {
namespace {

/// The number a cgroup limit file holds, or 0 when it is missing, says "max" (no limit) or holds
/// anything but a whole number.
std::uint64_t cgroup_limit(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::string text;
  if (!(in >> text) || text.empty() || text.find_first_not_of("0123456789") != std::string::npos)
    return 0;
  return std::strtoull(text.c_str(), nullptr, 10);
}

}  // namespace

std::uint64_t usable_memory_bytes(const std::filesystem::path& cgroup_root) {
  const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGESIZE);
  std::uint64_t memory = pages > 0 && page > 0
                             ? static_cast<std::uint64_t>(pages) * static_cast<std::uint64_t>(page)
                             : 0;
  // cgroup v1 writes "no limit" as a number near 2^63: any limit above the physical memory is none.
  for (const std::filesystem::path& path :
       {cgroup_root / "memory.max", cgroup_root / "memory" / "memory.limit_in_bytes"}) {
    const std::uint64_t limit = cgroup_limit(path);
    if (limit > 0 && (memory == 0 || limit < memory)) memory = limit;
  }
  return memory;
}

}  // namespace volreel::format::detail
