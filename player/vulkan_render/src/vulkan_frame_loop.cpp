// vulkan_frame_loop.cpp: the per-frame streaming loop on the GPU (see vulkan_frame_loop.hpp).
#include "volreel/vulkan_render/vulkan_frame_loop.hpp"

#include <algorithm>
#include <bit>
#include <chrono>
#include <cstring>
#include <exception>
#include <stdexcept>

#include "volreel/format/error.hpp"
#include "volreel/player/svo_layout.h"

namespace volreel::vulkan_render {
namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

}  // namespace

void leaf_histograms(std::span<const std::uint32_t> svo_leaves,
                     std::span<const std::uint64_t> slot_histograms,
                     std::vector<std::uint64_t>& out) {
  const std::size_t leaves = svo_leaves.size() / VR_SVO_LEAF_WORDS;
  out.assign(leaves, 0);
  for (std::size_t i = 0; i < leaves; ++i) {
    const std::uint32_t* r = svo_leaves.data() + i * VR_SVO_LEAF_WORDS;
    const float f = std::bit_cast<float>(r[3]);
    std::uint64_t h = 0;
    bool unknown = false;
    // The keyframes read: A and B, and C and D where the leaf blends levels of detail.
    const bool blends = r[7] != VR_SVO_BLEND_NONE || r[8] != VR_SVO_BLEND_NONE;
    const float g = std::bit_cast<float>(r[6]);
    for (int k = 0; k < (blends ? 4 : 2); ++k) {
      const float weight = k == 0 ? 1.0f - f : k == 1 ? f : k == 2 ? 1.0f - g : g;
      if (weight == 0.0f) continue;
      const std::uint32_t slot = r[k < 2 ? k : k + 2];
      const std::uint64_t s = slot < slot_histograms.size() ? slot_histograms[slot] : 0;
      unknown = unknown || s == 0;
      h |= s;
    }
    out[i] = unknown ? 0 : h;
  }
}

VulkanFrameLoop::VulkanFrameLoop(const vulkan::Context& context, const format::Container& container,
                                 const loop::FrameLoopOptions& options)
    : VulkanFrameLoop(nullptr, context, container, options) {}

VulkanFrameLoop::VulkanFrameLoop(std::unique_ptr<vulkan::Context> context,
                                 const format::Container& container,
                                 const loop::FrameLoopOptions& options)
    : VulkanFrameLoop(std::move(context), *context, container, options) {}

VulkanFrameLoop::VulkanFrameLoop(std::unique_ptr<vulkan::Context>&& owned,
                                 const vulkan::Context& context, const format::Container& container,
                                 const loop::FrameLoopOptions& options)
    : owned_context_(std::move(owned)),
      context_(context),
      container_(container),
      options_(options) {
  const format::Manifest& m = container.manifest();
  geometry_ = cpu_render::VolumeGeometry::of(m.dims, m.shape());
  // 1. The atlas over the sequence's value range with a margin (decoded values overshoot it).
  vulkan::AtlasOptions ao;
  ao.format = vulkan::AtlasFormat::r16_unorm;
  ao.slot_size = m.brick_size;
  ao.memory_budget_bytes = options.atlas_bytes;
  const double range = m.value_max - m.value_min;
  const double margin = 0.01 * (range > 0 ? range : 1.0);
  ao.value_min = static_cast<float>(m.value_min - margin);
  ao.value_max = static_cast<float>(m.value_max + margin);
  atlas_ = std::make_unique<vulkan::Atlas>(context, ao);
  // 2. The decoder, the ray caster, the scheduler with one heap entry per atlas slot ([0036]).
  vulkan::DecoderOptions dopt;
  dopt.upload_budget_bytes = options.gpu.staging_bytes;
  dopt.ring_size = 3;
  const bool cpu_device = context.properties().deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU;
  switch (options.gpu.decode) {
    case loop::FrameLoopOptions::Decode::cpu:
      dopt.kernel = vulkan::DecoderOptions::Kernel::host;
      break;
    case loop::FrameLoopOptions::Decode::gpu:  // the compute kernel that is faster there
      dopt.kernel = cpu_device ? vulkan::DecoderOptions::Kernel::buffer_copy
                               : vulkan::DecoderOptions::Kernel::image_store;
      break;
    default:
      dopt.kernel = vulkan::DecoderOptions::Kernel::automatic;
  }
  decoder_ = std::make_unique<vulkan::AtlasDecoder>(context, *atlas_, dopt);
  if (m.codec == format::Codec::ksvd) decoder_->set_dictionary(container.atoms());
  RaycasterOptions ro;
  ro.width = options.width;
  ro.height = options.height;
  ro.frames_in_flight = options.gpu.frames_in_flight;
  raycaster_ = std::make_unique<Raycaster>(context, *atlas_, ro);
  options_.scheduler.atlas_slots = atlas_->slot_count();
  // Feedback arrives when its frame completes, up to frames_in_flight frames after it was built
  // (one frame more of slack: a frame without a new table keeps the last one's hiding).
  options_.scheduler.feedback_frames =
      std::max(options_.scheduler.feedback_frames, ro.frames_in_flight + 2);
  scheduler_ = std::make_unique<stream::StreamScheduler>(container, options_.scheduler);
  slot_histograms_.assign(atlas_->slot_count(), 0);
}

