// memory.hpp: how much memory this process may use, for the checks that refuse work too large for
// the machine before it starts (training's Gram matrix, the encoder's frames in memory).
#pragma once

#include <cstdint>
#include <filesystem>

namespace volreel::format::detail {

/// The machine's physical memory, or the memory limit of the control group the process runs in
/// where that is lower (a container's or a batch job's: cgroup v2's memory.max, v1's
/// memory/memory.limit_in_bytes, under `cgroup_root`), in bytes; 0 when neither can be read.
std::uint64_t usable_memory_bytes(const std::filesystem::path& cgroup_root = "/sys/fs/cgroup");

}  // namespace volreel::format::detail
