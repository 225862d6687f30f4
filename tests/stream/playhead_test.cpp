// playhead_test.cpp: play, pause, reverse, speed, seek, step, clamping and looping.
#include <gtest/gtest.h>

#include "volreel/stream/playhead.hpp"

namespace volreel::stream {
namespace {

TEST(StreamPlayhead, PlaysForwardAndStopsAtTheEnd) {
  Playhead p(11, {.keyframes_per_second = 2.0, .loop = false});
  EXPECT_DOUBLE_EQ(p.last(), 10.0);
  EXPECT_DOUBLE_EQ(p.advance(1.0), 0.0);  // paused: nothing moves
  p.play();
  EXPECT_DOUBLE_EQ(p.advance(1.0), 2.0);
  p.set_speed(2.0);
  EXPECT_DOUBLE_EQ(p.advance(0.5), 4.0);
  p.set_speed(100);  // clamped to 8×
  EXPECT_DOUBLE_EQ(p.speed(), 8.0);
  p.set_speed(0.01);
  EXPECT_DOUBLE_EQ(p.speed(), 0.25);
  p.set_speed(8);
  EXPECT_DOUBLE_EQ(p.advance(10.0), 10.0);  // clamped at the end, paused
  EXPECT_FALSE(p.playing());
}

TEST(StreamPlayhead, ReverseSeekAndStep) {
  Playhead p(11, {.keyframes_per_second = 4.0, .loop = false});
  p.seek(7.3);
  EXPECT_DOUBLE_EQ(p.position(), 7.3);
  p.reverse();
  p.play();
  EXPECT_NEAR(p.advance(0.5), 5.3, 1e-12);
  EXPECT_DOUBLE_EQ(p.advance(5.0), 0.0);  // clamped at the start
  EXPECT_FALSE(p.playing());
  p.seek(-3);
  EXPECT_DOUBLE_EQ(p.position(), 0.0);
  p.seek(42);
  EXPECT_DOUBLE_EQ(p.position(), 10.0);
  p.seek(4.6);
  p.play();
  p.step(1);  // from the nearest keyframe (5), and pauses
  EXPECT_DOUBLE_EQ(p.position(), 6.0);
  EXPECT_FALSE(p.playing());
  p.step(-3);
  EXPECT_DOUBLE_EQ(p.position(), 3.0);
  p.step(-10);
  EXPECT_DOUBLE_EQ(p.position(), 0.0);
  p.toggle();
  EXPECT_TRUE(p.playing());
  p.pause();
  EXPECT_FALSE(p.playing());
}

TEST(StreamPlayhead, LoopsAroundBothEnds) {
  Playhead p(5, {.keyframes_per_second = 1.0, .loop = true});
  p.play();
  EXPECT_DOUBLE_EQ(p.advance(3.5), 3.5);
  EXPECT_DOUBLE_EQ(p.advance(1.0), 0.5);  // 4.5 wraps to 0.5 on a timeline of length 4
  EXPECT_TRUE(p.playing());
  p.set_reversed(true);
  EXPECT_DOUBLE_EQ(p.advance(1.0), 3.5);  // −0.5 wraps to 3.5
  p.step(3);                              // 4 + 3 = 7 wraps to 3
  EXPECT_DOUBLE_EQ(p.position(), 3.0);
  // A single keyframe: always 0.
  Playhead one(1);
  one.play();
  EXPECT_DOUBLE_EQ(one.advance(10), 0.0);
}

TEST(StreamPlayhead, MotionFollowsPlaybackAndIgnoresSeeks) {
  PlayheadMotion m;
  EXPECT_EQ(m.observe(0.0, 0.0), 0.0);
  // Forward at 6 keyframes/s, 10 frames per second.
  double v = 0;
  for (int i = 1; i <= 5; ++i) v = m.observe(0.1 * i, 0.6 * i);
  EXPECT_NEAR(v, 6.0, 1e-9);
  // A seek (one jump) does not read as fast playback.
  EXPECT_NEAR(m.observe(0.6, 40.0), 6.0, 1e-9);
  // Paused after it: the velocity drops to 0 within two frames.
  m.observe(0.7, 40.0);
  EXPECT_NEAR(m.observe(0.8, 40.0), 0.0, 1e-9);
  // Reverse at 2 keyframes/s.
  for (int i = 1; i <= 3; ++i) v = m.observe(0.8 + 0.1 * i, 40.0 - 0.2 * i);
  EXPECT_NEAR(v, -2.0, 1e-9);
  // The same instant again changes nothing.
  EXPECT_NEAR(m.observe(1.1, 10.0), -2.0, 1e-9);
  EXPECT_NEAR(m.velocity(), -2.0, 1e-9);
}

TEST(StreamPlayhead, MotionAtTheStart) {
  PlayheadMotion m;
  EXPECT_EQ(m.observe(0.0, 0.0), 0.0);
  EXPECT_NEAR(m.observe(0.1, 0.5), 5.0, 1e-9);  // the first difference: playback starts
  // A seek as the second difference: the smaller of the two, not the jump.
  EXPECT_NEAR(m.observe(0.2, 30.5), 5.0, 1e-9);
  PlayheadMotion n;
  n.observe(0.0, 0.0);
  n.observe(0.1, 30.0);                          // a seek first: one frame of a wrong velocity
  EXPECT_NEAR(n.observe(0.2, 30.0), 0.0, 1e-9);  // gone at once
}

}  // namespace
}  // namespace volreel::stream
