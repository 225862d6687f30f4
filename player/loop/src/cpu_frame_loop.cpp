// cpu_frame_loop.cpp: the streaming loop on the CPU (see cpu_frame_loop.hpp).
#include "volreel/loop/cpu_frame_loop.hpp"

#include <algorithm>
#include <chrono>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "volreel/format/error.hpp"

namespace volreel::loop {
namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

}  // namespace

std::uint32_t CpuFrameLoop::slots_for(const FrameLoopOptions& options, format::BrickShape shape) {
  return static_cast<std::uint32_t>(
      std::clamp<std::uint64_t>(options.atlas_bytes / gpu_slot_bytes(shape), 1, 1u << 20));
}

CpuFrameLoop::CpuFrameLoop(const format::Container& container, const FrameLoopOptions& options)
    : container_(container), options_(options) {
  const format::Manifest& m = container.manifest();
  geometry_ = cpu_render::VolumeGeometry::of(m.dims, m.shape());
  atlas_ = std::make_unique<cpu_render::CpuAtlas>(slots_for(options, m.shape()), m.shape());
  options_.scheduler.atlas_slots = atlas_->slot_count();
  scheduler_ = std::make_unique<stream::StreamScheduler>(container, options_.scheduler);
}

CpuFrameLoop::CpuFrameLoop(const format::Container& container, stream::SpatialIndex index,
                           const FrameLoopOptions& options)
    : container_(container), options_(options) {
  const format::Manifest& m = container.manifest();
  geometry_ = cpu_render::VolumeGeometry::of(m.dims, m.shape());
  atlas_ = std::make_unique<cpu_render::CpuAtlas>(slots_for(options, m.shape()), m.shape());
  options_.scheduler.atlas_slots = atlas_->slot_count();
  scheduler_ = std::make_unique<stream::StreamScheduler>(std::move(index), options_.scheduler);
}

stream::FrameUpdate CpuFrameLoop::update_and_decode(const player::OrbitCamera& camera,
                                                    double playhead, FrameReport& report) {
  // 1. The scheduler (the previous frame is complete: rendering is synchronous). Its slots are
  //    marked for the next frame to render.
  auto t = Clock::now();
  stream::FrameUpdate update = scheduler_->update(camera, playhead, ticket_ + 1);
  report.timings.schedule_ms = ms_since(t);
  report.new_errors = update.new_errors;
  // 2. Decode the arrived bricks into their slots; a bad one becomes the lowest value.
  t = Clock::now();
  const format::Manifest& m = container_.manifest();
  const format::AtomTable atoms = container_.atoms();
  for (const stream::BrickUpload& u : update.uploads) {
    try {
      atlas_->decode_into(u.slot, u.payload, m.codec, m.zfp_accuracy, atoms, u.file, u.offset);
    } catch (const format::FormatError& e) {
      std::string message = e.what();
      scheduler_->report_error(message);
      report.new_errors.push_back(std::move(message));
      const auto slot = atlas_->slot(u.slot);
      std::fill(slot.begin(), slot.end(), static_cast<float>(m.value_min));
    }
  }
  report.timings.decode_ms = ms_since(t);
  report.stats = update.stats;
  return update;
}

FrameReport CpuFrameLoop::stream(const player::OrbitCamera& camera, double playhead) {
  const auto start = Clock::now();
  FrameReport report;
  // A step draws nothing: no ray tells what this view reaches, and a table from an earlier view
  // must not hide what this one needs (a wait for a complete view would stop short).
  scheduler_->forget_feedback();
  update_and_decode(camera, playhead, report);
  // Nothing reads the atlas between frames here: the slots marked for the next frame may be
  // reused by the next step already.
  scheduler_->retire(ticket_ + 1);
  report.timings.frame_ms = ms_since(start);
  return report;
}

FrameReport CpuFrameLoop::frame(const player::OrbitCamera& camera, double playhead,
                                const cpu_render::TransferFunction& transfer, bool) {
  const auto start = Clock::now();
  FrameReport report;
  stream::FrameUpdate update = update_and_decode(camera, playhead, report);
  report.ticket = ++ticket_;
  // 3. Render.
  const auto t = Clock::now();
  cpu_render::SvoView svo;
  svo.nodes = update.svo_nodes;
  svo.leaves = update.svo_leaves;
  // The rays' feedback (which leaves they sampled) guides the next frame's selection.
  const bool feedback = options_.scheduler.ray_feedback;
  image_ = cpu_render::render_svo(svo, *atlas_, geometry_, camera, transfer, options_.render,
                                  feedback ? &feedback_ : nullptr);
  if (feedback) scheduler_->feedback(feedback_);
  report.timings.render_ms = ms_since(t);
  // 4. Retire: nothing reads the atlas after render_svo returned.
  scheduler_->retire(report.ticket);
  last_update_ = std::move(update);
  report.timings.frame_ms = ms_since(start);
  return report;
}

cpu_render::RgbaImage CpuFrameLoop::render_previous_working_set(
    const player::OrbitCamera& camera, double playhead,
    const cpu_render::TransferFunction& transfer) const {
  if (ticket_ == 0) return {};
  const stream::SvoArrays previous = scheduler_->previous_svo(playhead);
  cpu_render::SvoView svo;
  svo.nodes = previous.nodes;
  svo.leaves = previous.leaves;
  return cpu_render::render_svo(svo, *atlas_, geometry_, camera, transfer, options_.render,
                                nullptr);
}

const cpu_render::RgbaImage& CpuFrameLoop::last_image(Ticket ticket) const {
  if (ticket != ticket_ || ticket == 0)
    throw std::invalid_argument("CpuFrameLoop::read_back: only the last frame's image is kept");
  return image_;
}

void CpuFrameLoop::resize(int width, int height) {
  options_.width = std::max(width, 1);
  options_.height = std::max(height, 1);
}

std::string CpuFrameLoop::describe() const {
  return "CPU reference renderer (" + std::to_string(std::thread::hardware_concurrency()) +
         " threads)";
}

}  // namespace volreel::loop
