// priorities_test.cpp: the pre-load priorities of the Cesium patent [0042]–[0045], frustum culling
// and the SSE-driven traversal.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>

#include "stream_test_util.hpp"
#include "volreel/stream/priorities.hpp"

namespace volreel::stream {
namespace {

TEST(StreamPriorities, RandomTableOfNineKeyframesIsThePatents) {
  const std::vector<double> expected{1.0, 0.25, 0.5, 0.25, 1.0, 0.25, 0.5, 0.25, 1.0};
  EXPECT_EQ(random_selection_table(9), expected);
}

TEST(StreamPriorities, RandomTableIsRulerLikeForOtherSizes) {
  EXPECT_EQ(random_selection_table(1), std::vector<double>{1.0});
  EXPECT_EQ(random_selection_table(2), (std::vector<double>{1.0, 1.0}));
  EXPECT_EQ(random_selection_table(3), (std::vector<double>{1.0, 1.0, 1.0}));
  EXPECT_EQ(random_selection_table(5), (std::vector<double>{1.0, 0.5, 1.0, 0.5, 1.0}));
  // 17 keyframes: the 9-keyframe ruler with one more subdivision.
  const auto t = random_selection_table(17);
  EXPECT_EQ(t[0], 1.0);
  EXPECT_EQ(t[8], 1.0);
  EXPECT_EQ(t[16], 1.0);
  EXPECT_EQ(t[4], 0.5);
  EXPECT_EQ(t[12], 0.5);
  EXPECT_EQ(t[2], 0.25);
  EXPECT_EQ(t[1], 0.125);
  EXPECT_EQ(t[15], 0.125);
  // Every keyframe gets a priority in (0, 1].
  for (std::size_t n : {4u, 7u, 10u, 100u, 1000u})
    for (double p : random_selection_table(n)) {
      EXPECT_GT(p, 0.0);
      EXPECT_LE(p, 1.0);
    }
}

TEST(StreamPriorities, FormulasOfTheParagraphs) {
  EXPECT_DOUBLE_EQ(sse_priority(0), 0.0);
  EXPECT_DOUBLE_EQ(sse_priority(1), 0.5);
  EXPECT_DOUBLE_EQ(sse_priority(3), 0.75);
  // 9 keyframes, playhead 2: maxDistance = 6.
  EXPECT_DOUBLE_EQ(temporal_priority(2, 2, 9), 1.0);
  EXPECT_DOUBLE_EQ(temporal_priority(5, 2, 9), std::pow(0.5, 4));
  EXPECT_DOUBLE_EQ(temporal_priority(8, 2, 9), 0.0);
  EXPECT_DOUBLE_EQ(temporal_priority(0, 2, 9), std::pow(1.0 - 2.0 / 6.0, 4));
  EXPECT_DOUBLE_EQ(temporal_priority(0, 0, 1), 1.0);
  // [0045]: 10·sse + lerp(random, temporal, lerp(0.15, 1, temporal)).
  PrioritySettings s;
  s.temporal_lerp_min = 0.15;  // [0045]'s weight (volreel's default is 1)
  const double temporal = 0.4, random = 0.25, sse = 0.5;
  const double w = 0.15 + (1.0 - 0.15) * temporal;
  EXPECT_DOUBLE_EQ(combined_priority(sse, temporal, random, s),
                   10 * sse + random + (temporal - random) * w);
  // Temporal 1: the temporal priority alone; temporal 0: 15 % of the way from random to 0.
  EXPECT_DOUBLE_EQ(combined_priority(0, 1, 0.25, s), 1.0);
  EXPECT_DOUBLE_EQ(combined_priority(0, 0, 1, s), 0.85);
  s.policy = PriorityPolicy::nearest_keyframe_first;
  EXPECT_DOUBLE_EQ(combined_priority(0.9, 0.3, 1, s), 0.3);
}

TEST(StreamPriorities, FrustumCullsBoxesBehindAndBesideTheCamera) {
  player::OrbitCamera c;
  c.target = {0, 0, 0};
  c.distance = 100;
  c.azimuth = 0;
  c.elevation = 0;  // eye at (100, 0, 0) looking towards -x
  const Frustum f(c);
  EXPECT_TRUE(f.intersects({{-1, -1, -1}, {1, 1, 1}}));
  EXPECT_FALSE(f.intersects({{150, -1, -1}, {160, 1, 1}}));                // behind the eye
  EXPECT_FALSE(f.intersects({{0, 500, -1}, {1, 510, 1}}));                 // far to the side
  EXPECT_TRUE(f.intersects({{-1000, -1000, -1000}, {1000, 1000, 1000}}));  // around the eye
  EXPECT_DOUBLE_EQ(distance_to_box({100, 0, 0}, {{-1, -1, -1}, {1, 1, 1}}), 99.0);
  EXPECT_DOUBLE_EQ(distance_to_box({0, 0, 0}, {{-1, -1, -1}, {1, 1, 1}}), 0.0);
}

TEST(StreamPriorities, TraversalRefinesWhileTheSseExceedsTheTarget) {
  const Dims dims{80, 40, 40};
  const SpatialIndex index = test::make_index(dims, 2);
  ASSERT_EQ(index.level_count(), 3u);
  ViewTraversal view;
  player::OrbitCamera near_cam = test::close_camera(dims);
  view.run(index, near_cam, 1.0);
  // Close: every node is visited, the finest ones are the targets.
  EXPECT_EQ(view.visits().size(), index.node_count());
  for (const auto& v : view.visits())
    EXPECT_EQ(v.refine, index.node(v.node).has_children) << "node " << v.node;
  // A voxel of a coarser level projects to twice the pixels at about the same distance.
  EXPECT_GT(view.visit(0).sse, view.visit(index.node(0).children[0]).sse);
  // Far away: the root alone.
  player::OrbitCamera far_cam = near_cam;
  far_cam.distance *= 100;
  view.run(index, far_cam, 1.0);
  ASSERT_EQ(view.visits().size(), 1u);
  EXPECT_FALSE(view.visits()[0].refine);
  EXPECT_TRUE(view.visited(0));
  EXPECT_FALSE(view.visited(1));
  // Looking away: nothing.
  player::OrbitCamera away = near_cam;
  away.target = near_cam.target -
                3.0 * (near_cam.eye() - near_cam.target);  // eye past the volume, facing away
  view.run(index, away, 1.0);
  EXPECT_TRUE(view.visits().empty());
}

/// Pairs of the view's target nodes (visited, not refined) that touch by a face, an edge or a
/// corner and differ by more than one level.
std::size_t restriction_violations(const SpatialIndex& index, const ViewTraversal& view) {
  std::vector<std::uint32_t> targets;
  for (const auto& v : view.visits())
    if (!v.refine) targets.push_back(v.node);
  std::size_t violations = 0;
  for (std::size_t i = 0; i < targets.size(); ++i)
    for (std::size_t j = i + 1; j < targets.size(); ++j) {
      const SpatialNode &a = index.node(targets[i]), &b = index.node(targets[j]);
      bool touch = true;
      for (std::size_t k = 0; k < 3; ++k) touch = touch && a.lo[k] <= b.hi[k] && b.lo[k] <= a.hi[k];
      const std::uint32_t la = a.key.level, lb = b.key.level;
      if (touch && (la > lb + 1 || lb > la + 1)) ++violations;
    }
  return violations;
}

TEST(StreamPriorities, RestrictedTargetNodesDifferByAtMostOneLevelWhereTheyTouch) {
  // Bricks of 12³ (interiors of 10) over 80³: 4 levels, 8³ finest nodes.
  const SpatialIndex index = test::make_index({80, 80, 80}, 1, 12);
  ASSERT_EQ(index.level_count(), 4u);
  // The eye just outside a face: the near nodes project 5 times larger than the far ones.
  player::OrbitCamera cam = player::OrbitCamera::framing({80, 80, 80}, 512, 512);
  cam.distance = 45;
  cam.azimuth = 0.3;
  cam.elevation = 0.2;
  cam.fov_y = glm::radians(100.0);
  ViewTraversal view;
  double target = 0;
  for (const double t : {64.0, 32.0, 24.0, 16.0, 12.0, 8.0, 6.0, 4.0, 3.0, 2.0, 1.0}) {
    view.run(index, cam, t);
    if (restriction_violations(index, view) > 0) {
      target = t;
      break;
    }
  }
  ASSERT_GT(target, 0) << "no view with target nodes two levels apart";
  std::vector<std::uint8_t> refined(index.node_count(), 0);
  for (const auto& visit : view.visits()) refined[visit.node] = visit.refine;
  const std::size_t free_visits = view.visits().size();
  EXPECT_EQ(view.forced_count(), 0u);

  view.run(index, cam, target, true);
  EXPECT_EQ(restriction_violations(index, view), 0u) << "SSE target " << target;
  EXPECT_GT(view.forced_count(), 0u);
  EXPECT_GT(view.visits().size(), free_visits);
  // Restriction only adds refinement, and marks what it added.
  std::size_t forced = 0;
  for (const auto& visit : view.visits()) {
    if (refined[visit.node]) {
      EXPECT_TRUE(visit.refine) << "node " << visit.node;
    }
    EXPECT_EQ(visit.forced, visit.refine && !refined[visit.node]) << "node " << visit.node;
    forced += visit.forced;
  }
  EXPECT_EQ(forced, view.forced_count());
  // The walk stays a depth-first preorder: a node's parent comes before it.
  std::vector<std::uint8_t> seen(index.node_count(), 0);
  for (const auto& visit : view.visits()) {
    const std::uint32_t parent = index.node(visit.node).parent;
    if (parent != no_node) {
      EXPECT_TRUE(seen[parent]) << "node " << visit.node;
    }
    seen[visit.node] = 1;
  }
  // Far away nothing needs forcing; the next run forgets the forced nodes.
  player::OrbitCamera far_cam = cam;
  far_cam.distance *= 100;
  view.run(index, far_cam, target, true);
  EXPECT_EQ(view.forced_count(), 0u);
  EXPECT_EQ(view.visits().size(), 1u);
}

/// A node's held time steps (all that matters to the due window), held range [begin, 10).
struct Times {
  Times(std::initializer_list<std::uint32_t> times, std::uint32_t begin_at = 0) : begin(begin_at) {
    for (const std::uint32_t t : times) bits |= std::uint64_t{1} << t;
  }
  HeldTimes view() const {
    return {&bits, 64, begin, 10, static_cast<std::uint32_t>(std::popcount(bits))};
  }
  std::uint64_t bits = 0;
  std::uint32_t begin = 0;
};

/// (t, seconds) of the due window.
std::vector<std::pair<std::uint32_t, double>> due(const Times& times, double playhead,
                                                  double velocity, double lookahead_s) {
  std::vector<DueTime> d;
  due_times(times.view(), playhead, velocity, lookahead_s, d);
  std::vector<std::pair<std::uint32_t, double>> out;
  for (const DueTime& x : d) out.emplace_back(x.t, x.seconds);
  return out;
}
using Due = std::vector<std::pair<std::uint32_t, double>>;

TEST(StreamPriorities, DueWindowIsTheTwoAroundThePlayheadAndTheirNeighboursWhenPaused) {
  const Times k({0, 1, 2, 3, 4, 5, 6, 7, 8});
  EXPECT_EQ(due(k, 2.5, 0.0, 1.0), (Due{{1, 1}, {2, 0}, {3, 0}, {4, 1}}));
  // On a keyframe: that keyframe (both sides' pick) and its neighbours.
  EXPECT_EQ(due(k, 4.0, 0.0, 1.0), (Due{{3, 1}, {4, 0}, {5, 1}}));
  EXPECT_EQ(due(k, 0.0, 0.0, 1.0), (Due{{0, 0}, {1, 1}}));
  // Before the node's first time step / after its last: the nearest one and the next.
  const Times sparse({3, 6, 9});
  EXPECT_EQ(due(sparse, 1.0, 0.0, 1.0), (Due{{3, 0}, {6, 1}}));
  EXPECT_EQ(due(sparse, 9.5, 0.0, 1.0), (Due{{6, 1}, {9, 0}}));
  // A gap in the node's time steps: the data nearest on each side.
  EXPECT_EQ(due(sparse, 4.0, 0.0, 2.0), (Due{{3, 0}, {6, 0}, {9, 2}}));
  // Only held time steps count: with the window from 4 on, 6 is the first.
  EXPECT_EQ(due(Times({3, 6, 9}, 4), 4.0, 0.0, 2.0), (Due{{6, 0}, {9, 2}}));
  EXPECT_TRUE(due(Times({}), 2.5, 0.0, 1.0).empty());
}

TEST(StreamPriorities, DueWindowLooksAheadInTheDirectionOfPlay) {
  const Times k({0, 1, 2, 3, 4, 5, 6, 7, 8});
  // Forward at 2 keyframes/s for 1.5 s: reaches 5.5; keyframes 3, 4, 5 due in 0.25, 0.75, 1.25 s
  // (3 is the playhead's pick after it: 0); 1 and 6 are the next ones beyond.
  EXPECT_EQ(due(k, 2.5, 2.0, 1.5), (Due{{1, 1.5}, {2, 0}, {3, 0}, {4, 0.75}, {5, 1.25}}));
  // Backwards: the keyframes behind it instead; ahead only the next one.
  EXPECT_EQ(due(k, 6.5, -4.0, 1.0),
            (Due{{3, 0.875}, {4, 0.625}, {5, 0.375}, {6, 0}, {7, 0}, {8, 1}}));
  // No lookahead: the two around the playhead and their neighbours (all due now), whatever the
  // speed.
  EXPECT_EQ(due(k, 2.5, 8.0, 0.0), (Due{{1, 0}, {2, 0}, {3, 0}, {4, 0}}));
  // Sparse steps ahead: those within reach, not the first one beyond it.
  EXPECT_EQ(due(Times({0, 2, 5, 9}), 2.0, 2.0, 2.0), (Due{{0, 2}, {2, 0}, {5, 1.5}}));
}

TEST(StreamPriorities, DuePriorityOutranksEveryPatentPriorityAndFallsWithTime) {
  PrioritySettings ps;
  // The largest [0045] priority: SSE priority → 1, temporal 1.
  const double max_patent = combined_priority(sse_priority(1e12), 1.0, 1.0, ps);
  EXPECT_GT(due_priority(0.0, ps), due_priority(0.5, ps));
  EXPECT_GT(due_priority(0.5, ps), due_priority(5.0, ps));
  EXPECT_DOUBLE_EQ(due_priority(0.0, ps), ps.sse_weight + 2.0);
  for (const double seconds : {0.0, 0.5, 1.0, 10.0, 1e6})
    EXPECT_GT(due_priority(seconds, ps), max_patent);
  ps.sse_weight = 1.5;
  EXPECT_GT(due_priority(1e6, ps), combined_priority(sse_priority(1e12), 1.0, 1.0, ps));
}

}  // namespace
}  // namespace volreel::stream
