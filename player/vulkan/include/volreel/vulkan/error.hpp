// error.hpp: Vulkan results turned into exceptions that name the call and the VkResult
// ("vkCreateBuffer: VK_ERROR_OUT_OF_DEVICE_MEMORY"). volreel never aborts on a failed call.
#pragma once

#include <vulkan/vulkan.h>

#include <stdexcept>
#include <string>

namespace volreel::vulkan {

/// A failed Vulkan call (or a missing capability), with the VkResult when there is one.
class Error : public std::runtime_error {
 public:
  Error(const std::string& what, VkResult result = VK_ERROR_UNKNOWN)
      : std::runtime_error(what), result_(result) {}
  VkResult result() const noexcept { return result_; }

 private:
  VkResult result_;
};

/// No Vulkan implementation, or none with a suitable device: callers (tests) skip rather than fail.
class NoDeviceError : public Error {
 public:
  using Error::Error;
};

/// "VK_ERROR_OUT_OF_DEVICE_MEMORY" (or "VkResult(unknown)" for a value this build does not name).
const char* result_name(VkResult result);

/// Throws Error("<call>: <result name>") unless result is VK_SUCCESS (or another non-error
/// success code such as VK_INCOMPLETE, which is returned).
inline VkResult check(VkResult result, const char* call) {
  if (result < 0) throw Error(std::string(call) + ": " + result_name(result), result);
  return result;
}

}  // namespace volreel::vulkan
