// module_residency.cpp: see module_residency.hpp.
#include "module_residency.hpp"

#include <vulkan/vulkan.h>

#ifdef VOLREEL_KEEP_VULKAN_MODULES
#include <dlfcn.h>
#include <link.h>

#include <algorithm>
#endif

#include "volreel/vulkan/context.hpp"

namespace volreel::vulkan::detail {

#ifdef VOLREEL_KEEP_VULKAN_MODULES

std::vector<std::string> loaded_modules() {
  std::vector<std::string> paths;
  dl_iterate_phdr(
      [](dl_phdr_info* info, std::size_t, void* out) {
        // The executable itself (and the vDSO on some systems) has an empty name.
        if (info->dlpi_name != nullptr && info->dlpi_name[0] != '\0')
          static_cast<std::vector<std::string>*>(out)->emplace_back(info->dlpi_name);
        return 0;
      },
      &paths);
  return paths;
}

void keep_modules_loaded_since(const std::vector<std::string>& before) {
  for (const std::string& path : loaded_modules())
    if (std::find(before.begin(), before.end(), path) == before.end())
      // RTLD_NOLOAD: only modules already loaded; RTLD_NODELETE: never unloaded. The handle is
      // deliberately not closed.
      dlopen(path.c_str(), RTLD_LAZY | RTLD_NOLOAD | RTLD_NODELETE);
}

#else

std::vector<std::string> loaded_modules() {
  return {};
}
void keep_modules_loaded_since(const std::vector<std::string>&) {}

#endif

}  // namespace volreel::vulkan::detail

namespace volreel::vulkan {

void keep_vulkan_drivers_loaded() {
#ifdef VOLREEL_KEEP_VULKAN_MODULES
  const std::vector<std::string> before = detail::loaded_modules();
  VkApplicationInfo app{VK_STRUCTURE_TYPE_APPLICATION_INFO};
  app.pApplicationName = "volreel";
  app.apiVersion = VK_API_VERSION_1_1;
  VkInstanceCreateInfo info{VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO};
  info.pApplicationInfo = &app;
  VkInstance instance = VK_NULL_HANDLE;
  if (vkCreateInstance(&info, nullptr, &instance) != VK_SUCCESS) return;  // a Context will say why
  detail::keep_modules_loaded_since(before);
  vkDestroyInstance(instance, nullptr);
#endif
}

}  // namespace volreel::vulkan

#ifdef VOLREEL_KEEP_VULKAN_MODULES
/// LeakSanitizer's suppressions for every program that creates a Context (LeakSanitizer reads this
/// hook at exit; LSAN_OPTIONS=suppressions=FILE adds to it): leaks whose stack passes through a
/// Vulkan driver (Mesa's libvulkan_*.so, lavapipe among them) or layer (libVkLayer_*.so).
/// Allocations made by volreel's own code are still reported, in Vulkan programs too
/// (tests/vulkan/leak_check_test.sh checks both).
extern "C" const char* __lsan_default_suppressions() {
  return "leak:libvulkan_*.so\n"
         "leak:libVkLayer_*.so\n";
}
#endif
