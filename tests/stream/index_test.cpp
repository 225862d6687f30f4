// index_test.cpp: the spatial octree with its keyframe nodes, built from a container.
#include <gtest/gtest.h>

#include <fstream>

#include "stream_test_util.hpp"
#include "volreel/stream/spatial_index.hpp"

namespace volreel::stream {
namespace {

TEST(StreamIndex, UnionOfTheFramesOctreesWithBoundsLinksAndKeyframes) {
  test::TempDir dir("stream-index");
  const Dims dims{80, 40, 36};
  const auto path = test::make_container(dir.path(), dims, 3);
  const format::Container c(path);
  std::vector<std::string> errors;
  const SpatialIndex index = build_spatial_index(c, &errors);
  EXPECT_TRUE(errors.empty());
  ASSERT_EQ(index.level_count(), 3u);  // grids 3x2x2 -> 2x1x1 -> 1x1x1
  EXPECT_EQ(index.frame_count(), 3u);
  // Levels: 1 + 2 + 12 nodes.
  ASSERT_EQ(index.node_count(), 15u);
  const SpatialNode& root = index.node(0);
  EXPECT_EQ(root.key, (NodeKey{0, 0, 0, 0}));
  EXPECT_EQ(root.parent, no_node);
  EXPECT_EQ(root.lo, (std::array<std::uint32_t, 3>{0, 0, 0}));
  EXPECT_EQ(root.hi, (std::array<std::uint32_t, 3>{80, 40, 36}));  // 136³ clipped to the volume
  EXPECT_EQ(index.voxel_size(0), 4u);
  EXPECT_EQ(index.voxel_size(2), 1u);
  // Level-1 node (1,0,0) covers x in [68, 136) ∩ [0, 80).
  const std::uint32_t n1 = index.find({1, 1, 0, 0});
  ASSERT_NE(n1, no_node);
  EXPECT_EQ(index.node(n1).lo[0], 68u);
  EXPECT_EQ(index.node(n1).hi[0], 80u);
  EXPECT_EQ(index.node(n1).parent, 0u);
  EXPECT_EQ(root.children[1], n1);
  EXPECT_EQ(root.children[2], no_node);  // (0,1,0) of level 1 lies outside the 2x1x1 grid
  // Finest (2,1,1,1) covers [34, 68) × [34, 40) × [34, 36); its parent is (1,0,0,0), octant 7.
  const std::uint32_t f = index.find({2, 1, 1, 1});
  ASSERT_NE(f, no_node);
  EXPECT_EQ(index.node(f).lo, (std::array<std::uint32_t, 3>{34, 34, 34}));
  EXPECT_EQ(index.node(f).hi, (std::array<std::uint32_t, 3>{68, 40, 36}));
  EXPECT_EQ(index.node(f).parent, index.find({1, 0, 0, 0}));
  EXPECT_EQ(index.node(index.find({1, 0, 0, 0})).children[7], f);
  EXPECT_FALSE(index.node(f).has_children);
  // Every node has one keyframe node per frame, sorted by t, pointing at that frame's brick.
  for (std::uint32_t t = 0; t < 3; ++t) {
    const format::FrameFile frame = c.open_frame(t);
    for (std::uint32_t i = 0; i < frame.view().node_count(); ++i) {
      const auto& p = frame.view().position(i);
      const std::uint32_t node = index.find({p.level, p.x, p.y, p.z});
      ASSERT_NE(node, no_node);
      ASSERT_EQ(index.keyframes(node).size(), 3u);
      const KeyframeId id = index.find_keyframe(node, t);
      ASSERT_NE(id, no_keyframe);
      const KeyframeNode& k = index.keyframe(id);
      EXPECT_EQ(k.t, t);
      const auto bytes = frame.view().brick_bytes(frame.view().node(i).brick);
      EXPECT_EQ(k.bytes, bytes.size());
      EXPECT_EQ(k.offset, static_cast<std::uint64_t>(bytes.data() - frame.view().bytes().data()));
      EXPECT_EQ(index.key(id), (KeyframeKey{p.level, p.x, p.y, p.z, t}));
      EXPECT_EQ(index.find_keyframe(index.key(id)), id);
      EXPECT_EQ(index.node_of(id), node);
    }
  }
  EXPECT_EQ(index.frame_file(1), path / "frames/000001.vrf");
}

TEST(StreamIndex, ABadFrameBecomesAnErrorAndIsLeftOut) {
  test::TempDir dir("stream-index-bad");
  const auto path = test::make_container(dir.path(), {40, 40, 40}, 3);
  {
    // Corrupt the node table of frame 1 (the index CRC catches it).
    std::fstream f(path / "frames/000001.vrf", std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(200);
    f.put('\x5a');
  }
  const format::Container c(path);
  std::vector<std::string> errors;
  const SpatialIndex index = build_spatial_index(c, &errors);
  ASSERT_EQ(errors.size(), 1u);
  EXPECT_NE(errors[0].find("000001.vrf"), std::string::npos) << errors[0];
  ASSERT_GT(index.node_count(), 0u);
  EXPECT_EQ(index.keyframes(0).size(), 2u);
  EXPECT_EQ(index.find_keyframe(0, 1), no_keyframe);
  EXPECT_NE(index.find_keyframe(0, 2), no_keyframe);
}

}  // namespace
}  // namespace volreel::stream
