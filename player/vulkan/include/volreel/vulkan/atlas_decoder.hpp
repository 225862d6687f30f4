// atlas_decoder.hpp: decodes batches of compressed bricks into atlas slots with a compute shader
// (MTV-Player §4.2): the batch's payloads go into a linear storage buffer with one record per
// brick {payload word offset, slot, kind, payload words}; the dictionary stays in a storage buffer
// for the dataset's life; one workgroup decodes one brick. Two kernels (DecoderOptions::Kernel):
// on GPUs the workgroup writes the slot with imageStore (shaders/decode/decode_bricks.comp); on CPU
// implementations (lavapipe) it writes 16-bit texels into a storage buffer that is then copied
// into the slots (shaders/decode/decode_bricks_rows.comp), several times faster there.
//
// Kinds: ksvd payloads are decoded on the GPU; 4-byte payloads (constant bricks) are filled
// without reading codes; zfp payloads are decoded on the CPU (format::decode_payload) and uploaded
// as S³ float32 values (S the brick size, AtlasOptions::slot_size). The host kernel instead decodes
// every brick on the CPU (the reference decoder, OpenMP over the bricks), converts it to the
// atlas's 16-bit texels and copies it into its slot: no compute pass at all, for CPU
// implementations, where the CPU decoder is several times faster than either shader.
//
// Staging: a ring of host-visible buffers, each of `upload_budget_bytes` (the most a frame
// uploads). A batch larger than one buffer is split over several ring entries. A ring entry is
// reused only after the fence of its previous submission signaled, so staging memory is never
// overwritten while the GPU reads it. All submissions go to the context's single queue; each decode
// command buffer starts with a barrier after all earlier compute and transfer work on that queue
// and ends with one that makes its atlas writes visible to later compute shader reads and
// transfers, so a slot is never overwritten while an earlier submitted compute pass (a ray caster)
// still reads it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "volreel/format/decoder.hpp"
#include "volreel/vulkan/atlas.hpp"
#include "volreel/vulkan/context.hpp"
#include "volreel/vulkan/resources.hpp"

namespace volreel::vulkan {

/// One brick to decode: its payload as stored in the frame file and its destination slot.
struct BrickUpload {
  std::span<const std::byte> payload;
  format::Codec codec = format::Codec::ksvd;
  double zfp_accuracy = 0;  ///< the frame's codec_parameter (zfp only)
  std::uint32_t slot = 0;
};

struct DecoderOptions {
  /// Bytes of one staging buffer = the most one submission uploads (≥ 1 MiB: a zfp brick
  /// uploads S³ float32: 186 624 bytes for 36³).
  std::uint64_t upload_budget_bytes = std::uint64_t{8} << 20;
  /// Staging buffers in the ring (≥ 1): submissions that may be in flight at once.
  std::uint32_t ring_size = 3;
  /// How the compute pass writes the slots:
  ///  - image_store: one workgroup of 54 invocations per brick, imageStore into the atlas
  ///    (shaders/decode/decode_bricks.comp): for GPUs;
  ///  - buffer_copy: one workgroup of 8 invocations per brick, 16-bit texel pairs written to a
  ///    storage buffer then copied into the slots with vkCmdCopyBufferToImage
  ///    (shaders/decode/decode_bricks_rows.comp): for CPU implementations (lavapipe), where
  ///    storage-image stores, shared memory and barriers are slow;
  ///  - host: every brick decoded on the CPU by format::decode_payload, converted to 16-bit texels
  ///    (Atlas::value_to_texel) and copied into its slot with vkCmdCopyBufferToImage (S³ · 2
  ///    bytes of staging per brick);
  ///  - automatic: host on a VK_PHYSICAL_DEVICE_TYPE_CPU device, image_store otherwise.
  enum class Kernel { automatic, image_store, buffer_copy, host };
  Kernel kernel = Kernel::automatic;
  /// buffer_copy: bricks decoded per dispatch (the decoded-brick buffer holds this many S³
  /// bricks of 16-bit texels, rows padded from 6 to 8 texels: 124 416 bytes each for 36³), at
  /// most as many as fit 32 MiB (42 bricks of 66³).
  std::uint32_t bricks_per_copy = 256;
};

/// "image_store (decode_bricks.comp)", "buffer_copy (…)", "host (CPU decoder, …)", "automatic".
const char* kernel_name(DecoderOptions::Kernel kernel);

/// Identifies a submission; 0 means "nothing", always complete. Increases with each submission.
using Ticket = std::uint64_t;

/// Not thread-safe: one thread submits, waits and reads back.
class AtlasDecoder {
 public:
  /// Builds the pipeline and the staging ring. The context and the atlas must outlive it.
  AtlasDecoder(const Context& context, const Atlas& atlas, const DecoderOptions& options = {});
  ~AtlasDecoder();
  AtlasDecoder(const AtlasDecoder&) = delete;
  AtlasDecoder& operator=(const AtlasDecoder&) = delete;

  /// Uploads the dictionary (K atoms of 216 float32) for ksvd bricks; waits for all submissions
  /// first. Throws Error on a Vulkan failure.
  void set_dictionary(const format::AtomTable& atoms);

