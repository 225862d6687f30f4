// player.cpp: the player window (player.hpp) — GLFW window, Vulkan swapchain, Dear ImGui HUD and
// controls, and the per-frame loop with two frames in flight.
//
// One frame n, on frame slot s = n mod 2 (the GPU may still run frame n − 1 on the other slot):
//   1. window events; quit, close and --frames end the loop (after one more frame when an exit
//      screenshot is wanted); a pending swapchain recreation happens here;
//   2. wait for slot s's fence (frame n − 2 retired), tell the renderer (atlas slots it used may
//      be overwritten now), write any screenshot that frame read back;
//   3. input: keys and mouse (unless ImGui wants them), due script actions; the playhead advances
//      by the frame time;
//   4. the renderer's frame: scheduler.update(camera, playhead) → uploads decoded into the atlas,
//      the array SVO, and (Vulkan) the decode and ray-casting submissions;
//   5. the ImGui windows (HUD, timeline, transfer function and quality);
//   6. acquire a swapchain image; record: the volume image, a blit onto the swapchain image, ImGui
//      on top, an optional read-back; submit with slot s's fence; present;
//   7. HUD figures.
// A swapchain that is out of date or suboptimal is recreated before the next frame. A minimized
// (iconified) window, or one whose framebuffer has zero size, renders nothing: the loop blocks in
// glfwWaitEvents until the window is back (or closed), and the time away does not advance the
// playhead or the script clock; both events are reported on stdout.
//
// Panel layout (draw_ui): the timeline along the bottom edge, the HUD in the top-left corner above
// it, and the side panel at the top right when it fits beside the HUD, otherwise below the HUD,
// never taller than the space above the timeline. Below 560 × 400 pixels the HUD and the timeline
// switch to a compact form, so nothing overlaps down to about 320 × 240.
#define GLFW_INCLUDE_VULKAN
#include "volreel/app/player.hpp"
#include "volreel/loop/auto_transfer.hpp"

#include <GLFW/glfw3.h>
#include <backends/imgui_impl_glfw.h>
#include <backends/imgui_impl_vulkan.h>
#include <imgui.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "swapchain.hpp"
#include "volreel/app/script.hpp"
#include "volreel/cpu_render/transfer_function.hpp"
#include "volreel/datasets/volume.hpp"
#include "volreel/format/container.hpp"
#include "volreel/image/image.hpp"
#include "volreel/player/camera.hpp"
#include "volreel/stream/playhead.hpp"
#include "volreel/stream/scheduler.hpp"
#include "volreel/vulkan/context.hpp"
#include "volreel/vulkan/error.hpp"
#include "volreel/vulkan/resources.hpp"
#include "volume_renderer.hpp"

namespace volreel::app {

namespace {

using Clock = std::chrono::steady_clock;
constexpr std::uint32_t frames_in_flight = 2;

double seconds_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

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

void check_imgui_vk(VkResult result) {
  vulkan::check(result, "ImGui Vulkan backend");
}

/// Dear ImGui's context and its GLFW and Vulkan backends; shut down in reverse order.
class ImGuiSession {
 public:
  ImGuiSession(const vulkan::Context& context, GLFWwindow* window,
               const detail::Swapchain& swapchain) {
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
  ~ImGuiSession() {
    ImGui_ImplVulkan_Shutdown();
    ImGui_ImplGlfw_Shutdown();
    ImGui::DestroyContext();
  }
  ImGuiSession(const ImGuiSession&) = delete;
  ImGuiSession& operator=(const ImGuiSession&) = delete;

 private:
  vulkan::DescriptorPool pool_;
};

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

/// The rectangle of the ImGui window being drawn (between Begin and End).
ScreenRect current_window_rect() {
  const ImVec2 pos = ImGui::GetWindowPos(), size = ImGui::GetWindowSize();
  return {pos.x, pos.y, size.x, size.y, true};
}

/// Width of a button with this label, pixels.
float button_width(const char* label) {
  return ImGui::CalcTextSize(label, nullptr, true).x + 2 * ImGui::GetStyle().FramePadding.x;
}

/// Width of a checkbox with this label, pixels.
float checkbox_width(const char* label) {
  return ImGui::GetFrameHeight() + ImGui::GetStyle().ItemInnerSpacing.x +
         ImGui::CalcTextSize(label, nullptr, true).x;
}

/// Continues the current row when an item `width` pixels wide still fits in the window, else
/// starts a new row: a flow layout, so a narrow window wraps its controls instead of clipping.
void same_line_if_fits(float width) {
  const float end = ImGui::GetItemRectMax().x + ImGui::GetStyle().ItemSpacing.x + width;
  if (end <= ImGui::GetWindowPos().x + ImGui::GetWindowContentRegionMax().x) ImGui::SameLine();
}

class Player {
 public:
  explicit Player(const PlayerOptions& options);
  ~Player();
  Player(const Player&) = delete;
  Player& operator=(const Player&) = delete;
  int run();

 private:
  PlayerOptions options_;
  format::Container container_;
  std::vector<ScriptAction> script_;
  GlfwSession glfw_;
  Window window_;
  std::unique_ptr<vulkan::Context> context_;
  std::unique_ptr<detail::Surface> surface_;
  std::unique_ptr<detail::Swapchain> swapchain_;
  std::unique_ptr<detail::VolumeRenderer> renderer_;
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
  std::size_t next_action_ = 0;
  double script_clock_ = 0;
  std::uint64_t previous_action_frame_ = 0;  ///< when the last script entry ran
  double previous_action_clock_ = 0;
  bool resumed_ = false;  ///< the window was just restored: the next frame time is not a sample
  bool settling_ = false;
  double settle_timeout_ = 0, settle_waited_ = 0;
  std::uint64_t settle_from_ = 0;  ///< first frame whose statistics count
  int idle_frames_ = 0;

