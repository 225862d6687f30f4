// context_test.cpp: the Vulkan foundation — device creation, errors, RAII wrappers, the atlas
// grid and the 16-bit conversions.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

#include "volreel/vulkan/atlas.hpp"
#include "volreel/vulkan/error.hpp"
#include "volreel/vulkan/resources.hpp"
#include "vulkan_test_util.hpp"

namespace volreel::vulkan {
namespace {

using test::VulkanTest;

// The shared Vulkan context is released when the test program ends.
[[maybe_unused]] ::testing::Environment* const vulkan_environment =
    ::testing::AddGlobalTestEnvironment(new test::VulkanEnvironment);

TEST(VulkanError, NamesTheCallAndTheResult) {
  try {
    check(VK_ERROR_OUT_OF_DEVICE_MEMORY, "vkCreateBuffer");
    FAIL() << "check did not throw";
  } catch (const Error& e) {
    EXPECT_STREQ(e.what(), "vkCreateBuffer: VK_ERROR_OUT_OF_DEVICE_MEMORY");
    EXPECT_EQ(e.result(), VK_ERROR_OUT_OF_DEVICE_MEMORY);
  }
  EXPECT_EQ(check(VK_INCOMPLETE, "vkEnumeratePhysicalDevices"), VK_INCOMPLETE);
  EXPECT_STREQ(result_name(VK_ERROR_DEVICE_LOST), "VK_ERROR_DEVICE_LOST");
}

TEST(AtlasGrid, LargestCubeLikeGridWithinBudgetAndLimits) {
  const AtlasGrid g = choose_atlas_grid(64, 2048);
  EXPECT_EQ(g.x, 4u);
  EXPECT_EQ(g.y, 4u);
  EXPECT_EQ(g.z, 4u);
  const AtlasGrid h = choose_atlas_grid(100, 2048);
  EXPECT_LE(h.slots(), 100u);
  EXPECT_GE(h.slots(), 96u);
  // 2048 / 36 = 56 slots per axis at most.
  const AtlasGrid big = choose_atlas_grid(1u << 30, 2048);
  EXPECT_EQ(big.x, 56u);
  EXPECT_EQ(big.y, 56u);
  EXPECT_EQ(big.z, 56u);
  EXPECT_EQ(choose_atlas_grid(0, 2048).slots(), 1u);
  EXPECT_EQ(choose_atlas_grid(7, 36 * 2).slots(), 4u);  // 2 per axis, 2×2×1 ≤ 7 < 8
}

TEST(HalfFloat, RoundsToNearestEvenAndBack) {
  EXPECT_EQ(float_to_half(0.0f), 0x0000);
  EXPECT_EQ(float_to_half(-0.0f), 0x8000);
  EXPECT_EQ(float_to_half(1.0f), 0x3C00);
  EXPECT_EQ(float_to_half(-2.0f), 0xC000);
  EXPECT_EQ(float_to_half(65504.0f), 0x7BFF);
  EXPECT_EQ(float_to_half(65520.0f), 0x7C00);
  EXPECT_EQ(float_to_half(1.0f + 0x1p-11f), 0x3C00);  // tie → even
  EXPECT_EQ(float_to_half(1.0f + 3 * 0x1p-11f), 0x3C02);
  EXPECT_EQ(float_to_half(0x1p-24f), 0x0001);
  for (std::uint32_t h = 0; h < 0x7C00; ++h)
    ASSERT_EQ(float_to_half(half_to_float(static_cast<std::uint16_t>(h))), h) << h;
}

TEST_F(VulkanTest, CreatesADeviceWithAComputeQueue) {
  Context& ctx = context();
  EXPECT_NE(ctx.device(), VK_NULL_HANDLE);
  EXPECT_NE(ctx.queue(), VK_NULL_HANDLE);
  EXPECT_TRUE(ctx.validation_enabled());
  EXPECT_FALSE(ctx.device_name().empty());
  std::printf("device: %s\n", ctx.describe().c_str());
}

TEST_F(VulkanTest, BufferRoundTripThroughACopy) {
  Context& ctx = context();
  Buffer src(ctx, 1024, VK_BUFFER_USAGE_TRANSFER_SRC_BIT,
             VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT);
  Buffer mid(ctx, 1024, VK_BUFFER_USAGE_TRANSFER_SRC_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT,
             VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
  Buffer dst(ctx, 1024, VK_BUFFER_USAGE_TRANSFER_DST_BIT,
             VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT);
  for (int i = 0; i < 1024; ++i) src.mapped()[i] = static_cast<std::byte>(i * 7);
  ctx.submit_and_wait([&](VkCommandBuffer commands) {
    const VkBufferCopy region{0, 0, 1024};
    vkCmdCopyBuffer(commands, src.handle(), mid.handle(), 1, &region);
    memory_barrier(commands, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
                   VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_READ_BIT);
    vkCmdCopyBuffer(commands, mid.handle(), dst.handle(), 1, &region);
    memory_barrier(commands, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
                   VK_PIPELINE_STAGE_HOST_BIT, VK_ACCESS_HOST_READ_BIT);
  });
  EXPECT_EQ(std::memcmp(src.mapped(), dst.mapped(), 1024), 0);
  // Moving transfers ownership; the moved-from wrapper owns nothing.
  Buffer moved = std::move(src);
  EXPECT_NE(moved.handle(), VK_NULL_HANDLE);
  EXPECT_EQ(src.handle(), VK_NULL_HANDLE);  // NOLINT(bugprone-use-after-move)
}

TEST_F(VulkanTest, FailedCallsThrowNamedErrors) {
  Context& ctx = context();
  // No memory type has every property bit.
  EXPECT_THROW(Buffer(ctx, 64, VK_BUFFER_USAGE_STORAGE_BUFFER_BIT, 0xFFFFFFFFu), Error);
  Fence fence(ctx, false);
  EXPECT_FALSE(fence.signaled());
  EXPECT_FALSE(fence.wait(1000));
}

TEST_F(VulkanTest, AtlasFormatsAreUsableForStorageAndLinearSampling) {
  Context& ctx = context();
  for (AtlasFormat f : {AtlasFormat::r16_unorm, AtlasFormat::r16_sfloat}) {
    AtlasOptions o;
    o.format = f;
    o.max_slots = 8;
    o.value_min = -1;
    o.value_max = 1;
    Atlas atlas(ctx, o);
    EXPECT_EQ(atlas.slot_count(), 8u);
    EXPECT_EQ(atlas.image().desc().extent.width, 72u);
    EXPECT_EQ(atlas.slot_origin(7).z, 36);
  }
}

}  // namespace
}  // namespace volreel::vulkan
