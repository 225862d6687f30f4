// memory.hpp: how much memory this process may use, for the checks that refuse work too large for
// the machine before it starts (training's Gram matrix, the encoder's frames in memory).
#pragma once

#include <cstdint>
#include <filesystem>

namespace volreel::format::detail {

/// The machine's physical memory, or the lowest memory limit of the control group the process
/// runs in and its parents where that is lower (a container's, a batch job's, a systemd slice's:
/// cgroup v2's memory.max, v1's memory/…/memory.limit_in_bytes, under `cgroup_root`, the group
/// read from `self_cgroup`), in bytes; 0 when none can be read.
std::uint64_t usable_memory_bytes(const std::filesystem::path& cgroup_root = "/sys/fs/cgroup",
                                  const std::filesystem::path& self_cgroup = "/proc/self/cgroup");

}  // namespace volreel::format::detail
