// player_impl.hpp: the player window's state (class Player) shared by the files that implement
// it: player.cpp (set-up and the frame loop), input.cpp (keys and mouse), script_runner.cpp
// (timed script actions) and panels.cpp (the HUD, the timeline and the side panel). See
// player.cpp for the steps of one frame and panels.cpp for the panel layout.
#pragma once

#include "window_session.hpp"

#include <array>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "swapchain.hpp"
#include "volreel/app/player.hpp"
#include "volreel/app/script.hpp"
#include "volreel/cpu_render/transfer_function.hpp"
#include "volreel/format/container.hpp"
#include "volreel/loop/resolution_control.hpp"
#include "volreel/player/camera.hpp"
#include "volreel/stream/playhead.hpp"
#include "volreel/stream/scheduler.hpp"
#include "volreel/vulkan/context.hpp"
#include "volreel/vulkan/resources.hpp"
#include "volume_renderer.hpp"

namespace volreel::app::detail {

using Clock = std::chrono::steady_clock;
constexpr std::uint32_t frames_in_flight = 2;

inline double seconds_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

/// What one frame slot owns: its command buffer, fence and acquire semaphore, and a read-back
/// buffer for screenshots.
struct FrameSlot {
  VkCommandBuffer commands = VK_NULL_HANDLE;
  vulkan::Fence done;
  vulkan::Semaphore image_acquired;
  std::uint64_t gpu_frame = 0;  ///< the frame number last submitted on this slot (0: none)
  vulkan::Buffer readback;
  std::vector<std::filesystem::path> screenshots;  ///< paths for the frame read back
  VkExtent2D shot_extent{};
  VkExtent2D shot_volume{};  ///< the volume image's size in that frame
  bool shot_bgr = false;
};

/// Exponential moving average for HUD figures.
struct Smoothed {
  double value = 0;
  bool set = false;
  void add(double x, double weight = 0.1) {
    value = set ? value + weight * (x - value) : x;
    set = true;
  }
};

/// An ImGui window's rectangle on screen, pixels.
struct ScreenRect {
  float x = 0, y = 0, width = 0, height = 0;
  bool shown = false;
  float right() const { return x + width; }
  float bottom() const { return y + height; }
};

class Player {
 public:
  explicit Player(const PlayerOptions& options);
  ~Player();
  Player(const Player&) = delete;
  Player& operator=(const Player&) = delete;
  PlayerResult run();
  /// An error of the player's own (not a read failure), for the HUD and stderr's list.
  void report(std::string message);

 private:
  PlayerOptions options_;
  format::Container container_;
  std::vector<ScriptAction> script_;
  GlfwSession glfw_;
  Window window_;
  std::unique_ptr<vulkan::Context> context_;
  std::unique_ptr<Surface> surface_;
  std::unique_ptr<Swapchain> swapchain_;
  std::unique_ptr<VolumeRenderer> renderer_;
  stream::Playhead playhead_;
  vulkan::CommandPool command_pool_;
  std::array<FrameSlot, frames_in_flight> slots_;
  std::unique_ptr<ImGuiSession> imgui_;

  // View and look.
  player::OrbitCamera camera_, home_camera_;
  cpu_render::TransferFunction transfer_;
  std::vector<cpu_render::ControlPoint> points_;
  float range_lo_ = 0, range_hi_ = 1;
  int preset_ = 0;
  float preset_opacity_ = 1.0f;
  float sse_target_ = 1.0f;
  bool show_ui_ = true;

  ScreenRect hud_rect_, timeline_rect_, panel_rect_;  ///< as drawn in the latest frame
  bool panel_collapsed_ = false;
  bool compact_ui_ = false;           ///< small window: the short HUD and the wrapped timeline
  const char* drag_cause_ = nullptr;  ///< what the current mouse drag does to the camera
  /// Key presses since the last frame: GLFW key code, and whether it is an auto-repeat.
  std::vector<std::pair<int, bool>> typed_keys_;

  // Loop state.
  std::uint64_t frame_number_ = 0;  ///< frames submitted so far
  bool recreate_ = false, quit_ = false;
  std::vector<std::filesystem::path> pending_screenshots_;
  std::size_t failed_screenshots_ = 0;  ///< screenshots that could not be written
  /// Messages the player itself gave (screenshots, transfer functions), and the others' distinct
  /// messages: bricks and frames that could not be read or decoded.
  std::set<std::string> own_messages_, read_failures_;
  std::size_t next_action_ = 0;
  double script_clock_ = 0;
  std::uint64_t previous_action_frame_ = 0;  ///< when the last script entry ran
  double previous_action_clock_ = 0;
  bool resumed_ = false;  ///< the window was just restored: the next frame time is not a sample
  bool settling_ = false;
  double settle_timeout_ = 0, settle_waited_ = 0;
  std::uint64_t settle_from_ = 0;  ///< first frame whose statistics count
  int idle_frames_ = 0;
  int quiet_frames_ = 0;  ///< settling: frames in a row with nothing in flight, waiting or uploaded

  // HUD figures.
  stream::StreamStats stats_;
  Smoothed fps_, t_schedule_, t_upload_, t_decode_, t_render_, t_wait_, t_frame_;
  bool decode_measured_ = false, render_measured_ = false, exact_timings_ = false;
  double mb_per_s_ = 0;
  std::uint64_t bytes_at_mark_ = 0;
  Clock::time_point mark_;
  Clock::time_point last_status_;

  VkExtent2D render_extent_{};
  /// Frame-time control: the volume image's scale while the view is busy (options.frame_ms).
  loop::ResolutionControl resolution_;
  double frame_scale_ = 1.0;  ///< of the frame being drawn
  player::OrbitCamera previous_camera_;
  double previous_playhead_ = -1;
  bool busy_ = true;  ///< the view was busy at the last frame

  /// The volume image size for the window at the scale of this frame (render_scale ×
  /// frame_scale_).
  VkExtent2D render_size(VkExtent2D window) const;
  /// Whether the view is busy: the camera moved or the playhead changed since the last frame, or
  /// what it shows is still streaming in.
  bool view_busy() const;
  bool window_hidden() const;
  void wait_while_hidden();
  void recreate_swapchain();
  void report_camera(const char* cause) const;
  void report_layout() const;
  void press(int key);
  void run_script(double dt);
  void handle_input();
  static void on_key(GLFWwindow* window, int key, int scancode, int action, int mods);
  void apply_preset(const std::string& name);
  void rebuild_transfer();
  void draw_ui();
  void draw_hud();
  void draw_timeline();
  void draw_panel();
  void record(FrameSlot& slot, std::uint32_t image_index, bool capture);
  void finish_screenshots(FrameSlot& slot);
  void print_status(bool force);
  /// Step 4 of a frame: the renderer's frame on frame slot `slot_index`.
  FrameOutput render_volume(std::uint32_t slot_index);
  /// Step 6: acquire a swapchain image, record, submit and present; false when the swapchain was
  /// out of date (nothing submitted).
  bool submit_and_present(FrameSlot& slot, VkExtent2D extent);
  /// Step 7: the HUD's smoothed figures.
  void update_figures(double dt, double waited, const FrameOutput& output);
};

}  // namespace volreel::app::detail
