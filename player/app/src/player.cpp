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
// The window and ImGui sessions are in window_session.hpp, input in input.cpp, the script in
// script_runner.cpp and the panels in panels.cpp.
#include "player_impl.hpp"

#include <backends/imgui_impl_glfw.h>
#include <backends/imgui_impl_vulkan.h>
#include <imgui.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "volreel/image/image.hpp"
#include "volreel/loop/auto_transfer.hpp"
#include "volreel/vulkan/error.hpp"

namespace volreel::app {
namespace detail {

Player::Player(const PlayerOptions& options)
    : options_(options),
      container_(options.source ? format::Container(options.source)
                                : format::Container(options.container)),
      script_(parse_script(options.script)),
      window_(options.width, options.height, "volreel — " + options.container.filename().string()),
      playhead_(std::max<std::size_t>(container_.frame_count(), 1),
                stream::PlayheadOptions{options.keyframes_per_second, options.loop}),
      resolution_(loop::ResolutionSettings{options.frame_ms > 0 ? options.frame_ms : 100}) {
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
  surface_ = std::make_unique<Surface>(context_->instance(), window_.get());
  VkBool32 present = VK_FALSE;
  vulkan::check(
      vkGetPhysicalDeviceSurfaceSupportKHR(context_->physical_device(), context_->queue_family(),
                                           surface_->handle(), &present),
      "vkGetPhysicalDeviceSurfaceSupportKHR");
  if (!present)
    throw vulkan::NoDeviceError(context_->device_name() +
                                ": its queue cannot present to the window");
  swapchain_ = std::make_unique<Swapchain>(*context_, surface_->handle(), options.vsync);
  int fw = 0, fh = 0;
  glfwGetFramebufferSize(window_.get(), &fw, &fh);
  if (!swapchain_->recreate({static_cast<std::uint32_t>(std::max(fw, 1)),
                             static_cast<std::uint32_t>(std::max(fh, 1))}))
    throw vulkan::Error("vkCreateSwapchainKHR: the window's surface has zero size at start-up");

  // 2. The renderer with its scheduler (its atlas decides the slot count).
  RendererSetup setup;
  setup.context = context_.get();
  setup.container = &container_;
  setup.atlas_bytes = options.atlas_bytes;
  setup.frames_in_flight = frames_in_flight;
  setup.scheduler.priority.sse_target = options.sse_target;
  setup.scheduler.loader.bandwidth_bytes_per_s = options.bandwidth_bytes_per_s;
  setup.scheduler.loader.latency_s = options.latency_s;
  setup.scheduler.loader.max_in_flight = options.max_requests;
  setup.scheduler.upload_budget_bytes = options.upload_bytes;
  setup.scheduler.lod_blend = options.lod_blend;
  setup.scheduler.ray_feedback = options.ray_feedback;
  setup.scheduler.priority.restricted = options.restricted;
  setup.scheduler.selection.restricted = options.restricted_drawing;
  setup.decode = options.decode;
  setup.width = render_size(swapchain_->extent()).width;
  setup.height = render_size(swapchain_->extent()).height;
  if (options.renderer == RendererKind::cpu) {
    renderer_ = make_cpu_renderer(setup);
  } else if (options.renderer == RendererKind::vulkan) {
    renderer_ = make_vulkan_renderer(setup);
  } else if (context_->properties().deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU) {
    // Vulkan itself runs on the CPU (lavapipe): the C++ ray caster draws the same image several
    // times faster there; the window still presents through Vulkan.
    if (!options.quiet)
      std::printf(
          "volreel play: Vulkan runs on the CPU here (%s): drawing with the CPU reference "
          "renderer, faster there (--renderer vulkan to use the Vulkan ray caster)\n",
          context_->device_name().c_str());
    renderer_ = make_cpu_renderer(setup);
  } else {
    try {
      renderer_ = make_vulkan_renderer(setup);
    } catch (const vulkan::Error& e) {
      std::fprintf(stderr,
                   "volreel play: the Vulkan ray caster is not available (%s); using the CPU "
                   "reference renderer\n",
                   e.what());
      renderer_ = make_cpu_renderer(setup);
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
  imgui_ = std::make_unique<ImGuiSession>(*context_, window_.get(), *swapchain_, frames_in_flight);

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

void Player::report(std::string message) {
  own_messages_.insert(message);
  renderer_->scheduler().report_error(std::move(message));
}

void Player::apply_preset(const std::string& name) {
  const auto& names = cpu_render::TransferFunction::preset_names();
  const auto it = std::find(names.begin(), names.end(), name);
  if (it == names.end()) {
    report("unknown transfer-function preset '" + name + "'");
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
    report(std::string("transfer function: ") + e.what());
  }
}

VkExtent2D Player::render_size(VkExtent2D window) const {
  const auto [w, h] =
      loop::scaled_size(static_cast<int>(window.width), static_cast<int>(window.height),
                        options_.render_scale * frame_scale_);
  return {static_cast<std::uint32_t>(w), static_cast<std::uint32_t>(h)};
}

bool Player::view_busy() const {
  const player::OrbitCamera& a = camera_;
  const player::OrbitCamera& b = previous_camera_;
  const bool moved = a.target != b.target || a.distance != b.distance || a.azimuth != b.azimuth ||
                     a.elevation != b.elevation || a.fov_y != b.fov_y;
  const bool streaming = stats_.fraction_at_target < 1.0;
  return moved || playhead_.position() != previous_playhead_ || streaming;
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
        std::printf("screenshot: %s (volume image %ux%u)\n", path.string().c_str(),
                    slot.shot_volume.width, slot.shot_volume.height);
        std::fflush(stdout);
      }
    } catch (const std::exception& e) {
      ++failed_screenshots_;
      report(std::string("screenshot: ") + e.what());
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
      "frame %llu  keyframe %.2f  %s  %.1f fps  image %ux%u  schedule %.1f upload %.1f decode "
      "%.1f render %.1f ms  atlas %u/%u  in flight %zu  %.2f MB/s  at target %.0f%%  errors "
      "%zu\n",
      static_cast<unsigned long long>(frame_number_), playhead_.position(),
      playhead_.playing() ? "playing" : "paused", fps_.value, render_extent_.width,
      render_extent_.height, t_schedule_.value, t_upload_.value, t_decode_.value, t_render_.value,
      stats_.atlas_occupied, stats_.atlas_capacity, stats_.requests_in_flight, mb_per_s_,
      100.0 * stats_.fraction_at_target, renderer_->scheduler().error_count());
  std::fflush(stdout);
}

FrameOutput Player::render_volume(std::uint32_t slot_index) {
  // The level of detail follows the full-size image: a frame reduced by the frame-time control
  // measures its screen-space error in its own smaller pixels, so its target shrinks with it
  // (else the still view's full-size frame would want finer bricks than the busy frames loaded).
  renderer_->scheduler().priority_settings().sse_target = double{sse_target_} * frame_scale_;
  renderer_->set_exact_timings(exact_timings_);
  FrameInputs inputs;
  inputs.slot = slot_index;
  inputs.gpu_frame = frame_number_ + 1;
  inputs.camera = camera_;
  inputs.camera.width = static_cast<int>(render_extent_.width);
  inputs.camera.height = static_cast<int>(render_extent_.height);
  inputs.playhead = playhead_.position();
  inputs.transfer = &transfer_;
  FrameOutput output = renderer_->frame(inputs);
  stats_ = output.stats;
  for (const std::string& e : output.new_errors) {
    std::fprintf(stderr, "volreel play: %s\n", e.c_str());
    if (!own_messages_.contains(e)) read_failures_.insert(e);
  }
  return output;
}

bool Player::submit_and_present(FrameSlot& slot, VkExtent2D extent) {
  std::uint32_t index = 0;
  const VkResult acquired =
      vkAcquireNextImageKHR(context_->device(), swapchain_->handle(), UINT64_MAX,
                            slot.image_acquired.handle(), VK_NULL_HANDLE, &index);
  if (acquired == VK_ERROR_OUT_OF_DATE_KHR) {
    recreate_ = true;
    return false;  // the fence was not reset: the slot stays usable
  }
  if (acquired != VK_SUBOPTIMAL_KHR) vulkan::check(acquired, "vkAcquireNextImageKHR");
  if (acquired == VK_SUBOPTIMAL_KHR) recreate_ = true;

  const bool capture = !pending_screenshots_.empty() && swapchain_->readable();
  record(slot, index, capture);
  if (capture) {
    slot.screenshots = std::move(pending_screenshots_);
    slot.shot_volume = render_extent_;
  }
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
  slot.gpu_frame = frame_number_ + 1;

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
  return true;
}

void Player::update_figures(double dt, double waited, const FrameOutput& output) {
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
}

PlayerResult Player::run() {
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
    const std::uint32_t slot_index = static_cast<std::uint32_t>(frame_number_ % frames_in_flight);
    FrameSlot& slot = slots_[slot_index];

    // 2. Frame n − 2 retired: its atlas slots may be reused, its read-back written.
    const auto wait_start = Clock::now();
    slot.done.wait();
    const double waited = seconds_between(wait_start, Clock::now());
    if (slot.gpu_frame > 0) renderer_->retired(slot.gpu_frame);
    finish_screenshots(slot);

    // 3. Input, script, playhead.
    const auto now = Clock::now();
    const double dt = seconds_between(previous, now);
    previous = now;
    // The last frame's period at its scale feeds the frame-time control (not across a pause).
    if (frame_number_ > 0 && !resumed_) resolution_.measured(frame_scale_, 1e3 * dt);
    ImGui_ImplVulkan_NewFrame();
    ImGui_ImplGlfw_NewFrame();
    ImGui::NewFrame();
    handle_input();
    run_script(frame_number_ == 0 ? 0.0 : dt);
    playhead_.advance(options_.fixed_frame_seconds > 0 ? options_.fixed_frame_seconds : dt);

    // The volume image's size: reduced while the view is busy, full once it is still; a new size
    // waits for the frames in flight (the output image is re-created). A screenshot shows what
    // the window shows.
    busy_ = view_busy();
    frame_scale_ = options_.frame_ms > 0 ? resolution_.next(busy_) : 1.0;
    previous_camera_ = camera_;
    previous_playhead_ = playhead_.position();
    const VkExtent2D wanted = render_size(extent);
    if (wanted.width != render_extent_.width || wanted.height != render_extent_.height) {
      context_->wait_idle();
      renderer_->resize(wanted.width, wanted.height);
      render_extent_ = renderer_->extent();
    }

    // 4. Scheduler, decode and render (the renderer's CPU work and its own submissions).
    const FrameOutput output = render_volume(slot_index);

    // 5. UI.
    draw_ui();
    ImGui::Render();

    // 6. Acquire, record, submit, present.
    if (!submit_and_present(slot, extent)) continue;  // out of date: the slot stays usable

    // 7. HUD figures.
    update_figures(dt, waited, output);
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
  return PlayerResult{failed_screenshots_, read_failures_.size()};
}

}  // namespace detail

PlayerResult run_player(const PlayerOptions& options) {
  detail::Player player(options);
  return player.run();
}

}  // namespace volreel::app
