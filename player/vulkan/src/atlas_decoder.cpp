// atlas_decoder.cpp: staging ring, batch layout and submission of the decode compute pass
// (see atlas_decoder.hpp and shaders/decode/decode_bricks.comp).
#include "volreel/vulkan/atlas_decoder.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <exception>
#include <stdexcept>
#include <string>

#include "volreel/format/brick_decode.h"
#include "volreel/format/decoder.hpp"
#include "volreel/format/error.hpp"
#include "volreel/player/atlas_layout.h"
#include "volreel_decode_bricks_r16_spv.h"
#include "volreel_decode_bricks_r16f_spv.h"
#include "volreel_decode_bricks_rows_r16_spv.h"
#include "volreel_decode_bricks_rows_r16f_spv.h"

namespace volreel::vulkan {

namespace {

// Record kinds, as in decode_bricks.comp.
constexpr std::uint32_t kind_ksvd = 0, kind_constant = 1, kind_raw = 2;
constexpr std::uint64_t record_bytes = 16;  // {payload word offset, slot, kind, payload words}
/// A raw brick's float32 values, and (host kernel) its 16-bit texels, for bricks of `shape`.
std::uint64_t raw_bytes(format::BrickShape shape) {
  return std::uint64_t{shape.voxels()} * 4;
}
std::uint64_t texel_bytes(format::BrickShape shape) {
  return std::uint64_t{shape.voxels()} * 2;
}
constexpr std::uint32_t max_bricks_per_dispatch = 65535;  // maxComputeWorkGroupCount[0] minimum
/// The most atoms the buffer_copy kernel's texel buffer holds: a learned dictionary of up to 1024
/// atoms with its 215 DCT atoms, rounded up.
constexpr std::uint32_t max_copy_atoms = 2048;
// decode_bricks_rows.comp: a decoded brick of S³ voxels is n = S/6 columns (one per block x),
// each S×S rows of 8 texels (6 voxels and 2 unused), copied into the slot with bufferRowLength 8.
constexpr std::uint32_t column_row_texels = 8;
std::uint64_t decoded_column_bytes(format::BrickShape shape) {
  return std::uint64_t{column_row_texels} * shape.size * shape.size * 2;
}
std::uint64_t decoded_brick_bytes(format::BrickShape shape) {
  return decoded_column_bytes(shape) * shape.blocks_per_axis();
}
// ... and an atom is 36 rows of 6 values padded to 8 floats (two RGBA32F texels per row).
constexpr std::uint32_t atom_row_floats = 8;
constexpr std::uint64_t copy_atom_floats =
    std::uint64_t{atom_row_floats} * VR_BLOCK_LENGTH / VR_BLOCK_SIZE;

std::uint32_t kind_of(const BrickUpload& brick) {
  if (brick.payload.size() == 4) return kind_constant;
  return brick.codec == format::Codec::ksvd ? kind_ksvd : kind_raw;
}

/// decode_bricks.comp: {grid_x, grid_y, value_min, inv_range}; decode_bricks_rows.comp:
/// {first_record, unused, value_min, inv_range}.
struct PushConstants {
  std::uint32_t grid_x_or_first_record, grid_y;
  float value_min, inv_range;
};
static_assert(sizeof(PushConstants) == 16);

/// lavapipe (llvmpipe) ends any shader loop after 65535 iterations (gallivm's guard against
/// endless loops), and both decode kernels walk a brick's blocks and codes in one loop nest of
/// one workgroup: on a CPU device, a ksvd brick whose blocks and codes pass this many is decoded
/// on the CPU and uploaded as values (a brick of 36³ never does: 216·(1 + 255) < 60000).
constexpr std::uint64_t cpu_device_loop_limit = 60000;

/// The checks of the CPU reference decoder (format::check_ksvd_payload) on a payload that is not
/// read there: header finite, mean bits, length against the sparsities, atom indices < K.
/// Returns a ksvd payload's code count (0 for the other kinds).
std::uint64_t validate_upload(const BrickUpload& brick, std::size_t index, std::uint32_t atom_count,
                              format::BrickShape shape) {
  const std::string name = "brick upload " + std::to_string(index);
  const auto fail = [&](std::uint64_t offset, const std::string& expected,
                        const std::string& found) {
    throw format::FormatError(name, offset, expected, found);
  };
  const std::span<const std::byte> bytes = brick.payload;
  const auto word = [&](std::size_t i) {
    vr_uint w;
    std::memcpy(&w, bytes.data() + 4 * i, 4);
    return w;
  };
  const std::uint32_t kind = kind_of(brick);
  if (kind == kind_constant) {
    if (!std::isfinite(vr_as_float(word(0)))) fail(0, "a finite constant", "NaN or infinity");
    return 0;
  }
  if (kind == kind_raw) return 0;  // decoded (and checked) by format::decode_payload
  if (atom_count == 0)
    throw std::invalid_argument(name +
                                ": a ksvd brick but no dictionary (AtlasDecoder::set_dictionary)");
  return format::check_ksvd_payload(bytes, atom_count, shape, name, 0).codes;
}

}  // namespace

const char* kernel_name(DecoderOptions::Kernel kernel) {
  switch (kernel) {
    case DecoderOptions::Kernel::image_store:
      return "image_store (GPU: decode_bricks.comp)";
    case DecoderOptions::Kernel::buffer_copy:
      return "buffer_copy (GPU: decode_bricks_rows.comp, vkCmdCopyBufferToImage)";
    case DecoderOptions::Kernel::host:
      return "host (CPU reference decoder, vkCmdCopyBufferToImage)";
    default:
      return "automatic";
  }
}

struct AtlasDecoder::RingEntry {
  Buffer staging;  ///< host-visible: records, then payloads
  Buffer device;   ///< device-local copy the shader reads, unless staging is device-local itself
  VkCommandBuffer commands = VK_NULL_HANDLE;
  Fence fence;  ///< signaled when the entry is free
  VkDescriptorSet set = VK_NULL_HANDLE;
  Ticket ticket = 0;  ///< the last submission that used this entry
  const Buffer& shader_buffer() const { return device.handle() ? device : staging; }
};

std::uint64_t AtlasDecoder::upload_bytes(const BrickUpload& brick, DecoderOptions::Kernel kernel,
                                         format::BrickShape shape, bool decoded_on_cpu) {
  if (kernel == DecoderOptions::Kernel::host) return texel_bytes(shape);
  if (decoded_on_cpu) return record_bytes + raw_bytes(shape);
  switch (kind_of(brick)) {
    case kind_constant:
      return record_bytes + 4;
    case kind_raw:
      return record_bytes + raw_bytes(shape);
    default:  // and a zero word after a ksvd payload: the look-ahead of its last Rice code
      return record_bytes + (brick.payload.size() + 3) / 4 * 4 +
             (kind_of(brick) == kind_ksvd ? 4 : 0);
  }
}

AtlasDecoder::AtlasDecoder(const Context& context, const Atlas& atlas,
                           const DecoderOptions& options)
    : context_(context), atlas_(atlas), shape_{atlas.slot_size()}, options_(options) {
  cpu_device_ = context.properties().deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU;
  // 1. Budget: whole words, room for a zfp brick, within the largest storage buffer binding.
  options_.upload_budget_bytes = options_.upload_budget_bytes / 4 * 4;
  if (options_.upload_budget_bytes < (std::uint64_t{1} << 20) || options_.ring_size == 0)
    throw std::invalid_argument(
        "AtlasDecoder: upload budget must be >= 1 MiB and the ring >= 1 buffer");
  options_.upload_budget_bytes = std::min<std::uint64_t>(
      options_.upload_budget_bytes, context.limits().maxStorageBufferRange / 4 * 4);
  // 2. Kernel and pipeline: batch, dictionary, atlas (image_store) or decoded bricks
  //    (buffer_copy).
  //    buffer_copy reads the dictionary as a texel buffer of up to max_copy_atoms atoms · 72
  //    texels.
  kernel_ = options_.kernel;
  const bool texels_fit =
      context.limits().maxTexelBufferElements >= max_copy_atoms * copy_atom_floats / 4;
  if (kernel_ == DecoderOptions::Kernel::automatic)
    kernel_ = context.properties().deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU
                  ? DecoderOptions::Kernel::host
                  : DecoderOptions::Kernel::image_store;
  if (kernel_ == DecoderOptions::Kernel::buffer_copy && !texels_fit)
    throw std::invalid_argument("AtlasDecoder: the buffer_copy kernel needs texel buffers of " +
                                std::to_string(max_copy_atoms * copy_atom_floats / 4) +
                                " elements");
  // The host kernel keeps the pipeline of image_store (cheap to build, never dispatched), so that
  // every descriptor stays valid whichever kernel runs.
  const bool copy = kernel_ == DecoderOptions::Kernel::buffer_copy;
  const bool unorm = atlas.format() == AtlasFormat::r16_unorm;
  const VkDescriptorType atoms_type =
      copy ? VK_DESCRIPTOR_TYPE_UNIFORM_TEXEL_BUFFER : VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
  const VkDescriptorType output_type =
      copy ? VK_DESCRIPTOR_TYPE_STORAGE_BUFFER : VK_DESCRIPTOR_TYPE_STORAGE_IMAGE;
  const VkDescriptorSetLayoutBinding bindings[] = {
      {0, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, VK_SHADER_STAGE_COMPUTE_BIT, nullptr},
      {1, atoms_type, 1, VK_SHADER_STAGE_COMPUTE_BIT, nullptr},
      {2, output_type, 1, VK_SHADER_STAGE_COMPUTE_BIT, nullptr}};
  set_layout_ = DescriptorSetLayout(context, bindings);
  if (copy)
    shader_ = unorm ? ShaderModule(context, volreel_decode_bricks_rows_r16_spv)
                    : ShaderModule(context, volreel_decode_bricks_rows_r16f_spv);
  else
    shader_ = unorm ? ShaderModule(context, volreel_decode_bricks_r16_spv)
                    : ShaderModule(context, volreel_decode_bricks_r16f_spv);
  const VkDescriptorSetLayout set_layout = set_layout_.handle();
  const std::uint32_t blocks_per_axis = shape_.blocks_per_axis();
  pipeline_ = ComputePipeline(context, shader_, {&set_layout, 1}, sizeof(PushConstants),
                              {&blocks_per_axis, 1});
  const VkDescriptorPoolSize sizes[] = {
      {VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 2 * options_.ring_size},
      {copy ? VK_DESCRIPTOR_TYPE_UNIFORM_TEXEL_BUFFER : VK_DESCRIPTOR_TYPE_STORAGE_BUFFER,
       options_.ring_size},
      {VK_DESCRIPTOR_TYPE_STORAGE_IMAGE, options_.ring_size}};
  descriptor_pool_ = DescriptorPool(context, sizes, options_.ring_size);
  if (copy) {
    options_.bricks_per_copy = std::clamp<std::uint32_t>(
        options_.bricks_per_copy, 1,
        static_cast<std::uint32_t>(std::min<std::uint64_t>(
            {max_bricks_per_dispatch,
             context.limits().maxStorageBufferRange / decoded_brick_bytes(shape_),
             std::max<std::uint64_t>(1,
                                     (std::uint64_t{32} << 20) / decoded_brick_bytes(shape_))})));
    decoded_ =
        Buffer(context, std::uint64_t{options_.bricks_per_copy} * decoded_brick_bytes(shape_),
               VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_SRC_BIT,
               VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
  }
  command_pool_ = CommandPool(context);
  // 3. A placeholder dictionary (one atom) until set_dictionary: every binding stays valid.
  atoms_ = Buffer(context, 4 * copy_atom_floats,
                  VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_UNIFORM_TEXEL_BUFFER_BIT |
                      VK_BUFFER_USAGE_TRANSFER_DST_BIT,
                  VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
  make_atoms_view();
  context.submit_and_wait([&](VkCommandBuffer commands) {
    vkCmdFillBuffer(commands, atoms_.handle(), 0, VK_WHOLE_SIZE, 0);
    memory_barrier(commands, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
                   VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_READ_BIT);
  });
  // 4. The staging ring.
  const std::vector<VkCommandBuffer> commands = command_pool_.allocate(options_.ring_size);
  ring_.resize(options_.ring_size);
  for (std::uint32_t i = 0; i < options_.ring_size; ++i) {
    RingEntry& e = ring_[i];
    e.staging = Buffer(context, options_.upload_budget_bytes,
                       VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_SRC_BIT,
                       VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT,
                       VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
    if (!e.staging.device_local())
      e.device = Buffer(context, options_.upload_budget_bytes,
                        VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT,
                        VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
    e.commands = commands[i];
    e.fence = Fence(context, true);
    e.set = descriptor_pool_.allocate(set_layout);
    write_descriptors(e);
  }
}

AtlasDecoder::~AtlasDecoder() {
  // Nothing may be destroyed while the GPU still uses it; errors cannot leave a destructor.
  for (const RingEntry& e : ring_)
    if (e.fence.handle()) {
      VkFence fence = e.fence.handle();
      vkWaitForFences(context_.device(), 1, &fence, VK_TRUE, UINT64_MAX);
    }
}

void AtlasDecoder::write_descriptors(RingEntry& entry) const {
  const VkDevice device = context_.device();
  write_storage_buffer(device, entry.set, 0, entry.shader_buffer().handle());
  if (kernel_ == DecoderOptions::Kernel::buffer_copy) {
    const VkBufferView view = atoms_view_.get();
    VkWriteDescriptorSet write{VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET};
    write.dstSet = entry.set;
    write.dstBinding = 1;
    write.descriptorCount = 1;
    write.descriptorType = VK_DESCRIPTOR_TYPE_UNIFORM_TEXEL_BUFFER;
    write.pTexelBufferView = &view;
    vkUpdateDescriptorSets(device, 1, &write, 0, nullptr);
  } else {
    write_storage_buffer(device, entry.set, 1, atoms_.handle());
  }
  if (kernel_ == DecoderOptions::Kernel::buffer_copy)
    write_storage_buffer(device, entry.set, 2, decoded_.handle());
  else
    write_storage_image(device, entry.set, 2, atlas_.view());
}

void AtlasDecoder::make_atoms_view() {
  if (kernel_ != DecoderOptions::Kernel::buffer_copy) return;
  // K·72 texels (rows padded to 8 floats): at most max_copy_atoms·72, checked against
  // maxTexelBufferElements when the kernel was chosen.
  VkBufferViewCreateInfo info{VK_STRUCTURE_TYPE_BUFFER_VIEW_CREATE_INFO};
  info.buffer = atoms_.handle();
  info.format = VK_FORMAT_R32G32B32A32_SFLOAT;
  info.offset = 0;
  info.range = VK_WHOLE_SIZE;
  VkBufferView view = VK_NULL_HANDLE;
  check(vkCreateBufferView(context_.device(), &info, nullptr, &view), "vkCreateBufferView");
  atoms_view_ = detail::DeviceHandle<VkBufferView, vkDestroyBufferView>(context_.device(), view);
}

void AtlasDecoder::set_dictionary(const format::AtomTable& atoms) {
  const std::uint64_t values = std::uint64_t{atoms.count} * VR_BLOCK_LENGTH;
  const bool copy = kernel_ == DecoderOptions::Kernel::buffer_copy;
  const std::uint64_t floats = copy ? atoms.count * copy_atom_floats : values;
  if (atoms.count == 0 || atoms.values.size() < values)
    throw std::invalid_argument("AtlasDecoder::set_dictionary: " + std::to_string(atoms.count) +
                                " atoms need " + std::to_string(values) +
                                " values, the table has " + std::to_string(atoms.values.size()));
  if (atoms.count > (1u << VR_MAX_ATOM_BITS) || (copy && atoms.count > max_copy_atoms))
    throw std::invalid_argument("AtlasDecoder::set_dictionary: " + std::to_string(atoms.count) +
                                " atoms; the decoder holds at most " +
                                std::to_string(copy ? max_copy_atoms : 1u << VR_MAX_ATOM_BITS));
  wait_all();
  // The host kernel decodes every brick on the CPU; the others some, on CPU devices (submit).
  host_atoms_.assign(atoms.values.begin(),
                     atoms.values.begin() + static_cast<std::ptrdiff_t>(values));
  host_dct_basis_ = format::atom_table(host_atoms_, atoms.count).dct_basis;
  if (kernel_ == DecoderOptions::Kernel::host) {
    atom_count_ = atoms.count;
    return;
  }
  Buffer staging(context_, 4 * floats, VK_BUFFER_USAGE_TRANSFER_SRC_BIT,
                 VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT);
  if (copy) {  // rows of 6 values padded to 8
    auto* out = reinterpret_cast<float*>(staging.mapped());
    std::fill(out, out + floats, 0.0f);
    for (std::uint64_t v = 0; v < values; ++v)
      out[v / VR_BLOCK_SIZE * atom_row_floats + v % VR_BLOCK_SIZE] = atoms.values[v];
  } else {
    std::memcpy(staging.mapped(), atoms.values.data(), 4 * values);
  }
  Buffer table(context_, 4 * floats,
               VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_UNIFORM_TEXEL_BUFFER_BIT |
                   VK_BUFFER_USAGE_TRANSFER_DST_BIT,
               VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
  context_.submit_and_wait([&](VkCommandBuffer commands) {
    const VkBufferCopy region{0, 0, 4 * floats};
    vkCmdCopyBuffer(commands, staging.handle(), table.handle(), 1, &region);
    memory_barrier(commands, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
                   VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_READ_BIT);
  });
  atoms_view_.reset();
  atoms_ = std::move(table);
  make_atoms_view();
  atom_count_ = atoms.count;
  for (RingEntry& e : ring_) write_descriptors(e);
}

Ticket AtlasDecoder::submit(std::span<const BrickUpload> batch) {
  // 1. Check everything before anything is uploaded.
  slot_mark_.resize(atlas_.slot_count(), 0);
  decode_on_cpu_.resize(batch.size());
  ++submit_calls_;
  for (std::size_t i = 0; i < batch.size(); ++i) {
    if (batch[i].slot >= atlas_.slot_count())
      throw std::invalid_argument("brick upload " + std::to_string(i) + ": slot " +
                                  std::to_string(batch[i].slot) + " outside the atlas (" +
                                  std::to_string(atlas_.slot_count()) + " slots)");
    if (slot_mark_[batch[i].slot] == submit_calls_)
      throw std::invalid_argument("brick upload " + std::to_string(i) + ": slot " +
                                  std::to_string(batch[i].slot) + " named twice in one batch");
    slot_mark_[batch[i].slot] = submit_calls_;
    const std::uint64_t codes = validate_upload(batch[i], i, atom_count_, shape_);
    decode_on_cpu_[i] = cpu_device_ && codes + shape_.blocks() > cpu_device_loop_limit;
  }
  const auto bytes_of = [&](std::size_t i) {
    return upload_bytes(batch[i], kernel_, shape_, decode_on_cpu_[i] != 0);
  };
  const std::uint64_t budget = options_.upload_budget_bytes;
  std::size_t next = 0;
  while (next < batch.size()) {
    // 2. The next ring entry, once the GPU is done with it.
    RingEntry& entry = ring_[next_entry_];
    next_entry_ = (next_entry_ + 1) % ring_.size();
    entry.fence.wait();
    // 3. As many bricks as fit the staging buffer: records first, then the payloads.
    std::size_t end = next;
    std::uint64_t bytes = 0;
    while (end < batch.size() && end - next < max_bricks_per_dispatch &&
           bytes + bytes_of(end) <= budget)
      bytes += bytes_of(end++);
    if (end == next)
      throw std::invalid_argument(
          "brick upload " + std::to_string(next) + " needs " + std::to_string(bytes_of(next)) +
          " bytes, more than the upload budget of " + std::to_string(budget));
    const auto count = static_cast<std::uint32_t>(end - next);
    if (kernel_ == DecoderOptions::Kernel::host) {
      const std::span<const BrickUpload> chunk = batch.subspan(next, count);
      decode_on_host(chunk, next, reinterpret_cast<std::uint16_t*>(entry.staging.mapped()));
      entry.staging.flush(0, VK_WHOLE_SIZE);
      const VkCommandBuffer commands = entry.commands;
      begin_commands(commands);
      record_host_copies(commands, entry.staging.handle(), chunk);
      end_and_submit(entry);
      stats_.bricks += count;
      stats_.uploaded_bytes += bytes;
      next = end;
      continue;
    }
    auto* words = reinterpret_cast<std::uint32_t*>(entry.staging.mapped());
    std::uint32_t cursor = 4 * count;  // word offset of the next payload
    for (std::uint32_t i = 0; i < count; ++i) {
      const BrickUpload& brick = batch[next + i];
      const bool on_cpu = decode_on_cpu_[next + i] != 0;
      const std::uint32_t kind = on_cpu ? kind_raw : kind_of(brick);
      std::uint32_t payload_words = 0;
      if (kind == kind_raw) {
        // zfp, and ksvd bricks past a CPU device's loop limit: decoded on the CPU by the
        // reference decoder, uploaded as float32.
        const auto start = std::chrono::steady_clock::now();
        zfp_scratch_.resize(shape_.voxels());
        format::decode_payload(brick.payload, brick.codec, brick.zfp_accuracy,
                               {host_atoms_, atom_count_, host_dct_basis_}, shape_, zfp_scratch_,
                               "brick upload " + std::to_string(next + i), 0);
        stats_.cpu_zfp_seconds +=
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        payload_words = static_cast<std::uint32_t>(shape_.voxels());
        std::memcpy(words + cursor, zfp_scratch_.data(), raw_bytes(shape_));
      } else {
        payload_words = static_cast<std::uint32_t>(brick.payload.size() / 4);  // validated above
        std::memcpy(words + cursor, brick.payload.data(), 4 * std::size_t{payload_words});
      }
      const std::uint32_t padding = kind == kind_ksvd ? 1 : 0;  // see upload_bytes
      if (padding) words[cursor + payload_words] = 0;
      words[4 * i + 0] = cursor;
      words[4 * i + 1] = brick.slot;
      words[4 * i + 2] = kind;
      words[4 * i + 3] = payload_words;
      cursor += payload_words + padding;
    }
    entry.staging.flush(0, VK_WHOLE_SIZE);
    record_and_submit(entry, count, std::uint64_t{cursor} * 4);
    stats_.bricks += count;
    stats_.uploaded_bytes += std::uint64_t{cursor} * 4;
    next = end;
  }
  return last_ticket_;
}

void AtlasDecoder::record_and_submit(RingEntry& entry, std::uint32_t bricks, std::uint64_t bytes) {
  const VkCommandBuffer commands = entry.commands;
  begin_commands(commands);
  // 1. After all earlier compute and transfer work on this queue: earlier decodes of the same
  //    slots, readbacks, a ray caster sampling the slots this batch overwrites.
  memory_barrier(
      commands, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
      VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT,
      VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
      VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT);
  // 2. Staging → device-local batch buffer where they differ.
  if (entry.device.handle()) {
    const VkBufferCopy region{0, 0, bytes};
    vkCmdCopyBuffer(commands, entry.staging.handle(), entry.device.handle(), 1, &region);
    memory_barrier(commands, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
                   VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_READ_BIT);
  }
  // 3. The decode pass.
  vkCmdBindPipeline(commands, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline_.handle());
  vkCmdBindDescriptorSets(commands, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline_.layout(), 0, 1,
                          &entry.set, 0, nullptr);
  record_decode(commands, reinterpret_cast<const std::uint32_t*>(entry.staging.mapped()), bricks);
  // 4. The slots' new values visible to later compute reads (the ray caster) and copies.
  memory_barrier(commands, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
                 VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT,
                 VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
                 VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT |
                     VK_ACCESS_TRANSFER_READ_BIT | VK_ACCESS_TRANSFER_WRITE_BIT);
  end_and_submit(entry);
}

void AtlasDecoder::end_and_submit(RingEntry& entry) {
  const VkCommandBuffer commands = entry.commands;
  end_commands(commands);
  entry.fence.reset();
  VkSubmitInfo info{VK_STRUCTURE_TYPE_SUBMIT_INFO};
  info.commandBufferCount = 1;
  info.pCommandBuffers = &commands;
  context_.submit(info, entry.fence.handle());
  entry.ticket = ++last_ticket_;
  ++stats_.submissions;
}

void AtlasDecoder::record_decode(VkCommandBuffer commands, const std::uint32_t* records,
                                 std::uint32_t bricks) {
  const float inv_range = 1.0f / (atlas_.value_max() - atlas_.value_min());
  if (kernel_ == DecoderOptions::Kernel::image_store) {
    // One workgroup per brick, writing its slot.
    const PushConstants push{atlas_.grid().x, atlas_.grid().y, atlas_.value_min(), inv_range};
    vkCmdPushConstants(commands, pipeline_.layout(), VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof push,
                       &push);
    vkCmdDispatch(commands, bricks, 1, 1);
    return;
  }
  // buffer_copy: chunks of bricks_per_copy bricks decoded into decoded_, each copied into its
  // slots (`records`: the batch's records as submit wrote them).
  std::vector<VkBufferImageCopy>& regions = copy_regions_;
  for (std::uint32_t first = 0; first < bricks; first += options_.bricks_per_copy) {
    const std::uint32_t n = std::min(options_.bricks_per_copy, bricks - first);
    if (first != 0)  // the previous chunk's copy has read decoded_
      memory_barrier(commands, VK_PIPELINE_STAGE_TRANSFER_BIT, 0,
                     VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT);
    const PushConstants push{first, 0, atlas_.value_min(), inv_range};
    vkCmdPushConstants(commands, pipeline_.layout(), VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof push,
                       &push);
    vkCmdDispatch(commands, n, 1, 1);
    memory_barrier(commands, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
                   VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_READ_BIT);
    const std::uint32_t columns = shape_.blocks_per_axis(), size = shape_.size;
    regions.resize(std::size_t{n} * columns);
    for (std::uint32_t i = 0; i < n; ++i) {
      const VkOffset3D origin = atlas_.slot_origin(records[4 * (first + i) + 1]);
      for (std::uint32_t c = 0; c < columns; ++c) {
        VkBufferImageCopy& r = regions[std::size_t{i} * columns + c];
        r = {};
        r.bufferOffset =
            std::uint64_t{i} * decoded_brick_bytes(shape_) + c * decoded_column_bytes(shape_);
        r.bufferRowLength = column_row_texels;
        r.bufferImageHeight = size;
        r.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
        r.imageOffset = {origin.x + static_cast<std::int32_t>(c * VR_BLOCK_SIZE), origin.y,
                         origin.z};
        r.imageExtent = {VR_BLOCK_SIZE, size, size};
      }
    }
    copy_into_atlas(commands, decoded_.handle(), regions);
  }
}

void AtlasDecoder::copy_into_atlas(VkCommandBuffer commands, VkBuffer source,
                                   const std::vector<VkBufferImageCopy>& regions) const {
  // After all earlier compute and transfer work on the queue (a ray caster sampling these slots,
  // earlier writes to them). The atlas leaves GENERAL only for the copy (the layout copies are
  // fastest in), as in read_slots.
  const VkImage image = atlas_.image().handle();
  image_barrier(commands, image, VK_IMAGE_LAYOUT_GENERAL, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL,
                VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
                VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT,
                VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT);
  vkCmdCopyBufferToImage(commands, source, image, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL,
                         static_cast<std::uint32_t>(regions.size()), regions.data());
  image_barrier(commands, image, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, VK_IMAGE_LAYOUT_GENERAL,
                VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
                VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
                VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT |
                    VK_ACCESS_TRANSFER_READ_BIT | VK_ACCESS_TRANSFER_WRITE_BIT);
}

void AtlasDecoder::decode_on_host(std::span<const BrickUpload> bricks, std::size_t first,
                                  std::uint16_t* texels) {
  const auto start = std::chrono::steady_clock::now();
  const format::AtomTable atoms{host_atoms_, atom_count_, host_dct_basis_};
  const auto n = static_cast<std::ptrdiff_t>(bricks.size());
  std::exception_ptr error;  // the first bad payload's error, raised after the loop
  std::size_t error_index = bricks.size();
  // Two bricks at a time when they share a codec (format::decode_payloads reads their codes in
  // step).
  const std::size_t voxels = shape_.voxels();
#pragma omp parallel
  {
    std::vector<float> values(2 * voxels);
#pragma omp for schedule(dynamic, 1)
    for (std::ptrdiff_t p = 0; p < (n + 1) / 2; ++p) {
      const auto i = 2 * static_cast<std::size_t>(p);
      std::size_t count = std::min<std::size_t>(2, bricks.size() - i);
      if (count == 2 && bricks[i].codec != bricks[i + 1].codec) count = 1;
      for (std::size_t done = 0; done < 2 && i + done < bricks.size();) {
        format::PayloadJob jobs[2];
        for (std::size_t j = 0; j < count; ++j) {
          const BrickUpload& brick = bricks[i + done + j];
          jobs[j] = {brick.payload,
                     {values.data() + j * voxels, voxels},
                     "brick upload " + std::to_string(first + i + done + j),
                     0,
                     brick.zfp_accuracy};
        }
        try {
          format::decode_payloads({jobs, count}, bricks[i + done].codec, atoms, shape_);
          for (std::size_t j = 0; j < count; ++j)
            atlas_.values_to_texels(jobs[j].out, texels + (i + done + j) * voxels);
        } catch (...) {
#pragma omp critical(volreel_host_decode_error)
          // decode_payloads throws the first bad one's error; its index may be the pair's second
          // (pairs do not overlap, so the first error in batch order still wins).
          if (i + done < error_index) {
            error_index = i + done;
            error = std::current_exception();
          }
        }
        done += count;
      }
    }
  }
  stats_.cpu_decode_seconds +=
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (error) std::rethrow_exception(error);
}

void AtlasDecoder::record_host_copies(VkCommandBuffer commands, VkBuffer texels,
                                      std::span<const BrickUpload> bricks) {
  // Each brick's texels (S³, x fastest) into its slot.
  std::vector<VkBufferImageCopy>& regions = copy_regions_;
  regions.resize(bricks.size());
  for (std::size_t i = 0; i < bricks.size(); ++i) {
    VkBufferImageCopy& r = regions[i];
    r = {};
    r.bufferOffset = i * texel_bytes(shape_);
    r.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
    r.imageOffset = atlas_.slot_origin(bricks[i].slot);
    r.imageExtent = {shape_.size, shape_.size, shape_.size};
  }
  copy_into_atlas(commands, texels, regions);
}

bool AtlasDecoder::poll(Ticket ticket) const {
  for (const RingEntry& e : ring_)
    if (e.ticket != 0 && e.ticket <= ticket && !e.fence.signaled()) return false;
  return true;
}

void AtlasDecoder::wait(Ticket ticket) const {
  for (const RingEntry& e : ring_)
    if (e.ticket != 0 && e.ticket <= ticket) e.fence.wait();
}

std::vector<float> AtlasDecoder::read_slots(std::span<const std::uint32_t> slots) const {
  wait_all();
  const std::uint64_t slot_texels = shape_.voxels();
  constexpr std::size_t chunk = 64;  // slots per readback
  std::vector<float> values(slots.size() * slot_texels);
  if (slots.empty()) return values;
  Buffer readback(context_, std::min(chunk, slots.size()) * slot_texels * 2,
                  VK_BUFFER_USAGE_TRANSFER_DST_BIT,
                  VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT,
                  VK_MEMORY_PROPERTY_HOST_CACHED_BIT);
  for (std::size_t first = 0; first < slots.size(); first += chunk) {
    const std::size_t n = std::min(chunk, slots.size() - first);
    std::vector<VkBufferImageCopy> regions(n);
    for (std::size_t i = 0; i < n; ++i) {
      const std::uint32_t slot = slots[first + i];
      if (slot >= atlas_.slot_count())
        throw std::invalid_argument("read_slots: slot " + std::to_string(slot) +
                                    " outside the atlas");
      VkBufferImageCopy& r = regions[i];
      r.bufferOffset = i * slot_texels * 2;
      r.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
      r.imageOffset = atlas_.slot_origin(slot);
      r.imageExtent = {shape_.size, shape_.size, shape_.size};
    }
    context_.submit_and_wait([&](VkCommandBuffer commands) {
      // The atlas leaves GENERAL only for the copy (the layout copies are fastest in).
      const VkImage image = atlas_.image().handle();
      image_barrier(commands, image, VK_IMAGE_LAYOUT_GENERAL, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL,
                    VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
                    VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT,
                    VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_READ_BIT);
      vkCmdCopyImageToBuffer(commands, image, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL,
                             readback.handle(), static_cast<std::uint32_t>(n), regions.data());
      image_barrier(
          commands, image, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, VK_IMAGE_LAYOUT_GENERAL,
          VK_PIPELINE_STAGE_TRANSFER_BIT, 0,
          VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
          VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_READ_BIT);
      memory_barrier(commands, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
                     VK_PIPELINE_STAGE_HOST_BIT, VK_ACCESS_HOST_READ_BIT);
    });
    readback.invalidate();
    const auto* texels = reinterpret_cast<const std::uint16_t*>(readback.mapped());
    float* out = values.data() + first * slot_texels;
    for (std::size_t i = 0; i < n * slot_texels; ++i) out[i] = atlas_.texel_to_value(texels[i]);
  }
  return values;
}

}  // namespace volreel::vulkan
