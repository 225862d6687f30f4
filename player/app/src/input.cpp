// input.cpp: the player's keys and mouse — key presses queued by the GLFW callback, mouse drags
// that orbit and pan the camera, the wheel that zooms — and the report of camera changes.
#include "player_impl.hpp"

#include <backends/imgui_impl_glfw.h>
#include <backends/imgui_impl_vulkan.h>
#include <imgui.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

namespace volreel::app::detail {

void Player::press(int key) {
  switch (key) {
    case GLFW_KEY_SPACE:
      playhead_.toggle();
      break;
    case GLFW_KEY_R:
      playhead_.reverse();
      break;
    case GLFW_KEY_LEFT_BRACKET:
      playhead_.set_speed(playhead_.speed() / 2);
      break;
    case GLFW_KEY_RIGHT_BRACKET:
      playhead_.set_speed(playhead_.speed() * 2);
      break;
    case GLFW_KEY_LEFT:
      playhead_.step(-1);
      break;
    case GLFW_KEY_RIGHT:
      playhead_.step(1);
      break;
    case GLFW_KEY_HOME:
      playhead_.seek(0);
      break;
    case GLFW_KEY_END:
      playhead_.seek(playhead_.last());
      break;
    case GLFW_KEY_C:
      camera_ = home_camera_;
      break;
    case GLFW_KEY_H:
      show_ui_ = !show_ui_;
      break;
    case GLFW_KEY_L:
      playhead_.set_loop(!playhead_.options().loop);
      break;
    case GLFW_KEY_ESCAPE:
    case GLFW_KEY_Q:
      quit_ = true;
      break;
    default:
      break;
  }
}

void Player::on_key(GLFWwindow* window, int key, int, int action, int) {
  auto* player = static_cast<Player*>(glfwGetWindowUserPointer(window));
  if (player && (action == GLFW_PRESS || action == GLFW_REPEAT))
    player->typed_keys_.emplace_back(key, action == GLFW_REPEAT);
}

void Player::handle_input() {
  const ImGuiIO& io = ImGui::GetIO();
  std::vector<std::pair<int, bool>> typed;
  typed.swap(typed_keys_);
  if (!io.WantCaptureKeyboard)
    for (const auto& [key, repeat] : typed)
      if (!repeat || key == GLFW_KEY_LEFT || key == GLFW_KEY_RIGHT)  // steps repeat while held
        press(key);
  // A drag's camera change is reported once, when its button is released.
  if (drag_cause_ && !ImGui::IsMouseDown(ImGuiMouseButton_Left) &&
      !ImGui::IsMouseDown(ImGuiMouseButton_Right) && !ImGui::IsMouseDown(ImGuiMouseButton_Middle)) {
    report_camera(drag_cause_);
    drag_cause_ = nullptr;
  }
  if (io.WantCaptureMouse) return;
  const double dx = io.MouseDelta.x, dy = io.MouseDelta.y;
  if (ImGui::IsMouseDown(ImGuiMouseButton_Left) && (dx != 0 || dy != 0)) {
    camera_.azimuth -= dx * 0.01;
    camera_.elevation = std::clamp(camera_.elevation + dy * 0.01, -1.5, 1.5);
    drag_cause_ = "left drag: orbit";
  }
  if ((ImGui::IsMouseDown(ImGuiMouseButton_Right) || ImGui::IsMouseDown(ImGuiMouseButton_Middle)) &&
      (dx != 0 || dy != 0)) {
    drag_cause_ = "right drag: pan";
    // Pan in the view plane: one window pixel moves the target by one pixel at its depth.
    const auto [forward, right, up] = camera_.basis();
    const double per_pixel = 2.0 * camera_.distance * std::tan(0.5 * camera_.fov_y) /
                             std::max(1.0, static_cast<double>(io.DisplaySize.y));
    camera_.target += (-dx * right + dy * up) * per_pixel;
  }
  if (io.MouseWheel != 0) {
    camera_.distance = std::max(1.0, camera_.distance * std::pow(0.9, double(io.MouseWheel)));
    report_camera("wheel: zoom");
  }
}

void Player::report_camera(const char* cause) const {
  if (options_.quiet) return;
  std::printf(
      "camera (%s): azimuth %.2f deg elevation %.2f deg distance %.3f target %.3f %.3f %.3f\n",
      cause, camera_.azimuth * 180.0 / M_PI, camera_.elevation * 180.0 / M_PI, camera_.distance,
      camera_.target.x, camera_.target.y, camera_.target.z);
  std::fflush(stdout);
}

}  // namespace volreel::app::detail
