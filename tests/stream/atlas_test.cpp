// atlas_test.cpp: the occupied and over-writeable slot lists of the Cesium patent [0035].
#include <gtest/gtest.h>

#include "volreel/stream/atlas_slots.hpp"

namespace volreel::stream {
namespace {

KeyframeKey key(std::uint32_t x, std::uint32_t t) {
  return {1, x, 0, 0, t};
}

TEST(StreamAtlas, Paragraph0035LeaveAndComeBackBeforeAndAfterBeingOverwritten) {
  AtlasSlots atlas(3);
  const KeyframeKey a = key(0, 0), b = key(1, 0), c = key(2, 0), d = key(3, 0), e = key(4, 0);
  // Fresh slots are taken in order.
  EXPECT_EQ(atlas.acquire(a), 0u);
  EXPECT_EQ(atlas.acquire(b), 1u);
  EXPECT_EQ(atlas.acquire(c), 2u);
  EXPECT_EQ(atlas.occupied_count(), 3u);
  EXPECT_FALSE(atlas.acquire(d).has_value());  // full
  // a's and then b's spatial node leave the view: their slots become over-writeable, data kept.
  atlas.release(a);
  atlas.release(b);
  EXPECT_EQ(atlas.overwriteable_slots(), (std::vector<std::uint32_t>{0, 1}));
  EXPECT_EQ(atlas.occupied_count(), 1u);
  EXPECT_EQ(atlas.find(a), 0u);
  // b comes back before being overwritten: it re-occupies its slot without a new request.
  EXPECT_EQ(atlas.reoccupy(b), 1u);
  EXPECT_TRUE(atlas.is_occupied(b));
  EXPECT_EQ(atlas.overwriteable_slots(), (std::vector<std::uint32_t>{0}));
  // New data takes the stalest over-writeable slot: a's.
  atlas.release(c);  // c leaves after a: a's slot is staler
  EXPECT_EQ(atlas.overwriteable_slots(), (std::vector<std::uint32_t>{0, 2}));
  EXPECT_EQ(atlas.acquire(d), 0u);
  EXPECT_EQ(atlas.key(0), d);
  // a comes back after being overwritten: it is gone and needs a new request.
  EXPECT_FALSE(atlas.find(a).has_value());
  EXPECT_FALSE(atlas.reoccupy(a).has_value());
  // c is still there.
  EXPECT_EQ(atlas.reoccupy(c), 2u);
  EXPECT_EQ(atlas.occupied_count(), 3u);
  EXPECT_FALSE(atlas.acquire(e).has_value());
  // acquire() of a key already held re-occupies it.
  atlas.release(d);
  EXPECT_EQ(atlas.acquire(d), 0u);
  EXPECT_TRUE(atlas.is_occupied(d));
}

TEST(StreamAtlas, ASlotIsOverwrittenOnlyAfterItsLastGpuFrameRetired) {
  AtlasSlots atlas(2);
  const KeyframeKey a = key(0, 0), b = key(1, 0), c = key(2, 0);
  ASSERT_EQ(atlas.acquire(a), 0u);
  ASSERT_EQ(atlas.acquire(b), 1u);
  atlas.mark_used(0, 5);  // GPU frames 5 and 6 sample slot 0
  atlas.mark_used(0, 6);
  atlas.release(a);
  EXPECT_FALSE(atlas.retired(0));
  EXPECT_FALSE(atlas.acquire(c).has_value());
  atlas.retire(5);
  EXPECT_FALSE(atlas.acquire(c).has_value());  // frame 6 still samples it
  atlas.retire(6);
  EXPECT_TRUE(atlas.retired(0));
  EXPECT_EQ(atlas.acquire(c), 0u);
  EXPECT_FALSE(atlas.find(a).has_value());
  // Retiring is monotonic.
  atlas.retire(2);
  atlas.mark_used(1, 7);
  atlas.release(b);
  EXPECT_FALSE(atlas.acquire(a).has_value());
  atlas.retire(7);
  EXPECT_EQ(atlas.acquire(a), 1u);
}

TEST(StreamAtlas, AnUnretiredStaleSlotIsPassedOverForTheNextOne) {
  AtlasSlots atlas(3);
  const KeyframeKey a = key(0, 0), b = key(1, 0), c = key(2, 0), d = key(3, 0), e = key(4, 0);
  ASSERT_EQ(atlas.acquire(a), 0u);
  ASSERT_EQ(atlas.acquire(b), 1u);
  ASSERT_EQ(atlas.acquire(c), 2u);
  atlas.mark_used(0, 10);
  atlas.mark_used(1, 8);
  atlas.release(a);
  atlas.release(b);
  atlas.retire(9);
  EXPECT_EQ(atlas.overwriteable_slots(), (std::vector<std::uint32_t>{0, 1}));
  EXPECT_EQ(atlas.acquire(d), 1u);  // slot 0 is staler but frame 10 still samples it
  EXPECT_FALSE(atlas.acquire(e).has_value());
  EXPECT_EQ(atlas.find(a), 0u);  // a's data is still there
  atlas.retire(10);
  EXPECT_EQ(atlas.acquire(e), 0u);
  EXPECT_FALSE(atlas.find(a).has_value());
}

}  // namespace
}  // namespace volreel::stream
