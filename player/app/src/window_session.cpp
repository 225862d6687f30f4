// window_session.cpp: Dear ImGui's session (see window_session.hpp).
#include "window_session.hpp"

#include <backends/imgui_impl_glfw.h>
#include <backends/imgui_impl_vulkan.h>
#include <imgui.h>

#include <algorithm>
#include <array>

#include "volreel/vulkan/error.hpp"

namespace volreel::app::detail {
namespace {

void check_imgui_vk(VkResult result) {
  vulkan::check(result, "ImGui Vulkan backend");
}

}  // namespace

ImGuiSession::ImGuiSession(const vulkan::Context& context, GLFWwindow* window,
                           const Swapchain& swapchain, std::uint32_t frames_in_flight) {
  const std::array<VkDescriptorPoolSize, 1> sizes{
      VkDescriptorPoolSize{VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, 16}};
  pool_ = vulkan::DescriptorPool(context, sizes, 16);
  IMGUI_CHECKVERSION();
  ImGui::CreateContext();
  ImGui::GetIO().IniFilename = nullptr;  // no imgui.ini next to the user's files
  ImGui::StyleColorsDark();
  ImGui::GetStyle().Alpha = 0.92f;
  ImGui_ImplGlfw_InitForVulkan(window, true);
  ImGui_ImplVulkan_InitInfo info{};
  info.Instance = context.instance();
  info.PhysicalDevice = context.physical_device();
  info.Device = context.device();
  info.QueueFamily = context.queue_family();
  info.Queue = context.queue();
  info.DescriptorPool = pool_.handle();
  info.Subpass = 0;
  info.MinImageCount = std::max(swapchain.min_image_count(), 2u);
  info.ImageCount = std::max(swapchain.image_count(), frames_in_flight + 1);
  info.MSAASamples = VK_SAMPLE_COUNT_1_BIT;
  info.CheckVkResultFn = check_imgui_vk;
  ImGui_ImplVulkan_Init(&info, swapchain.render_pass());
  context.submit_and_wait([](VkCommandBuffer cb) { ImGui_ImplVulkan_CreateFontsTexture(cb); });
  ImGui_ImplVulkan_DestroyFontUploadObjects();
}
ImGuiSession::~ImGuiSession() {
  ImGui_ImplVulkan_Shutdown();
  ImGui_ImplGlfw_Shutdown();
  ImGui::DestroyContext();
}

}  // namespace volreel::app::detail
