// scheduler_test.cpp: the scheduler end to end on small zfp containers: convergence to full
// detail with the SVO referencing only resident slots, the per-frame upload budget, discarding of
// stale arrivals, and I/O errors reported and retried without blocking the rest.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <map>
#include <set>
#include <thread>

#include "../keyframe_series.hpp"
#include "stream_test_util.hpp"
#include "volreel/stream/scheduler.hpp"

namespace volreel::stream {
namespace {

constexpr Dims dims{40, 40, 40};

/// Runs frames until done(update) or about 10 s; retires every frame at once (a synchronous
/// renderer). Checks every upload's payload against the frame file. Returns the last update.
template <class Done>
FrameUpdate run_until(StreamScheduler& s, const player::OrbitCamera& cam, double playhead,
                      std::uint64_t& frame, Done done,
                      std::vector<BrickUpload>* uploads = nullptr) {
  FrameUpdate u;
  for (int i = 0; i < 5000; ++i) {
    u = s.update(cam, playhead, frame);
    s.retire(frame);
    ++frame;
    for (BrickUpload& up : u.uploads) {
      const KeyframeId id = s.index().find_keyframe(up.key);
      EXPECT_NE(id, no_keyframe);
      EXPECT_EQ(up.payload.size(), s.index().keyframe(id).bytes);
      EXPECT_EQ(up.offset, s.index().keyframe(id).offset);
      EXPECT_EQ(up.constant, up.payload.size() == 4);
      if (uploads) uploads->push_back(std::move(up));
    }
    if (done(u)) return u;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  ADD_FAILURE() << "did not converge";
  return u;
}

/// Every leaf of the SVO references occupied slots holding keyframe nodes of the right spatial
/// node (its own, or the ancestor its LOD difference names).
void expect_svo_references_resident_slots(const StreamScheduler& s, const FrameUpdate& u) {
  const auto problems =
      validate_svo(u.svo_nodes, u.svo_leaves, s.atlas().capacity(), s.index().level_count());
  EXPECT_TRUE(problems.empty()) << problems.front();
  for (std::size_t l = 0; l < u.svo_leaves.size(); l += VR_SVO_LEAF_WORDS)
    for (int k = 0; k < 2; ++k) {
      const std::uint32_t slot = u.svo_leaves[l + static_cast<std::size_t>(k)];
      EXPECT_EQ(s.atlas().state(slot), AtlasSlots::State::occupied) << "slot " << slot;
      EXPECT_TRUE(s.atlas().key(slot).has_value());
    }
}

class StreamSchedulerPolicy : public ::testing::TestWithParam<PriorityPolicy> {};

TEST_P(StreamSchedulerPolicy, ConvergesToEveryVisibleFinestNodeResident) {
  test::TempDir dir("stream-scheduler");
  const auto path = test::make_container(dir.path(), dims, 4);
  const format::Container c(path);
  SchedulerSettings settings;
  settings.atlas_slots = 64;
  settings.priority.policy = GetParam();
  StreamScheduler s(c, settings);
  ASSERT_TRUE(s.errors().empty());
  ASSERT_EQ(s.index().node_count(), 9u);
  const auto cam = test::close_camera(dims);
  std::uint64_t frame = 0;
  std::vector<BrickUpload> uploads;
  const double playhead = 1.5;
  const FrameUpdate u = run_until(
      s, cam, playhead, frame,
      [&](const FrameUpdate& f) {
        return f.stats.fraction_at_target == 1.0 && f.stats.requests_in_flight == 0 &&
               f.stats.arrivals_waiting == 0 && f.stats.atlas_occupied == 36;
      },
      &uploads);
  // All 9 nodes × 4 keyframes fit (heap and atlas of 64): every one was loaded once.
  EXPECT_EQ(uploads.size(), 36u);
  EXPECT_EQ(u.stats.target_nodes, 8u);
  EXPECT_EQ(u.stats.at_target_nodes, 8u);
  EXPECT_EQ(u.stats.holes, 0u);
  EXPECT_EQ(u.stats.errors, 0u);
  // The uploaded payloads are the frame files' bricks.
  for (const BrickUpload& up : uploads) {
    const format::FrameFile f = c.open_frame(up.key.t);
    const std::uint32_t node = s.index().find({up.key.level, up.key.x, up.key.y, up.key.z});
    const KeyframeNode& k = s.index().keyframe(s.index().find_keyframe(node, up.key.t));
    const auto bytes = f.view().brick_bytes(k.brick);
    EXPECT_TRUE(std::equal(bytes.begin(), bytes.end(), up.payload.begin(), up.payload.end()));
  }
  expect_svo_references_resident_slots(s, u);
  // The root refines into 8 leaves, each interpolating its own keyframes 1 and 2 halfway.
  ASSERT_EQ(u.svo_nodes.size(), VR_SVO_NODE_WORDS);
  EXPECT_EQ(u.svo_nodes[9], VR_SVO_NO_LEAF);
  for (std::uint32_t i = 0; i < 8; ++i) {
    const std::uint32_t word = u.svo_nodes[1 + i];
    ASSERT_EQ(vr_svo_child_kind(word), VR_SVO_CHILD_LEAF);
    const std::uint32_t* leaf = &u.svo_leaves[vr_svo_child_index(word) * VR_SVO_LEAF_WORDS];
    const NodeKey& child = s.index().node(s.index().node(0).children[i]).key;
    EXPECT_EQ(s.atlas().key(leaf[0]), (KeyframeKey{child.level, child.x, child.y, child.z, 1}));
    EXPECT_EQ(s.atlas().key(leaf[1]), (KeyframeKey{child.level, child.x, child.y, child.z, 2}));
    EXPECT_EQ(vr_svo_lod_a(leaf[2]), 0u);
    EXPECT_EQ(vr_svo_lod_b(leaf[2]), 0u);
    EXPECT_EQ(std::bit_cast<float>(leaf[3]), 0.5f);
  }
  // Nothing more is requested or uploaded once everything is resident.
  const FrameUpdate again = s.update(cam, playhead, frame++);
  EXPECT_TRUE(again.uploads.empty());
  EXPECT_EQ(again.stats.requests_sent, 0u);
}

INSTANTIATE_TEST_SUITE_P(Stream, StreamSchedulerPolicy,
                         ::testing::Values(PriorityPolicy::patent,
                                           PriorityPolicy::nearest_keyframe_first),
                         [](const ::testing::TestParamInfo<PriorityPolicy>& param_info) {
                           return param_info.param == PriorityPolicy::patent
                                      ? std::string("patent")
                                      : std::string("nearest");
                         });

TEST(StreamScheduler, NodesNoRayReachedAreNotRequestedAndComeBackWhenReached) {
  // Ray-guided feedback from a stand-in renderer whose rays reach every region of the root's
  // octants but `skip` (-1: all of them).
  test::TempDir dir("stream-scheduler-feedback");
  const auto path = test::make_container(dir.path(), dims, 4);
  const format::Container c(path);
  SchedulerSettings settings;
  settings.atlas_slots = 64;
  // One request at a time: the root arrives (and is drawn, giving feedback) before any octant's
  // bricks are requested.
  settings.loader.max_in_flight = 1;
  StreamScheduler s(c, settings);
  const auto cam = test::close_camera(dims);
  const double playhead = 1.5;
  const auto reached_but = [&](const FrameUpdate& f, int skip) {
    std::vector<std::uint32_t> table(VR_SVO_FEEDBACK_ENTRIES * f.svo_leaves.size() /
                                     VR_SVO_LEAF_WORDS);
    for (std::uint32_t i = 0; i < 8; ++i) {
      const std::uint32_t word = f.svo_nodes[1 + i];
      if (static_cast<int>(i) == skip) continue;
      if (vr_svo_child_kind(word) == VR_SVO_CHILD_LEAF)
        table[VR_SVO_FEEDBACK_ENTRIES * vr_svo_child_index(word)] = 1;
      else if (vr_svo_child_kind(word) == VR_SVO_CHILD_UP)
        table[VR_SVO_FEEDBACK_ENTRIES * f.svo_nodes[9] + i] = 2;  // the root's data, a level up
    }
    return table;
  };
  const std::uint32_t octant0 = s.index().node(0).children[0];
  const NodeKey& k0 = s.index().node(octant0).key;
  std::uint64_t frame = 0;
  std::set<std::uint32_t> uploaded_nodes;
  // Frames drawn with feedback until nothing more comes.
  const auto play = [&](int skip) {
    FrameUpdate u;
    for (int i = 0; i < 3000; ++i) {
      u = s.update(cam, playhead, frame);
      s.retire(frame++);
      for (const BrickUpload& up : u.uploads)
        uploaded_nodes.insert(s.index().find({up.key.level, up.key.x, up.key.y, up.key.z}));
      if (u.svo_nodes.size() >= VR_SVO_NODE_WORDS && u.stats.fraction_at_target == 1.0 &&
          u.stats.requests_in_flight == 0 && u.stats.arrivals_waiting == 0 && i > 2)
        return u;
      if (vr_svo_child_kind(u.svo_nodes[1]) != VR_SVO_CHILD_EMPTY) s.feedback(reached_but(u, skip));
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    ADD_FAILURE() << "did not converge";
    return u;
  };
  EXPECT_THROW(s.feedback(std::vector<std::uint32_t>(3)), std::invalid_argument);
  // No ray ever reaches octant 0: it is drawn from the root's data, and none of its bricks is
  // ever requested; the other seven converge.
  FrameUpdate u = play(0);
  EXPECT_EQ(uploaded_nodes.count(octant0), 0u);
  EXPECT_EQ(uploaded_nodes.size(), 8u);  // the root and seven octants
  EXPECT_EQ(u.stats.hidden_nodes, 1u);
  EXPECT_EQ(u.stats.hidden_targets, 1u);
  EXPECT_EQ(u.stats.target_nodes, 7u);
  EXPECT_EQ(vr_svo_child_kind(u.svo_nodes[1]), VR_SVO_CHILD_UP);
  // A ray reaches it (through the root's data): it is requested and drawn from its own bricks.
  s.feedback(reached_but(u, -1));
  u = play(-1);
  EXPECT_EQ(uploaded_nodes.count(octant0), 1u);
  EXPECT_EQ(u.stats.hidden_nodes, 0u);
  EXPECT_EQ(u.stats.target_nodes, 8u);
  EXPECT_EQ(vr_svo_child_kind(u.svo_nodes[1]), VR_SVO_CHILD_LEAF);
  // Hidden again with its bricks resident and the atlas roomy: they stay (drawn, not reloaded).
  s.feedback(reached_but(u, 0));
  u = s.update(cam, playhead, frame);
  s.retire(frame++);
  EXPECT_EQ(u.stats.hidden_nodes, 1u);
  EXPECT_EQ(u.stats.requests_sent, 0u);
  EXPECT_EQ(vr_svo_child_kind(u.svo_nodes[1]), VR_SVO_CHILD_LEAF);
  for (std::uint32_t t = 1; t <= 2; ++t) {
    const auto slot = s.atlas().find(KeyframeKey{k0.level, k0.x, k0.y, k0.z, t});
    ASSERT_TRUE(slot.has_value()) << "t " << t;
    EXPECT_EQ(s.atlas().state(*slot), AtlasSlots::State::occupied) << "t " << t;
  }
  // Feedback keeps guiding while its frame is one of the last feedback_frames (a GPU's table
  // comes frames in flight late); older, nothing is hidden.
  ASSERT_EQ(settings.feedback_frames, 4u);
  for (int i = 1; i <= 4; ++i) {
    u = s.update(cam, playhead, frame);
    s.retire(frame++);
    EXPECT_EQ(u.stats.hidden_nodes, i < 4 ? 1u : 0u) << i << " frames after the feedback";
  }
  // Late feedback: the table of a frame drawn two updates ago, for that frame's SVO.
  const std::uint64_t drawn = frame;
  const FrameUpdate drawn_update = s.update(cam, playhead, frame);
  s.retire(frame++);
  for (int i = 0; i < 2; ++i) {
    // A stream step (the same GPU frame number twice) replaces that frame's SVO.
    s.update(cam, playhead, frame);
    u = s.update(cam, playhead, frame);
    s.retire(frame++);
    EXPECT_EQ(u.stats.hidden_nodes, 0u);
  }
  EXPECT_THROW(s.feedback(std::vector<std::uint32_t>(3), drawn), std::invalid_argument);
  EXPECT_TRUE(s.feedback(reached_but(drawn_update, 0), drawn));
  // Older than the feedback given (its SVO still kept), or no longer kept: ignored.
  EXPECT_FALSE(s.feedback(reached_but(drawn_update, -1), drawn - 1));
  EXPECT_FALSE(s.feedback(reached_but(drawn_update, -1), 0));
  u = s.update(cam, playhead, frame);
  s.retire(frame++);
  EXPECT_EQ(u.stats.hidden_nodes, 1u);
  // Forgotten (a stream step that draws nothing): nothing is hidden until the next feedback,
  // and a table of a frame drawn before is refused; the step's own frame number is not.
  const std::uint64_t before = frame - 1;
  s.update(cam, playhead, frame);
  s.forget_feedback();
  EXPECT_FALSE(s.feedback(reached_but(drawn_update, 0), before));
  u = s.update(cam, playhead, frame);
  EXPECT_EQ(u.stats.hidden_nodes, 0u);
  EXPECT_TRUE(s.feedback(reached_but(u, 0), frame));
  s.retire(frame++);
  u = s.update(cam, playhead, frame);
  s.retire(frame++);
  EXPECT_EQ(u.stats.hidden_nodes, 1u);
  // Switched off, feedback is ignored.
  SchedulerSettings off_settings = settings;
  off_settings.ray_feedback = false;
  StreamScheduler off(c, off_settings);
  std::uint64_t off_frame = 0;
  u = run_until(off, cam, playhead, off_frame,
                [](const FrameUpdate& f) { return f.stats.fraction_at_target == 1.0; });
  off.feedback(reached_but(u, 0));
  u = off.update(cam, playhead, off_frame);
  EXPECT_EQ(u.stats.hidden_nodes, 0u);
}

/// The scheduler's occupied slots as the selection sees them.
ResidentKeyframes resident_of(const StreamScheduler& s) {
  std::vector<ResidentKeyframe> entries;
  for (std::uint32_t slot = 0; slot < s.atlas().capacity(); ++slot)
    if (const auto key = s.atlas().key(slot);
        key && s.atlas().state(slot) == AtlasSlots::State::occupied)
      entries.push_back({s.index().find_keyframe(*key), slot});
  ResidentKeyframes resident;
  resident.assign(s.index(), entries);
  return resident;
}

TEST(StreamScheduler, ASeekIntoALongGapDrawsTheInterpolatedState) {
  // Sparse keyframes: the finest nodes of grid column 0 never change, so they store bricks at
  // steps 0 and 8 only; column 2 at every step. After a seek to 4, the still nodes are drawn from
  // their own keyframes 0 and 8 halfway (not from a coarser node at step 4), the others from their
  // own keyframe at 4.
  test::TempDir dir("stream-scheduler-gap");
  const Dims gap_dims{70, 40, 40};
  test::write_keyframe_series(dir.path() / "series", gap_dims, 9);
  encoder::EncodeJob job;
  job.coding = test::zfp_coding();
  job.max_keyframe_gap = 8;
  const auto series = datasets::open_series(dir.path() / "series");
  encoder::encode_series(*series, dir.path() / "gap.vreel", job);
  const format::Container c(dir.path() / "gap.vreel");
  SchedulerSettings settings;
  settings.atlas_slots = 256;
  StreamScheduler s(c, settings);
  ASSERT_TRUE(s.errors().empty());
  const std::uint32_t finest = s.index().level_count() - 1;
  const std::uint32_t still = s.index().find({finest, 0, 1, 1});
  const std::uint32_t moving = s.index().find({finest, 2, 1, 1});
  ASSERT_NE(still, no_node);
  ASSERT_NE(moving, no_node);
  ASSERT_EQ(s.index().times(still).size(), 2u);
  EXPECT_EQ(s.index().times(moving).size(), 9u);
  const auto cam = test::close_camera(gap_dims);
  std::uint64_t frame = 0;
  const double playhead = 4.0;
  const FrameUpdate u = run_until(s, cam, playhead, frame, [&](const FrameUpdate& f) {
    return f.stats.fraction_at_target == 1.0 && f.stats.requests_in_flight == 0 &&
           f.stats.arrivals_waiting == 0;
  });
  expect_svo_references_resident_slots(s, u);
  const ResidentKeyframes resident = resident_of(s);
  const KeyframePair p = select_keyframe_pair(s.index(), still, playhead, resident);
  EXPECT_TRUE(p.at_full_detail());
  EXPECT_EQ(p.a.t, 0u);
  EXPECT_EQ(p.b.t, 8u);
  EXPECT_EQ(p.a.lod_difference, 0u);
  EXPECT_EQ(p.b.lod_difference, 0u);
  EXPECT_FLOAT_EQ(p.factor, 0.5f);
  const KeyframePair q = select_keyframe_pair(s.index(), moving, playhead, resident);
  EXPECT_TRUE(q.at_full_detail());
  EXPECT_EQ(q.a.t, 4u);
  EXPECT_EQ(q.b.t, 4u);
}

/// The keyframe pair of every present node from the scheduler's occupied slots.
std::vector<std::pair<std::uint32_t, std::uint32_t>> drawn_pairs(const StreamScheduler& s,
                                                                 double playhead) {
  const ResidentKeyframes resident = resident_of(s);
  std::vector<std::pair<std::uint32_t, std::uint32_t>> out;
  for (std::uint32_t n = 0; n < s.index().node_count(); ++n) {
    if (!s.index().node(n).present()) continue;
    const KeyframePair pair = select_keyframe_pair(s.index(), n, playhead, resident);
    EXPECT_TRUE(pair.at_full_detail()) << "node " << n;
    out.emplace_back(pair.a.t, pair.b.t);
  }
  return out;
}

TEST(StreamScheduler, AWindowedIndexStreamsWhatTheWholeIndexDoesAfterSeeks) {
  // A container held as a 10-frame time window draws, once settled, every node from the same two
  // keyframes as with the whole index held.
  test::TempDir dir("stream-scheduler-window");
  const Dims wide{80, 40, 36};
  const auto path = test::make_container(dir.path(), wide, 30, datasets::AnalyticField::blobs, 3);
  const format::Container c(path);
  SchedulerSettings settings;
  settings.atlas_slots = 512;
  StreamScheduler whole(c, settings);
  ASSERT_FALSE(whole.index().windowed());
  IndexOptions o;
  o.memory_bytes = 10 * whole.index().node_count() * (sizeof(KeyframeNode) + sizeof(std::uint32_t));
  StreamScheduler windowed(c, settings, o);
  ASSERT_TRUE(windowed.index().windowed());
  const auto cam = test::close_camera(wide);
  std::uint64_t frame = 1, whole_frame = 1;
  for (const double playhead : {20.5, 4.0, 27.25, 0.0}) {
    SCOPED_TRACE("playhead " + std::to_string(playhead));
    const auto settled = [](const FrameUpdate& f) {
      return f.stats.index_ready && f.stats.fraction_at_target == 1.0 &&
             f.stats.requests_in_flight == 0 && f.stats.arrivals_waiting == 0;
    };
    const FrameUpdate u = run_until(windowed, cam, playhead, frame, settled);
    expect_svo_references_resident_slots(windowed, u);
    EXPECT_LE(windowed.index().held_end() - windowed.index().held_begin(), 10u);
    run_until(whole, cam, playhead, whole_frame, settled);
    EXPECT_EQ(drawn_pairs(windowed, playhead), drawn_pairs(whole, playhead));
    EXPECT_TRUE(windowed.errors().empty());
  }
}

TEST(StreamScheduler, TheRootArrivesFirstAndTheUploadBudgetHolds) {
  test::TempDir dir("stream-scheduler-budget");
  const auto path = test::make_container(dir.path(), dims, 4);
  const format::Container c(path);
  SchedulerSettings settings;
  settings.atlas_slots = 64;
  settings.upload_budget_bytes = 1;  // one upload per frame
  settings.loader.threads = 1;       // reads complete in request order
  StreamScheduler s(c, settings);
  const auto cam = test::close_camera(dims);
  std::uint64_t frame = 0;
  std::vector<BrickUpload> uploads;
  std::size_t max_per_frame = 0;
  const FrameUpdate u = run_until(
      s, cam, 0.0, frame,
      [&](const FrameUpdate& f) {
        max_per_frame = std::max(max_per_frame, f.uploads.size());
        return f.stats.atlas_occupied == 36;
      },
      &uploads);
  EXPECT_EQ(max_per_frame, 1u);
  // The patent's priorities load the root's keyframe at the playhead first: the coarsest node
  // has the largest SSE, and keyframe 0 the largest temporal priority.
  ASSERT_FALSE(uploads.empty());
  EXPECT_EQ(uploads.front().key, (KeyframeKey{0, 0, 0, 0, 0}));
  expect_svo_references_resident_slots(s, u);
}

/// The order in which keyframe nodes arrive when one request is in flight at a time on a
/// simulated link that delivers one brick per frame, playhead fixed at `playhead`.
std::vector<KeyframeKey> arrival_order(const format::Container& c, bool due_window, double playhead,
                                       std::size_t count) {
  double now = 0;
  SchedulerSettings settings;
  settings.atlas_slots = 256;
  settings.priority.policy = PriorityPolicy::patent;
  settings.priority.due_window = due_window;
  settings.loader.clock = [&now] { return now; };
  settings.loader.max_in_flight = 1;
  settings.loader.bandwidth_bytes_per_s = 1e9;
  StreamScheduler s(c, settings);
  const auto cam = test::close_camera(dims);
  std::vector<KeyframeKey> order;
  for (std::uint64_t frame = 1; frame < 400 && order.size() < count; ++frame) {
    const FrameUpdate u = s.update(cam, playhead, frame);
    s.retire(frame);
    for (const BrickUpload& up : u.uploads) order.push_back(up.key);
    now += 1.0;
  }
  return order;
}

TEST(StreamScheduler, TheDueWindowLoadsTheKeyframesAroundThePlayheadFirst) {
  test::TempDir dir("stream-scheduler-due");
  const auto path = test::make_container(dir.path(), dims, 9);
  const format::Container c(path);
  // Playhead 4.5: keyframes 4 and 5 at every level (2 × 9 bricks) come before anything else,
  // each keyframe's root before its children.
  const auto due = arrival_order(c, true, 4.5, 18);
  ASSERT_EQ(due.size(), 18u);
  for (const KeyframeKey& k : due) EXPECT_TRUE(k.t == 4 || k.t == 5) << "t " << k.t;
  for (const std::uint32_t t : {4u, 5u}) {
    const auto first =
        std::find_if(due.begin(), due.end(), [&](const KeyframeKey& k) { return k.t == t; });
    ASSERT_NE(first, due.end());
    EXPECT_EQ(first->level, 0u);
  }
  // [0045] alone: the 10·ssePriority term puts the roots of other keyframes (the ruler's first,
  // middle and last) before the leaves the frame draws.
  const auto patent_only = arrival_order(c, false, 4.5, 18);
  ASSERT_EQ(patent_only.size(), 18u);
  EXPECT_TRUE(std::any_of(patent_only.begin(), patent_only.end(),
                          [](const KeyframeKey& k) { return k.t != 4 && k.t != 5; }));
}

TEST(StreamScheduler, MoreDueKeyframeNodesThanSlotsKeepTheBestOfThemInTheHeapsOrder) {
  test::TempDir dir("stream-scheduler-due-full");
  const auto path = test::make_container(dir.path(), dims, 9);
  const format::Container c(path);
  // Paused at 4.5, every node's keyframe nodes 3, 4, 5 and 6 are due (36), 4 and 5 soonest (18):
  // 12 slots keep the two roots (coarser first on ties), then the leaves by ascending id (node,
  // then t), so nodes 1 to 5 at both time steps.
  SchedulerSettings settings;
  settings.atlas_slots = 12;
  StreamScheduler s(c, settings);
  ASSERT_EQ(s.index().node_count(), 9u);
  const auto cam = test::close_camera(dims);
  std::uint64_t frame = 0;
  run_until(s, cam, 4.5, frame, [&](const FrameUpdate& f) {
    return f.stats.requests_in_flight == 0 && f.stats.arrivals_waiting == 0 &&
           f.stats.atlas_occupied == 12;
  });
  std::vector<KeyframeId> resident;
  for (std::uint32_t slot = 0; slot < 12; ++slot) {
    ASSERT_EQ(s.atlas().state(slot), AtlasSlots::State::occupied);
    resident.push_back(s.index().find_keyframe(*s.atlas().key(slot)));
  }
  std::sort(resident.begin(), resident.end());
  std::vector<KeyframeId> expected;
  for (std::uint32_t node = 0; node <= 5; ++node)
    for (const std::uint32_t t : {4u, 5u}) expected.push_back(keyframe_id(node, t));
  EXPECT_EQ(resident, expected);
}

/// Per time step, the finest-level keyframe nodes resident (occupied) once a scheduler with
/// `slots` atlas slots (fewer than the 9 × 9 keyframe nodes) has converged at playhead 4.2 with the
/// [0045] order alone; `roots`: time steps whose root is resident.
std::map<std::uint32_t, int> resident_leaves(const format::Container& c, SseScope scope,
                                             std::uint32_t slots, int* roots) {
  SchedulerSettings settings;
  settings.atlas_slots = slots;
  settings.priority.policy = PriorityPolicy::patent;
  settings.priority.due_window = false;
  settings.priority.sse_scope = scope;
  StreamScheduler s(c, settings);
  const auto cam = test::close_camera(dims);
  std::uint64_t frame = 0;
  run_until(s, cam, 4.2, frame, [&](const FrameUpdate& f) {
    return f.stats.requests_in_flight == 0 && f.stats.arrivals_waiting == 0 &&
           f.stats.atlas_occupied == slots;
  });
  std::map<std::uint32_t, int> leaves;
  *roots = 0;
  for (std::uint32_t slot = 0; slot < slots; ++slot) {
    const auto key = s.atlas().key(slot);
    if (!key || s.atlas().state(slot) != AtlasSlots::State::occupied) continue;
    if (key->level == 0)
      ++*roots;
    else
      ++leaves[key->t];
  }
  return leaves;
}

TEST(StreamScheduler, TheSseOfALevelKeepsWholeKeyframesWhenTheAtlasIsFull) {
  test::TempDir dir("stream-scheduler-sse-scope");
  const auto path = test::make_container(dir.path(), dims, 9);
  const format::Container c(path);
  // 45 slots: the 9 roots and 36 of the 72 leaves.
  int roots = 0;
  const auto partial = [](const std::map<std::uint32_t, int>& leaves) {
    return std::count_if(leaves.begin(), leaves.end(),
                         [](const auto& e) { return e.second > 0 && e.second < 8; });
  };
  const auto level = resident_leaves(c, SseScope::level, 45, &roots);
  EXPECT_EQ(roots, 9);  // coarser levels first: every time step's root
  int total = 0;
  for (const auto& [t, n] : level) total += n;
  EXPECT_EQ(total, 36);
  // One SSE per level: whole keyframes nearest the playhead (4, 5, 3, 6), half of the next (2).
  EXPECT_LE(partial(level), 1);
  for (const std::uint32_t t : {3u, 4u, 5u, 6u})
    EXPECT_EQ(level.count(t) ? level.at(t) : 0, 8) << t;
  // Each node's own SSE: the leaves nearer the camera of many time steps, few of them whole.
  const auto node = resident_leaves(c, SseScope::node, 45, &roots);
  EXPECT_EQ(roots, 9);
  EXPECT_GE(partial(node), 3);
}

TEST(StreamScheduler, SpeculativeRequestsGoOutOnlyWhileTheLinkBacklogIsShort) {
  test::TempDir dir("stream-scheduler-speculative");
  const auto path = test::make_container(dir.path(), dims, 9);
  const format::Container c(path);
  const auto run = [&](double speculative_link_s, std::uint64_t* max_speculative) {
    double now = 0;
    SchedulerSettings settings;
    settings.atlas_slots = 256;
    settings.priority.policy = PriorityPolicy::patent;
    settings.speculative_link_s = speculative_link_s;
    settings.loader.clock = [&now] { return now; };
    settings.loader.max_in_flight = 1000;
    settings.loader.bandwidth_bytes_per_s = 200000;
    StreamScheduler s(c, settings);
    std::uint32_t largest = 0;
    for (const KeyframeId k : s.index().held_keyframes())
      largest = std::max(largest, s.index().keyframe(k).bytes);
    const auto cam = test::close_camera(dims);
    const double bound = std::max(200000.0 * speculative_link_s, static_cast<double>(largest));
    std::size_t first_in_flight = 0;
    for (std::uint64_t frame = 1; frame <= 40; ++frame) {
      const std::uint64_t speculative_before = s.speculative_bytes_in_flight();
      const FrameUpdate u = s.update(cam, 4.0, frame);
      s.retire(frame);
      if (frame == 1) first_in_flight = u.stats.requests_in_flight;
      *max_speculative = std::max(*max_speculative, s.speculative_bytes_in_flight());
      // A speculative request went out this frame: the whole backlog is within the bound (due
      // requests go out before speculative ones).
      if (s.speculative_bytes_in_flight() > speculative_before) {
        EXPECT_LE(static_cast<double>(s.requested_bytes_in_flight()), bound) << "frame " << frame;
      }
      EXPECT_LE(static_cast<double>(s.speculative_bytes_in_flight()), bound);
      now += 0.1;
    }
    return first_in_flight;
  };
  std::uint64_t bounded_max = 0, unbounded_max = 0;
  const std::size_t bounded = run(0.25, &bounded_max);
  const std::size_t unbounded = run(0.0, &unbounded_max);
  EXPECT_GT(bounded_max, 0u);     // speculative requests do go out
  EXPECT_EQ(unbounded_max, 0u);   // no bound: not tracked
  EXPECT_LT(bounded, unbounded);  // the bound holds back the [0045] order's far keyframes
  // The due keyframe (4, 9 bricks) is always requested whatever the bound.
  EXPECT_GE(bounded, 9u);
}

TEST(StreamScheduler, SlotsSampledByUnretiredGpuFramesAreNotOverwritten) {
  test::TempDir dir("stream-scheduler-retire");
  const auto path = test::make_container(dir.path(), dims, 4);
  const format::Container c(path);
  SchedulerSettings settings;
  settings.atlas_slots = 2;
  settings.priority.policy = PriorityPolicy::nearest_keyframe_first;
  StreamScheduler s(c, settings);
  auto cam = test::close_camera(dims);
  cam.distance *= 100;  // the root alone is visited
  const KeyframeKey root[4] = {{0, 0, 0, 0, 0}, {0, 0, 0, 0, 1}, {0, 0, 0, 0, 2}, {0, 0, 0, 0, 3}};
  std::uint64_t frame = 0;
  // Playhead 0: the two nearest keyframes of the root, 0 and 1, are loaded.
  run_until(s, cam, 0.0, frame, [&](const FrameUpdate&) {
    return s.atlas().is_occupied(root[0]) && s.atlas().is_occupied(root[1]);
  });
  // One more frame samples keyframe 0's slot (at playhead 0 both picks are keyframe 0) and is
  // not retired.
  const FrameUpdate sampled = s.update(cam, 0.0, frame);
  const std::uint64_t unretired = frame++;
  const std::uint32_t slot0 = *s.atlas().find(root[0]);
  ASSERT_EQ(sampled.svo_leaves.size(), VR_SVO_LEAF_WORDS);
  ASSERT_EQ(sampled.svo_leaves[0], slot0);
  // Playhead 3: keyframes 3 and 2 are selected. Keyframe 1's slot (never sampled) takes one of
  // them; the other waits for keyframe 0's slot, which frame `unretired` still samples.
  std::vector<BrickUpload> uploads;
  FrameUpdate u;
  for (int i = 0; i < 5000; ++i) {
    u = s.update(cam, 3.0, frame++);
    for (auto& up : u.uploads) uploads.push_back(std::move(up));
    if (uploads.size() == 1 && u.stats.arrivals_waiting == 1) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  ASSERT_EQ(uploads.size(), 1u);
  EXPECT_NE(uploads[0].slot, slot0);
  EXPECT_EQ(u.stats.arrivals_waiting, 1u);
  EXPECT_EQ(s.atlas().find(root[0]), slot0);  // still holds keyframe 0
  for (int i = 0; i < 20; ++i) {              // however long the GPU takes
    u = s.update(cam, 3.0, frame++);
    EXPECT_TRUE(u.uploads.empty());
  }
  // Every frame up to the last one completes: the slot is free to take.
  s.retire(frame - 1);
  u = s.update(cam, 3.0, frame++);
  ASSERT_EQ(u.uploads.size(), 1u);
  EXPECT_EQ(u.uploads[0].slot, slot0);
  EXPECT_TRUE(s.atlas().is_occupied(root[2]));
  EXPECT_TRUE(s.atlas().is_occupied(root[3]));
  EXPECT_FALSE(s.atlas().find(root[0]).has_value());
  (void)unretired;
}

// A collapse fades out in the scheduler too: when the camera moves away and the root alone is the
// cut, its children are no longer selected and their slots become over-writeable, but they still
// hold the children's bricks. For fade_s the children are drawn from them, their weights falling
// from 255, and their slots are marked used (no upload may overwrite a slot a GPU frame samples);
// then the root is drawn alone.
TEST(StreamScheduler, ACollapseFadesOutFromBricksTheAtlasStillHolds) {
  test::TempDir dir("stream-scheduler-fade-out");
  const auto path = test::make_container(dir.path(), dims, 4);
  const format::Container c(path);
  double now = 0;
  SchedulerSettings settings;
  settings.atlas_slots = 64;
  settings.lod_blend.fade_out_s = 1.0;  // the fade-out alone: arrivals replace at once
  settings.loader.clock = [&] { return now; };
  StreamScheduler s(c, settings);
  const auto close = test::close_camera(dims);
  auto far = close;
  far.distance *= 100;  // the root alone is visited
  std::uint64_t frame = 0;
  const double playhead = 1.5;
  // 1. Close: everything arrives; the root refines into its 8 children.
  FrameUpdate u;
  for (int i = 0; i < 400; ++i, now += 0.05) {
    u = s.update(close, playhead, frame);
    s.retire(frame++);
    if (u.stats.fraction_at_target == 1.0 && u.stats.atlas_occupied == 36 &&
        u.stats.blended_leaves == 0 && now > 2)
      break;
  }
  ASSERT_EQ(u.stats.atlas_occupied, 36u);
  ASSERT_EQ(u.stats.target_nodes, 8u);
  ASSERT_EQ(u.svo_leaves.size(), 8 * VR_SVO_LEAF_WORDS);
  // 2. Far: the children fade out from their own bricks, then the root's leaf is drawn alone.
  std::vector<std::uint32_t> weights;
  for (int i = 0; i < 30; ++i, now += 0.1, s.retire(frame++)) {
    u = s.update(far, playhead, frame);
    EXPECT_TRUE(u.uploads.empty());
    EXPECT_EQ(u.stats.target_nodes, 1u);
    EXPECT_EQ(u.stats.atlas_occupied, 4u);  // the root's 4 keyframe nodes alone are selected
    if (u.svo_leaves.size() == VR_SVO_LEAF_WORDS) break;    // faded out
    ASSERT_EQ(u.svo_leaves.size(), 8 * VR_SVO_LEAF_WORDS);  // the 8 children (none drawn "up")
    std::set<std::uint32_t> w;
    for (std::uint32_t o = 0; o < 8; ++o) {
      const std::uint32_t word = u.svo_nodes[1 + o];
      ASSERT_EQ(vr_svo_child_kind(word), VR_SVO_CHILD_LEAF);
      const std::uint32_t* leaf = &u.svo_leaves[vr_svo_child_index(word) * VR_SVO_LEAF_WORDS];
      // Keyframes 1 and 2 of the child, in over-writeable slots that the frame marks used.
      const NodeKey& child = s.index().node(s.index().node(0).children[o]).key;
      EXPECT_EQ(s.atlas().key(leaf[0]), (KeyframeKey{child.level, child.x, child.y, child.z, 1}));
      EXPECT_EQ(s.atlas().state(leaf[0]), AtlasSlots::State::overwriteable);
      EXPECT_FALSE(s.atlas().retired(leaf[0]));  // this frame samples it and is not done yet
      w.insert(leaf[7] & 0xffu);
    }
    ASSERT_EQ(w.size(), 1u) << "every child fades alike";
    weights.push_back(*w.begin());
  }
  EXPECT_EQ(u.svo_leaves.size(), VR_SVO_LEAF_WORDS);
  ASSERT_GE(weights.size(), 9u);  // 1 s at 10 frames a second
  EXPECT_EQ(weights.front(), 255u);
  for (std::size_t i = 1; i < weights.size(); ++i) EXPECT_LT(weights[i], weights[i - 1]) << i;
  // Without a fade the collapse is at once.
  settings.lod_blend.fade_out_s = 0;
  StreamScheduler instant(c, settings);
  for (int i = 0; i < 400; ++i, now += 0.05) {
    u = instant.update(close, playhead, frame);
    instant.retire(frame++);
    if (u.stats.fraction_at_target == 1.0 && u.stats.atlas_occupied == 36) break;
  }
  ASSERT_EQ(u.svo_leaves.size(), 8 * VR_SVO_LEAF_WORDS);
  u = instant.update(far, playhead, frame++);
  EXPECT_EQ(u.svo_leaves.size(), VR_SVO_LEAF_WORDS);
}

TEST(StreamScheduler, AStaleArrivalIsDiscardedAndTheAtlasLeftUntouched) {
  test::TempDir dir("stream-scheduler-stale");
  const auto path = test::make_container(dir.path(), dims, 4);
  const format::Container c(path);
  SchedulerSettings settings;
  settings.atlas_slots = 1;         // the heap keeps one keyframe node: the root's nearest
  settings.loader.latency_s = 0.2;  // arrivals come well after the playhead moved
  StreamScheduler s(c, settings);
  const auto cam = test::close_camera(dims);
  const KeyframeKey root0{0, 0, 0, 0, 0}, root3{0, 0, 0, 0, 3};
  std::uint64_t frame = 0;
  FrameUpdate u = s.update(cam, 0.0, frame++);
  ASSERT_EQ(u.stats.requests_sent, 1u);
  ASSERT_EQ(u.stats.selected, 1u);
  // Wait until a worker has started the read (so it is not simply cancelled), then move the
  // playhead to the end: the root's keyframe 3 is selected instead.
  for (int i = 0; i < 10000 && s.loader().queued() > 0; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  std::size_t discarded = 0;
  std::vector<BrickUpload> uploads;
  u = run_until(
      s, cam, 3.0, frame,
      [&](const FrameUpdate& f) {
        discarded += f.stats.arrivals_discarded;
        return discarded > 0 && s.atlas().is_occupied(root3);
      },
      &uploads);
  EXPECT_EQ(discarded, 1u);
  EXPECT_FALSE(s.atlas().find(root0).has_value());
  ASSERT_EQ(uploads.size(), 1u);
  EXPECT_EQ(uploads[0].key, root3);
  expect_svo_references_resident_slots(s, u);
}

TEST(StreamScheduler, AnIoErrorIsReportedAndRetriedWithoutBlockingOthers) {
  test::TempDir dir("stream-scheduler-io");
  const auto path = test::make_container(dir.path(), dims, 4);
  const format::Container c(path);
  SchedulerSettings settings;
  settings.atlas_slots = 64;
  settings.loader.retry_initial_s = 0.01;
  settings.loader.retry_max_s = 0.05;
  StreamScheduler s(c, settings);  // indexed while the files are intact
  const auto frame2 = path / "frames/000002.vrf", moved = path / "frame2.bak";
  std::filesystem::rename(frame2, moved);
  const auto cam = test::close_camera(dims);
  std::uint64_t frame = 0;
  const auto resident_of_frame = [&](std::uint32_t t) {
    std::uint32_t n = 0;
    for (std::uint32_t node = 0; node < s.index().node_count(); ++node) {
      const NodeKey& k = s.index().node(node).key;
      n += s.atlas().is_occupied({k.level, k.x, k.y, k.z, t}) ? 1u : 0u;
    }
    return n;
  };
  std::vector<std::string> messages;
  FrameUpdate u = run_until(s, cam, 1.5, frame, [&](const FrameUpdate& f) {
    for (const auto& m : f.new_errors) messages.push_back(m);
    return s.error_count() >= 2 * 9 && resident_of_frame(0) == 9 && resident_of_frame(1) == 9 &&
           resident_of_frame(3) == 9;
  });
  // Every brick of frame 2 failed at least twice (retried), and the other frames loaded.
  EXPECT_EQ(resident_of_frame(2), 0u);
  ASSERT_FALSE(messages.empty());
  EXPECT_NE(messages.front().find("000002.vrf"), std::string::npos) << messages.front();
  EXPECT_NE(s.errors().back().find("will retry"), std::string::npos);
  EXPECT_LE(s.errors().size(), settings.max_messages);
  // Meanwhile every node is drawn, from the keyframes that are there: no holes.
  EXPECT_EQ(u.stats.holes, 0u);
  expect_svo_references_resident_slots(s, u);
  // The file comes back: the retries load it.
  std::filesystem::rename(moved, frame2);
  u = run_until(s, cam, 1.5, frame, [&](const FrameUpdate&) { return resident_of_frame(2) == 9; });
  EXPECT_EQ(resident_of_frame(2), 9u);
  expect_svo_references_resident_slots(s, u);
}

TEST(StreamScheduler, ABadFrameAtIndexTimeIsReportedNotThrown) {
  test::TempDir dir("stream-scheduler-bad-frame");
  const auto path = test::make_container(dir.path(), dims, 4);
  {
    std::fstream f(path / "frames/000003.vrf", std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(200);  // inside the node table: the index CRC fails
    f.put('\x5a');
  }
  const format::Container c(path);
  SchedulerSettings settings;
  settings.atlas_slots = 64;
  StreamScheduler s(c, settings);
  ASSERT_EQ(s.errors().size(), 1u);
  EXPECT_NE(s.errors().front().find("000003.vrf"), std::string::npos) << s.errors().front();
  const auto cam = test::close_camera(dims);
  std::uint64_t frame = 0;
  bool reported = false;
  // Playhead on the bad frame: the nodes draw from frame 2, its nearest neighbour.
  const FrameUpdate u = run_until(s, cam, 3.0, frame, [&](const FrameUpdate& f) {
    for (const auto& m : f.new_errors) reported |= m.find("000003.vrf") != std::string::npos;
    return f.stats.atlas_occupied == 27 && f.stats.requests_in_flight == 0;
  });
  EXPECT_TRUE(reported);
  EXPECT_EQ(u.stats.holes, 0u);
  EXPECT_EQ(u.stats.at_target_nodes, 8u);
  expect_svo_references_resident_slots(s, u);
  // Drawn, but not as encoded: the view is not at its target (a render waiting for it, or a
  // seek timed to full quality, must not count it complete).
  EXPECT_TRUE(u.stats.index_failed);
  EXPECT_EQ(u.stats.fraction_at_target, 0.0);
  // Where a frame between the playhead and the bad frame stores every node, the view completes.
  const FrameUpdate away = run_until(s, cam, 1.0, frame, [](const FrameUpdate& f) {
    return f.stats.fraction_at_target == 1.0 && f.stats.requests_in_flight == 0;
  });
  EXPECT_FALSE(away.stats.index_failed);
  EXPECT_EQ(away.stats.fraction_at_target, 1.0);
}

}  // namespace
}  // namespace volreel::stream
