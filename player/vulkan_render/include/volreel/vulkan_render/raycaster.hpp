// raycaster.hpp: the Vulkan ray caster of volreel's player (docs/design.md, "Streaming", step 7) —
// a compute shader (shaders/render/raycast.comp) that walks the array-encoded SVO (svo_layout.h)
// per sample, fetches both keyframes of a leaf from the brick atlas with trilinear filtering (the
// second mapped into its ancestor's brick for any LOD difference, Cesium patent [0050]),
// interpolates them with the leaf's factor and composites front to back through a 1D transfer
// function, skipping regions that are empty or whose leaf histograms the transfer function makes
// invisible, and samples whose 6³ atlas blocks hold only invisible values (block value ranges,
// recomputed for the slots a frame lists as changed: shaders/render/block_ranges.comp). The step
// follows the level of the leaf a sample reads, with the opacity corrected for it
// (RenderOptions::max_step_doublings). It takes the same samples as cpu_render::render_svo
// (cpu_render/renderer.hpp, steps 1–5), so the two images agree up to 16-bit atlas storage, the
// GPU's filtering and float rounding where a coarse step ends at a region's exit.
//
// Output: a 2D storage image (rgba8 or rgba16f, usage STORAGE | SAMPLED | TRANSFER_SRC) in
// VK_IMAGE_LAYOUT_GENERAL between frames. A headless caller reads it back (render() with readback,
// then read_back()); a window blits it to its swapchain image after render() (same queue), moving
// it GENERAL → TRANSFER_SRC_OPTIMAL → GENERAL around the blit as the readback copy does (the
// validation layer flags copies in GENERAL), or samples it in a fragment shader.
//
// Frames in flight: the per-frame buffers (parameters, SVO words, histograms, transfer function,
// readback) form a ring of `frames_in_flight` entries. render() submits on the context's queue
// with its own fence and returns a Ticket; an entry is refilled only after its previous frame's
// fence signalled, so the CPU can build frame N+1 while the GPU renders frame N.
//
// Synchronization on the single queue: every frame's commands start with a barrier after all
// earlier compute and transfer work (the atlas decoder's writes, the previous frame's copy of the
// output image) and end with the output image's compute writes made visible to transfers (copy,
// blit). A graphics reader (a fragment shader sampling the output) adds its own barrier.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "volreel/cpu_render/renderer.hpp"
#include "volreel/cpu_render/transfer_function.hpp"
#include "volreel/player/camera.hpp"
#include "volreel/vulkan/atlas.hpp"
#include "volreel/vulkan/context.hpp"
#include "volreel/vulkan/resources.hpp"

namespace volreel::vulkan_render {

enum class OutputFormat { rgba8_unorm, rgba16_sfloat };

/// How the atlas is filtered: the sampler's linear filter, or eight texel fetches blended in the
/// shader (identical up to the hardware's filter-weight rounding; on CPU implementations such as
/// lavapipe the fetches are much faster than their software 3D sampler, so `automatic` takes
/// them on CPU devices).
enum class AtlasFilter { automatic, sampler, fetch };

struct RaycasterOptions {
  int width = 512, height = 512;  ///< output image size, pixels (≥ 1; resize() changes it)
  OutputFormat output = OutputFormat::rgba8_unorm;
  std::uint32_t frames_in_flight = 2;           ///< ring entries (≥ 1)
  AtlasFilter filter = AtlasFilter::automatic;  ///< automatic: fetch on CPU devices, else sampler
};

/// Everything one frame needs besides the atlas. Spans are copied during render()/record().
struct FrameInput {
  std::span<const std::uint32_t> svo_nodes;   ///< svo_layout.h node records (record 0 the root)
  std::span<const std::uint32_t> svo_leaves;  ///< svo_layout.h leaf records
  /// Optional leaf histograms (VR_SVO_HISTOGRAM_WORDS words per leaf record, bins over
  /// `histogram_range`); empty: no transfer-function culling.
  std::span<const std::uint64_t> leaf_histograms;
  std::array<float, 2> histogram_range{0, 1};  ///< the container's value range (manifest)
  cpu_render::VolumeGeometry geometry;         ///< finest dims and octree levels
  player::OrbitCamera camera;                  ///< its width/height must equal the output's
  const cpu_render::TransferFunction* transfer = nullptr;  ///< required
  /// Step, reference step, background, termination, max step doublings.
  cpu_render::RenderOptions options;
  /// Atlas slots written since the previous frame (decoded bricks): their 6³-block value ranges
  /// are recomputed before ray casting. Every slot written must be listed once it is sampled
  /// with skip_invisible_blocks.
  std::span<const std::uint32_t> changed_slots;
  /// Skip samples whose atlas blocks hold only values the transfer function hides (the image is
  /// unchanged; the texel fetches are saved).
  bool skip_invisible_blocks = false;
  /// Write the ray-guided feedback table (svo_layout.h: VR_SVO_FEEDBACK_ENTRIES per leaf record),
  /// as cpu_render::render_svo does, for Raycaster::feedback().
  bool feedback = false;
};

/// Identifies a submitted frame; 0 is "nothing" (always complete). Increases by one per frame.
using Ticket = std::uint64_t;

class Raycaster {
 public:
  /// Builds the pipeline, the sampler, the output image and the ring. The context and the atlas
  /// must outlive the ray caster. Throws vulkan::Error on a Vulkan failure or an unsupported
  /// output format, std::invalid_argument on bad options.
  Raycaster(const vulkan::Context& context, const vulkan::Atlas& atlas,
            const RaycasterOptions& options = {});
  ~Raycaster();
  Raycaster(const Raycaster&) = delete;
  Raycaster& operator=(const Raycaster&) = delete;