VulkanFrameLoop::~VulkanFrameLoop() {
  try {
    finish();
  } catch (...) {
    context_.wait_idle();
  }
}

void VulkanFrameLoop::retire_completed() {
  while (retired_ < raycaster_->last_ticket() && raycaster_->poll(retired_ + 1)) ++retired_;
  if (retired_ > 0) scheduler_->retire(retired_);
  // Ray-guided feedback (Thiele et al. §3): the newest completed frame's table guides the next
  // selection, for the SVO the scheduler built for that frame (it keeps the last few).
  const Ticket last = raycaster_->last_ticket(), ring = options_.gpu.frames_in_flight;
  for (Ticket t = last; t > fed_back_ && t + ring > last; --t)
    if (raycaster_->has_feedback(t) && raycaster_->poll(t)) {
      take_feedback(t);
      break;
    }
}

void VulkanFrameLoop::take_feedback(Ticket ticket) {
  scheduler_->feedback(raycaster_->feedback(ticket), ticket);
  fed_back_ = ticket;
}

void VulkanFrameLoop::finish() {
  raycaster_->wait_all();
  decoder_->wait_all();
  retired_ = raycaster_->last_ticket();
  if (retired_ > 0) scheduler_->retire(retired_);
}

std::uint64_t VulkanFrameLoop::histogram_of(const stream::KeyframeKey& key) const {
  // Read with the node table when the index was built; 0 (never culled) for an unknown key.
  const stream::KeyframeId id = scheduler_->index().find_keyframe(key);
  return id == stream::no_keyframe ? 0 : scheduler_->index().keyframe(id).histogram;
}

void VulkanFrameLoop::decode_uploads(const std::vector<stream::BrickUpload>& uploads,
                                     std::vector<std::string>& errors) {
  if (uploads.empty()) return;
  const format::Manifest& m = container_.manifest();
  const auto to_decoder = [&](const stream::BrickUpload& u) {
    return vulkan::BrickUpload{u.payload, m.codec, m.zfp_accuracy, u.slot};
  };
  std::vector<vulkan::BrickUpload> batch;
  batch.reserve(uploads.size());
  for (const stream::BrickUpload& u : uploads) batch.push_back(to_decoder(u));
  try {
    decoder_->submit(batch);
  } catch (const format::FormatError&) {
    // A bad payload rejects the whole batch before anything is submitted: decode the bricks one
    // by one and fill each bad one's slot with the lowest value, so it shows as background.
    const float fill = static_cast<float>(m.value_min);
    std::byte constant[4];
    std::memcpy(constant, &fill, 4);
    for (std::size_t i = 0; i < uploads.size(); ++i) {
      try {
        decoder_->submit({&batch[i], 1});
      } catch (const format::FormatError& e) {
        std::string message = uploads[i].file.string() + ": offset " +
                              std::to_string(uploads[i].offset) + ": " + e.what();
        scheduler_->report_error(message);
        errors.push_back(std::move(message));
        const vulkan::BrickUpload blank{constant, m.codec, m.zfp_accuracy, uploads[i].slot};
        decoder_->submit({&blank, 1});
        slot_histograms_[uploads[i].slot] = 0;
      }
    }
  }
}

