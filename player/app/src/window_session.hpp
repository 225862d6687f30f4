// window_session.hpp: the player's window and its libraries' sessions — GLFW (glfwInit /
// glfwTerminate), the GLFW window, and Dear ImGui with its GLFW and Vulkan backends — each owned
// by one object and shut down in reverse order.
#pragma once

#define GLFW_INCLUDE_VULKAN
#include <GLFW/glfw3.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "swapchain.hpp"
#include "volreel/app/player.hpp"
#include "volreel/vulkan/context.hpp"
#include "volreel/vulkan/resources.hpp"

namespace volreel::app::detail {

/// glfwInit / glfwTerminate.
class GlfwSession {
 public:
  GlfwSession() {
    glfwSetErrorCallback([](int code, const char* text) {
      std::fprintf(stderr, "volreel play: GLFW error %d: %s\n", code, text);
    });
    const char* display = std::getenv("DISPLAY");
    const char* wayland = std::getenv("WAYLAND_DISPLAY");
    const bool has_display = (display && *display) || (wayland && *wayland);
    if (!has_display || !glfwInit())
      throw NoDisplayError(std::string(has_display ? "cannot connect to the display"
                                                   : "no display ($DISPLAY unset)") +
                           ": `volreel play` needs a window. Run it under a virtual display with "
                           "`xvfb-run -a volreel play NAME.vreel`, or render without a window with "
                           "`volreel render NAME.vreel --tour T.json --out DIR`.");
  }
  ~GlfwSession() { glfwTerminate(); }
  GlfwSession(const GlfwSession&) = delete;
  GlfwSession& operator=(const GlfwSession&) = delete;
};

class Window {
 public:
  Window(int width, int height, const std::string& title) {
    glfwWindowHint(GLFW_CLIENT_API, GLFW_NO_API);
    glfwWindowHint(GLFW_RESIZABLE, GLFW_TRUE);
    window_ = glfwCreateWindow(width, height, title.c_str(), nullptr, nullptr);
    if (!window_) throw NoDisplayError("glfwCreateWindow failed (see the GLFW error above)");
  }
  ~Window() { glfwDestroyWindow(window_); }
  Window(const Window&) = delete;
  Window& operator=(const Window&) = delete;
  GLFWwindow* get() const { return window_; }

 private:
  GLFWwindow* window_ = nullptr;
};

/// Dear ImGui's context and its GLFW and Vulkan backends; shut down in reverse order.
class ImGuiSession {
 public:
  /// Sets up ImGui for `window`, drawing in the swapchain's render pass with up to
  /// `frames_in_flight` frames in flight.
  ImGuiSession(const vulkan::Context& context, GLFWwindow* window, const Swapchain& swapchain,
               std::uint32_t frames_in_flight);
  ~ImGuiSession();
  ImGuiSession(const ImGuiSession&) = delete;
  ImGuiSession& operator=(const ImGuiSession&) = delete;

 private:
  vulkan::DescriptorPool pool_;
};

}  // namespace volreel::app::detail