  /// Renders one frame: waits for the ring entry's previous frame, uploads the frame's buffers,
  /// records and submits (ctx.submit with the entry's fence). With `readback`, the output is also
  /// copied to the entry's host buffer for read_back(ticket). Validates the input first
  /// (std::invalid_argument naming the problem; nothing is submitted then).
  Ticket render(const FrameInput& input, bool readback = false);

  /// For a caller that submits itself (a window): uploads the frame's buffers and records the
  /// dispatch into `commands` (begun, not ended). The caller submits it and guarantees that the
  /// commands recorded `frames_in_flight` calls earlier have completed (the usual wait on its
  /// frame fence) before calling again. Returns the ticket the frame would have; poll() and
  /// wait() do not apply to it.
  Ticket record(VkCommandBuffer commands, const FrameInput& input);

  /// Whether frame `ticket` (render()) has completed.
  bool poll(Ticket ticket) const;
  /// Waits for frame `ticket` (render()) to complete.
  void wait(Ticket ticket) const;
  /// Waits for every frame submitted with render().
  void wait_all() const;
  /// The image of frame `ticket`, rendered with readback = true and still in the ring (one of the
  /// last frames_in_flight frames); waits for it. Throws std::invalid_argument otherwise.
  cpu_render::RgbaImage read_back(Ticket ticket) const;
  /// The feedback table of frame `ticket` (render() with FrameInput::feedback, still in the
  /// ring); waits for it. Throws std::invalid_argument otherwise.
  std::vector<std::uint32_t> feedback(Ticket ticket) const;
  /// Whether frame `ticket` was rendered with FrameInput::feedback and is still in the ring.
  bool has_feedback(Ticket ticket) const;
  /// GPU time of the dispatch of a completed frame `ticket` (render()), milliseconds, when the
  /// queue supports timestamps; waits for it.
  std::optional<double> gpu_milliseconds(Ticket ticket) const;

  /// Recreates the output image at a new size (waits for every frame first).
  void resize(int width, int height);

  int width() const { return options_.width; }
  int height() const { return options_.height; }
  const vulkan::Image& output() const { return output_; }
  VkFormat output_format() const;
  /// Always VK_IMAGE_LAYOUT_GENERAL.
  VkImageLayout output_layout() const { return VK_IMAGE_LAYOUT_GENERAL; }
  Ticket last_ticket() const { return last_ticket_; }
  const RaycasterOptions& options() const { return options_; }
  /// Whether the shader filters with texel fetches (AtlasFilter::fetch, or automatic on a CPU).
  bool fetch_filter() const { return fetch_filter_; }

 private:
  struct Entry;
  Entry& prepare(const FrameInput& input);
  void record_commands(VkCommandBuffer commands, Entry& entry, bool readback);
  void create_output();
  const Entry& entry_of(Ticket ticket, const char* what) const;

  const vulkan::Context& context_;
  const vulkan::Atlas& atlas_;
  RaycasterOptions options_;
  vulkan::DescriptorSetLayout set_layout_;
  vulkan::ShaderModule shader_;
  vulkan::ComputePipeline pipeline_;
  vulkan::DescriptorPool descriptor_pool_;
  vulkan::CommandPool command_pool_;
  vulkan::Sampler sampler_;
  vulkan::Image output_;
  // Value ranges of the atlas's 6³ blocks (shaders/render/block_ranges.comp).
  vulkan::DescriptorSetLayout ranges_layout_;
  vulkan::ShaderModule ranges_shader_;
  vulkan::ComputePipeline ranges_pipeline_;
  vulkan::Buffer block_ranges_;
  VkQueryPool timestamps_ = VK_NULL_HANDLE;
  double timestamp_period_ns_ = 0;
  std::vector<std::unique_ptr<Entry>> ring_;
  // The opacity-corrected transfer function of the last frame and its visible-entry prefix count,
  // kept so that a frame with the same function and step allocates nothing.
  cpu_render::TransferFunction tf_source_, tf_corrected_;
  double tf_step_ratio_ = 0;
  std::vector<std::uint32_t> visible_prefix_;
  Ticket last_ticket_ = 0;
  bool fetch_filter_ = false;
};

}  // namespace volreel::vulkan_render
