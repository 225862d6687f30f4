// frame_loop.cpp: waiting for a view's data before drawing it (see frame_loop.hpp).
#include "volreel/loop/frame_loop.hpp"

#include <chrono>
#include <thread>

namespace volreel::loop {

ViewWait wait_for_view(FrameLoop& loop, const player::OrbitCamera& camera, double playhead,
                       double timeout_s, const std::function<void()>& between_steps) {
  using Clock = std::chrono::steady_clock;
  const auto start = Clock::now();
  const auto elapsed = [&] { return std::chrono::duration<double>(Clock::now() - start).count(); };
  ViewWait wait;
  int idle = 0;  // consecutive steps with nothing in flight, waiting or uploaded
  while (true) {
    FrameReport r = loop.stream(camera, playhead);
    ++wait.steps;
    wait.stats = r.stats;
    for (std::string& e : r.new_errors) wait.new_errors.push_back(std::move(e));
    const stream::StreamStats& s = r.stats;
    if (s.fraction_at_target >= 1.0) {
      wait.complete = true;
      break;
    }
    // Two quiet steps in a row: the scheduler had a chance to request more and did not (once the
    // frame indexes around the playhead are read or failed: before, it has nothing to request).
    idle = s.quiet() ? idle + 1 : 0;
    if (idle >= 2) break;
    if (elapsed() >= timeout_s) {
      wait.timed_out = true;
      break;
    }
    if (s.uploads == 0 && s.arrivals_waiting == 0)
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    if (between_steps) between_steps();
  }
  wait.seconds = elapsed();
  return wait;
}

}  // namespace volreel::loop