  // HUD figures.
  stream::StreamStats stats_;
  Smoothed fps_, t_schedule_, t_upload_, t_decode_, t_render_, t_wait_, t_frame_;
  bool decode_measured_ = false, render_measured_ = false, exact_timings_ = false;
  double mb_per_s_ = 0;
  std::uint64_t bytes_at_mark_ = 0;
  Clock::time_point mark_;
  Clock::time_point last_status_;

  VkExtent2D render_extent_{};

  VkExtent2D render_size(VkExtent2D window) const;
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
};

Player::Player(const PlayerOptions& options)
    : options_(options),
      container_(options.container),
      script_(parse_script(options.script)),
      window_(options.width, options.height, "volreel — " + options.container.filename().string()),
      playhead_(std::max<std::size_t>(container_.frame_count(), 1),
                stream::PlayheadOptions{options.keyframes_per_second, options.loop}) {
  const format::Manifest& m = container_.manifest();
  // 1. Vulkan: a device whose queue can present to the window's surface.
  vulkan::keep_vulkan_drivers_loaded();  // before GLFW's own first Vulkan calls
  if (!glfwVulkanSupported())
    throw vulkan::NoDeviceError("no Vulkan loader or implementation usable by GLFW");
  vulkan::ContextOptions co;
  co.application_name = "volreel play";
  std::uint32_t count = 0;
  const char** extensions = glfwGetRequiredInstanceExtensions(&count);
  if (!extensions)
    throw vulkan::NoDeviceError(
        "no Vulkan implementation offers window surfaces (glfwGetRequiredInstanceExtensions)");
  for (std::uint32_t i = 0; i < count; ++i) co.instance_extensions.emplace_back(extensions[i]);
  co.device_extensions = {"VK_KHR_swapchain"};
  co.require_graphics = true;
  context_ = std::make_unique<vulkan::Context>(co);
  surface_ = std::make_unique<detail::Surface>(context_->instance(), window_.get());
  VkBool32 present = VK_FALSE;
  vulkan::check(
      vkGetPhysicalDeviceSurfaceSupportKHR(context_->physical_device(), context_->queue_family(),
                                           surface_->handle(), &present),
      "vkGetPhysicalDeviceSurfaceSupportKHR");
  if (!present)
    throw vulkan::NoDeviceError(context_->device_name() +
                                ": its queue cannot present to the window");
  swapchain_ = std::make_unique<detail::Swapchain>(*context_, surface_->handle(), options.vsync);
  int fw = 0, fh = 0;
  glfwGetFramebufferSize(window_.get(), &fw, &fh);
  if (!swapchain_->recreate({static_cast<std::uint32_t>(std::max(fw, 1)),
                             static_cast<std::uint32_t>(std::max(fh, 1))}))
    throw vulkan::Error("vkCreateSwapchainKHR: the window's surface has zero size at start-up");

  // 2. The renderer with its scheduler (its atlas decides the slot count).
  detail::RendererSetup setup;
  setup.context = context_.get();
  setup.container = &container_;
  setup.atlas_bytes = options.atlas_bytes;
  setup.frames_in_flight = frames_in_flight;
  setup.scheduler.priority.sse_target = options.sse_target;
  setup.scheduler.loader.bandwidth_bytes_per_s = options.bandwidth_bytes_per_s;
  setup.scheduler.loader.latency_s = options.latency_s;
  setup.scheduler.loader.max_in_flight = options.max_requests;
  setup.scheduler.upload_budget_bytes = options.upload_bytes;
  setup.width = render_size(swapchain_->extent()).width;
  setup.height = render_size(swapchain_->extent()).height;
  if (options.renderer == RendererKind::cpu) {
    renderer_ = detail::make_cpu_renderer(setup);
  } else if (options.renderer == RendererKind::vulkan) {
    renderer_ = detail::make_vulkan_renderer(setup);
  } else {
    try {
      renderer_ = detail::make_vulkan_renderer(setup);
    } catch (const vulkan::Error& e) {
      std::fprintf(stderr,
                   "volreel play: the Vulkan ray caster is not available (%s); using the CPU "
                   "reference renderer\n",
                   e.what());
      renderer_ = detail::make_cpu_renderer(setup);
    }
  }
  render_extent_ = renderer_->extent();
  sse_target_ = static_cast<float>(options.sse_target);

  // 3. Frame slots and ImGui.
  command_pool_ = vulkan::CommandPool(*context_);
  const auto buffers = command_pool_.allocate(frames_in_flight);
  for (std::uint32_t i = 0; i < frames_in_flight; ++i) {
    slots_[i].commands = buffers[i];
    slots_[i].done = vulkan::Fence(*context_, true);
    slots_[i].image_acquired = vulkan::Semaphore(*context_);
  }
  // Key presses are queued by our GLFW callback (ImGui's backend chains to it), so a tap shorter
  // than a frame is not lost: ImGui 1.86 only sees whether a key is down when a frame starts.
  glfwSetWindowUserPointer(window_.get(), this);
  glfwSetKeyCallback(window_.get(), &Player::on_key);
  imgui_ = std::make_unique<ImGuiSession>(*context_, window_.get(), *swapchain_);

  // 4. View and transfer function.
  range_lo_ = static_cast<float>(m.value_min);
  range_hi_ = static_cast<float>(m.value_max);
  if (!(range_hi_ > range_lo_)) range_hi_ = range_lo_ + 1.0f;
  // "auto" (quantiles of the data), a preset or a JSON file, as `volreel render` takes them.
  const auto& names = cpu_render::TransferFunction::preset_names();
  if (auto it = std::find(names.begin(), names.end(), options.transfer); it != names.end()) {
    apply_preset(*it);
  } else {
    transfer_ = loop::transfer_from_spec(options.transfer, container_, "--transfer");
    points_ = transfer_.points();
    range_lo_ = transfer_.lo();
    range_hi_ = transfer_.hi();
    preset_ = -1;
  }
  mark_ = last_status_ = Clock::now();
}

Player::~Player() {
  if (context_) context_->wait_idle();
}

void Player::apply_preset(const std::string& name) {
  const auto& names = cpu_render::TransferFunction::preset_names();
  const auto it = std::find(names.begin(), names.end(), name);
  if (it == names.end()) {
    renderer_->scheduler().report_error("unknown transfer-function preset '" + name + "'");
    return;
  }
  preset_ = static_cast<int>(it - names.begin());
  transfer_ = cpu_render::TransferFunction::preset(name, range_lo_, range_hi_, preset_opacity_);
  points_ = transfer_.points();
}

void Player::rebuild_transfer() {
  std::vector<cpu_render::ControlPoint> sorted = points_;
  std::stable_sort(sorted.begin(), sorted.end(),
                   [](const auto& a, const auto& b) { return a.value < b.value; });
  try {
    transfer_ = cpu_render::TransferFunction(sorted, range_lo_, range_hi_);
  } catch (const std::exception& e) {
    renderer_->scheduler().report_error(std::string("transfer function: ") + e.what());
  }
}

VkExtent2D Player::render_size(VkExtent2D window) const {
  const auto scaled = [&](std::uint32_t n) {
    return std::max(1u, static_cast<std::uint32_t>(std::lround(n * options_.render_scale)));
  };
  return {scaled(window.width), scaled(window.height)};
}

bool Player::window_hidden() const {
  int fw = 0, fh = 0;
  glfwGetFramebufferSize(window_.get(), &fw, &fh);
  return glfwGetWindowAttrib(window_.get(), GLFW_ICONIFIED) == GLFW_TRUE || fw <= 0 || fh <= 0;
}

void Player::wait_while_hidden() {
  const auto since = Clock::now();
  const bool iconified = glfwGetWindowAttrib(window_.get(), GLFW_ICONIFIED) == GLFW_TRUE;
  if (!options_.quiet) {
    std::printf("window %s at frame %llu: rendering paused\n",
                iconified ? "minimized" : "has zero size",
                static_cast<unsigned long long>(frame_number_));
    std::fflush(stdout);
  }
  while (window_hidden() && !glfwWindowShouldClose(window_.get())) glfwWaitEvents();
  if (!options_.quiet && !glfwWindowShouldClose(window_.get())) {
    std::printf("window restored after %.1f s: rendering resumes at frame %llu\n",
                seconds_between(since, Clock::now()),
                static_cast<unsigned long long>(frame_number_));
    std::fflush(stdout);
  }
  recreate_ = true;  // the surface may have changed size or become out of date meanwhile
  resumed_ = true;
}

void Player::recreate_swapchain() {
  int fw = 0, fh = 0;
  glfwGetFramebufferSize(window_.get(), &fw, &fh);
  if (fw <= 0 || fh <= 0) return;  // minimized again: the loop waits (window_hidden)
  context_->wait_idle();
  if (!swapchain_->recreate({static_cast<std::uint32_t>(fw), static_cast<std::uint32_t>(fh)})) {
    glfwWaitEventsTimeout(0.05);  // the surface reports zero size: try again shortly
    return;
  }
  ImGui_ImplVulkan_SetMinImageCount(std::max(swapchain_->min_image_count(), 2u));
  recreate_ = false;
}

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

void Player::run_script(double dt) {
  if (settling_) {
    // stats_ are those of the previous frame: only frames after the one that started settling
    // count, and two complete frames in a row end it. Prefetching of other keyframes may go on.
    settle_waited_ += dt;
    const bool idle =
        frame_number_ > settle_from_ && stats_.fraction_at_target >= 1.0 && stats_.holes == 0;
    idle_frames_ = idle ? idle_frames_ + 1 : 0;
    if (idle_frames_ >= 2 || settle_waited_ >= settle_timeout_) {
      if (idle_frames_ < 2)
        std::fprintf(stderr, "volreel play: script: settle timed out after %.1f s\n",
                     settle_waited_);
      settling_ = false;
    }
    return;  // the script clock stops while settling
  }
  script_clock_ += dt;
  using Kind = ScriptAction::Kind;
  while (next_action_ < script_.size() && !settling_) {
    const ScriptAction& a = script_[next_action_];
    const std::int64_t frame = static_cast<std::int64_t>(frame_number_) -
                               (a.relative ? static_cast<std::int64_t>(previous_action_frame_) : 0);
    const double clock = script_clock_ - (a.relative ? previous_action_clock_ : 0.0);
    const bool due = a.at_frame >= 0 ? frame >= a.at_frame : clock >= a.at_seconds;
    if (!due) break;
    ++next_action_;
    previous_action_frame_ = frame_number_;
    previous_action_clock_ = script_clock_;
    if (!options_.quiet)
      std::printf("script: frame %llu keyframe %.3f: %s\n",
                  static_cast<unsigned long long>(frame_number_), playhead_.position(),
                  a.source.c_str());
    switch (a.kind) {
      case Kind::key:
        press(key_code(a.text));
        break;
      case Kind::seek:
        playhead_.seek(a.x);
        break;
      case Kind::speed:
        playhead_.set_speed(a.x);
        break;
      case Kind::play:
        playhead_.play();
        break;
      case Kind::pause:
        playhead_.pause();
        break;
      case Kind::reverse:
        playhead_.reverse();
        break;
      case Kind::orbit:
        camera_.azimuth += a.x * M_PI / 180.0;
        camera_.elevation = std::clamp(camera_.elevation + a.y * M_PI / 180.0, -1.5, 1.5);
        break;
      case Kind::zoom:
        camera_.distance *= a.x;
        break;
      case Kind::transfer:
        apply_preset(a.text);
        break;
      case Kind::sse:
        sse_target_ = static_cast<float>(a.x);
        break;
      case Kind::settle:
        settling_ = true;
        settle_timeout_ = a.x;
        settle_waited_ = 0;
        settle_from_ = frame_number_;
        idle_frames_ = 0;
        break;
      case Kind::resize:
        glfwSetWindowSize(window_.get(), static_cast<int>(a.x), static_cast<int>(a.y));
        break;
      case Kind::screenshot:
        pending_screenshots_.emplace_back(a.text);
        return;  // this frame is the screenshot: later entries wait for the next frame
      case Kind::camera:
        report_camera("script");
        break;
      case Kind::layout:
        report_layout();
        break;
      case Kind::quit:
        quit_ = true;
        break;
    }
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

void Player::report_layout() const {
  const ImVec2 size = ImGui::GetIO().DisplaySize;
  std::printf("layout %.0fx%.0f:", double{size.x}, double{size.y});
  const auto print = [](const char* name, const ScreenRect& r, const char* note) {
    if (r.shown)
      std::printf(" %s %.0f %.0f %.0f %.0f%s;", name, double{r.x}, double{r.y}, double{r.width},
                  double{r.height}, note);
    else
      std::printf(" %s hidden;", name);
  };
  print("hud", hud_rect_, "");
  print("timeline", timeline_rect_, "");
  print("panel", panel_rect_, panel_collapsed_ ? " collapsed" : "");
  std::printf("\n");
  std::fflush(stdout);
}

void Player::draw_hud() {
  const ImVec2 size = ImGui::GetIO().DisplaySize;
  const ImGuiStyle& style = ImGui::GetStyle();
  const ImGuiWindowFlags flags = ImGuiWindowFlags_NoDecoration | ImGuiWindowFlags_AlwaysAutoResize |
                                 ImGuiWindowFlags_NoSavedSettings |
                                 ImGuiWindowFlags_NoFocusOnAppearing | ImGuiWindowFlags_NoNav;
  // Top left, above the timeline; lines longer than the window is wide wrap.
  const float bottom = timeline_rect_.shown ? timeline_rect_.y - 8 : size.y - 10;
  const ImVec2 max_size(std::max(size.x - 20, 1.0f), std::max(bottom - 10, 1.0f));
  ImGui::SetNextWindowPos(ImVec2(10, 10), ImGuiCond_Always);
  ImGui::SetNextWindowSizeConstraints(ImVec2(0, 0), max_size);
  ImGui::SetNextWindowBgAlpha(0.55f);
  const bool open = ImGui::Begin("HUD", nullptr, flags);
  hud_rect_ = current_window_rect();
  if (open) {
    ImGui::PushTextWrapPos(std::min(max_size.x - style.WindowPadding.x,
                                    style.WindowPadding.x + ImGui::GetFontSize() * 36.0f));
    const double t = playhead_.position();
    const auto& ts = container_.manifest().timestamps;
    // Between keyframes k and k + 1 the picture interpolates both: say so, with the simulation
    // time interpolated from the manifest's timestamps.
    const auto k = static_cast<std::size_t>(std::floor(t));
    const double f = t - static_cast<double>(k);
    ImGui::TextUnformatted(options_.container.filename().string().c_str());
    if (compact_ui_) {
      // A small window: four short lines (position and transport, rate, streaming state).
      ImGui::Text("keyframe %.2f / %.0f  %s %s %.2gx", t, playhead_.last(),
                  playhead_.playing() ? "playing" : "paused", playhead_.reversed() ? "back" : "fwd",
                  playhead_.speed());
      ImGui::Text("%.1f fps  %.1f ms  %.2f MB/s", fps_.value, 1e3 * t_frame_.value, mb_per_s_);
      ImGui::Text(
          "atlas %.0f%%  at target %.0f%%  holes %u",
          stats_.atlas_capacity ? 100.0 * stats_.atlas_occupied / stats_.atlas_capacity : 0.0,
          100.0 * stats_.fraction_at_target, stats_.holes);
    } else {
      if (f < 1e-6)
        ImGui::Text("keyframe %.2f / %.0f   frame %zu", t, playhead_.last(), k);
      else
        ImGui::Text("keyframe %.2f / %.0f   frames %zu-%zu (f = %.2f)", t, playhead_.last(), k,
                    k + 1, f);
      if (k < ts.size()) {
        const double time = k + 1 < ts.size() ? ts[k] + f * (ts[k + 1] - ts[k]) : ts[k];
        ImGui::SameLine();
        ImGui::Text("  t = %.4g", time);
      }
      ImGui::Text("%s %s %.2gx%s", playhead_.playing() ? "playing" : "paused",
                  playhead_.reversed() ? "backward" : "forward", playhead_.speed(),
                  playhead_.options().loop ? "  loop" : "");
      ImGui::Separator();
      ImGui::Text("%.1f fps   frame %.1f ms", fps_.value, 1e3 * t_frame_.value);
      const auto ms = [](bool measured, const Smoothed& v) {
        char text[32] = "-";
        if (measured) std::snprintf(text, sizeof text, "%.2f", v.value);
        return std::string(text);
      };
      ImGui::Text("schedule %.2f  upload %.2f  decode %s  render %s  wait %.2f ms",
                  t_schedule_.value, t_upload_.value, ms(decode_measured_, t_decode_).c_str(),
                  ms(render_measured_, t_render_).c_str(), 1e3 * t_wait_.value);
      ImGui::Checkbox("exact timings (no overlap)", &exact_timings_);
      ImGui::Text(
          "atlas %u / %u slots (%.0f%%)", stats_.atlas_occupied, stats_.atlas_capacity,
          stats_.atlas_capacity ? 100.0 * stats_.atlas_occupied / stats_.atlas_capacity : 0.0);
      ImGui::Text("requests in flight %zu   %.2f MB/s   uploads %zu", stats_.requests_in_flight,
                  mb_per_s_, stats_.uploads);
      ImGui::Text("at target LOD %.0f%% of %u nodes   holes %u", 100.0 * stats_.fraction_at_target,
                  stats_.target_nodes, stats_.holes);
      ImGui::TextDisabled("%s", renderer_->name().c_str());
    }
    const auto& errors = renderer_->scheduler().errors();
    if (!errors.empty()) {
      ImGui::Separator();
      ImGui::TextColored(ImVec4(1.0f, 0.45f, 0.35f, 1.0f),
                         "%zu problem(s), newest:", renderer_->scheduler().error_count());
      const std::size_t shown = std::min<std::size_t>(errors.size(), compact_ui_ ? 1 : 4);
      ImGui::PushStyleColor(ImGuiCol_Text, ImVec4(1.0f, 0.6f, 0.5f, 1.0f));
      for (std::size_t i = errors.size() - shown; i < errors.size(); ++i)
        ImGui::TextUnformatted(errors[i].c_str());
      ImGui::PopStyleColor();
    }
    ImGui::PopTextWrapPos();
  }
  ImGui::End();
}

void Player::draw_timeline() {
  const ImVec2 size = ImGui::GetIO().DisplaySize;
  const ImGuiStyle& style = ImGui::GetStyle();
  // Along the bottom edge, as wide as the window; its height follows its rows (0: auto-fit).
  ImGui::SetNextWindowPos(ImVec2(10, size.y - 10), ImGuiCond_Always, ImVec2(0, 1));
  ImGui::SetNextWindowSize(ImVec2(std::max(size.x - 20, 1.0f), 0), ImGuiCond_Always);
  ImGui::SetNextWindowBgAlpha(0.6f);
  const ImGuiWindowFlags flags =
      ImGuiWindowFlags_NoDecoration | ImGuiWindowFlags_NoSavedSettings | ImGuiWindowFlags_NoMove;
  const bool open = ImGui::Begin("Timeline", nullptr, flags);
  timeline_rect_ = current_window_rect();
  if (open) {
    // Transport buttons, reverse, speed and reset view on one row while they fit (a narrow window
    // wraps them onto more rows), then the slider across the whole width.
    if (ImGui::Button("|<")) press(GLFW_KEY_HOME);
    same_line_if_fits(button_width("<"));
    if (ImGui::Button("<")) press(GLFW_KEY_LEFT);
    same_line_if_fits(button_width("pause"));
    if (ImGui::Button(playhead_.playing() ? "pause" : "play ")) press(GLFW_KEY_SPACE);
    same_line_if_fits(button_width(">"));
    if (ImGui::Button(">")) press(GLFW_KEY_RIGHT);
    same_line_if_fits(button_width(">|"));
    if (ImGui::Button(">|")) press(GLFW_KEY_END);
    same_line_if_fits(checkbox_width("reverse"));
    bool reversed = playhead_.reversed();
    if (ImGui::Checkbox("reverse", &reversed)) playhead_.set_reversed(reversed);
    const float speed_width = compact_ui_ ? 70.0f : 110.0f;
    same_line_if_fits(speed_width + style.ItemInnerSpacing.x + ImGui::CalcTextSize("speed").x);
    ImGui::SetNextItemWidth(speed_width);
    static constexpr std::array<double, 6> speeds{0.25, 0.5, 1, 2, 4, 8};
    char label[32];
    std::snprintf(label, sizeof label, "%.2gx", playhead_.speed());
    if (ImGui::BeginCombo("speed", label)) {
      for (double s : speeds) {
        std::snprintf(label, sizeof label, "%.2gx", s);
        if (ImGui::Selectable(label, s == playhead_.speed())) playhead_.set_speed(s);
      }
      ImGui::EndCombo();
    }
    same_line_if_fits(button_width("reset view"));
    if (ImGui::Button("reset view")) press(GLFW_KEY_C);
    ImGui::SetNextItemWidth(-1);
    float t = static_cast<float>(playhead_.position());
    if (ImGui::SliderFloat("##time", &t, 0.0f, static_cast<float>(playhead_.last()),
                           "keyframe %.2f"))
      playhead_.seek(t);
  }
  ImGui::End();
}

void Player::draw_panel() {
  const ImVec2 size = ImGui::GetIO().DisplaySize;
  const float width = std::min(330.0f, std::max(size.x - 20, 1.0f));
  // Top right when it fits beside the HUD, else right below the HUD; never over the timeline
  // (a panel taller than the space left scrolls).
  const bool beside = !hud_rect_.shown || hud_rect_.right() + 10 + width <= size.x - 10;
  const float top = beside ? 10.0f : hud_rect_.bottom() + 8;
  const float bottom = timeline_rect_.shown ? timeline_rect_.y - 8 : size.y - 10;
  const float max_height = std::max(bottom - top, ImGui::GetFrameHeight());
  ImGui::SetNextWindowPos(ImVec2(size.x - 10, top), ImGuiCond_Always, ImVec2(1, 0));
  ImGui::SetNextWindowSizeConstraints(ImVec2(width, 0), ImVec2(width, max_height));
  ImGui::SetNextWindowCollapsed(size.x < 1000, ImGuiCond_FirstUseEver);
  const bool open =
      ImGui::Begin("Transfer function & quality", nullptr, ImGuiWindowFlags_AlwaysAutoResize);
  panel_rect_ = current_window_rect();
  panel_collapsed_ = ImGui::IsWindowCollapsed();
  if (open) {
    const auto& names = cpu_render::TransferFunction::preset_names();
    const char* current =
        preset_ >= 0 ? names[static_cast<std::size_t>(preset_)].c_str() : "(custom)";
    if (ImGui::BeginCombo("preset", current)) {
      for (const auto& n : names)
        if (ImGui::Selectable(n.c_str(), n == current)) apply_preset(n);
      ImGui::EndCombo();
    }
    if (ImGui::SliderFloat("preset opacity", &preset_opacity_, 0.0f, 4.0f) && preset_ >= 0)
      apply_preset(names[static_cast<std::size_t>(preset_)]);
    bool changed = false;
    float range[2] = {range_lo_, range_hi_};
    if (ImGui::DragFloat2("range", range, (range_hi_ - range_lo_) * 0.005f) &&
        range[1] > range[0]) {
      range_lo_ = range[0];
      range_hi_ = range[1];
      changed = true;
    }
    // The table as a strip of opacity values, to see what the points make.
    std::array<float, 128> alpha{};
    for (std::size_t i = 0; i < alpha.size(); ++i)
      alpha[i] = transfer_.lookup(range_lo_ + (range_hi_ - range_lo_) * float(i) / 127.0f)[3];
    ImGui::PlotLines("opacity", alpha.data(), static_cast<int>(alpha.size()), 0, nullptr, 0.0f,
                     FLT_MAX, ImVec2(0, 50));
    ImGui::Text("control points (value, opacity, colour)");
    int remove = -1;
    for (std::size_t i = 0; i < points_.size(); ++i) {
      auto& p = points_[i];
      ImGui::PushID(static_cast<int>(i));
      ImGui::SetNextItemWidth(90);
      changed |= ImGui::DragFloat("##v", &p.value, (range_hi_ - range_lo_) * 0.002f, 0, 0, "%.4g");
      ImGui::SameLine();
      ImGui::SetNextItemWidth(90);
      changed |= ImGui::SliderFloat("##a", &p.a, 0.0f, 1.0f, "a %.3f");
      ImGui::SameLine();
      float rgb[3] = {p.r, p.g, p.b};
      if (ImGui::ColorEdit3("##c", rgb, ImGuiColorEditFlags_NoInputs)) {
        p.r = rgb[0];
        p.g = rgb[1];
        p.b = rgb[2];
        changed = true;
      }
      ImGui::SameLine();
      if (ImGui::SmallButton("x") && points_.size() > 1) remove = static_cast<int>(i);
      ImGui::PopID();
    }
    if (remove >= 0) {
      points_.erase(points_.begin() + remove);
      changed = true;
    }
    if (ImGui::Button("add point")) {
      cpu_render::ControlPoint p;
      p.value = 0.5f * (range_lo_ + range_hi_);
      const auto rgba = transfer_.lookup(p.value);
      p.r = rgba[0];
      p.g = rgba[1];
      p.b = rgba[2];
      p.a = rgba[3];
      points_.push_back(p);
      changed = true;
    }
    if (changed) {
      preset_ = -1;
      rebuild_transfer();
    }
    ImGui::Separator();
    ImGui::SliderFloat("SSE target (px)", &sse_target_, 0.25f, 16.0f, "%.2f",
                       ImGuiSliderFlags_Logarithmic);
    ImGui::TextDisabled("lower: finer detail, more bricks");
  }
  ImGui::End();
}

void Player::draw_ui() {
  hud_rect_ = timeline_rect_ = panel_rect_ = ScreenRect{};
  if (!show_ui_) return;
  const ImVec2 size = ImGui::GetIO().DisplaySize;
  compact_ui_ = size.x < 560 || size.y < 400;
  // The timeline first: the HUD and the panel are placed in the space above it.
  draw_timeline();
  draw_hud();
  draw_panel();
}

void Player::record(FrameSlot& slot, std::uint32_t index, bool capture) {
  const VkCommandBuffer cb = slot.commands;
  vulkan::check(vkResetCommandBuffer(cb, 0), "vkResetCommandBuffer");
  vulkan::begin_commands(cb);
  // 1. The volume image (left in TRANSFER_SRC_OPTIMAL).
  renderer_->record(cb, static_cast<std::uint32_t>(frame_number_ % frames_in_flight));
  const VkImageLayout source_layout = renderer_->image_layout();
  // 2. Blit it over the whole swapchain image.
  const VkImage target = swapchain_->image(index);
  const VkExtent2D extent = swapchain_->extent();
  vulkan::image_barrier(cb, target, VK_IMAGE_LAYOUT_UNDEFINED, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL,
                        VK_PIPELINE_STAGE_TRANSFER_BIT, 0, VK_PIPELINE_STAGE_TRANSFER_BIT,
                        VK_ACCESS_TRANSFER_WRITE_BIT);
  const VkExtent2D source = renderer_->extent();
  VkImageBlit blit{};
  blit.srcSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
  blit.srcOffsets[1] = {static_cast<std::int32_t>(source.width),
                        static_cast<std::int32_t>(source.height), 1};
  blit.dstSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
  blit.dstOffsets[1] = {static_cast<std::int32_t>(extent.width),
                        static_cast<std::int32_t>(extent.height), 1};
  vkCmdBlitImage(cb, renderer_->image(), source_layout, target,
                 VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 1, &blit, VK_FILTER_LINEAR);
  // 3. ImGui on top (the render pass loads the blit's result and ends in PRESENT_SRC).
  VkRenderPassBeginInfo pass{VK_STRUCTURE_TYPE_RENDER_PASS_BEGIN_INFO};
  pass.renderPass = swapchain_->render_pass();
  pass.framebuffer = swapchain_->framebuffer(index);
  pass.renderArea.extent = extent;
  vkCmdBeginRenderPass(cb, &pass, VK_SUBPASS_CONTENTS_INLINE);
  ImGui_ImplVulkan_RenderDrawData(ImGui::GetDrawData(), cb);
  vkCmdEndRenderPass(cb);
  // 4. Screenshot: copy the composed image to the slot's host-visible buffer.
  if (capture) {
    const VkDeviceSize bytes = VkDeviceSize{extent.width} * extent.height * 4;
    if (slot.readback.size() < bytes)
      slot.readback =
          vulkan::Buffer(*context_, bytes, VK_BUFFER_USAGE_TRANSFER_DST_BIT,
                         VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT, VK_MEMORY_PROPERTY_HOST_CACHED_BIT);
    vulkan::image_barrier(
        cb, target, VK_IMAGE_LAYOUT_PRESENT_SRC_KHR, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL,
        VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT, VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT,
        VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_READ_BIT);
    VkBufferImageCopy copy{};
    copy.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
    copy.imageExtent = {extent.width, extent.height, 1};
    vkCmdCopyImageToBuffer(cb, target, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, slot.readback.handle(),
                           1, &copy);
    vulkan::image_barrier(cb, target, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL,
                          VK_IMAGE_LAYOUT_PRESENT_SRC_KHR, VK_PIPELINE_STAGE_TRANSFER_BIT,
                          VK_ACCESS_TRANSFER_READ_BIT, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, 0);
    vulkan::memory_barrier(cb, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
                           VK_PIPELINE_STAGE_HOST_BIT, VK_ACCESS_HOST_READ_BIT);
    slot.shot_extent = extent;
    slot.shot_bgr = swapchain_->bgr();
  }
  vulkan::end_commands(cb);
}

void Player::finish_screenshots(FrameSlot& slot) {
  if (slot.screenshots.empty()) return;
  slot.readback.invalidate();
  image::Image shot;
  shot.width = static_cast<int>(slot.shot_extent.width);
  shot.height = static_cast<int>(slot.shot_extent.height);
  shot.channels = 3;
  const std::size_t pixels = std::size_t{slot.shot_extent.width} * slot.shot_extent.height;
  shot.pixels.assign(pixels * 3, std::uint8_t{0});
  const auto* in = reinterpret_cast<const std::uint8_t*>(slot.readback.mapped());
  for (std::size_t i = 0; i < pixels; ++i)
    for (std::size_t c = 0; c < 3; ++c)
      shot.pixels[3 * i + c] = in[4 * i + (slot.shot_bgr ? 2 - c : c)];
  for (const auto& path : slot.screenshots) {
    try {
      image::write_png(path, shot);
      if (!options_.quiet) {
        std::printf("screenshot: %s\n", path.string().c_str());
        std::fflush(stdout);
      }
    } catch (const std::exception& e) {
      renderer_->scheduler().report_error(std::string("screenshot: ") + e.what());
      std::fprintf(stderr, "volreel play: screenshot: %s\n", e.what());
    }
  }
  slot.screenshots.clear();
}

void Player::print_status(bool force) {
  const auto now = Clock::now();
  if (options_.quiet || (!force && seconds_between(last_status_, now) < 1.0)) return;
  last_status_ = now;
  std::printf(
      "frame %llu  keyframe %.2f  %s  %.1f fps  schedule %.1f upload %.1f decode %.1f render "
      "%.1f ms  atlas %u/%u  in flight %zu  %.2f MB/s  at target %.0f%%  errors %zu\n",
      static_cast<unsigned long long>(frame_number_), playhead_.position(),
      playhead_.playing() ? "playing" : "paused", fps_.value, t_schedule_.value, t_upload_.value,
      t_decode_.value, t_render_.value, stats_.atlas_occupied, stats_.atlas_capacity,
      stats_.requests_in_flight, mb_per_s_, 100.0 * stats_.fraction_at_target,
      renderer_->scheduler().error_count());
  std::fflush(stdout);
}

int Player::run() {
  const auto dims = container_.manifest().dims;
  const VkExtent2D first = swapchain_->extent();
  home_camera_ =
      player::OrbitCamera::framing(glm::dvec3(dims[0], dims[1], dims[2]),
                                   static_cast<int>(first.width), static_cast<int>(first.height));
  camera_ = home_camera_;
  auto previous = Clock::now();
  bool final_frame = false;

  while (true) {
    // 1. Events; window closed or quit requested: one more frame for the exit screenshot.
    glfwPollEvents();
    if (glfwWindowShouldClose(window_.get())) quit_ = true;
    if (window_hidden()) {  // minimized: no frames until the window is back
      if (quit_) break;
      wait_while_hidden();
      previous = Clock::now();  // the time away moves neither the playhead nor the script
      continue;
    }
    if (options_.max_frames > 0 && frame_number_ >= options_.max_frames) break;
    const bool last_of_n = options_.max_frames > 0 && frame_number_ + 1 == options_.max_frames;
    if (quit_ || last_of_n) {
      if (quit_ && (final_frame || !options_.screenshot_on_exit)) break;
      if (!final_frame && options_.screenshot_on_exit)
        pending_screenshots_.push_back(*options_.screenshot_on_exit);
      final_frame = true;
    }
    if (recreate_) {
      recreate_swapchain();
      if (recreate_) continue;  // minimized or zero-sized again: the next pass waits
    }
    const VkExtent2D extent = swapchain_->extent();
    const VkExtent2D wanted = render_size(extent);
    const std::uint32_t slot_index = static_cast<std::uint32_t>(frame_number_ % frames_in_flight);
    FrameSlot& slot = slots_[slot_index];

    // 2. Frame n − 2 retired: its atlas slots may be reused, its read-back written.
    const auto wait_start = Clock::now();
    slot.done.wait();
    const double waited = seconds_between(wait_start, Clock::now());
    if (slot.gpu_frame > 0) renderer_->retired(slot.gpu_frame);
    finish_screenshots(slot);
    if (wanted.width != render_extent_.width || wanted.height != render_extent_.height) {
      context_->wait_idle();
      renderer_->resize(wanted.width, wanted.height);
      render_extent_ = renderer_->extent();
    }

    // 3. Input, script, playhead.
    const auto now = Clock::now();
    const double dt = seconds_between(previous, now);
    previous = now;
    ImGui_ImplVulkan_NewFrame();
    ImGui_ImplGlfw_NewFrame();
    ImGui::NewFrame();
    handle_input();
    run_script(frame_number_ == 0 ? 0.0 : dt);
    playhead_.advance(options_.fixed_frame_seconds > 0 ? options_.fixed_frame_seconds : dt);

    // 4. Scheduler, decode and render (the renderer's CPU work and its own submissions).
    renderer_->scheduler().priority_settings().sse_target = sse_target_;
    renderer_->set_exact_timings(exact_timings_);
    detail::FrameInputs inputs;
    inputs.slot = slot_index;
    inputs.gpu_frame = frame_number_ + 1;
    inputs.camera = camera_;
    inputs.camera.width = static_cast<int>(render_extent_.width);
    inputs.camera.height = static_cast<int>(render_extent_.height);
    inputs.playhead = playhead_.position();
    inputs.transfer = &transfer_;
    const detail::FrameOutput output = renderer_->frame(inputs);
    stats_ = output.stats;
    for (const std::string& e : output.new_errors)
      std::fprintf(stderr, "volreel play: %s\n", e.c_str());

    // 5. UI.
    draw_ui();
    ImGui::Render();

    // 6. Acquire, record, submit, present.
    std::uint32_t index = 0;
    const VkResult acquired =
        vkAcquireNextImageKHR(context_->device(), swapchain_->handle(), UINT64_MAX,
                              slot.image_acquired.handle(), VK_NULL_HANDLE, &index);
    if (acquired == VK_ERROR_OUT_OF_DATE_KHR) {
      recreate_ = true;
      continue;  // the fence was not reset: the slot stays usable
    }
    if (acquired != VK_SUBOPTIMAL_KHR) vulkan::check(acquired, "vkAcquireNextImageKHR");
    if (acquired == VK_SUBOPTIMAL_KHR) recreate_ = true;

    const bool capture = !pending_screenshots_.empty() && swapchain_->readable();
    record(slot, index, capture);
    if (capture) slot.screenshots = std::move(pending_screenshots_);
    pending_screenshots_.clear();
    slot.done.reset();
    const VkSemaphore wait_semaphore = slot.image_acquired.handle();
    const VkPipelineStageFlags wait_stage = VK_PIPELINE_STAGE_TRANSFER_BIT;
    const VkSemaphore signal_semaphore = swapchain_->render_finished(index);
    VkSubmitInfo submit{VK_STRUCTURE_TYPE_SUBMIT_INFO};
    submit.waitSemaphoreCount = 1;
    submit.pWaitSemaphores = &wait_semaphore;
    submit.pWaitDstStageMask = &wait_stage;
    submit.commandBufferCount = 1;
    submit.pCommandBuffers = &slot.commands;
    submit.signalSemaphoreCount = 1;
    submit.pSignalSemaphores = &signal_semaphore;
    context_->submit(submit, slot.done.handle());
    slot.gpu_frame = inputs.gpu_frame;

    // The queue is used only from this thread (the scheduler's loader threads read files and
    // never touch Vulkan), so presenting here does not race Context::submit.
    VkPresentInfoKHR present{VK_STRUCTURE_TYPE_PRESENT_INFO_KHR};
    present.waitSemaphoreCount = 1;
    present.pWaitSemaphores = &signal_semaphore;
    const VkSwapchainKHR swapchain = swapchain_->handle();
    present.swapchainCount = 1;
    present.pSwapchains = &swapchain;
    present.pImageIndices = &index;
    const VkResult presented = vkQueuePresentKHR(context_->queue(), &present);
    if (presented == VK_ERROR_OUT_OF_DATE_KHR || presented == VK_SUBOPTIMAL_KHR)
      recreate_ = true;
    else
      vulkan::check(presented, "vkQueuePresentKHR");
    int fw = 0, fh = 0;
    glfwGetFramebufferSize(window_.get(), &fw, &fh);
    if (static_cast<std::uint32_t>(fw) != extent.width ||
        static_cast<std::uint32_t>(fh) != extent.height)
      recreate_ = true;

    // 7. HUD figures.
    const auto end = Clock::now();
    if (frame_number_ > 0 && dt > 0 && !resumed_) {
      fps_.add(1.0 / dt);
      t_frame_.add(dt);
    }
    resumed_ = false;
    t_schedule_.add(output.times.schedule);
    t_upload_.add(output.times.upload);
    decode_measured_ = output.times.decode.has_value();
    if (decode_measured_) t_decode_.add(*output.times.decode);
    render_measured_ = output.times.render.has_value();
    if (render_measured_) t_render_.add(*output.times.render);
    t_wait_.add(waited);
    if (const double span = seconds_between(mark_, end); span >= 1.0) {
      mb_per_s_ = double(stats_.bytes_loaded - bytes_at_mark_) / span / 1e6;
      bytes_at_mark_ = stats_.bytes_loaded;
      mark_ = end;
    }
    ++frame_number_;
    print_status(false);
  }

  // Every submitted frame finishes; screenshots still in flight are written.
  context_->wait_idle();
  for (auto& slot : slots_) finish_screenshots(slot);
  print_status(true);
  if (context_->validation_enabled()) {
    const auto messages = context_->validation_messages();
    std::fprintf(stderr, "volreel play: %zu Vulkan validation message(s)\n", messages.size());
    for (std::size_t i = 0; i < std::min<std::size_t>(messages.size(), 20); ++i)
      std::fprintf(stderr, "  %s\n", messages[i].text.c_str());
  }
  return 0;
}

}  // namespace

int run_player(const PlayerOptions& options) {
  Player player(options);
  return player.run();
}

}  // namespace volreel::app
