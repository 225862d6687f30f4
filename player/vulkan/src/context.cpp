// context.cpp: instance, validation messenger, physical device choice, device and queue.
#include "volreel/vulkan/context.hpp"

#include "module_residency.hpp"

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <optional>

namespace volreel::vulkan {

namespace {

constexpr const char* validation_layer = "VK_LAYER_KHRONOS_validation";

bool env_flag(const char* name) {
  const char* v = std::getenv(name);
  return v != nullptr && *v != '\0' && std::strcmp(v, "0") != 0;
}

bool layer_available(const char* name) {
  std::uint32_t count = 0;
  check(vkEnumerateInstanceLayerProperties(&count, nullptr), "vkEnumerateInstanceLayerProperties");
  std::vector<VkLayerProperties> layers(count);
  check(vkEnumerateInstanceLayerProperties(&count, layers.data()),
        "vkEnumerateInstanceLayerProperties");
  return std::any_of(layers.begin(), layers.end(), [&](const VkLayerProperties& l) {
    return std::strcmp(l.layerName, name) == 0;
  });
}

bool instance_extension_available(const char* name) {
  std::uint32_t count = 0;
  check(vkEnumerateInstanceExtensionProperties(nullptr, &count, nullptr),
        "vkEnumerateInstanceExtensionProperties");
  std::vector<VkExtensionProperties> ext(count);
  check(vkEnumerateInstanceExtensionProperties(nullptr, &count, ext.data()),
        "vkEnumerateInstanceExtensionProperties");
  return std::any_of(ext.begin(), ext.end(), [&](const VkExtensionProperties& e) {
    return std::strcmp(e.extensionName, name) == 0;
  });
}

bool device_supports(VkPhysicalDevice device, const std::vector<std::string>& extensions) {
  std::uint32_t count = 0;
  check(vkEnumerateDeviceExtensionProperties(device, nullptr, &count, nullptr),
        "vkEnumerateDeviceExtensionProperties");
  std::vector<VkExtensionProperties> ext(count);
  check(vkEnumerateDeviceExtensionProperties(device, nullptr, &count, ext.data()),
        "vkEnumerateDeviceExtensionProperties");
  for (const std::string& want : extensions)
    if (std::none_of(ext.begin(), ext.end(),
                     [&](const VkExtensionProperties& e) { return want == e.extensionName; }))
      return false;
  return true;
}

int type_rank(VkPhysicalDeviceType type) {
  switch (type) {
    case VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU:
      return 4;
    case VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU:
      return 3;
    case VK_PHYSICAL_DEVICE_TYPE_VIRTUAL_GPU:
      return 2;
    case VK_PHYSICAL_DEVICE_TYPE_CPU:
      return 1;
    default:
      return 0;
  }
}

const char* type_name(VkPhysicalDeviceType type) {
  switch (type) {
    case VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU:
      return "discrete GPU";
    case VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU:
      return "integrated GPU";
    case VK_PHYSICAL_DEVICE_TYPE_VIRTUAL_GPU:
      return "virtual GPU";
    case VK_PHYSICAL_DEVICE_TYPE_CPU:
      return "CPU";
    default:
      return "other";
  }
}

std::string version_string(std::uint32_t v) {
  return std::to_string(VK_API_VERSION_MAJOR(v)) + "." + std::to_string(VK_API_VERSION_MINOR(v)) +
         "." + std::to_string(VK_API_VERSION_PATCH(v));
}

}  // namespace

VKAPI_ATTR VkBool32 VKAPI_CALL Context::on_message(VkDebugUtilsMessageSeverityFlagBitsEXT severity,
                                                   VkDebugUtilsMessageTypeFlagsEXT,
                                                   const VkDebugUtilsMessengerCallbackDataEXT* data,
                                                   void* user) {
  auto* self = static_cast<Context*>(user);
  std::lock_guard lock(self->messages_mutex_);
  self->messages_.push_back({severity, data && data->pMessage ? data->pMessage : "(no text)"});
  return VK_FALSE;
}

Context::Context(const ContextOptions& options) {
  // The destructor does not run when the constructor throws: release what was made so far.
  struct Cleanup {
    Context* self;
    bool armed = true;
    ~Cleanup() {
      if (!armed) return;
      if (self->one_off_pool_) vkDestroyCommandPool(self->device_, self->one_off_pool_, nullptr);
      if (self->device_) vkDestroyDevice(self->device_, nullptr);
      if (self->messenger_) {
        auto destroy = reinterpret_cast<PFN_vkDestroyDebugUtilsMessengerEXT>(
            vkGetInstanceProcAddr(self->instance_, "vkDestroyDebugUtilsMessengerEXT"));
        if (destroy) destroy(self->instance_, self->messenger_, nullptr);
      }
      if (self->instance_) vkDestroyInstance(self->instance_, nullptr);
    }
  } cleanup{this};
  const std::vector<std::string> modules_before = detail::loaded_modules();

  // 1. Instance: API version, validation layer, extensions.
  std::uint32_t loader_version = VK_API_VERSION_1_0;
  if (vkEnumerateInstanceVersion(&loader_version) != VK_SUCCESS)
    loader_version = VK_API_VERSION_1_0;
  if (loader_version < VK_API_VERSION_1_1)
    throw NoDeviceError(
        "Vulkan 1.1 is required; the loader offers " + version_string(loader_version),
        VK_ERROR_INCOMPATIBLE_DRIVER);
  bool want_validation = false;
  switch (options.validation) {
    case Validation::on:
      want_validation = true;
      if (!layer_available(validation_layer))
        throw Error(std::string(validation_layer) +
                        " was requested but is not installed (Debian: vulkan-validationlayers)",
                    VK_ERROR_LAYER_NOT_PRESENT);
      break;
    case Validation::automatic:
#ifndef NDEBUG
      want_validation = true;
#endif
      if (env_flag("VOLREEL_VULKAN_VALIDATION")) want_validation = true;
      want_validation = want_validation && layer_available(validation_layer);
      break;
    case Validation::off:
      break;
  }
  want_validation =
      want_validation && instance_extension_available(VK_EXT_DEBUG_UTILS_EXTENSION_NAME);
  std::vector<const char*> layers, extensions;
  if (want_validation) {
    layers.push_back(validation_layer);
    extensions.push_back(VK_EXT_DEBUG_UTILS_EXTENSION_NAME);
  }
  for (const std::string& e : options.instance_extensions) extensions.push_back(e.c_str());

  VkApplicationInfo app{VK_STRUCTURE_TYPE_APPLICATION_INFO};
  app.pApplicationName = options.application_name.c_str();
  app.pEngineName = "volreel";
  app.apiVersion = std::min<std::uint32_t>(loader_version, VK_API_VERSION_1_2);
  VkDebugUtilsMessengerCreateInfoEXT messenger_info{
      VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT};
  messenger_info.messageSeverity = VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT |
                                   VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT;
  messenger_info.messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT |
                               VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT |
                               VK_DEBUG_UTILS_MESSAGE_TYPE_PERFORMANCE_BIT_EXT;
  messenger_info.pfnUserCallback = &Context::on_message;
  messenger_info.pUserData = this;
  VkInstanceCreateInfo instance_info{VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO};
  instance_info.pNext = want_validation ? &messenger_info : nullptr;  // instance creation messages
  instance_info.pApplicationInfo = &app;
  instance_info.enabledLayerCount = static_cast<std::uint32_t>(layers.size());
  instance_info.ppEnabledLayerNames = layers.data();
  instance_info.enabledExtensionCount = static_cast<std::uint32_t>(extensions.size());
  instance_info.ppEnabledExtensionNames = extensions.data();
  const VkResult created = vkCreateInstance(&instance_info, nullptr, &instance_);
  if (created == VK_ERROR_INCOMPATIBLE_DRIVER)
    throw NoDeviceError(
        "vkCreateInstance: VK_ERROR_INCOMPATIBLE_DRIVER (no Vulkan implementation "
        "is installed; Debian: mesa-vulkan-drivers)",
        created);
  check(created, "vkCreateInstance");
  detail::keep_modules_loaded_since(modules_before);  // the drivers (ICDs) and layers just opened
  if (want_validation) {
    auto create = reinterpret_cast<PFN_vkCreateDebugUtilsMessengerEXT>(
        vkGetInstanceProcAddr(instance_, "vkCreateDebugUtilsMessengerEXT"));
    if (!create) throw Error("vkGetInstanceProcAddr: vkCreateDebugUtilsMessengerEXT is missing");
    check(create(instance_, &messenger_info, nullptr, &messenger_),
          "vkCreateDebugUtilsMessengerEXT");
  }

  // 2. Physical device: a queue family with compute (and graphics if asked), the extensions;
  //    rank discrete > integrated > virtual > CPU, a name match first.
  std::uint32_t count = 0;
  check(vkEnumeratePhysicalDevices(instance_, &count, nullptr), "vkEnumeratePhysicalDevices");
  std::vector<VkPhysicalDevice> devices(count);
  check(vkEnumeratePhysicalDevices(instance_, &count, devices.data()),
        "vkEnumeratePhysicalDevices");
  std::string preferred = options.preferred_device;
  if (preferred.empty() && std::getenv("VOLREEL_VULKAN_DEVICE"))
    preferred = std::getenv("VOLREEL_VULKAN_DEVICE");
  int best_rank = -1;
  std::string seen;
  for (VkPhysicalDevice candidate : devices) {
    VkPhysicalDeviceProperties props;
    vkGetPhysicalDeviceProperties(candidate, &props);
    seen += std::string(seen.empty() ? "" : ", ") + props.deviceName;
    if (props.apiVersion < VK_API_VERSION_1_1) continue;
    if (!device_supports(candidate, options.device_extensions)) continue;
    std::uint32_t family_count = 0;
    vkGetPhysicalDeviceQueueFamilyProperties(candidate, &family_count, nullptr);
    std::vector<VkQueueFamilyProperties> families(family_count);
    vkGetPhysicalDeviceQueueFamilyProperties(candidate, &family_count, families.data());
    std::optional<std::uint32_t> family;
    for (std::uint32_t f = 0; f < family_count && !family; ++f) {
      const VkQueueFlags flags = families[f].queueFlags;
      if (!(flags & VK_QUEUE_COMPUTE_BIT)) continue;
      if (options.require_graphics && !(flags & VK_QUEUE_GRAPHICS_BIT)) continue;
      if (options.queue_family_filter && !options.queue_family_filter(candidate, f)) continue;
      family = f;
    }
    if (!family) continue;
    int rank = type_rank(props.deviceType);
    if (!preferred.empty() && std::string(props.deviceName).find(preferred) != std::string::npos)
      rank += 100;
    if (rank > best_rank) {
      best_rank = rank;
      physical_device_ = candidate;
      queue_family_ = *family;
      properties_ = props;
    }
  }
  if (physical_device_ == VK_NULL_HANDLE)
    throw NoDeviceError(
        devices.empty()
            ? std::string("no Vulkan device (vkEnumeratePhysicalDevices found none)")
            : "no Vulkan device with the queue and extensions volreel needs among: " + seen);
  vkGetPhysicalDeviceMemoryProperties(physical_device_, &memory_);

  // 3. Device and queue; features the atlas needs where present (storage images of 16-bit formats).
  VkPhysicalDeviceFeatures supported;
  vkGetPhysicalDeviceFeatures(physical_device_, &supported);
  enabled_features_.shaderStorageImageExtendedFormats = supported.shaderStorageImageExtendedFormats;
  enabled_features_.shaderStorageImageWriteWithoutFormat =
      supported.shaderStorageImageWriteWithoutFormat;
  enabled_features_.samplerAnisotropy = supported.samplerAnisotropy;
  const float priority = 1.0f;
  VkDeviceQueueCreateInfo queue_info{VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO};
  queue_info.queueFamilyIndex = queue_family_;
  queue_info.queueCount = 1;
  queue_info.pQueuePriorities = &priority;
  std::vector<const char*> device_extensions;
  for (const std::string& e : options.device_extensions) device_extensions.push_back(e.c_str());
  VkDeviceCreateInfo device_info{VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO};
  device_info.queueCreateInfoCount = 1;
  device_info.pQueueCreateInfos = &queue_info;
  device_info.enabledExtensionCount = static_cast<std::uint32_t>(device_extensions.size());
  device_info.ppEnabledExtensionNames = device_extensions.data();
  device_info.pEnabledFeatures = &enabled_features_;
  check(vkCreateDevice(physical_device_, &device_info, nullptr, &device_), "vkCreateDevice");
  detail::keep_modules_loaded_since(modules_before);  // and any the device brought in
  vkGetDeviceQueue(device_, queue_family_, 0, &queue_);

  VkCommandPoolCreateInfo pool_info{VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO};
  pool_info.flags = VK_COMMAND_POOL_CREATE_TRANSIENT_BIT;
  pool_info.queueFamilyIndex = queue_family_;
  check(vkCreateCommandPool(device_, &pool_info, nullptr, &one_off_pool_), "vkCreateCommandPool");
  cleanup.armed = false;
}

Context::~Context() {
  if (device_) vkDeviceWaitIdle(device_);
  if (one_off_pool_) vkDestroyCommandPool(device_, one_off_pool_, nullptr);
  if (device_) vkDestroyDevice(device_, nullptr);
  if (messenger_) {
    auto destroy = reinterpret_cast<PFN_vkDestroyDebugUtilsMessengerEXT>(
        vkGetInstanceProcAddr(instance_, "vkDestroyDebugUtilsMessengerEXT"));
    if (destroy) destroy(instance_, messenger_, nullptr);
  }
  if (instance_) vkDestroyInstance(instance_, nullptr);
}

std::string Context::describe() const {
  return std::string(properties_.deviceName) + ", " + type_name(properties_.deviceType) +
         ", Vulkan " + version_string(properties_.apiVersion) +
         (validation_enabled() ? ", validation on" : "");
}

std::vector<ValidationMessage> Context::validation_messages() const {
  std::lock_guard lock(messages_mutex_);
  return messages_;
}

void Context::clear_validation_messages() {
  std::lock_guard lock(messages_mutex_);
  messages_.clear();
}

std::uint32_t Context::find_memory_type(std::uint32_t type_bits, VkMemoryPropertyFlags required,
                                        VkMemoryPropertyFlags preferred) const {
  std::optional<std::uint32_t> fallback;
  for (std::uint32_t i = 0; i < memory_.memoryTypeCount; ++i) {
    if (!(type_bits & (1u << i))) continue;
    const VkMemoryPropertyFlags flags = memory_.memoryTypes[i].propertyFlags;
    if ((flags & required) != required) continue;
    if ((flags & preferred) == preferred) return i;
    if (!fallback) fallback = i;
  }
  if (!fallback)
    throw Error("vkGetPhysicalDeviceMemoryProperties: no memory type with flags " +
                    std::to_string(required) + " among types " + std::to_string(type_bits),
                VK_ERROR_OUT_OF_DEVICE_MEMORY);
  return *fallback;
}

VkMemoryPropertyFlags Context::memory_type_flags(std::uint32_t type_index) const {
  return memory_.memoryTypes[type_index].propertyFlags;
}

VkFormatFeatureFlags Context::optimal_format_features(VkFormat format) const {
  VkFormatProperties props;
  vkGetPhysicalDeviceFormatProperties(physical_device_, format, &props);
  return props.optimalTilingFeatures;
}

void Context::submit(const VkSubmitInfo& info, VkFence fence) const {
  std::lock_guard lock(queue_mutex_);
  check(vkQueueSubmit(queue_, 1, &info, fence), "vkQueueSubmit");
}

void Context::submit_and_wait(const std::function<void(VkCommandBuffer)>& record) const {
  VkCommandBufferAllocateInfo alloc{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
  alloc.commandPool = one_off_pool_;
  alloc.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  alloc.commandBufferCount = 1;
  VkCommandBuffer commands = VK_NULL_HANDLE;
  VkFence fence = VK_NULL_HANDLE;
  std::lock_guard lock(queue_mutex_);  // the one-off pool is used under the same lock
  check(vkAllocateCommandBuffers(device_, &alloc, &commands), "vkAllocateCommandBuffers");
  struct Release {
    const Context* self;
    VkCommandBuffer& commands;
    VkFence& fence;
    ~Release() {
      if (fence) vkDestroyFence(self->device_, fence, nullptr);
      vkFreeCommandBuffers(self->device_, self->one_off_pool_, 1, &commands);
    }
  } release{this, commands, fence};
  VkCommandBufferBeginInfo begin{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
  begin.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  check(vkBeginCommandBuffer(commands, &begin), "vkBeginCommandBuffer");
  record(commands);
  check(vkEndCommandBuffer(commands), "vkEndCommandBuffer");
  VkFenceCreateInfo fence_info{VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
  check(vkCreateFence(device_, &fence_info, nullptr, &fence), "vkCreateFence");
  VkSubmitInfo submit_info{VK_STRUCTURE_TYPE_SUBMIT_INFO};
  submit_info.commandBufferCount = 1;
  submit_info.pCommandBuffers = &commands;
  check(vkQueueSubmit(queue_, 1, &submit_info, fence), "vkQueueSubmit");
  check(vkWaitForFences(device_, 1, &fence, VK_TRUE, UINT64_MAX), "vkWaitForFences");
}

void Context::wait_idle() const {
  std::lock_guard lock(queue_mutex_);
  check(vkDeviceWaitIdle(device_), "vkDeviceWaitIdle");
}

}  // namespace volreel::vulkan
