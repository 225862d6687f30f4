// selection_test.cpp: two keyframe nodes per spatial node with the ancestor handicap (Cesium
// patent [0039], [0046]–[0048]) and the array-encoded SVO built from them ([0049]).
#include <gtest/gtest.h>

#include <array>
#include <bit>
#include <cmath>

#include "stream_test_util.hpp"
#include "volreel/player/atlas_layout.h"
#include "volreel/stream/selection.hpp"
#include "volreel/stream/svo_builder.hpp"

namespace volreel::stream {
namespace {

/// Resident keyframe nodes given as (node, t), slots numbered in order.
ResidentKeyframes resident(const SpatialIndex& index,
                           std::initializer_list<std::pair<std::uint32_t, std::uint32_t>> list) {
  std::vector<ResidentKeyframe> entries;
  std::uint32_t slot = 0;
  for (const auto& [node, t] : list) entries.push_back({index.find_keyframe(node, t), slot++});
  ResidentKeyframes r;
  r.assign(index, entries);
  return r;
}

class StreamSelection : public ::testing::Test {
 protected:
  // 40³: a root and 8 finest children; 10 time steps.
  SpatialIndex index = test::make_index({40, 40, 40}, 10);
  std::uint32_t child = index.find({1, 0, 0, 0});
};

TEST_F(StreamSelection, Paragraph0039Example) {
  ASSERT_EQ(index.level_count(), 2u);
  ASSERT_NE(child, no_node);
  // Playhead 5.5; detailed (finest) keyframes at 5 and 7, a coarser one (the root) at 6.
  const auto r = resident(index, {{child, 5}, {child, 7}, {0, 6}});
  const KeyframePair p = select_keyframe_pair(index, child, 5.5, r);
  // Before: own 5 at distance 0.5; the root has nothing before 5.5, so its 6 stands in at
  // 0.5·200·e^4. After: own 7 at 1.5 beats the root's 6 at 0.5·e^4 ≈ 27.3. The formulas keep the
  // detailed pair (visual quality); the patent's example pair (5, coarse 6) needs a weaker
  // handicap.
  EXPECT_EQ(p.a.t, 5u);
  EXPECT_EQ(p.a.lod_difference, 0u);
  EXPECT_DOUBLE_EQ(p.a.score, 0.5);
  EXPECT_EQ(p.b.t, 7u);
  EXPECT_EQ(p.b.lod_difference, 0u);
  EXPECT_DOUBLE_EQ(p.b.score, 1.5);
  EXPECT_FLOAT_EQ(p.factor, 0.25f);
  EXPECT_TRUE(p.at_full_detail());
  EXPECT_EQ(p.a.slot, 0u);
  EXPECT_EQ(p.b.slot, 1u);

  // With handicap exp(1·up): 0.5·e ≈ 1.36 < 1.5, so the coarser keyframe at 6 is taken — the
  // patent's example interpolates between 5.0 (detailed) and 6.0 (coarser).
  SelectionSettings weak;
  weak.ancestor_handicap = 1.0;
  const KeyframePair q = select_keyframe_pair(index, child, 5.5, r, weak);
  EXPECT_EQ(q.a.t, 5u);
  EXPECT_EQ(q.b.t, 6u);
  EXPECT_EQ(q.b.lod_difference, 1u);
  EXPECT_FALSE(q.b.exact);
  EXPECT_DOUBLE_EQ(q.b.score, 0.5 * std::exp(1.0));
  EXPECT_FLOAT_EQ(q.factor, 0.5f);
  EXPECT_FALSE(q.drawn_by_ancestor());
}

TEST_F(StreamSelection, MissingSideFallsBackToTheAncestor) {
  // Only 5 is resident at the node: its "after" side is missing (5 stands in at 0.5·200 = 100),
  // so the root's 6 at 0.5·e^4 ≈ 27.3 wins.
  const auto r = resident(index, {{child, 5}, {0, 6}});
  const KeyframePair p = select_keyframe_pair(index, child, 5.5, r);
  EXPECT_EQ(p.a.t, 5u);
  EXPECT_EQ(p.a.lod_difference, 0u);
  EXPECT_EQ(p.b.t, 6u);
  EXPECT_EQ(p.b.lod_difference, 1u);
  EXPECT_DOUBLE_EQ(p.b.score, 0.5 * std::exp(4.0));
  EXPECT_FLOAT_EQ(p.factor, 0.5f);
  // Nothing at all on either side of the root: the missing side uses the same keyframe.
  const auto only_root = resident(index, {{0, 6}});
  const KeyframePair root_pair = select_keyframe_pair(index, 0, 5.5, only_root);
  EXPECT_EQ(root_pair.a.t, 6u);
  EXPECT_DOUBLE_EQ(root_pair.a.score, 0.5 * 200);
  EXPECT_EQ(root_pair.b.t, 6u);
  EXPECT_FLOAT_EQ(root_pair.factor, 0.0f);
  // The child with only the root resident: both picks from the ancestor, drawn by it ([0048]).
  const KeyframePair c = select_keyframe_pair(index, child, 5.5, only_root);
  EXPECT_TRUE(c.valid());
  EXPECT_TRUE(c.drawn_by_ancestor());
  // Nothing resident: no pair.
  EXPECT_FALSE(select_keyframe_pair(index, child, 5.5, resident(index, {})).valid());
  // On a keyframe: both sides pick it.
  const auto on = resident(index, {{child, 5}, {child, 7}});
  const KeyframePair e = select_keyframe_pair(index, child, 5.0, on);
  EXPECT_EQ(e.a.t, 5u);
  EXPECT_EQ(e.b.t, 5u);
  EXPECT_FLOAT_EQ(e.factor, 0.0f);
}

/// A constant subtree: the root of frame 1 is `empty`, so frame 1 has no finest bricks.
TEST(StreamSelectionConstant, AConstantAncestorIsExactData) {
  const Dims dims{40, 40, 40};
  Volume varying(dims), constant(dims);
  datasets::AnalyticParams p;
  p.dims = dims;
  datasets::analytic_frame(p, 0, varying.data);
  std::fill(constant.data.begin(), constant.data.end(), 0.25f);
  const encoder::FrameEncoder enc(nullptr, test::zfp_coding());
  const auto b0 = enc.encode(0, varying), b1 = enc.encode(1, constant), b2 = enc.encode(2, varying);
  SpatialIndexBuilder builder({40, 40, 40}, 3);
  builder.add_frame(0, format::FrameView(b0, "0.vrf"), "0.vrf");
  builder.add_frame(1, format::FrameView(b1, "1.vrf"), "1.vrf");
  builder.add_frame(2, format::FrameView(b2, "2.vrf"), "2.vrf");
  const SpatialIndex index = std::move(builder).build();
  const std::uint32_t child = index.find({1, 1, 1, 1});
  ASSERT_NE(child, no_node);
  ASSERT_TRUE(index.keyframe(index.find_keyframe(0, 1)).subtree_constant);
  EXPECT_TRUE(index.keyframe(index.find_keyframe(0, 1)).constant);
  EXPECT_EQ(index.find_keyframe(child, 1), no_keyframe);  // nothing below a constant root
  EXPECT_EQ(index.times(child).size(), 2u);
  // Playhead 0.75: the child's own 0 before; after, the constant root at 1 is exact (no
  // handicap: 0.25 beats the child's own 2 at 1.25).
  const auto r = resident(index, {{child, 0}, {child, 2}, {0, 1}});
  const KeyframePair pair = select_keyframe_pair(index, child, 0.75, r);
  EXPECT_EQ(pair.a.t, 0u);
  EXPECT_EQ(pair.b.t, 1u);
  EXPECT_EQ(pair.b.lod_difference, 1u);
  EXPECT_TRUE(pair.b.exact);
  EXPECT_DOUBLE_EQ(pair.b.score, 0.25);
  EXPECT_TRUE(pair.at_full_detail());
  EXPECT_FLOAT_EQ(pair.factor, 0.75f);
  // Stored times remembered over a pass (and started again for each playhead) pick the same.
  StoredTimes stored;
  for (const double at : {0.0, 0.75, 1.0, 1.5, 2.0, 0.25}) {
    stored.start(index, at);
    for (const std::uint32_t n : {std::uint32_t{0}, child, index.find({1, 0, 0, 0})}) {
      const KeyframePair alone = select_keyframe_pair(index, n, at, r);
      const KeyframePair shared = select_keyframe_pair(index, n, at, r, {}, &stored);
      EXPECT_EQ(shared.a.keyframe, alone.a.keyframe) << "node " << n << " at " << at;
      EXPECT_EQ(shared.b.keyframe, alone.b.keyframe) << "node " << n << " at " << at;
      EXPECT_EQ(shared.a.score, alone.a.score) << "node " << n << " at " << at;
      EXPECT_EQ(shared.b.score, alone.b.score) << "node " << n << " at " << at;
      EXPECT_EQ(shared.factor, alone.factor) << "node " << n << " at " << at;
    }
  }
  EXPECT_EQ(stored.nearest(child, true, false), 2.0);   // after 0.25: the child's own at 2
  EXPECT_EQ(stored.nearest(0, true, true), 1.0);        // the constant root at 1
  EXPECT_EQ(stored.nearest(child, false, true), -1.0);  // the child is never constant
}

TEST_F(StreamSelection, SvoOfPartlyResidentData) {
  const player::OrbitCamera cam = test::close_camera({40, 40, 40});
  ViewTraversal view;
  view.run(index, cam, 1.0);
  ASSERT_EQ(view.visits().size(), 9u);
  ASSERT_TRUE(view.visit(0).refine);
  // Root at 5 and 6; child octant 0 at 5 and 6; octant 3 only at 5 (its after side comes from
  // the root); the other children have nothing (drawn by the root).
  const std::uint32_t c0 = index.node(0).children[0], c3 = index.node(0).children[3];
  const auto r = resident(index, {{0, 5}, {0, 6}, {c0, 5}, {c0, 6}, {c3, 5}});
  SvoStats stats;
  const SvoArrays svo = build_svo(index, view, r, 5.25, {}, &stats);
  EXPECT_TRUE(validate_svo(svo.nodes, svo.leaves, 5, index.level_count()).empty());
  ASSERT_EQ(svo.nodes.size(), VR_SVO_NODE_WORDS);  // the root's record only
  ASSERT_EQ(svo.leaves.size(), 3 * VR_SVO_LEAF_WORDS);
  EXPECT_EQ(svo.nodes[0], VR_SVO_NO_PARENT);
  const auto kind = [&](std::size_t octant) { return vr_svo_child_kind(svo.nodes[1 + octant]); };
  EXPECT_EQ(kind(0), VR_SVO_CHILD_LEAF);
  EXPECT_EQ(kind(3), VR_SVO_CHILD_LEAF);
  for (std::size_t o : {1u, 2u, 4u, 5u, 6u, 7u}) EXPECT_EQ(kind(o), VR_SVO_CHILD_UP) << o;
  // Octant 0's leaf: slots 2 and 3 (its own 5 and 6), d = 0, factor 0.25.
  const std::uint32_t* l0 = &svo.leaves[vr_svo_child_index(svo.nodes[1]) * VR_SVO_LEAF_WORDS];
  EXPECT_EQ(l0[0], 2u);
  EXPECT_EQ(l0[1], 3u);
  EXPECT_EQ(l0[2], vr_svo_lod_pack(0, 0));
  EXPECT_EQ(std::bit_cast<float>(l0[3]), 0.25f);
  // Octant 3's leaf: its own 5 (slot 4) and the root's 6 (slot 1) one level up.
  const std::uint32_t* l3 = &svo.leaves[vr_svo_child_index(svo.nodes[4]) * VR_SVO_LEAF_WORDS];
  EXPECT_EQ(l3[0], 4u);
  EXPECT_EQ(l3[1], 1u);
  EXPECT_EQ(l3[2], vr_svo_lod_pack(0, 1));
  // The root's own leaf draws the other octants.
  const std::uint32_t* own = &svo.leaves[svo.nodes[9] * VR_SVO_LEAF_WORDS];
  EXPECT_EQ(own[0], 0u);
  EXPECT_EQ(own[1], 1u);
  EXPECT_EQ(stats.target_nodes, 8u);
  EXPECT_EQ(stats.at_target_nodes, 1u);
  EXPECT_EQ(stats.ancestor_drawn, 6u);
  EXPECT_EQ(stats.used_slots, (std::vector<std::uint32_t>{0, 1, 2, 3, 4}));

  // Only the root resident: one record, every octant drawn by its own leaf.
  const SvoArrays root_only = build_svo(index, view, resident(index, {{0, 5}}), 5.25);
  EXPECT_TRUE(validate_svo(root_only.nodes, root_only.leaves, 1, 2).empty());
  ASSERT_EQ(root_only.nodes.size(), VR_SVO_NODE_WORDS);
  ASSERT_EQ(root_only.leaves.size(), VR_SVO_LEAF_WORDS);
  for (int o = 0; o < 8; ++o)
    EXPECT_EQ(vr_svo_child_kind(root_only.nodes[1 + static_cast<std::size_t>(o)]), VR_SVO_CHILD_UP);
  // Nothing resident: every octant empty, no leaf.
  const SvoArrays none = build_svo(index, view, resident(index, {}), 5.25);
  EXPECT_TRUE(validate_svo(none.nodes, none.leaves, 1, 2).empty());
  EXPECT_EQ(none.nodes[9], VR_SVO_NO_LEAF);
  EXPECT_TRUE(none.leaves.empty());
}

TEST_F(StreamSelection, LodBlendingFadesNewDetailInAndBlendsTowardsCoarserNeighbours) {
  const player::OrbitCamera cam = test::close_camera({40, 40, 40});
  ViewTraversal view;
  view.run(index, cam, 1.0);
  ASSERT_TRUE(view.visit(0).refine);
  const std::uint32_t c0 = index.node(0).children[0];
  // Corner bytes of octant 0's leaf, and the leaf itself.
  const auto leaf_of = [&](const SvoArrays& svo, std::uint32_t octant) {
    EXPECT_EQ(vr_svo_child_kind(svo.nodes[1 + octant]), VR_SVO_CHILD_LEAF);
    return &svo.leaves[vr_svo_child_index(svo.nodes[1 + octant]) * VR_SVO_LEAF_WORDS];
  };
  const auto corners = [](const std::uint32_t* leaf) {
    std::array<std::uint32_t, 8> c{};
    for (std::uint32_t i = 0; i < 8; ++i) c[i] = vr_svo_blend_corner(leaf[7], leaf[8], i);
    return c;
  };
  LodBlendState blend;
  blend.settings.fade_s = 1.0;
  blend.settings.fade_out_s = 1.0;
  blend.settings.spatial = true;
  SvoStats stats;
  // Slots are numbered in the order the resident list was written: at most 18 (root + 8 × 2).
  const auto build = [&](const ResidentKeyframes& r, double now) {
    SvoArrays svo = build_svo(index, view, r, 5.25, {}, &stats, nullptr, {}, &blend, now);
    EXPECT_TRUE(validate_svo(svo.nodes, svo.leaves, 18, index.level_count()).empty());
    return svo;
  };
  // 1. Only the root resident: every octant drawn by the root, nothing blends.
  const auto root_only = resident(index, {{0, 5}, {0, 6}});
  EXPECT_EQ(build(root_only, 0.0).leaves.size(), VR_SVO_LEAF_WORDS);
  EXPECT_EQ(stats.blended_leaves, 0u);
  // 2. Octant 0's bricks arrive: it fades in from the root's drawing. Its coarse pair is the
  //    root's (slots 0 and 1, one level up, the root's factor); every corner starts at 0.
  const auto with_c0 = resident(index, {{0, 5}, {0, 6}, {c0, 5}, {c0, 6}});
  SvoArrays svo = build(with_c0, 1.0);
  const std::uint32_t* leaf = leaf_of(svo, 0);
  EXPECT_EQ(leaf[0], 2u);
  EXPECT_EQ(leaf[4], 0u);
  EXPECT_EQ(leaf[5], 1u);
  EXPECT_EQ(vr_svo_lod_c(leaf[2]), 1u);
  EXPECT_EQ(vr_svo_lod_d(leaf[2]), 1u);
  EXPECT_EQ(std::bit_cast<float>(leaf[6]), 0.25f);
  EXPECT_EQ(corners(leaf), (std::array<std::uint32_t, 8>{0, 0, 0, 0, 0, 0, 0, 0}));
  EXPECT_EQ(stats.blended_leaves, 1u);
  EXPECT_EQ(stats.used_slots, (std::vector<std::uint32_t>{0, 1, 2, 3}));
  // 3. Half way: corner 0 (the volume's corner, no neighbour) at 0.5; the other corners touch
  //    octants drawn by the root (coarser) and stay 0 (spatial blending).
  svo = build(with_c0, 1.5);
  EXPECT_EQ(corners(leaf_of(svo, 0)), (std::array<std::uint32_t, 8>{128, 0, 0, 0, 0, 0, 0, 0}));
  // 4. Faded in.
  svo = build(with_c0, 2.5);
  EXPECT_EQ(corners(leaf_of(svo, 0)), (std::array<std::uint32_t, 8>{255, 0, 0, 0, 0, 0, 0, 0}));
  // 5. Every octant's bricks: the seven new ones fade in, each corner they share taking the
  //    least weight among them (0); octant 0 has faded in already and keeps its weights (a
  //    neighbour that starts fading does not pull it back to the root's drawing).
  std::vector<std::pair<std::uint32_t, std::uint32_t>> all = {{0, 5}, {0, 6}};
  for (const std::uint32_t c : index.node(0).children) {
    all.emplace_back(c, 5);
    all.emplace_back(c, 6);
  }
  std::vector<ResidentKeyframe> entries;
  for (std::uint32_t i = 0; i < all.size(); ++i)
    entries.push_back({index.find_keyframe(all[i].first, all[i].second), i});
  ResidentKeyframes everything;
  everything.assign(index, entries);
  svo = build(everything, 3.0);
  EXPECT_EQ(leaf_of(svo, 0)[7], VR_SVO_BLEND_NONE);
  EXPECT_EQ(leaf_of(svo, 0)[8], VR_SVO_BLEND_NONE);
  EXPECT_EQ(corners(leaf_of(svo, 7)), (std::array<std::uint32_t, 8>{0, 0, 0, 0, 0, 0, 0, 0}));
  svo = build(everything, 3.25);
  EXPECT_EQ(leaf_of(svo, 0)[7], VR_SVO_BLEND_NONE);
  EXPECT_EQ(corners(leaf_of(svo, 7)),
            (std::array<std::uint32_t, 8>{64, 64, 64, 64, 64, 64, 64, 64}));
  // Two neighbours fading in at different times meet at the later one's weight: octant 1's
  // bricks leave and come back at 3.5, so it fades in again from 0 while octant 3 is at 0.5.
  std::vector<ResidentKeyframe> without_1;
  for (const ResidentKeyframe& e : entries)
    if (index.node_of(e.keyframe) != index.node(0).children[1]) without_1.push_back(e);
  ResidentKeyframes missing_1;
  missing_1.assign(index, without_1);
  build(missing_1, 3.45);
  svo = build(everything, 3.5);
  // Octant 3 at (1, 1, 0) shares its face y = 0 (corners 0, 1, 4, 5) with octant 1 at (1, 0, 0):
  // those corners take octant 1's weight 0; corners 3 and 7 touch only octants fading since 3.0
  // or the volume's outside: octant 3's own 0.5.
  const auto c3 = corners(leaf_of(svo, 3));
  EXPECT_EQ(c3[0], 0u);
  EXPECT_EQ(c3[1], 0u);
  EXPECT_EQ(c3[5], 0u);
  EXPECT_EQ(c3[3], 128u);
  EXPECT_EQ(c3[7], 128u);
  // 6. All faded in: nothing blends, and the coarse slots are not used.
  svo = build(everything, 4.5);
  for (std::uint32_t o = 0; o < 8; ++o) {
    EXPECT_EQ(leaf_of(svo, o)[7], VR_SVO_BLEND_NONE) << o;
    EXPECT_EQ(leaf_of(svo, o)[8], VR_SVO_BLEND_NONE) << o;
  }
  EXPECT_EQ(stats.blended_leaves, 0u);
  // 7. The camera moves away and the root alone is the cut (a collapse): the octants fade out
  //    towards the root's drawing, each leaf's coarse pair the root's, then the root draws alone.
  ViewTraversal far_view;
  player::OrbitCamera far_cam = cam;
  far_cam.distance *= 100;
  far_view.run(index, far_cam, 1.0);
  ASSERT_FALSE(far_view.visit(0).refine);
  const auto build_far = [&](double now) {
    SvoArrays far =
        build_svo(index, far_view, everything, 5.25, {}, &stats, nullptr, {}, &blend, now);
    EXPECT_TRUE(validate_svo(far.nodes, far.leaves, 18, index.level_count()).empty());
    return far;
  };
  svo = build_far(5.0);
  ASSERT_EQ(svo.nodes.size(), VR_SVO_NODE_WORDS);
  EXPECT_EQ(stats.target_nodes, 1u);
  for (std::uint32_t o = 0; o < 8; ++o) {
    EXPECT_EQ(corners(leaf_of(svo, o)),
              (std::array<std::uint32_t, 8>{255, 255, 255, 255, 255, 255, 255, 255}))
        << o;
    EXPECT_EQ(leaf_of(svo, o)[4], 0u);  // coarse pair: the root's
  }
  svo = build_far(5.5);
  for (std::uint32_t o = 0; o < 8; ++o)
    EXPECT_EQ(corners(leaf_of(svo, o)),
              (std::array<std::uint32_t, 8>{128, 128, 128, 128, 128, 128, 128, 128}))
        << o;
  EXPECT_EQ(stats.blended_leaves, 8u);
  EXPECT_EQ(stats.used_slots.size(), 18u);  // the octants' slots are kept while they fade
  svo = build_far(6.0);
  EXPECT_EQ(svo.leaves.size(), VR_SVO_LEAF_WORDS);  // faded out: the root's leaf alone
  for (std::uint32_t o = 0; o < 8; ++o)
    EXPECT_EQ(vr_svo_child_kind(svo.nodes[1 + o]), VR_SVO_CHILD_UP) << o;
  EXPECT_EQ(stats.used_slots, (std::vector<std::uint32_t>{0, 1}));
  // A collapse where the octants' resident bricks are of other times than the playhead needs
  // (keyframes 5 and 6 at playhead 7.5, after a seek): they are further from the truth than the
  // root's own drawing at 7 and 8, so nothing fades out.
  LodBlendState stale;
  stale.settings.fade_out_s = 1.0;
  std::vector<ResidentKeyframe> old_octants = {{index.find_keyframe(0, 7), 0},
                                               {index.find_keyframe(0, 8), 1}};
  for (std::uint32_t i = 2; i < entries.size(); ++i) old_octants.push_back(entries[i]);
  ResidentKeyframes seeked;
  seeked.assign(index, old_octants);
  build_svo(index, view, everything, 5.25, {}, &stats, nullptr, {}, &stale, 20.0);
  svo = build_svo(index, far_view, seeked, 7.5, {}, &stats, nullptr, {}, &stale, 20.1);
  EXPECT_EQ(svo.leaves.size(), VR_SVO_LEAF_WORDS);
  EXPECT_EQ(stats.target_nodes, 1u);
  // The same collapse with the octants' bricks at 7 and 8 fades out.
  std::vector<ResidentKeyframe> current = {old_octants[0], old_octants[1]};
  for (const std::uint32_t c : index.node(0).children)
    for (const std::uint32_t t : {7u, 8u})
      current.push_back({index.find_keyframe(c, t), static_cast<std::uint32_t>(current.size())});
  ResidentKeyframes at_7;
  at_7.assign(index, current);
  build_svo(index, view, at_7, 7.5, {}, &stats, nullptr, {}, &stale, 30.0);
  svo = build_svo(index, far_view, at_7, 7.5, {}, &stats, nullptr, {}, &stale, 30.1);
  EXPECT_EQ(svo.leaves.size(), 8 * VR_SVO_LEAF_WORDS);
  // Without a fade, a collapse is at once.
  LodBlendState instant;
  instant.settings.fade_out_s = 0;
  instant.settings.spatial = true;
  build_svo(index, view, everything, 5.25, {}, &stats, nullptr, {}, &instant, 0.0);
  svo = build_svo(index, far_view, everything, 5.25, {}, &stats, nullptr, {}, &instant, 0.1);
  EXPECT_EQ(svo.leaves.size(), VR_SVO_LEAF_WORDS);
  // 8. A node first seen with its bricks resident (not visited in the last build) is drawn at
  //    once; without spatial blending its corners next to coarser octants are not lowered.
  LodBlendState fresh;
  fresh.settings.fade_s = 1.0;
  fresh.settings.spatial = false;
  svo = build_svo(index, view, with_c0, 5.25, {}, &stats, nullptr, {}, &fresh, 10.0);
  EXPECT_EQ(leaf_of(svo, 0)[7], VR_SVO_BLEND_NONE);
  EXPECT_EQ(leaf_of(svo, 0)[8], VR_SVO_BLEND_NONE);
  // 9. At start-up (nothing drawn in the last build, a hole) new bricks are drawn at once: there
  //    is no drawing to fade from.
  LodBlendState start;
  start.settings.fade_s = 1.0;
  start.settings.spatial = true;
  build_svo(index, view, resident(index, {}), 5.25, {}, &stats, nullptr, {}, &start, 0.0);
  svo = build_svo(index, view, with_c0, 5.25, {}, &stats, nullptr, {}, &start, 0.1);
  EXPECT_EQ(corners(leaf_of(svo, 0)), (std::array<std::uint32_t, 8>{255, 0, 0, 0, 0, 0, 0, 0}));
  // Without a blend state nothing blends either.
  svo = build_svo(index, view, with_c0, 5.25, {}, &stats);
  EXPECT_EQ(leaf_of(svo, 0)[7], VR_SVO_BLEND_NONE);
  EXPECT_EQ(leaf_of(svo, 0)[4], VR_ATLAS_NO_SLOT);
}

/// The regions an SVO draws: per spatial node whose cell a leaf or an "up" octant covers, the data
/// level it is drawn at (the node's level minus the coarser LOD difference its keyframes read).
std::vector<std::pair<std::uint32_t, std::uint32_t>> drawn_regions(const SpatialIndex& index,
                                                                   const SvoArrays& svo) {
  std::vector<std::pair<std::uint32_t, std::uint32_t>> regions;
  const auto data_level = [&](std::uint32_t level, std::uint32_t leaf) {
    const std::uint32_t* w = &svo.leaves[std::size_t{leaf} * VR_SVO_LEAF_WORDS];
    return level - vr_svo_coarser_lod(w[2], std::bit_cast<float>(w[3]));
  };
  const std::size_t records = svo.nodes.size() / VR_SVO_NODE_WORDS;
  for (std::size_t r = 0; r < records; ++r) {
    const std::uint32_t* w = &svo.nodes[r * VR_SVO_NODE_WORDS];
    const SpatialNode& n = index.node(svo.node_ids[r]);
    for (std::uint32_t i = 0; i < 8; ++i) {
      const std::uint32_t kind = vr_svo_child_kind(w[1 + i]);
      const std::uint32_t cell = n.has_children ? n.children[i] : svo.node_ids[r];
      if (kind == VR_SVO_CHILD_LEAF)
        regions.emplace_back(cell, data_level(n.key.level + 1, vr_svo_child_index(w[1 + i])));
      else if (kind == VR_SVO_CHILD_UP)
        regions.emplace_back(cell, data_level(n.key.level, w[9]));
    }
  }
  return regions;
}

/// Pairs of drawn regions that touch (by a face, an edge or a corner) with data levels more than
/// one apart.
std::size_t drawn_violations(const SpatialIndex& index, const SvoArrays& svo) {
  const auto regions = drawn_regions(index, svo);
  std::size_t violations = 0;
  for (std::size_t i = 0; i < regions.size(); ++i)
    for (std::size_t j = i + 1; j < regions.size(); ++j) {
      const SpatialNode &a = index.node(regions[i].first), &b = index.node(regions[j].first);
      bool touch = true;
      for (std::size_t k = 0; k < 3; ++k) touch = touch && a.lo[k] <= b.hi[k] && b.lo[k] <= a.hi[k];
      const std::uint32_t la = regions[i].second, lb = regions[j].second;
      if (touch && (la > lb + 1 || lb > la + 1)) ++violations;
    }
  return violations;
}

TEST(StreamSvoRestricted, TouchingRegionsAreDrawnAtMostOneLevelApart) {
  // 80³ in bricks of 12³: 4 levels; every visible node refined to the finest.
  const SpatialIndex index = test::make_index({80, 80, 80}, 2, 12);
  ASSERT_EQ(index.level_count(), 4u);
  ViewTraversal view;
  view.run(index, test::close_camera({80, 80, 80}), 0.5);
  // A finest node X at the volume's corner, and its ancestors A2 (level 2) and A1 (level 1): each
  // touches only its own siblings, inside its parent's cell.
  const std::uint32_t x = index.find({3, 0, 0, 0});
  ASSERT_NE(x, no_node);
  ASSERT_TRUE(view.visited(x));
  ASSERT_FALSE(view.visit(x).refine);
  const std::uint32_t a2 = index.node(x).parent, a1 = index.node(a2).parent;
  for (const std::uint32_t n : {x, a2, a1, 0u})
    ASSERT_FALSE(index.keyframe(index.find_keyframe(n, 0)).subtree_constant);
  const SelectionSettings restricted;  // the default
  EXPECT_TRUE(restricted.restricted);
  SelectionSettings free;
  free.restricted = false;
  const auto build = [&](const ResidentKeyframes& r, const SelectionSettings& s, SvoStats& st) {
    SvoArrays svo = build_svo(index, view, r, 0.0, s, &st);
    EXPECT_TRUE(validate_svo(svo.nodes, svo.leaves, 8, index.level_count()).empty());
    return svo;
  };
  const auto max_level = [&](const SvoArrays& svo) {
    std::uint32_t m = 0;
    for (const auto& region : drawn_regions(index, svo)) m = std::max(m, region.second);
    return m;
  };
  SvoStats free_stats, stats;

  // 1. Every ancestor resident: X at level 3 beside its siblings drawn by A2 (2), A2's siblings
  //    by A1 (1), A1's by the root (0). Nothing to restrict: the same SVO either way.
  const auto chain = resident(index, {{0, 0}, {a1, 0}, {a2, 0}, {x, 0}});
  const SvoArrays free_chain = build(chain, free, free_stats);
  EXPECT_EQ(drawn_violations(index, free_chain), 0u);
  const SvoArrays chain_r = build(chain, restricted, stats);
  EXPECT_EQ(chain_r.nodes, free_chain.nodes);
  EXPECT_EQ(chain_r.leaves, free_chain.leaves);
  EXPECT_EQ(stats.restricted_nodes, 0u);
  EXPECT_EQ(stats.restriction_builds, 0u);
  EXPECT_EQ(max_level(chain_r), 3u);

  // 2. A2 missing: X (3) touches its siblings, drawn by A1's data (1). X is drawn from A1 too.
  const auto no_a2 = resident(index, {{0, 0}, {a1, 0}, {x, 0}});
  const SvoArrays free_no_a2 = build(no_a2, free, free_stats);
  EXPECT_GT(drawn_violations(index, free_no_a2), 0u);
  EXPECT_EQ(max_level(free_no_a2), 3u);
  const SvoArrays no_a2_r = build(no_a2, restricted, stats);
  EXPECT_EQ(drawn_violations(index, no_a2_r), 0u);
  EXPECT_EQ(max_level(no_a2_r), 1u);  // A1's detail kept
  EXPECT_EQ(stats.restricted_nodes, 1u);
  EXPECT_EQ(stats.restriction_builds, 1u);

  // 3. A1 missing: A2's regions (2) touch the root's (0), and then X (3) touches the root's: both
  //    drawn from the root, in two rounds.
  const auto no_a1 = resident(index, {{0, 0}, {a2, 0}, {x, 0}});
  const SvoArrays free_no_a1 = build(no_a1, free, free_stats);
  EXPECT_GT(drawn_violations(index, free_no_a1), 0u);
  const SvoArrays no_a1_r = build(no_a1, restricted, stats);
  EXPECT_EQ(drawn_violations(index, no_a1_r), 0u);
  EXPECT_EQ(max_level(no_a1_r), 0u);
  EXPECT_EQ(stats.restricted_nodes, 2u);
  EXPECT_EQ(stats.restriction_builds, 2u);
  EXPECT_EQ(stats.target_nodes, free_stats.target_nodes);

  // 4. With the blending's state: the same drawing, and the state's scratch reused.
  LodBlendState blend;
  blend.settings.fade_s = 1.0;
  SvoStats blend_stats;
  const SvoArrays blended =
      build_svo(index, view, no_a1, 0.0, restricted, &blend_stats, nullptr, {}, &blend, 0.0);
  EXPECT_TRUE(validate_svo(blended.nodes, blended.leaves, 8, index.level_count()).empty());
  EXPECT_EQ(drawn_violations(index, blended), 0u);
  EXPECT_EQ(blend_stats.restricted_nodes, 2u);
  EXPECT_EQ(blend_stats.restriction_builds, 3u);  // two rounds, then the build that blends
  EXPECT_EQ(blend.drawn.stamp.size(), index.node_count());
}

TEST(StreamSvo, ValidationFindsBrokenTrees) {
  // A root with a node child whose parent word is wrong, a leaf with a slot out of range and a
  // LOD difference deeper than its node.
  std::vector<std::uint32_t> nodes(2 * VR_SVO_NODE_WORDS, 0),
      leaves{7,
             0,
             vr_svo_lod_pack(0, 3),
             std::bit_cast<std::uint32_t>(0.5f),
             VR_ATLAS_NO_SLOT,
             VR_ATLAS_NO_SLOT,
             0,
             VR_SVO_BLEND_NONE,
             VR_SVO_BLEND_NONE};
  nodes[0] = VR_SVO_NO_PARENT;
  nodes[1] = vr_svo_child_word(VR_SVO_CHILD_NODE, 1);
  for (int i = 2; i <= 8; ++i)
    nodes[static_cast<std::size_t>(i)] = vr_svo_child_word(VR_SVO_CHILD_EMPTY, 0);
  nodes[9] = VR_SVO_NO_LEAF;
  nodes[10] = 5;  // wrong parent
  nodes[11] = vr_svo_child_word(VR_SVO_CHILD_LEAF, 0);
  for (int i = 12; i <= 18; ++i)
    nodes[static_cast<std::size_t>(i)] = vr_svo_child_word(VR_SVO_CHILD_EMPTY, 0);
  nodes[19] = VR_SVO_NO_LEAF;
  const auto problems = validate_svo(nodes, leaves, 4, 3);
  EXPECT_EQ(problems.size(), 3u);
  // Fixed, it validates.
  nodes[10] = 0;
  leaves[0] = 1;
  leaves[2] = vr_svo_lod_pack(0, 2);
  EXPECT_TRUE(validate_svo(nodes, leaves, 4, 3).empty());
  // A record deeper than the octree's levels.
  EXPECT_FALSE(validate_svo(nodes, leaves, 4, 2).empty());
  // A leaf that blends needs a coarse pair: slots in range, LOD differences in [1, depth].
  leaves[7] = 0x00FF00FFu;
  EXPECT_EQ(validate_svo(nodes, leaves, 4, 3).size(), 3u);  // two slots, two LOD differences
  leaves[4] = 2;
  leaves[5] = 3;
  leaves[2] |= vr_svo_lod_pack(1, 2) << 16;
  EXPECT_TRUE(validate_svo(nodes, leaves, 4, 3).empty());
  leaves[6] = std::bit_cast<std::uint32_t>(1.5f);
  EXPECT_EQ(validate_svo(nodes, leaves, 4, 3).size(), 1u);
}

}  // namespace
}  // namespace volreel::stream
