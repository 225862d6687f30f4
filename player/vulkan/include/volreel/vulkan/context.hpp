// context.hpp: the Vulkan instance, the chosen physical device, the logical device and its queue
// — the foundation the atlas decoder, the ray-casting renderer and a windowed player share.
//
// Object lifetimes: every wrapper of resources.hpp keeps the VkDevice of the Context it was made
// from, so a Context must outlive every object created from it. A Context destroys, in order: its
// one-off command pool, the device (after vkDeviceWaitIdle), the debug messenger, the instance.
#pragma once

#include <vulkan/vulkan.h>

#include <cstdint>
#include <functional>
#include <mutex>
#include <string>
#include <vector>

#include "volreel/vulkan/error.hpp"

namespace volreel::vulkan {

/// Whether VK_LAYER_KHRONOS_validation is loaded.
enum class Validation {
  automatic,  ///< on in debug builds (no NDEBUG) or when VOLREEL_VULKAN_VALIDATION=1, if installed
  on,         ///< required: Context throws if the layer is not installed
  off,
};

struct ContextOptions {
  std::string application_name = "volreel";
  Validation validation = Validation::automatic;
  /// Extra instance extensions (e.g. glfwGetRequiredInstanceExtensions() for a window).
  std::vector<std::string> instance_extensions;
  /// Device extensions the device must support (e.g. VK_KHR_swapchain for a window).
  std::vector<std::string> device_extensions;
  /// Require a queue family that has graphics as well as compute.
  bool require_graphics = false;
  /// Optional extra test a queue family must pass (e.g. surface presentation support).
  std::function<bool(VkPhysicalDevice, std::uint32_t family)> queue_family_filter;
  /// Substring of the device name to prefer (also read from VOLREEL_VULKAN_DEVICE when empty).
  std::string preferred_device;
};

/// In LeakSanitizer builds: loads the Vulkan drivers once (a throwaway instance) and keeps them
/// loaded until exit, so that a leak inside a driver names its module and is suppressed, not
/// reported from "<unknown module>". A Context does this for the drivers and layers it loads; call
/// this first where other code makes Vulkan calls before any Context exists (GLFW's
/// glfwVulkanSupported loads and unloads every driver). Does nothing in other builds or when no
/// instance can be created.
void keep_vulkan_drivers_loaded();

/// One validation-layer message (severity warning or error).
struct ValidationMessage {
  VkDebugUtilsMessageSeverityFlagBitsEXT severity;
  std::string text;
};

/// Instance + physical device + device + one queue that supports compute (and graphics when
/// asked). Among suitable devices it takes a discrete GPU first, then integrated, virtual, and a
/// CPU implementation (lavapipe) last. Move-less: hold it in a unique_ptr or as a member.
class Context {
 public:
  /// Throws NoDeviceError when there is no Vulkan implementation or no suitable device, Error
  /// naming the call on any other failure.
  explicit Context(const ContextOptions& options = {});
  ~Context();
  Context(const Context&) = delete;
  Context& operator=(const Context&) = delete;

  VkInstance instance() const { return instance_; }
  VkPhysicalDevice physical_device() const { return physical_device_; }
  VkDevice device() const { return device_; }
  VkQueue queue() const { return queue_; }
  std::uint32_t queue_family() const { return queue_family_; }
  const VkPhysicalDeviceProperties& properties() const { return properties_; }
  const VkPhysicalDeviceLimits& limits() const { return properties_.limits; }
  const VkPhysicalDeviceFeatures& enabled_features() const { return enabled_features_; }
  std::string device_name() const { return properties_.deviceName; }
  /// "llvmpipe (LLVM 15.0.6, 256 bits), CPU, Vulkan 1.3.230, driver Mesa 22.3.6".
  std::string describe() const;
  bool validation_enabled() const { return messenger_ != VK_NULL_HANDLE; }

  /// Validation warnings and errors recorded so far (thread-safe copy).
  std::vector<ValidationMessage> validation_messages() const;
  void clear_validation_messages();

  /// A memory type index with all bits of `required` among `type_bits`, preferring one that also
  /// has `preferred`; throws Error if none.
  std::uint32_t find_memory_type(std::uint32_t type_bits, VkMemoryPropertyFlags required,
                                 VkMemoryPropertyFlags preferred = 0) const;
  VkMemoryPropertyFlags memory_type_flags(std::uint32_t type_index) const;
  /// Format features with optimal tiling.
  VkFormatFeatureFlags optimal_format_features(VkFormat format) const;

  /// Records commands with `record` into a one-off command buffer, submits it on the queue and
  /// waits for it (setup and readback; not for per-frame work).
  void submit_and_wait(const std::function<void(VkCommandBuffer)>& record) const;
  /// vkQueueSubmit on the queue (serialized by a mutex: a VkQueue is externally synchronized).
  void submit(const VkSubmitInfo& info, VkFence fence) const;
  void wait_idle() const;

 private:
  static VKAPI_ATTR VkBool32 VKAPI_CALL on_message(VkDebugUtilsMessageSeverityFlagBitsEXT severity,
                                                   VkDebugUtilsMessageTypeFlagsEXT types,
                                                   const VkDebugUtilsMessengerCallbackDataEXT* data,
                                                   void* user);

  VkInstance instance_ = VK_NULL_HANDLE;
  VkDebugUtilsMessengerEXT messenger_ = VK_NULL_HANDLE;
  VkPhysicalDevice physical_device_ = VK_NULL_HANDLE;
  VkDevice device_ = VK_NULL_HANDLE;
  VkQueue queue_ = VK_NULL_HANDLE;
  std::uint32_t queue_family_ = 0;
  VkPhysicalDeviceProperties properties_{};
  VkPhysicalDeviceMemoryProperties memory_{};
  VkPhysicalDeviceFeatures enabled_features_{};
  VkCommandPool one_off_pool_ = VK_NULL_HANDLE;
  mutable std::mutex messages_mutex_;
  std::vector<ValidationMessage> messages_;
  mutable std::mutex queue_mutex_;
};

}  // namespace volreel::vulkan