stream::FrameUpdate VulkanFrameLoop::update_and_decode(const player::OrbitCamera& camera,
                                                       double playhead, loop::FrameReport& report) {
  // 1. Retire finished frames: their slots may be overwritten now.
  retire_completed();
  // 2. The scheduler: arrivals, priorities, requests, slots, the SVO ([0029]–[0075]), for the
  //    next frame the ray caster renders.
  const Ticket gpu_frame = raycaster_->last_ticket() + 1;
  auto t = Clock::now();
  stream::FrameUpdate update = scheduler_->update(camera, playhead, gpu_frame);
  report.timings.schedule_ms = ms_since(t);
  report.new_errors = std::move(update.new_errors);
  // 3. Decode the arrived bricks into their slots (MTV-Player §4.2); the next frame recomputes
  //    their block ranges.
  t = Clock::now();
  for (const stream::BrickUpload& u : update.uploads) {
    slot_histograms_[u.slot] = options_.transfer_culling ? histogram_of(u.key) : 0;
    changed_slots_.push_back(u.slot);
  }
  decode_uploads(update.uploads, report.new_errors);
  report.timings.upload_ms = ms_since(t);
  if (!options_.pipelined) {
    t = Clock::now();
    decoder_->wait_all();
    report.timings.decode_ms = ms_since(t);
  }
  report.stats = update.stats;
  return update;
}

loop::FrameReport VulkanFrameLoop::stream(const player::OrbitCamera& camera, double playhead) {
  const auto start = Clock::now();
  loop::FrameReport report;
  // A step draws nothing: no ray tells what this view reaches, and a table from an earlier view
  // must not hide what this one needs (a wait for a complete view would stop short).
  fed_back_ = raycaster_->last_ticket();
  scheduler_->forget_feedback();
  update_and_decode(camera, playhead, report);
  report.timings.frame_ms = ms_since(start);
  return report;
}

loop::FrameReport VulkanFrameLoop::frame(const player::OrbitCamera& camera, double playhead,
                                         const cpu_render::TransferFunction& transfer,
                                         bool readback) {
  const auto start = Clock::now();
  loop::FrameReport report;
  stream::FrameUpdate update = update_and_decode(camera, playhead, report);
  const Ticket gpu_frame = raycaster_->last_ticket() + 1;  // what the scheduler was told
  // 4. Ray casting (same queue: it sees the decoded slots).
  FrameInput input;
  input.svo_nodes = update.svo_nodes;
  input.svo_leaves = update.svo_leaves;
  if (options_.transfer_culling) {
    leaf_histograms(update.svo_leaves, slot_histograms_, leaf_histograms_);
    input.leaf_histograms = leaf_histograms_;
  }
  const format::Manifest& m = container_.manifest();
  input.histogram_range = {static_cast<float>(m.value_min), static_cast<float>(m.value_max)};
  input.geometry = geometry_;
  input.camera = camera;
  input.transfer = &transfer;
  input.options = options_.render;
  // Slots decoded since the last frame (stream() steps included), each once.
  std::sort(changed_slots_.begin(), changed_slots_.end());
  changed_slots_.erase(std::unique(changed_slots_.begin(), changed_slots_.end()),
                       changed_slots_.end());
  input.changed_slots = changed_slots_;
  input.skip_invisible_blocks = options_.transfer_culling;
  input.feedback = options_.scheduler.ray_feedback;
  // The frame whose ring entry this one reuses: render() waits for it, so its table costs no
  // wait (with the GPU frames behind, no frame is complete at retire_completed()).
  const std::uint32_t ring = options_.gpu.frames_in_flight;
  if (gpu_frame > ring && gpu_frame - ring > fed_back_ &&
      raycaster_->has_feedback(gpu_frame - ring))
    take_feedback(gpu_frame - ring);
  const auto t = Clock::now();
  report.ticket = raycaster_->render(input, readback);
  changed_slots_.clear();
  if (gpu_frame != report.ticket)
    throw std::logic_error("VulkanFrameLoop: the ray caster's frame numbers went out of step");
  if (!options_.pipelined) {
    raycaster_->wait(report.ticket);
    const double wall = ms_since(t);
    report.timings.render_ms = raycaster_->gpu_milliseconds(report.ticket).value_or(wall);
    retire_completed();
  }
  last_update_ = std::move(update);
  report.timings.frame_ms = ms_since(start);
  return report;
}

std::string VulkanFrameLoop::describe() const {
  return context_.describe() + ", bricks decoded by " + vulkan::kernel_name(decoder_->kernel());
}

void VulkanFrameLoop::resize(int width, int height) {
  raycaster_->resize(width, height);
  options_.width = raycaster_->width();
  options_.height = raycaster_->height();
}

}  // namespace volreel::vulkan_render
