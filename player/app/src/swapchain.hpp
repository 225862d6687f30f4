// swapchain.hpp: the window's surface and swapchain for the player — swapchain images used as
// blit destinations (the volume image), color attachments (ImGui) and copy sources (screenshots),
// one render pass that draws over what the blit left, framebuffers, and a "render finished"
// semaphore per image. Recreated on resize and on VK_ERROR_OUT_OF_DATE_KHR / VK_SUBOPTIMAL_KHR.
//
// Destruction order: framebuffers, views and semaphores, the swapchain, the render pass; the
// surface (Surface) after the swapchain. The caller waits for the device to be idle first.
#pragma once

#include <vulkan/vulkan.h>

#include <cstdint>
#include <vector>

#include "volreel/vulkan/context.hpp"
#include "volreel/vulkan/resources.hpp"

struct GLFWwindow;

namespace volreel::app::detail {

/// A VkSurfaceKHR of a GLFW window, destroyed with the instance's vkDestroySurfaceKHR.
class Surface {
 public:
  Surface(VkInstance instance, GLFWwindow* window);
  ~Surface();
  Surface(const Surface&) = delete;
  Surface& operator=(const Surface&) = delete;
  VkSurfaceKHR handle() const { return surface_; }

 private:
  VkInstance instance_ = VK_NULL_HANDLE;
  VkSurfaceKHR surface_ = VK_NULL_HANDLE;
};

class Swapchain {
 public:
  /// Chooses a B8G8R8A8/R8G8B8A8 UNORM format and FIFO (vsync) or IMMEDIATE/MAILBOX presentation;
  /// creates the render pass. Call recreate() before use. Throws vulkan::Error.
  Swapchain(const vulkan::Context& context, VkSurfaceKHR surface, bool vsync);
  ~Swapchain();
  Swapchain(const Swapchain&) = delete;
  Swapchain& operator=(const Swapchain&) = delete;

  /// (Re)creates the swapchain for the window's framebuffer size `wanted` (clamped to the
  /// surface's limits). The device must be idle. Returns false when the surface's extent is zero
  /// (minimized): nothing is created then.
  bool recreate(VkExtent2D wanted);

  VkSwapchainKHR handle() const { return swapchain_; }
  VkFormat format() const { return format_.format; }
  VkExtent2D extent() const { return extent_; }
  VkRenderPass render_pass() const { return render_pass_; }
  std::uint32_t image_count() const { return static_cast<std::uint32_t>(images_.size()); }
  std::uint32_t min_image_count() const { return min_image_count_; }
  VkImage image(std::uint32_t i) const { return images_[i]; }
  VkFramebuffer framebuffer(std::uint32_t i) const { return framebuffers_[i]; }
  VkSemaphore render_finished(std::uint32_t i) const { return render_finished_[i].handle(); }
  /// Whether the format stores blue first (B8G8R8A8): screenshots swap channels.
  bool bgr() const;
  /// Whether images can be copied from (screenshots of the composed frame).
  bool readable() const { return readable_; }

 private:
  const vulkan::Context& context_;
  VkSurfaceKHR surface_;
  VkSurfaceFormatKHR format_{};
  VkPresentModeKHR present_mode_ = VK_PRESENT_MODE_FIFO_KHR;
  VkRenderPass render_pass_ = VK_NULL_HANDLE;
  VkSwapchainKHR swapchain_ = VK_NULL_HANDLE;
  VkExtent2D extent_{};
  std::uint32_t min_image_count_ = 2;
  bool readable_ = false;
  std::vector<VkImage> images_;
  std::vector<VkImageView> views_;
  std::vector<VkFramebuffer> framebuffers_;
  std::vector<vulkan::Semaphore> render_finished_;

  void destroy_images();
};

}  // namespace volreel::app::detail
