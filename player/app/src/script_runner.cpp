// script_runner.cpp: the player's timed script actions (script.hpp), run once per frame.
#include "player_impl.hpp"

#include <backends/imgui_impl_glfw.h>
#include <backends/imgui_impl_vulkan.h>
#include <imgui.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

namespace volreel::app::detail {

void Player::run_script(double dt) {
  if (settling_) {
    // stats_ are those of the previous frame: only frames after the one that started settling
    // count, and two complete frames in a row end it. Prefetching of other keyframes may go on.
    // So do two quiet frames in a row (the frame indexes around the playhead read or failed, and
    // nothing in flight, waiting or uploaded: the scheduler had a chance to request more and did
    // not), as loop::wait_for_view: a view whose bricks cannot be read (a damaged frame) never
    // completes, and waiting for it would only run out the time.
    settle_waited_ += dt;
    const bool counted = frame_number_ > settle_from_;
    const bool idle = counted && stats_.fraction_at_target >= 1.0 && stats_.holes == 0;
    const bool quiet = counted && stats_.quiet();
    idle_frames_ = idle ? idle_frames_ + 1 : 0;
    quiet_frames_ = quiet ? quiet_frames_ + 1 : 0;
    if (idle_frames_ >= 2 || quiet_frames_ >= 2 || settle_waited_ >= settle_timeout_) {
      if (idle_frames_ < 2 && quiet_frames_ >= 2) {
        std::fprintf(stderr,
                     "volreel play: script: settle ended after %.1f s with %.0f %% of the view at "
                     "its target level of detail and nothing more to load (read errors: %zu)\n",
                     settle_waited_, 100 * stats_.fraction_at_target, stats_.errors);
      } else if (idle_frames_ < 2) {
        std::fprintf(stderr, "volreel play: script: settle timed out after %.1f s\n",
                     settle_waited_);
      }
      settling_ = false;
    }
    return;  // the script clock stops while settling
  }
  script_clock_ += dt;
  using Kind = ScriptAction::Kind;
  while (next_action_ < script_.size() && !settling_) {
    const ScriptAction& a = script_[next_action_];
    const std::int64_t frame = static_cast<std::int64_t>(frame_number_) -
                               (a.relative ? static_cast<std::int64_t>(previous_action_frame_) : 0);
    const double clock = script_clock_ - (a.relative ? previous_action_clock_ : 0.0);
    const bool due = a.at_frame >= 0 ? frame >= a.at_frame : clock >= a.at_seconds;
    if (!due) break;
    ++next_action_;
    previous_action_frame_ = frame_number_;
    previous_action_clock_ = script_clock_;
    if (!options_.quiet)
      std::printf("script: frame %llu keyframe %.3f: %s\n",
                  static_cast<unsigned long long>(frame_number_), playhead_.position(),
                  a.source.c_str());
    switch (a.kind) {
      case Kind::key:
        press(key_code(a.text));
        break;
      case Kind::seek:
        playhead_.seek(a.x);
        break;
      case Kind::speed:
        playhead_.set_speed(a.x);
        break;
      case Kind::play:
        playhead_.play();
        break;
      case Kind::pause:
        playhead_.pause();
        break;
      case Kind::reverse:
        playhead_.reverse();
        break;
      case Kind::orbit:
        camera_.azimuth += a.x * M_PI / 180.0;
        camera_.elevation = std::clamp(camera_.elevation + a.y * M_PI / 180.0, -1.5, 1.5);
        break;
      case Kind::zoom:
        camera_.distance *= a.x;
        break;
      case Kind::transfer:
        apply_preset(a.text);
        break;
      case Kind::sse:
        sse_target_ = static_cast<float>(a.x);
        break;
      case Kind::settle:
        settling_ = true;
        settle_timeout_ = a.x;
        settle_waited_ = 0;
        settle_from_ = frame_number_;
        idle_frames_ = quiet_frames_ = 0;
        break;
      case Kind::resize:
        glfwSetWindowSize(window_.get(), static_cast<int>(a.x), static_cast<int>(a.y));
        break;
      case Kind::screenshot:
        pending_screenshots_.emplace_back(a.text);
        return;  // this frame is the screenshot: later entries wait for the next frame
      case Kind::camera:
        report_camera("script");
        break;
      case Kind::layout:
        report_layout();
        break;
      case Kind::quit:
        quit_ = true;
        break;
    }
  }
}

}  // namespace volreel::app::detail
