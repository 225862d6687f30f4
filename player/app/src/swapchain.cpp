// swapchain.cpp: the player window's surface, swapchain and render pass (swapchain.hpp).
#define GLFW_INCLUDE_VULKAN
#include "swapchain.hpp"

#include <GLFW/glfw3.h>

#include <algorithm>

#include "volreel/vulkan/error.hpp"

namespace volreel::app::detail {

Surface::Surface(VkInstance instance, GLFWwindow* window) : instance_(instance) {
  vulkan::check(glfwCreateWindowSurface(instance, window, nullptr, &surface_),
                "glfwCreateWindowSurface");
}

Surface::~Surface() {
  if (surface_ != VK_NULL_HANDLE) vkDestroySurfaceKHR(instance_, surface_, nullptr);
}

Swapchain::Swapchain(const vulkan::Context& context, VkSurfaceKHR surface, bool vsync)
    : context_(context), surface_(surface) {
  const VkPhysicalDevice pd = context.physical_device();
  std::uint32_t count = 0;
  vulkan::check(vkGetPhysicalDeviceSurfaceFormatsKHR(pd, surface, &count, nullptr),
                "vkGetPhysicalDeviceSurfaceFormatsKHR");
  std::vector<VkSurfaceFormatKHR> formats(count);
  vulkan::check(vkGetPhysicalDeviceSurfaceFormatsKHR(pd, surface, &count, formats.data()),
                "vkGetPhysicalDeviceSurfaceFormatsKHR");
  if (formats.empty()) throw vulkan::Error("vkGetPhysicalDeviceSurfaceFormatsKHR: no format");
  // UNORM formats: the renderers' 8-bit values are display values already.
  format_ = formats[0];
  for (VkFormat wanted : {VK_FORMAT_B8G8R8A8_UNORM, VK_FORMAT_R8G8B8A8_UNORM}) {
    auto it = std::find_if(formats.begin(), formats.end(),
                           [&](const VkSurfaceFormatKHR& f) { return f.format == wanted; });
    if (it != formats.end()) {
      format_ = *it;
      break;
    }
  }
  vulkan::check(vkGetPhysicalDeviceSurfacePresentModesKHR(pd, surface, &count, nullptr),
                "vkGetPhysicalDeviceSurfacePresentModesKHR");
  std::vector<VkPresentModeKHR> modes(count);
  vulkan::check(vkGetPhysicalDeviceSurfacePresentModesKHR(pd, surface, &count, modes.data()),
                "vkGetPhysicalDeviceSurfacePresentModesKHR");
  if (!vsync) {
    for (VkPresentModeKHR m : {VK_PRESENT_MODE_MAILBOX_KHR, VK_PRESENT_MODE_IMMEDIATE_KHR})
      if (std::find(modes.begin(), modes.end(), m) != modes.end()) {
        present_mode_ = m;
        break;
      }
  }

  // The render pass draws ImGui over the blitted volume image (load, not clear) and leaves the
  // image ready to present.
  VkAttachmentDescription color{};
  color.format = format_.format;
  color.samples = VK_SAMPLE_COUNT_1_BIT;
  color.loadOp = VK_ATTACHMENT_LOAD_OP_LOAD;
  color.storeOp = VK_ATTACHMENT_STORE_OP_STORE;
  color.stencilLoadOp = VK_ATTACHMENT_LOAD_OP_DONT_CARE;
  color.stencilStoreOp = VK_ATTACHMENT_STORE_OP_DONT_CARE;
  color.initialLayout = VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL;
  color.finalLayout = VK_IMAGE_LAYOUT_PRESENT_SRC_KHR;
  VkAttachmentReference ref{0, VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL};
  VkSubpassDescription subpass{};
  subpass.pipelineBindPoint = VK_PIPELINE_BIND_POINT_GRAPHICS;
  subpass.colorAttachmentCount = 1;
  subpass.pColorAttachments = &ref;
  VkSubpassDependency dependency{};
  dependency.srcSubpass = VK_SUBPASS_EXTERNAL;
  dependency.dstSubpass = 0;
  dependency.srcStageMask = VK_PIPELINE_STAGE_TRANSFER_BIT;
  dependency.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
  dependency.dstStageMask = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
  dependency.dstAccessMask =
      VK_ACCESS_COLOR_ATTACHMENT_READ_BIT | VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
  VkRenderPassCreateInfo info{VK_STRUCTURE_TYPE_RENDER_PASS_CREATE_INFO};
  info.attachmentCount = 1;
  info.pAttachments = &color;
  info.subpassCount = 1;
  info.pSubpasses = &subpass;
  info.dependencyCount = 1;
  info.pDependencies = &dependency;
  vulkan::check(vkCreateRenderPass(context.device(), &info, nullptr, &render_pass_),
                "vkCreateRenderPass");
}

Swapchain::~Swapchain() {
  destroy_images();
  if (swapchain_ != VK_NULL_HANDLE) vkDestroySwapchainKHR(context_.device(), swapchain_, nullptr);
  if (render_pass_ != VK_NULL_HANDLE) vkDestroyRenderPass(context_.device(), render_pass_, nullptr);
}

bool Swapchain::bgr() const {
  return format_.format == VK_FORMAT_B8G8R8A8_UNORM || format_.format == VK_FORMAT_B8G8R8A8_SRGB;
}

void Swapchain::destroy_images() {
  const VkDevice device = context_.device();
  for (VkFramebuffer f : framebuffers_) vkDestroyFramebuffer(device, f, nullptr);
  for (VkImageView v : views_) vkDestroyImageView(device, v, nullptr);
  framebuffers_.clear();
  views_.clear();
  images_.clear();
  render_finished_.clear();
}

bool Swapchain::recreate(VkExtent2D wanted) {
  const VkDevice device = context_.device();
  VkSurfaceCapabilitiesKHR caps{};
  vulkan::check(
      vkGetPhysicalDeviceSurfaceCapabilitiesKHR(context_.physical_device(), surface_, &caps),
      "vkGetPhysicalDeviceSurfaceCapabilitiesKHR");
  VkExtent2D extent = caps.currentExtent;
  if (extent.width == 0xFFFFFFFFu) {
    extent.width = std::clamp(wanted.width, caps.minImageExtent.width, caps.maxImageExtent.width);
    extent.height =
        std::clamp(wanted.height, caps.minImageExtent.height, caps.maxImageExtent.height);
  }
  if (extent.width == 0 || extent.height == 0) return false;

  std::uint32_t images = std::max(caps.minImageCount + 1, 3u);
  if (caps.maxImageCount > 0) images = std::min(images, caps.maxImageCount);
  VkImageUsageFlags usage = VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT | VK_IMAGE_USAGE_TRANSFER_DST_BIT;
  if (caps.supportedUsageFlags & VK_IMAGE_USAGE_TRANSFER_SRC_BIT)
    usage |= VK_IMAGE_USAGE_TRANSFER_SRC_BIT;
  readable_ = (usage & VK_IMAGE_USAGE_TRANSFER_SRC_BIT) != 0;
  if (!(caps.supportedUsageFlags & VK_IMAGE_USAGE_TRANSFER_DST_BIT))
    throw vulkan::Error("vkCreateSwapchainKHR: the surface does not allow transfer destinations");

  VkSwapchainCreateInfoKHR info{VK_STRUCTURE_TYPE_SWAPCHAIN_CREATE_INFO_KHR};
  info.surface = surface_;
  info.minImageCount = images;
  info.imageFormat = format_.format;
  info.imageColorSpace = format_.colorSpace;
  info.imageExtent = extent;
  info.imageArrayLayers = 1;
  info.imageUsage = usage;
  info.imageSharingMode = VK_SHARING_MODE_EXCLUSIVE;
  info.preTransform = (caps.supportedTransforms & VK_SURFACE_TRANSFORM_IDENTITY_BIT_KHR)
                          ? VK_SURFACE_TRANSFORM_IDENTITY_BIT_KHR
                          : caps.currentTransform;
  info.compositeAlpha = (caps.supportedCompositeAlpha & VK_COMPOSITE_ALPHA_OPAQUE_BIT_KHR)
                            ? VK_COMPOSITE_ALPHA_OPAQUE_BIT_KHR
                            : VK_COMPOSITE_ALPHA_INHERIT_BIT_KHR;
  info.presentMode = present_mode_;
  info.clipped = VK_TRUE;
  info.oldSwapchain = swapchain_;
  VkSwapchainKHR created = VK_NULL_HANDLE;
  vulkan::check(vkCreateSwapchainKHR(device, &info, nullptr, &created), "vkCreateSwapchainKHR");
  destroy_images();
  if (swapchain_ != VK_NULL_HANDLE) vkDestroySwapchainKHR(device, swapchain_, nullptr);
  swapchain_ = created;
  extent_ = extent;
  min_image_count_ = images;

  std::uint32_t count = 0;
  vulkan::check(vkGetSwapchainImagesKHR(device, swapchain_, &count, nullptr),
                "vkGetSwapchainImagesKHR");
  images_.resize(count);
  vulkan::check(vkGetSwapchainImagesKHR(device, swapchain_, &count, images_.data()),
                "vkGetSwapchainImagesKHR");
  for (VkImage image : images_) {
    VkImageViewCreateInfo view{VK_STRUCTURE_TYPE_IMAGE_VIEW_CREATE_INFO};
    view.image = image;
    view.viewType = VK_IMAGE_VIEW_TYPE_2D;
    view.format = format_.format;
    view.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
    VkImageView v = VK_NULL_HANDLE;
    vulkan::check(vkCreateImageView(device, &view, nullptr, &v), "vkCreateImageView");
    views_.push_back(v);
    VkFramebufferCreateInfo fb{VK_STRUCTURE_TYPE_FRAMEBUFFER_CREATE_INFO};
    fb.renderPass = render_pass_;
    fb.attachmentCount = 1;
    fb.pAttachments = &v;
    fb.width = extent.width;
    fb.height = extent.height;
    fb.layers = 1;
    VkFramebuffer f = VK_NULL_HANDLE;
    vulkan::check(vkCreateFramebuffer(device, &fb, nullptr, &f), "vkCreateFramebuffer");
    framebuffers_.push_back(f);
    render_finished_.emplace_back(context_);
  }
  return true;
}

}  // namespace volreel::app::detail
