// index_test.cpp: the spatial octree with its keyframe nodes, built from a container.
#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <random>
#include <set>
#include <thread>

#include "stream_test_util.hpp"
#include "volreel/stream/spatial_index.hpp"

namespace volreel::stream {
namespace {

TEST(StreamIndex, HeldTimesAnswerLikeASortedSetAcrossTheRingsWrap) {
  // A window of up to 100 time steps on a ring of 128 slots (two words) that slides forward,
  // backward and jumps, with about half the steps held: every question against std::set.
  constexpr std::uint32_t ring = 128, window = 100;
  std::vector<std::uint64_t> words(ring / 64, 0);
  std::set<std::uint32_t> reference;
  std::mt19937 random(7);
  std::uint32_t lo = 5000, hi = 5000;  // held range [lo, hi)
  const auto set_bit = [&](std::uint32_t t, bool on) {
    const std::uint64_t bit = std::uint64_t{1} << (t % ring % 64);
    if (on) {
      words[t % ring / 64] |= bit;
      reference.insert(t);
    } else {
      words[t % ring / 64] &= ~bit;
      reference.erase(t);
    }
  };
  const auto check = [&] {
    const HeldTimes times(words.data(), ring, lo, hi, static_cast<std::uint32_t>(reference.size()));
    ASSERT_EQ(times.size(), reference.size());
    std::vector<std::uint32_t> all, part;
    times.for_each([&](std::uint32_t t) { all.push_back(t); });
    ASSERT_EQ(all, std::vector<std::uint32_t>(reference.begin(), reference.end()));
    const std::uint32_t a = lo - 3 + static_cast<std::uint32_t>(random() % (window + 6));
    const std::uint32_t b = a + static_cast<std::uint32_t>(random() % 40);
    times.for_each(a, b, [&](std::uint32_t t) { part.push_back(t); });
    ASSERT_EQ(part, std::vector<std::uint32_t>(reference.lower_bound(a), reference.upper_bound(b)));
    for (std::uint32_t t = lo - 2; t < hi + 2; ++t) {
      ASSERT_EQ(times.contains(t), reference.count(t) == 1) << t;
      const auto after = reference.lower_bound(t);
      ASSERT_EQ(times.at_or_after(t), after == reference.end() ? no_time : *after) << t;
      const auto upto = reference.upper_bound(t);
      ASSERT_EQ(times.at_or_before(t), upto == reference.begin() ? no_time : *std::prev(upto)) << t;
    }
  };
  for (int step = 0; step < 3000; ++step) {
    const int phase = (step / 400) % 4;  // forward, backward, forward again, jumpy
    const bool forward = phase == 0 || phase == 2 || (phase == 3 && random() % 2 == 0);
    if (forward) {
      set_bit(hi++, random() % 2 == 0);
      if (hi - lo > window) set_bit(lo++, false);
    } else {
      set_bit(--lo, random() % 2 == 0);
      if (hi - lo > window) set_bit(--hi, false);
    }
    ASSERT_NO_FATAL_FAILURE(check());
    if (step % 700 == 699) {  // a seek: everything dropped
      while (hi > lo) set_bit(--hi, false);
      lo = hi = lo + 333;
      ASSERT_NO_FATAL_FAILURE(check());
    }
  }
}

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
      ASSERT_EQ(index.times(node).size(), 3u);
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
  EXPECT_EQ(index.times(0).size(), 2u);
  EXPECT_EQ(index.find_keyframe(0, 1), no_keyframe);
  EXPECT_NE(index.find_keyframe(0, 2), no_keyframe);
  // Every frame stores a brick of every node (max_keyframe_gap 1): frame 1 is needed from 0 to
  // 2, not at 0 or 2, whose own frames hold every node's state.
  EXPECT_TRUE(index.failed_around(0.5));
  EXPECT_TRUE(index.failed_around(1));
  EXPECT_TRUE(index.failed_around(1.5));
  EXPECT_FALSE(index.failed_around(0));
  EXPECT_FALSE(index.failed_around(2));
}

/// Follows the playhead until the index holds the frames around it (the reader runs on its own
/// thread); false after 10 s.
bool follow_until_held(SpatialIndex& index, double playhead, double velocity,
                       std::vector<std::string>* errors = nullptr) {
  for (int i = 0; i < 10000; ++i) {
    index.follow(playhead, velocity, errors);
    if (index.holds_around(playhead)) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return false;
}

/// Every keyframe node the windowed index holds is the whole index's, and the held nodes are
/// present in both with the same children.
void expect_held_agree(const SpatialIndex& window, const SpatialIndex& whole) {
  std::size_t held = 0;
  for (std::uint32_t n = 0; n < window.node_count(); ++n) {
    window.for_each_keyframe(n, [&](const KeyframeNode& k) {
      ASSERT_GE(k.t, window.held_begin());
      ASSERT_LT(k.t, window.held_end());
      const KeyframeId id = whole.find_keyframe(n, k.t);
      ASSERT_NE(id, no_keyframe);
      const KeyframeNode& w = whole.keyframe(id);
      EXPECT_EQ(k.offset, w.offset);
      EXPECT_EQ(k.bytes, w.bytes);
      EXPECT_EQ(k.crc32c, w.crc32c);
      EXPECT_EQ(k.histogram, w.histogram);
      EXPECT_EQ(k.subtree_constant, w.subtree_constant);
      EXPECT_EQ(window.constant_times(n).contains(k.t), k.subtree_constant);
      ++held;
    });
    if (window.node(n).present()) {
      EXPECT_TRUE(whole.node(n).present());
      for (std::size_t i = 0; i < 8; ++i) {
        if (window.node(n).children[i] != no_node) {
          EXPECT_EQ(window.node(n).children[i], whole.node(n).children[i]);
        }
      }
    }
  }
  EXPECT_EQ(held, window.keyframe_count());
  // Every frame in the held range is whole.
  for (std::uint32_t n = 0; n < whole.node_count(); ++n)
    whole.for_each_keyframe(n, [&](const KeyframeNode& k) {
      if (k.t >= window.held_begin() && k.t < window.held_end()) {
        EXPECT_NE(window.find_keyframe(n, k.t), no_keyframe) << "node " << n << " t " << k.t;
      }
    });
}

TEST(StreamIndex, AWindowFollowsThePlayheadForwardBackwardAndAcrossSeeks) {
  test::TempDir dir("stream-index-window");
  const auto path =
      test::make_container(dir.path(), {80, 40, 36}, 30, datasets::AnalyticField::blobs, 3);
  const format::Container c(path);
  const SpatialIndex whole = build_spatial_index(c);
  ASSERT_FALSE(whole.windowed());
  ASSERT_EQ(whole.held_begin(), 0u);
  ASSERT_EQ(whole.held_end(), 30u);
  // Room for 10 frames of every node.
  IndexOptions o;
  o.memory_bytes = 10 * whole.node_count() * (sizeof(KeyframeNode) + sizeof(std::uint32_t));
  SpatialIndex index = build_spatial_index(c, nullptr, o);
  ASSERT_TRUE(index.windowed());
  EXPECT_EQ(index.window_frames(), 10u);
  EXPECT_EQ(index.keyframe_count(), 0u);  // nothing read at open
  EXPECT_FALSE(index.holds_around(0));
  std::vector<std::string> errors;
  const auto check = [&](double p, double v) {
    SCOPED_TRACE("playhead " + std::to_string(p));
    ASSERT_TRUE(follow_until_held(index, p, v, &errors));
    EXPECT_LE(index.held_end() - index.held_begin(), 10u);
    EXPECT_LE(index.held_begin(), static_cast<std::uint32_t>(p));
    EXPECT_GT(index.held_end(), static_cast<std::uint32_t>(p));
    expect_held_agree(index, whole);
  };
  for (double p = 0; p <= 29; p += 1.5) check(p, 15);  // playing forward
  EXPECT_GE(index.held_end(), 29u);
  for (double p = 29; p >= 0; p -= 2.5) check(p, -25);  // backward
  EXPECT_LE(index.held_begin(), 1u);
  check(24.5, 0);  // seeks, paused
  check(3, 0);
  check(17.25, 0);
  // Played forward, the window keeps max_keyframe_gap + 2 frames behind the playhead (more than
  // a quarter of 10) and the rest ahead.
  check(18, 1);
  for (int i = 0; i < 2000 && index.held_end() < 23; ++i) {
    index.follow(18, 1, &errors);
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  EXPECT_EQ(index.held_end(), 23u);
  EXPECT_EQ(index.held_begin(), 13u);
  EXPECT_TRUE(errors.empty());
  EXPECT_GT(index.memory_bytes(), 0u);
  // A copy reads with its own thread.
  SpatialIndex copy = index;
  EXPECT_EQ(copy.memory_bytes(), index.memory_bytes());
  check(18, 1);
  ASSERT_TRUE(follow_until_held(copy, 5, 0));
  expect_held_agree(copy, whole);
}

TEST(StreamIndex, AWindowReportsABadFrameOnceAndHoldsTheRest) {
  test::TempDir dir("stream-index-window-bad");
  const auto path = test::make_container(dir.path(), {40, 40, 40}, 12);
  {
    std::fstream f(path / "frames/000005.vrf", std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(200);
    f.put('\x5a');
  }
  const format::Container c(path);
  const SpatialIndex whole = build_spatial_index(c);
  IndexOptions o;
  o.memory_bytes = 2 * whole.node_count() * (sizeof(KeyframeNode) + sizeof(std::uint32_t));
  SpatialIndex index = build_spatial_index(c, nullptr, o);
  ASSERT_EQ(index.window_frames(), 6u);  // the least: 2·max_keyframe_gap + 4
  std::vector<std::string> errors;
  for (double p = 0; p <= 11; p += 0.5) {
    ASSERT_TRUE(follow_until_held(index, p, 2, &errors));
    // Frame 5 is needed between frames 4 and 6 (each frame stores every node).
    EXPECT_EQ(index.failed_around(p), p > 4 && p < 6) << p;
  }
  ASSERT_EQ(errors.size(), 1u);
  EXPECT_NE(errors[0].find("000005.vrf"), std::string::npos) << errors[0];
  EXPECT_EQ(index.find_keyframe(0, 5), no_keyframe);
  EXPECT_NE(index.find_keyframe(0, 10), no_keyframe);
}

}  // namespace
}  // namespace volreel::stream
