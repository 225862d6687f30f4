// raycaster.cpp: the Vulkan ray caster's host side — pipeline, ring of per-frame buffers,
// command recording, readback (see raycaster.hpp).
#include "volreel/vulkan_render/raycaster.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>

#include "volreel/format/error.hpp"
#include "volreel/format/frame_file.hpp"
#include "volreel/player/svo_layout.h"
#include "volreel_block_ranges_spv.h"
#include "volreel_raycast_rgba16f_spv.h"
#include "volreel_raycast_rgba8_spv.h"

namespace volreel::vulkan_render {
namespace {

constexpr std::uint32_t local_size = 8;  // raycast.comp's workgroup is 8 × 8
constexpr std::uint32_t flag_histograms = 1;
constexpr std::uint32_t flag_fetch_filter = 2;
constexpr std::uint32_t flag_block_skip = 4;
constexpr std::uint32_t flag_feedback = 8;
// RenderOptions::max_step_doublings at most (as cpu_render checks): 2^16 fine steps, and k stays
// an exact integer in the shader's floats.
constexpr std::uint32_t max_step_doublings = 16;

// The shader's Params block (std430: vec4 and uvec4 members only, 160 bytes).
struct Params {
  float eye_step[4];
  float forward_tan[4];
  float right_aspect[4];
  float up_termination[4];
  float background_lo[4];
  float inv_extent_scale[4];
  float dims_tf_lo[4];
  float tf_scale_entries[4];
  std::uint32_t size_levels[4];
  std::uint32_t grid_mask[4];
};
static_assert(sizeof(Params) == 160);

VkFormat vk_format(OutputFormat f) {
  return f == OutputFormat::rgba8_unorm ? VK_FORMAT_R8G8B8A8_UNORM : VK_FORMAT_R16G16B16A16_SFLOAT;
}
std::uint32_t texel_bytes(OutputFormat f) {
  return f == OutputFormat::rgba8_unorm ? 4 : 8;
}

/// A host-visible buffer (device-local where the device offers such memory) of at least `bytes`.
void ensure(const vulkan::Context& context, vulkan::Buffer& buffer, VkDeviceSize bytes,
            VkBufferUsageFlags usage, VkMemoryPropertyFlags preferred) {
  bytes = std::max<VkDeviceSize>(bytes, 16);
  if (buffer.handle() != VK_NULL_HANDLE && buffer.size() >= bytes) return;
  const VkDeviceSize size = std::max(bytes, 2 * buffer.size());
  buffer = vulkan::Buffer(context, size, usage, VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT, preferred);
}

void upload(const vulkan::Buffer& buffer, const void* data, std::size_t bytes) {
  if (bytes == 0) return;
  std::memcpy(buffer.mapped(), data, bytes);
  buffer.flush(0, VK_WHOLE_SIZE);
}

std::string size_text(int w, int h) {
  return std::to_string(w) + "x" + std::to_string(h);
}

}  // namespace

struct Raycaster::Entry {
  vulkan::Buffer params, nodes, leaves, histograms, transfer, readback;
  vulkan::Buffer visible_prefix, ranges_params, changed_slots;
  vulkan::Buffer feedback_table;     ///< the feedback table (svo_layout.h) the shader writes
  vulkan::Buffer feedback;           ///< its copy for the host
  std::size_t feedback_entries = 0;  ///< its entries this frame
  bool has_feedback = false;         ///< the frame writes it (FrameInput::feedback)
  VkDescriptorSet ranges_set = VK_NULL_HANDLE;
  std::uint32_t changed = 0;  ///< slots whose block ranges this frame recomputes
  vulkan::Fence fence;
  VkCommandBuffer commands = VK_NULL_HANDLE;
  VkDescriptorSet set = VK_NULL_HANDLE;
  Ticket ticket = 0;
  bool fenced = false;  ///< submitted by render() (the fence belongs to this ticket)
  bool has_readback = false, timed = false;
  int width = 0, height = 0;
  OutputFormat format = OutputFormat::rgba8_unorm;
  std::uint32_t index = 0;  ///< position in the ring (timestamp queries 2·index, 2·index + 1)
};

Raycaster::Raycaster(const vulkan::Context& context, const vulkan::Atlas& atlas,
                     const RaycasterOptions& options)
    : context_(context), atlas_(atlas), options_(options) {
  if (options.width < 1 || options.height < 1)
    throw std::invalid_argument("Raycaster: expected an output size of at least 1x1, found " +
                                size_text(options.width, options.height));
  if (options.frames_in_flight < 1)
    throw std::invalid_argument("Raycaster: expected at least one frame in flight");
  const VkFormat format = vk_format(options.output);
  if (!(context.optimal_format_features(format) & VK_FORMAT_FEATURE_STORAGE_IMAGE_BIT))
    throw vulkan::Error("Raycaster: the device cannot write the output format as a storage image");

  fetch_filter_ = options.filter == AtlasFilter::fetch ||
                  (options.filter == AtlasFilter::automatic &&
                   context.properties().deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU);

  // 1. Pipeline: bindings as raycast.comp declares them.
  const VkShaderStageFlags compute = VK_SHADER_STAGE_COMPUTE_BIT;
  const VkDescriptorSetLayoutBinding bindings[] = {
      {0, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, compute, nullptr},
      {1, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, compute, nullptr},
      {2, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, compute, nullptr},
      {3, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, compute, nullptr},
      {4, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, compute, nullptr},
      {5, VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, 1, compute, nullptr},
      {6, VK_DESCRIPTOR_TYPE_STORAGE_IMAGE, 1, compute, nullptr},
      {7, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, compute, nullptr},
      {8, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, compute, nullptr},
      {9, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, compute, nullptr},
  };
  set_layout_ = vulkan::DescriptorSetLayout(context, bindings);
  if (options.output == OutputFormat::rgba8_unorm)
    shader_ = vulkan::ShaderModule(context, volreel_raycast_rgba8_spv);
  else
    shader_ = vulkan::ShaderModule(context, volreel_raycast_rgba16f_spv);
  const VkDescriptorSetLayout layouts[] = {set_layout_.handle()};
  // Specialization constant 0 of both shaders: blocks per brick axis (slots of 6n voxels a side).
  const std::uint32_t blocks_per_axis = atlas.slot_size() / format::brick_block_size;
  pipeline_ = vulkan::ComputePipeline(context, shader_, layouts, 0, {&blocks_per_axis, 1});
  const VkDescriptorSetLayoutBinding range_bindings[] = {
      {0, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, compute, nullptr},
      {1, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, compute, nullptr},
      {2, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, compute, nullptr},
      {3, VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, 1, compute, nullptr},
  };
  ranges_layout_ = vulkan::DescriptorSetLayout(context, range_bindings);
  ranges_shader_ = vulkan::ShaderModule(context, volreel_block_ranges_spv);
  const VkDescriptorSetLayout range_layouts[] = {ranges_layout_.handle()};
  ranges_pipeline_ =
      vulkan::ComputePipeline(context, ranges_shader_, range_layouts, 0, {&blocks_per_axis, 1});
  const std::uint32_t ring = options.frames_in_flight;
  const VkDescriptorPoolSize sizes[] = {
      {VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 11 * ring},
      {VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, 2 * ring},
      {VK_DESCRIPTOR_TYPE_STORAGE_IMAGE, ring},
  };
  descriptor_pool_ = vulkan::DescriptorPool(context, sizes, 2 * ring);
  // Block ranges start as "anything" until a slot's ranges are computed.
  const VkDeviceSize blocks_per_slot =
      VkDeviceSize{blocks_per_axis} * blocks_per_axis * blocks_per_axis;  // 6³ voxels each
  const VkDeviceSize range_bytes = VkDeviceSize{atlas.slot_count()} * blocks_per_slot * 8;
  block_ranges_ =
      vulkan::Buffer(context, range_bytes, VK_BUFFER_USAGE_STORAGE_BUFFER_BIT,
                     VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
  {
    auto* ranges = reinterpret_cast<float*>(block_ranges_.mapped());
    for (VkDeviceSize i = 0; i < range_bytes / 8; ++i) {
      ranges[2 * i] = -1e30f;
      ranges[2 * i + 1] = 1e30f;
    }
    block_ranges_.flush();
  }
  command_pool_ = vulkan::CommandPool(context);
  sampler_ = vulkan::Sampler(context, VK_FILTER_LINEAR, VK_SAMPLER_ADDRESS_MODE_CLAMP_TO_EDGE);

  // 2. Timestamps, when the queue family has them.
  std::uint32_t family_count = 0;
  vkGetPhysicalDeviceQueueFamilyProperties(context.physical_device(), &family_count, nullptr);
  std::vector<VkQueueFamilyProperties> families(family_count);
  vkGetPhysicalDeviceQueueFamilyProperties(context.physical_device(), &family_count,
                                           families.data());
  if (context.queue_family() < family_count &&
      families[context.queue_family()].timestampValidBits > 0 &&
      context.limits().timestampPeriod > 0) {
    VkQueryPoolCreateInfo info{VK_STRUCTURE_TYPE_QUERY_POOL_CREATE_INFO};
    info.queryType = VK_QUERY_TYPE_TIMESTAMP;
    info.queryCount = 2 * ring;
    vulkan::check(vkCreateQueryPool(context.device(), &info, nullptr, &timestamps_),
                  "vkCreateQueryPool");
    timestamp_period_ns_ = context.limits().timestampPeriod;
  }

  // 3. The ring.
  const std::vector<VkCommandBuffer> commands = command_pool_.allocate(ring);
  for (std::uint32_t i = 0; i < ring; ++i) {
    auto entry = std::make_unique<Entry>();
    entry->fence = vulkan::Fence(context, true);
    entry->commands = commands[i];
    entry->set = descriptor_pool_.allocate(set_layout_.handle());
    entry->ranges_set = descriptor_pool_.allocate(ranges_layout_.handle());
    entry->index = i;
    ring_.push_back(std::move(entry));
  }
  create_output();
}

Raycaster::~Raycaster() {
  // Nothing may be destroyed while a frame still uses it.
  try {
    wait_all();
  } catch (...) {
    context_.wait_idle();
  }
  if (timestamps_ != VK_NULL_HANDLE) vkDestroyQueryPool(context_.device(), timestamps_, nullptr);
}

VkFormat Raycaster::output_format() const {
  return vk_format(options_.output);
}

void Raycaster::create_output() {
  vulkan::ImageDesc desc;
  desc.type = VK_IMAGE_TYPE_2D;
  desc.format = vk_format(options_.output);
  desc.extent = {static_cast<std::uint32_t>(options_.width),
                 static_cast<std::uint32_t>(options_.height), 1};
  desc.usage =
      VK_IMAGE_USAGE_STORAGE_BIT | VK_IMAGE_USAGE_TRANSFER_SRC_BIT | VK_IMAGE_USAGE_SAMPLED_BIT;
  output_ = vulkan::Image(context_, desc);
  const VkImage image = output_.handle();
  context_.submit_and_wait([&](VkCommandBuffer cb) {
    vulkan::image_barrier(cb, image, VK_IMAGE_LAYOUT_UNDEFINED, VK_IMAGE_LAYOUT_GENERAL,
                          VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, 0,
                          VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT);
  });
}

void Raycaster::resize(int width, int height) {
  if (width < 1 || height < 1)
    throw std::invalid_argument("Raycaster::resize: expected at least 1x1, found " +
                                size_text(width, height));
  if (width == options_.width && height == options_.height) return;
  wait_all();
  context_.wait_idle();  // frames recorded by a caller (record()) too
  options_.width = width;
  options_.height = height;
  create_output();
}

Raycaster::Entry& Raycaster::prepare(const FrameInput& input) {
  // 1. Validate everything the shader trusts (indices, levels, sizes).
  if (!input.transfer) throw std::invalid_argument("Raycaster: no transfer function");
  const player::OrbitCamera& camera = input.camera;
  if (camera.width != options_.width || camera.height != options_.height)
    throw std::invalid_argument("Raycaster: the camera is " +
                                size_text(camera.width, camera.height) + ", the output " +
                                size_text(options_.width, options_.height) + " (resize first)");
  const cpu_render::RenderOptions& o = input.options;
  if (!(o.step > 0 && std::isfinite(o.step)) ||
      !(o.reference_step > 0 && std::isfinite(o.reference_step)))
    throw std::invalid_argument("Raycaster: expected step and reference step > 0, found " +
                                format::number_text(o.step) + " and " +
                                format::number_text(o.reference_step));
  if (o.max_step_doublings > max_step_doublings)
    throw std::invalid_argument("Raycaster: expected max_step_doublings ≤ " +
                                std::to_string(max_step_doublings) + ", found " +
                                std::to_string(o.max_step_doublings));
  cpu_render::validate_svo({input.svo_nodes, input.svo_leaves}, atlas_.slot_count(),
                           input.geometry);
  if (input.geometry.shape.size != atlas_.slot_size())
    throw std::invalid_argument("Raycaster: bricks of " +
                                std::to_string(input.geometry.shape.size) + "^3 in an atlas of " +
                                std::to_string(atlas_.slot_size()) + "^3 slots");
  const std::size_t leaf_count = input.svo_leaves.size() / VR_SVO_LEAF_WORDS;
  const bool histograms = !input.leaf_histograms.empty();
  if (histograms && input.leaf_histograms.size() != leaf_count)
    throw std::invalid_argument("Raycaster: expected one histogram per leaf record (" +
                                std::to_string(leaf_count) + "), found " +
                                std::to_string(input.leaf_histograms.size()));

  // 2. The next ring entry, once its previous frame completed.
  Entry& entry = *ring_[last_ticket_ % ring_.size()];
  if (entry.fenced) entry.fence.wait();
  entry.fenced = false;
  entry.ticket = ++last_ticket_;

  // 3. Parameters (raycast.comp's Params).
  const double step_ratio = o.step / o.reference_step;
  // tf_step_ratio_ starts at 0, never a valid ratio: the first frame always computes these.
  if (step_ratio != tf_step_ratio_ || !(*input.transfer == tf_source_)) {
    tf_source_ = *input.transfer;
    tf_step_ratio_ = step_ratio;
    tf_corrected_ = input.transfer->opacity_corrected(step_ratio);
    // The prefix count of visible entries: entries i..j hold a visible one iff prefix[j + 1] ≠
    // prefix[i] (opacity correction keeps zero opacities zero).
    const std::vector<cpu_render::Rgba>& table = tf_corrected_.table();
    visible_prefix_.assign(table.size() + 1, 0);
    for (std::size_t i = 0; i < table.size(); ++i)
      visible_prefix_[i + 1] = visible_prefix_[i] + (table[i][3] > 0 ? 1u : 0u);
  }
  const cpu_render::TransferFunction& tf = tf_corrected_;
  Params p{};
  const glm::dvec3 eye = camera.eye();
  const auto [forward, right, up] = camera.basis();
  const auto put = [](float* dst, glm::dvec3 v, double w) {
    dst[0] = static_cast<float>(v.x);
    dst[1] = static_cast<float>(v.y);
    dst[2] = static_cast<float>(v.z);
    dst[3] = static_cast<float>(w);
  };
  put(p.eye_step, eye, o.step);
  put(p.forward_tan, forward, std::tan(0.5 * camera.fov_y));
  put(p.right_aspect, right, double(camera.width) / double(camera.height));
  put(p.up_termination, up, o.termination_alpha);
  const bool unorm = atlas_.format() == vulkan::AtlasFormat::r16_unorm;
  const double value_lo = unorm ? double(atlas_.value_min()) : 0.0;
  const double value_scale = unorm ? double(atlas_.value_max()) - double(atlas_.value_min()) : 1.0;
  put(p.background_lo, {o.background[0], o.background[1], o.background[2]}, value_lo);
  const VkExtent3D extent = atlas_.image().desc().extent;
  put(p.inv_extent_scale, {1.0 / extent.width, 1.0 / extent.height, 1.0 / extent.depth},
      value_scale);
  const auto& dims = input.geometry.dims;
  put(p.dims_tf_lo, {double(dims[0]), double(dims[1]), double(dims[2])}, tf.lo());
  const auto entries = static_cast<std::uint32_t>(tf.entry_count());
  p.tf_scale_entries[0] =
      static_cast<float>(double(entries - 1) / (double(tf.hi()) - double(tf.lo())));
  p.tf_scale_entries[1] = static_cast<float>(entries);
  p.tf_scale_entries[2] = static_cast<float>(o.max_step_doublings);  // exact: ≤ 16
  p.size_levels[0] = static_cast<std::uint32_t>(camera.width);
  p.size_levels[1] = static_cast<std::uint32_t>(camera.height);
  p.size_levels[2] = input.geometry.levels;
  p.size_levels[3] = (histograms ? flag_histograms : 0) | (fetch_filter_ ? flag_fetch_filter : 0) |
                     (input.skip_invisible_blocks ? flag_block_skip : 0) |
                     (input.feedback ? flag_feedback : 0);
  p.grid_mask[0] = atlas_.grid().x;
  p.grid_mask[1] = atlas_.grid().y;
  const std::uint64_t visible =
      histograms ? input.transfer->visible_bins(input.histogram_range[0], input.histogram_range[1])
                 : ~std::uint64_t{0};
  p.grid_mask[2] = static_cast<std::uint32_t>(visible);
  p.grid_mask[3] = static_cast<std::uint32_t>(visible >> 32);

  // 4. Buffers (grown as needed) and their descriptors.
  const VkBufferUsageFlags storage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT;
  const VkMemoryPropertyFlags device_local = VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT;
  ensure(context_, entry.params, sizeof(Params), storage, device_local);
  ensure(context_, entry.nodes, input.svo_nodes.size_bytes(), storage, device_local);
  ensure(context_, entry.leaves, input.svo_leaves.size_bytes(), storage, device_local);
  ensure(context_, entry.histograms, input.leaf_histograms.size_bytes(), storage, device_local);
  ensure(context_, entry.transfer, std::size_t{entries} * sizeof(cpu_render::Rgba), storage,
         device_local);
  upload(entry.params, &p, sizeof p);
  upload(entry.nodes, input.svo_nodes.data(), input.svo_nodes.size_bytes());
  upload(entry.leaves, input.svo_leaves.data(), input.svo_leaves.size_bytes());
  upload(entry.histograms, input.leaf_histograms.data(), input.leaf_histograms.size_bytes());
  static_assert(sizeof(cpu_render::Rgba) == 16);
  upload(entry.transfer, tf.table().data(), tf.table().size() * sizeof(cpu_render::Rgba));
  ensure(context_, entry.visible_prefix, visible_prefix_.size() * 4, storage, device_local);
  upload(entry.visible_prefix, visible_prefix_.data(), visible_prefix_.size() * 4);
  // Slots whose block ranges this frame recomputes (checked: the shader indexes with them).
  for (const std::uint32_t slot : input.changed_slots)
    if (slot >= atlas_.slot_count())
      throw std::invalid_argument("Raycaster: changed slot " + std::to_string(slot) + " of " +
                                  std::to_string(atlas_.slot_count()));
  entry.changed = static_cast<std::uint32_t>(input.changed_slots.size());
  const std::uint32_t range_params[4] = {atlas_.grid().x, atlas_.grid().y, entry.changed, 0};
  ensure(context_, entry.ranges_params, sizeof range_params, storage, device_local);
  upload(entry.ranges_params, range_params, sizeof range_params);
  ensure(context_, entry.changed_slots, input.changed_slots.size_bytes(), storage, device_local);
  upload(entry.changed_slots, input.changed_slots.data(), input.changed_slots.size_bytes());
  const VkDevice device = context_.device();
  vulkan::write_storage_buffer(device, entry.set, 0, entry.params.handle());
  vulkan::write_storage_buffer(device, entry.set, 1, entry.nodes.handle());
  vulkan::write_storage_buffer(device, entry.set, 2, entry.leaves.handle());
  vulkan::write_storage_buffer(device, entry.set, 3, entry.histograms.handle());
  vulkan::write_storage_buffer(device, entry.set, 4, entry.transfer.handle());
  vulkan::write_sampled_image(device, entry.set, 5, atlas_.view(), sampler_.handle());
  vulkan::write_storage_image(device, entry.set, 6, output_.view());
  vulkan::write_storage_buffer(device, entry.set, 7, block_ranges_.handle());
  vulkan::write_storage_buffer(device, entry.set, 8, entry.visible_prefix.handle());
  // The feedback table (bound always: the shader declares it), cleared by the frame's commands,
  // in device memory where the shader's atomics are cheap (not across the bus to host memory on a
  // discrete GPU), and copied to a host-cached buffer after the dispatch.
  entry.has_feedback = input.feedback;
  entry.feedback_entries = input.feedback ? VR_SVO_FEEDBACK_ENTRIES * leaf_count : 0;
  const VkDeviceSize table_bytes =
      std::max<VkDeviceSize>(VkDeviceSize{4} * entry.feedback_entries, 16);
  if (entry.feedback_table.handle() == VK_NULL_HANDLE || entry.feedback_table.size() < table_bytes)
    entry.feedback_table = vulkan::Buffer(
        context_, std::max(table_bytes, 2 * entry.feedback_table.size()),
        storage | VK_BUFFER_USAGE_TRANSFER_DST_BIT | VK_BUFFER_USAGE_TRANSFER_SRC_BIT, 0,
        VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
  ensure(context_, entry.feedback, table_bytes, VK_BUFFER_USAGE_TRANSFER_DST_BIT,
         VK_MEMORY_PROPERTY_HOST_CACHED_BIT);
  vulkan::write_storage_buffer(device, entry.set, 9, entry.feedback_table.handle());
  vulkan::write_storage_buffer(device, entry.ranges_set, 0, entry.ranges_params.handle());
  vulkan::write_storage_buffer(device, entry.ranges_set, 1, entry.changed_slots.handle());
  vulkan::write_storage_buffer(device, entry.ranges_set, 2, block_ranges_.handle());
  vulkan::write_sampled_image(device, entry.ranges_set, 3, atlas_.view(), sampler_.handle());
  entry.width = options_.width;
  entry.height = options_.height;
  entry.format = options_.output;
  entry.has_readback = false;
  entry.timed = false;
  return entry;
}

void Raycaster::record_commands(VkCommandBuffer cb, Entry& entry, bool readback) {
  // 0. The feedback table starts at 0 (made visible to the shader by the barrier below).
  if (entry.feedback_entries > 0)
    vkCmdFillBuffer(cb, entry.feedback_table.handle(), 0, VkDeviceSize{4} * entry.feedback_entries,
                    0);
  // 1. After every earlier compute and transfer command on the queue: the atlas decoder's slot
  //    writes, the previous frame's copy or blit of the output image.
  vulkan::memory_barrier(cb, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
                         VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT,
                         VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                         VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT);
  const bool timed = timestamps_ != VK_NULL_HANDLE && entry.fenced;
  if (timed) {
    vkCmdResetQueryPool(cb, timestamps_, 2 * entry.index, 2);
    vkCmdWriteTimestamp(cb, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, timestamps_, 2 * entry.index);
  }
  // 2. The block ranges of the slots written since the previous frame, one workgroup per slot.
  if (entry.changed > 0) {
    vkCmdBindPipeline(cb, VK_PIPELINE_BIND_POINT_COMPUTE, ranges_pipeline_.handle());
    vkCmdBindDescriptorSets(cb, VK_PIPELINE_BIND_POINT_COMPUTE, ranges_pipeline_.layout(), 0, 1,
                            &entry.ranges_set, 0, nullptr);
    vkCmdDispatch(cb, entry.changed, 1, 1);
    vulkan::memory_barrier(cb, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
                           VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_READ_BIT);
  }
  // 3. One invocation per pixel.
  vkCmdBindPipeline(cb, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline_.handle());
  vkCmdBindDescriptorSets(cb, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline_.layout(), 0, 1, &entry.set,
                          0, nullptr);
  vkCmdDispatch(cb, (static_cast<std::uint32_t>(entry.width) + local_size - 1) / local_size,
                (static_cast<std::uint32_t>(entry.height) + local_size - 1) / local_size, 1);
  if (timed)
    vkCmdWriteTimestamp(cb, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, timestamps_, 2 * entry.index + 1);
  entry.timed = timed;
  // 4. The output's and the feedback table's writes visible to copies and blits; the table's copy
  //    to the host.
  vulkan::memory_barrier(cb, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
                         VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_READ_BIT);
  if (entry.feedback_entries > 0) {
    const VkBufferCopy region{0, 0, VkDeviceSize{4} * entry.feedback_entries};
    vkCmdCopyBuffer(cb, entry.feedback_table.handle(), entry.feedback.handle(), 1, &region);
    vulkan::memory_barrier(cb, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
                           VK_PIPELINE_STAGE_HOST_BIT, VK_ACCESS_HOST_READ_BIT);
  }
  // 5. Optionally a copy to the entry's host buffer.
  if (readback) {
    const VkDeviceSize bytes = VkDeviceSize{texel_bytes(entry.format)} *
                               static_cast<VkDeviceSize>(entry.width) *
                               static_cast<VkDeviceSize>(entry.height);
    ensure(context_, entry.readback, bytes, VK_BUFFER_USAGE_TRANSFER_DST_BIT,
           VK_MEMORY_PROPERTY_HOST_CACHED_BIT);
    VkBufferImageCopy region{};
    region.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
    region.imageExtent = {static_cast<std::uint32_t>(entry.width),
                          static_cast<std::uint32_t>(entry.height), 1};
    // The output leaves GENERAL only for the copy (the layout copies are fastest in).
    const VkImage image = output_.handle();
    vulkan::image_barrier(cb, image, VK_IMAGE_LAYOUT_GENERAL, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL,
                          VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
                          VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_READ_BIT);
    vkCmdCopyImageToBuffer(cb, image, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, entry.readback.handle(),
                           1, &region);
    vulkan::image_barrier(cb, image, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, VK_IMAGE_LAYOUT_GENERAL,
                          VK_PIPELINE_STAGE_TRANSFER_BIT, 0,
                          VK_PIPELINE_STAGE_TRANSFER_BIT | VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                          VK_ACCESS_TRANSFER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT);
    vulkan::memory_barrier(cb, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
                           VK_PIPELINE_STAGE_HOST_BIT, VK_ACCESS_HOST_READ_BIT);
    entry.has_readback = true;
  }
}

Ticket Raycaster::render(const FrameInput& input, bool readback) {
  Entry& entry = prepare(input);
  entry.fenced = true;
  vulkan::check(vkResetCommandBuffer(entry.commands, 0), "vkResetCommandBuffer");
  vulkan::begin_commands(entry.commands);
  record_commands(entry.commands, entry, readback);
  vulkan::end_commands(entry.commands);
  entry.fence.reset();
  VkSubmitInfo submit{VK_STRUCTURE_TYPE_SUBMIT_INFO};
  submit.commandBufferCount = 1;
  submit.pCommandBuffers = &entry.commands;
  try {
    context_.submit(submit, entry.fence.handle());
  } catch (...) {
    entry.fenced = false;  // never submitted: the fence will not signal
    throw;
  }
  return entry.ticket;
}

Ticket Raycaster::record(VkCommandBuffer commands, const FrameInput& input) {
  Entry& entry = prepare(input);
  record_commands(commands, entry, false);
  return entry.ticket;
}

const Raycaster::Entry& Raycaster::entry_of(Ticket ticket, const char* what) const {
  const Entry& entry = *ring_[(ticket - 1) % ring_.size()];
  if (ticket == 0 || entry.ticket != ticket || !entry.fenced)
    throw std::invalid_argument(std::string("Raycaster::") + what + ": frame " +
                                std::to_string(ticket) +
                                " is not a render() frame still in the ring");
  return entry;
}

bool Raycaster::poll(Ticket ticket) const {
  if (ticket == 0) return true;
  const Entry& entry = *ring_[(ticket - 1) % ring_.size()];
  if (entry.ticket != ticket || !entry.fenced) return true;  // older: its entry was reused
  return entry.fence.signaled();
}

void Raycaster::wait(Ticket ticket) const {
  if (ticket == 0) return;
  const Entry& entry = *ring_[(ticket - 1) % ring_.size()];
  if (entry.ticket == ticket && entry.fenced) entry.fence.wait();
}

void Raycaster::wait_all() const {
  for (const auto& entry : ring_)
    if (entry->fenced) entry->fence.wait();
}

cpu_render::RgbaImage Raycaster::read_back(Ticket ticket) const {
  const Entry& entry = entry_of(ticket, "read_back");
  if (!entry.has_readback)
    throw std::invalid_argument("Raycaster::read_back: frame " + std::to_string(ticket) +
                                " was rendered without readback");
  entry.fence.wait();
  entry.readback.invalidate();
  cpu_render::RgbaImage image;
  image.width = entry.width;
  image.height = entry.height;
  const std::size_t values =
      4 * static_cast<std::size_t>(entry.width) * static_cast<std::size_t>(entry.height);
  image.rgba.resize(values);
  if (entry.format == OutputFormat::rgba8_unorm) {
    const auto* bytes = reinterpret_cast<const std::uint8_t*>(entry.readback.mapped());
    for (std::size_t i = 0; i < values; ++i) image.rgba[i] = static_cast<float>(bytes[i]) / 255.0f;
  } else {
    std::vector<std::uint16_t> halves(values);
    std::memcpy(halves.data(), entry.readback.mapped(), values * sizeof(std::uint16_t));
    for (std::size_t i = 0; i < values; ++i) image.rgba[i] = vulkan::half_to_float(halves[i]);
  }
  return image;
}

std::vector<std::uint32_t> Raycaster::feedback(Ticket ticket) const {
  const Entry& entry = entry_of(ticket, "feedback");
  if (!entry.has_feedback)
    throw std::invalid_argument("Raycaster::feedback: frame " + std::to_string(ticket) +
                                " was rendered without FrameInput::feedback");
  entry.fence.wait();
  entry.feedback.invalidate();
  std::vector<std::uint32_t> table(entry.feedback_entries);  // empty for an SVO without leaves
  if (!table.empty())
    std::memcpy(table.data(), entry.feedback.mapped(), table.size() * sizeof(std::uint32_t));
  return table;
}

bool Raycaster::has_feedback(Ticket ticket) const {
  if (ticket == 0) return false;
  const Entry& entry = *ring_[(ticket - 1) % ring_.size()];
  return entry.ticket == ticket && entry.fenced && entry.has_feedback;
}

std::optional<double> Raycaster::gpu_milliseconds(Ticket ticket) const {
  const Entry& entry = entry_of(ticket, "gpu_milliseconds");
  if (!entry.timed) return std::nullopt;
  entry.fence.wait();
  std::uint64_t stamps[2] = {0, 0};
  vulkan::check(vkGetQueryPoolResults(context_.device(), timestamps_, 2 * entry.index, 2,
                                      sizeof stamps, stamps, sizeof(std::uint64_t),
                                      VK_QUERY_RESULT_64_BIT | VK_QUERY_RESULT_WAIT_BIT),
                "vkGetQueryPoolResults");
  return double(stamps[1] - stamps[0]) * timestamp_period_ns_ * 1e-6;
}

}  // namespace volreel::vulkan_render
