// memory.cpp: the memory this process may use (see memory.hpp).
#include "volreel/format/memory.hpp"

#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

namespace volreel::format::detail {
namespace {

/// The number a cgroup limit file holds, or 0 when it is missing, says "max" (no limit), holds
/// anything but a whole number, or a value of 2^62 or more (cgroup v1 writes "no limit" as a
/// number near 2^63).
std::uint64_t cgroup_limit(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::string text;
  if (!(in >> text) || text.empty() || text.size() > 19 ||
      text.find_first_not_of("0123456789") != std::string::npos)
    return 0;
  const std::uint64_t limit = std::strtoull(text.c_str(), nullptr, 10);
  return limit < (std::uint64_t{1} << 62) ? limit : 0;
}

/// The folders whose memory limit binds this process, below `root` (the v2 hierarchy, or v1's
/// memory controller): its own control group's folder and every parent, from /proc/self/cgroup's
/// line for that hierarchy ("0::PATH" for v2, "N:...memory...:PATH" for v1), and `root` itself.
std::vector<std::filesystem::path> limit_folders(const std::filesystem::path& root,
                                                 const std::filesystem::path& self_cgroup,
                                                 bool v2) {
  std::vector<std::filesystem::path> folders{root};
  std::ifstream in(self_cgroup);
  for (std::string line; std::getline(in, line);) {
    const std::size_t first = line.find(':'), second = line.find(':', first + 1);
    if (first == std::string::npos || second == std::string::npos) continue;
    const std::string controllers = line.substr(first + 1, second - first - 1);
    bool memory = false;
    for (std::size_t at = 0; at <= controllers.size();) {
      const std::size_t end = std::min(controllers.find(',', at), controllers.size());
      memory = memory || controllers.substr(at, end - at) == "memory";
      at = end + 1;
    }
    if (v2 ? !(line.compare(0, first, "0") == 0 && controllers.empty()) : !memory) continue;
    std::filesystem::path path = line.substr(second + 1);
    for (; path.has_relative_path(); path = path.parent_path())
      folders.push_back(root / path.relative_path());
  }
  return folders;
}

}  // namespace

std::uint64_t usable_memory_bytes(const std::filesystem::path& cgroup_root,
                                  const std::filesystem::path& self_cgroup) {
  const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGESIZE);
  std::uint64_t memory = pages > 0 && page > 0
                             ? static_cast<std::uint64_t>(pages) * static_cast<std::uint64_t>(page)
                             : 0;
  const auto lower = [&](const std::filesystem::path& file) {
    const std::uint64_t limit = cgroup_limit(file);
    if (limit > 0 && (memory == 0 || limit < memory)) memory = limit;
  };
  for (const std::filesystem::path& folder : limit_folders(cgroup_root, self_cgroup, true))
    lower(folder / "memory.max");
  for (const std::filesystem::path& folder :
       limit_folders(cgroup_root / "memory", self_cgroup, false))
    lower(folder / "memory.limit_in_bytes");
  return memory;
}

}  // namespace volreel::format::detail