  /// Uploads and decodes a batch; returns the ticket of its last submission. Blocks while the
  /// next ring entry is still in use. Validates every payload first (ksvd: length against the
  /// block sparsities, atom indices < K, finite dequantization values; constants finite) and
  /// throws format::FormatError ("brick upload N: ...") on a bad one (a bad zfp stream is found
  /// only when it is decoded, after the bricks before it were submitted), or std::invalid_argument
  /// for a slot outside the atlas, a slot named twice in the batch (the order of writes inside
  /// one dispatch is undefined) or a ksvd brick without a dictionary. Nothing is submitted then.
  Ticket submit(std::span<const BrickUpload> batch);
  /// Whether the submission `ticket` (and every earlier one) finished.
  bool poll(Ticket ticket) const;
  /// Waits for submission `ticket` and every earlier one.
  void wait(Ticket ticket) const;
  void wait_all() const { wait(last_ticket_); }
  Ticket last_ticket() const { return last_ticket_; }

  /// Reads slots back from the atlas as values (S³ each, x fastest, concatenated in the order
  /// given); waits for every submission first. For tests and benchmarks.
  std::vector<float> read_slots(std::span<const std::uint32_t> slots) const;
  std::vector<float> read_slot(std::uint32_t slot) const { return read_slots({&slot, 1}); }

  /// Bytes that uploading `brick` (of `shape`) takes in a staging buffer with `kernel` (its record
  /// included); `decoded_on_cpu`: a ksvd brick uploaded as values (see submit).
  static std::uint64_t upload_bytes(
      const BrickUpload& brick, DecoderOptions::Kernel kernel = DecoderOptions::Kernel::image_store,
      format::BrickShape shape = {}, bool decoded_on_cpu = false);

  struct Stats {
    std::uint64_t bricks = 0, submissions = 0;
    std::uint64_t uploaded_bytes = 0;  ///< staging bytes written (records, payloads, zfp floats)
    /// CPU time decoding zfp bricks in submit (and, on a CPU device, ksvd bricks of more codes
    /// than its shader loops run)
    double cpu_zfp_seconds = 0;
    double cpu_decode_seconds = 0;  ///< host kernel: wall time decoding bricks in submit
  };
  const Stats& stats() const { return stats_; }
  const DecoderOptions& options() const { return options_; }
  /// The kernel in use (options().kernel with automatic resolved).
  DecoderOptions::Kernel kernel() const { return kernel_; }

 private:
  struct RingEntry;
  void record_and_submit(RingEntry& entry, std::uint32_t bricks, std::uint64_t bytes);
  /// Ends the entry's command buffer and submits it with the entry's fence (a new ticket).
  void end_and_submit(RingEntry& entry);
  void write_descriptors(RingEntry& entry) const;
  void make_atoms_view();
  void record_decode(VkCommandBuffer commands, const std::uint32_t* records, std::uint32_t bricks);
  void record_host_copies(VkCommandBuffer commands, VkBuffer texels,
                          std::span<const BrickUpload> bricks);
  /// Barriers around a copy of `regions` of `source` into the atlas.
  void copy_into_atlas(VkCommandBuffer commands, VkBuffer source,
                       const std::vector<VkBufferImageCopy>& regions) const;
  /// host: decodes `bricks` into `texels` (S³ per brick) on the CPU; throws FormatError naming
  /// "brick upload first + i" for a bad payload.
  void decode_on_host(std::span<const BrickUpload> bricks, std::size_t first,
                      std::uint16_t* texels);

  const Context& context_;
  const Atlas& atlas_;
  format::BrickShape shape_;  ///< the atlas's slots: the bricks' shape
  DecoderOptions options_;
  DecoderOptions::Kernel kernel_ = DecoderOptions::Kernel::image_store;
  Buffer decoded_;  ///< buffer_copy: the decoded bricks of one dispatch, before the copy
  DescriptorSetLayout set_layout_;
  ShaderModule shader_;
  ComputePipeline pipeline_;
  DescriptorPool descriptor_pool_;
  CommandPool command_pool_;
  Buffer atoms_;
  /// buffer_copy: atoms_ as a uniform texel buffer of RGBA32F (4 values of an atom a texel).
  detail::DeviceHandle<VkBufferView, vkDestroyBufferView> atoms_view_;
  std::uint32_t atom_count_ = 0;
  std::vector<float> host_atoms_;  ///< the dictionary's values, for the CPU decoder
  bool host_dct_basis_ = false;    ///< they end with the DCT basis (format::AtomTable)
  std::vector<RingEntry> ring_;
  std::size_t next_entry_ = 0;
  Ticket last_ticket_ = 0;
  Stats stats_;
  std::vector<float> zfp_scratch_;
  /// CPU devices (lavapipe) end a shader loop after 65535 iterations: per brick of the batch
  /// being submitted, whether its codes are too many for the kernels' loops there, so that it is
  /// decoded on the CPU and uploaded as values.
  bool cpu_device_ = false;
  std::vector<char> decode_on_cpu_;
  std::vector<VkBufferImageCopy> copy_regions_;
  std::vector<std::uint64_t> slot_mark_;  ///< per slot, the last submit() call that named it
  std::uint64_t submit_calls_ = 0;
};

}  // namespace volreel::vulkan
