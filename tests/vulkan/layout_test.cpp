// layout_test.cpp: brick_decode.h and atlas_layout.h give the same results compiled as GLSL (the
// probe shader layout_probe.comp, run on the device) as compiled as C++.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstring>

#include "brick_samples.hpp"
#include "volreel/format/brick_decode.h"
#include "volreel/player/atlas_layout.h"
#include "volreel/vulkan/resources.hpp"
#include "volreel_layout_probe_spv.h"
#include "vulkan_test_util.hpp"

namespace volreel::vulkan {
namespace {

constexpr std::uint32_t sections = 11;

class LayoutTest : public test::VulkanTest, public ::testing::WithParamInterface<std::uint32_t> {};

// Bricks of 36³ (216 blocks) and of 18³ (27 blocks, the specialization constant at work).
INSTANTIATE_TEST_SUITE_P(BrickSizes, LayoutTest, ::testing::Values(36u, 18u));

TEST_P(LayoutTest, GlslAndCppAgree) {
  Context& ctx = context();
  const format::BrickShape shape{GetParam()};
  const std::uint32_t blocks = shape.blocks(), n = shape.blocks_per_axis();
  const std::uint32_t N = blocks * VR_BLOCK_LENGTH;  // values of a brick: one section
  SplitMix64 rng(5);
  const std::uint32_t atom_count = 1024;
  const std::vector<float> atoms = test::random_atoms(rng, atom_count);
  // A payload that codes a box of blocks, not all of them (about every other one does), of at
  // least the 34 words the probe's bit reads cover.
  const auto coded_blocks = [](const std::vector<std::byte>& payload) {
    return vr_box_entries(format::ksvd_box_word(payload));
  };
  std::vector<std::byte> bytes;
  do {
    bytes = test::random_ksvd_payload(rng, atom_count, 0, shape);
  } while (coded_blocks(bytes) == blocks || bytes.size() < 4 * 34 ||  // the probe reads 34 words
           vr_box_run_limit(format::ksvd_box_word(bytes)) == 0);      // and codes runs
  std::vector<vr_uint> payload(bytes.size() / 4 + 1, 0u);             // + the look-ahead word
  std::memcpy(payload.data(), bytes.data(), bytes.size());
  const format::KsvdPayloadParts parts =
      format::unpack_ksvd_payload(bytes, atom_count, shape, "<memory>", 0);

  // 1. Run the probe.
  const auto host = VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT;
  Buffer payload_buffer(ctx, 4 * payload.size(), VK_BUFFER_USAGE_STORAGE_BUFFER_BIT, host);
  Buffer atom_buffer(ctx, 4 * atoms.size(), VK_BUFFER_USAGE_STORAGE_BUFFER_BIT, host);
  Buffer results(ctx, 4ull * sections * N, VK_BUFFER_USAGE_STORAGE_BUFFER_BIT, host);
  std::memcpy(payload_buffer.mapped(), payload.data(), 4 * payload.size());
  std::memcpy(atom_buffer.mapped(), atoms.data(), 4 * atoms.size());
  VkDescriptorSetLayoutBinding bindings[3];
  for (std::uint32_t b = 0; b < 3; ++b)
    bindings[b] = {b, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, VK_SHADER_STAGE_COMPUTE_BIT, nullptr};
  DescriptorSetLayout set_layout(ctx, bindings);
  ShaderModule shader(ctx, volreel_layout_probe_spv);
  const VkDescriptorSetLayout layouts[] = {set_layout.handle()};
  ComputePipeline pipeline(ctx, shader, layouts, 0, {&n, 1});
  const VkDescriptorPoolSize sizes[] = {{VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 3}};
  DescriptorPool pool(ctx, sizes, 1);
  VkDescriptorSet set = pool.allocate(set_layout.handle());
  write_storage_buffer(ctx.device(), set, 0, payload_buffer.handle());
  write_storage_buffer(ctx.device(), set, 1, atom_buffer.handle());
  write_storage_buffer(ctx.device(), set, 2, results.handle());
  ctx.submit_and_wait([&](VkCommandBuffer commands) {
    vkCmdBindPipeline(commands, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline.handle());
    vkCmdBindDescriptorSets(commands, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline.layout(), 0, 1, &set,
                            0, nullptr);
    vkCmdDispatch(commands, blocks, 1, 1);
    memory_barrier(commands, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
                   VK_PIPELINE_STAGE_HOST_BIT, VK_ACCESS_HOST_READ_BIT);
  });
  const auto* gpu = reinterpret_cast<const std::uint32_t*>(results.mapped());

  // 2. The same functions in C++.
  const vr_uint* p = payload.data();
  const float* a = atoms.data();
  const vr_uint layout_word = vr_layout_word(p), box_word = vr_box_word(p);
  const vr_uint entries = vr_box_entries(box_word);
  ASSERT_LT(entries, blocks) << "the probe's payload codes a box of blocks, not all";
  std::uint32_t codes = 0;
  for (std::uint32_t e = 0; e < entries; ++e)
    codes += vr_entry_sparsity(layout_word, vr_block_entry(p, layout_word, e));
  ASSERT_GT(codes, 0u);
  ASSERT_GE(payload.size(), 34u) << "the probe reads bits 0..1055";
  const std::uint32_t constants[16] = {shape.size,
                                       shape.interior(),
                                       VR_BLOCK_SIZE,
                                       VR_BLOCK_LENGTH,
                                       n,
                                       blocks,
                                       VR_HEADER_WORDS,
                                       VR_MEAN_BITS,
                                       VR_MAX_SPARSITY_BITS,
                                       VR_MAX_COEF_BITS,
                                       VR_MAX_ATOM_BITS,
                                       box_word,
                                       VR_ATLAS_NO_SLOT,
                                       layout_word,
                                       codes,
                                       vr_code_first_word(layout_word, entries)};
  for (std::uint32_t k = 0; k < 16; ++k)
    EXPECT_EQ(gpu[8 * N + k], constants[k]) << "constant " << k;
  std::uint32_t mismatches = 0;
  float worst = 0;
  std::size_t first_code = 0;  // of block b in parts
  for (std::uint32_t b = 0; b < blocks; ++b) {
    for (std::uint32_t v = 0; v < VR_BLOCK_LENGTH; ++v) {
      const std::uint32_t i = b * 216 + v;
      const vr_uint other = vr_make_layout(i % 16, (i / 16) % 9, 1 + (i / 144) % 16,
                                           1 + (i / 2304) % 16, (i / 3) % 4, i % 4096);
      const vr_uint entry = vr_block_entry(p, layout_word, i % entries);
      vr_uint rice_bit = (i * 7) % 900;
      const vr_uint rice = vr_read_rice(p, 0, rice_bit, i % 16, 1 + i % 16);
      const std::uint32_t expected[sections] = {
          vr_brick_voxel(n, b, v),
          0,  // the decoded value, compared below
          vr_read_bits(p, 0, (i * 13) % 1024, i % 33),
          vr_entry_sparsity(layout_word, entry) | (vr_entry_mean(layout_word, entry) << 8),
          v < parts.sparsity[b] ? parts.atoms[first_code + v] |
                                      (static_cast<vr_uint>(parts.values[first_code + v]) << 16)
                                : 0xFFFFFFFFu,
          vr_layout_entry_bits(other) | (vr_gap_rice(other, 1 + i % 255) << 5) |
              (vr_band_rice(other, i * 2654435761u, i % 300) << 10) |
              (vr_entry_words(other, blocks) << 15) | (vr_code_first_word(other, blocks) << 23),
          vr_atlas_cell_x(i, 7) | (vr_atlas_cell_y(i, 7, 5) << 8) |
              (vr_atlas_cell_z(i, 7, 5) << 16),
          vr_atlas_cell_x(i, 56) | (vr_atlas_cell_y(i, 56, 56) << 8) |
              (vr_atlas_cell_z(i, 56, 56) << 16),
          0,  // constants
          rice ^ (rice_bit << 20),
          vr_block_band_word(i * 2654435761u, vr_box_with_magnitude_model(0, i % 10), i % 256)};
      for (std::uint32_t s = 0; s < sections; ++s)
        if (s != 1 && s != 8 && gpu[s * N + i] != expected[s] && ++mismatches <= 3000)
          ADD_FAILURE() << "section " << s << " index " << i << ": GLSL " << gpu[s * N + i]
                        << ", C++ " << expected[s];
      // The decoded value: the same arithmetic; the device may fuse multiply-adds.
      const float cpu = vr_decode_value(p, a, n, b, v);
      const float glsl = std::bit_cast<float>(gpu[N + i]);
      worst = std::max(worst, std::fabs(cpu - glsl) / std::max(1.0f, std::fabs(cpu)));
    }
    first_code += parts.sparsity[b];
  }
  EXPECT_EQ(mismatches, 0u);
  EXPECT_LT(worst, 1e-5f) << "largest relative difference of decoded values";
}

}  // namespace
}  // namespace volreel::vulkan
