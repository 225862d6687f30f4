// module_residency.hpp: keeps the shared objects the Vulkan loader opens (drivers, layers) loaded
// until exit in LeakSanitizer builds, so that leak reports inside them can name their module.
//
// The loader unloads its drivers and layers (dlclose) when an instance is destroyed. Memory a
// driver holds in its globals until then would be reported as a leak from "<unknown module>",
// which no suppression can match, and its own leaks could not be told from volreel's. With the
// modules resident, LeakSanitizer scans their globals at exit and names the module of what is
// left; module_residency.cpp holds the suppressions, scoped to Vulkan drivers and layers.
// In other builds these functions do nothing.
#pragma once

#include <string>
#include <vector>

namespace volreel::vulkan::detail {

/// Paths of the shared objects loaded now; empty in builds without LeakSanitizer.
std::vector<std::string> loaded_modules();

/// Marks every shared object loaded now and absent from `before` as never to be unloaded.
void keep_modules_loaded_since(const std::vector<std::string>& before);

}  // namespace volreel::vulkan::detail
