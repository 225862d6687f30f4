// player.hpp: `volreel play NAME.vreel` — the interactive player window (GLFW + a Vulkan swapchain
// + Dear ImGui). Per rendered frame (docs/design.md, "Streaming"): stream scheduler → brick
// uploads within the budget → decode into the atlas → array SVO → render the volume → ImGui on
// top → present, with two frames in flight so the CPU work of frame N+1 overlaps the GPU work of
// frame N.
//
// Controls: space play/pause, r reverse, [ ] speed ÷2 ×2 (0.25×–8×), ← → step one keyframe,
// Home/End first/last keyframe, c reset view, h hide the panels, l loop, q or Escape quit; left
// drag orbits, right or middle drag pans, the wheel zooms. The timeline slider scrubs; the side
// panel edits the transfer function and the screen-space-error target; in small windows (down to
// about 320 × 240) the panels take a compact form and never overlap. While the window is minimized
// nothing is rendered and the playhead stands still. A script (script.hpp) replays the same
// actions for tests.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>

#include "volreel/format/source.hpp"
#include "volreel/loop/frame_loop.hpp"
#include "volreel/stream/scheduler.hpp"

namespace volreel::app {

/// Which volume renderer draws the frame.
enum class RendererKind {
  /// The Vulkan ray caster on a GPU; the CPU reference renderer where Vulkan runs on the CPU
  /// (lavapipe) or the Vulkan ray caster cannot be created.
  automatic,
  cpu,     ///< CPU reference renderer (cpu_render::render_svo), image uploaded each frame
  vulkan,  ///< the Vulkan compute ray caster
};

struct PlayerOptions {
  std::filesystem::path container;  ///< NAME.vreel (or its URL, for the title)
  /// Where to read it from (a remote source); empty: the folder `container`.
  std::shared_ptr<const format::ContainerSource> source;
  int width = 1024, height = 720;            ///< initial window size, pixels
  std::uint64_t atlas_bytes = 256ull << 20;  ///< GPU atlas memory budget
  double bandwidth_bytes_per_s = 0;          ///< loader bandwidth limit (0: unlimited)
  double latency_s = 0;                      ///< loader latency added to each request
  std::size_t max_requests = 128;            ///< brick requests in flight at most
  std::uint64_t upload_bytes = 8ull << 20;   ///< compressed brick bytes decoded per frame at most
  std::string transfer = "auto";       ///< "auto" (quantiles of the data), a preset or a JSON file
  double sse_target = 1.0;             ///< pixels per voxel at which a node is detailed enough
  double keyframes_per_second = 10.0;  ///< playback rate at 1×
  bool loop = false;                   ///< wrap around at the ends of the timeline
  bool vsync = true;                   ///< FIFO presentation (else immediate when available)
  RendererKind renderer = RendererKind::automatic;
  double render_scale = 1.0;  ///< volume image size / window size, (0, 1]
  /// Frame-time target while the view is busy (camera moving, playing, bricks streaming in),
  /// milliseconds: the volume image is rendered smaller to hold it and at full size once the
  /// view is still (loop::ResolutionControl). 0: always full size.
  double frame_ms = 100;
  /// Where the Vulkan renderer decodes bricks (loop::FrameLoopOptions::Decode).
  loop::FrameLoopOptions::Decode decode = loop::FrameLoopOptions::Decode::automatic;
  /// Level-of-detail blending (stream::LodBlendSettings: the fade's seconds, spatial blending).
  stream::LodBlendSettings lod_blend;
  /// A restricted working set (stream::PrioritySettings::restricted).
  bool restricted = stream::PrioritySettings{}.restricted;
  /// Restricted drawing (stream::SelectionSettings::restricted).
  bool restricted_drawing = stream::SelectionSettings{}.restricted;
  /// Ray-guided feedback (stream::SchedulerSettings::ray_feedback).
  bool ray_feedback = stream::SchedulerSettings{}.ray_feedback;
  std::string script;            ///< script text (script.hpp), empty for none
  std::uint64_t max_frames = 0;  ///< quit after this many frames (0: never)
  std::optional<std::filesystem::path> screenshot_on_exit;  ///< PNG of the last frame
  /// When > 0, the playhead advances by this many seconds per frame instead of the wall-clock
  /// frame time (reproducible runs for tests).
  double fixed_frame_seconds = 0;
  bool quiet = false;  ///< no per-second status lines on stdout
};

/// There is no display to open a window on (no $DISPLAY / $WAYLAND_DISPLAY, or GLFW could not
/// connect); what() suggests `xvfb-run` and `volreel render`.
class NoDisplayError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// What went wrong in a session that ran to its end.
struct PlayerResult {
  std::size_t failed_screenshots = 0;  ///< screenshots that could not be written
  std::size_t read_failures = 0;       ///< distinct bricks or frames that could not be read
};

/// Runs the player until the window is closed, the script quits or max_frames is reached.
/// Throws NoDisplayError without a display, vulkan::NoDeviceError without a Vulkan device with
/// presentation support, and format::FormatError / InputError for a container or option that
/// cannot be used. Bad frame files found while playing are HUD and stderr messages, counted in the
/// result; the session goes on without them.
PlayerResult run_player(const PlayerOptions& options);

}  // namespace volreel::app
