// script.hpp: scripted input for the player window, for tests and demos — a list of timed
// actions replayed as if typed:
//
//   "0.5 key space; 1.0 key right; 1.5 screenshot a.png; 2.0 quit"
//
// Entries are separated by ';' or newlines; '#' starts a comment. Each entry is WHEN ACTION ARGS:
//   WHEN    seconds since the first frame ("0.5" or "0.5s"), or a frame number ("12f"); with a
//           leading '+', seconds or frames after the previous entry ran ("+0.3", "+4f")
//   ACTION  key NAME          a key press (space, r, left, right, home, end, c, [, ], ...)
//           seek T            playhead to T (keyframe units)
//           speed X           playback speed (0.25–8)
//           play | pause | reverse
//           orbit DAZ DEL     rotate the camera by DAZ, DEL degrees
//           zoom F            multiply the camera distance by F
//           transfer PRESET   switch to a transfer-function preset
//           sse X             screen-space-error target, pixels
//           resize W H        resize the window to W × H pixels
//           settle [SECONDS]  hold the script until two frames in a row draw every visible
//                             node at its target LOD with both keyframes (prefetching of other
//                             keyframes may go on), or two in a row have the frame indexes
//                             around the playhead and nothing in flight, waiting or uploaded
//                             (what is missing cannot be read: said on stderr), or the timeout
//                             (default 20 s) passes
//           screenshot PATH   write this frame, as presented, to PATH (PNG: a name ending in
//                             .png, in a folder that exists when the script is read); later
//                             entries run from the next frame on
//           camera            print the camera ("camera (script): azimuth A deg elevation E deg
//                             distance D target X Y Z") on stdout
//           layout            print the screen rectangles of the HUD, timeline and side panel as
//                             drawn in the previous frame ("layout WxH: hud X Y W H; ...")
//           quit
// Entries run in the order given; an entry runs at the first frame at or after its time. Time
// spent in `settle` does not count: the script clock stops while it waits.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace volreel::app {

struct ScriptAction {
  enum class Kind {
    key,
    seek,
    speed,
    play,
    pause,
    reverse,
    orbit,
    zoom,
    transfer,
    sse,
    settle,
    resize,
    screenshot,
    camera,
    layout,
    quit
  };
  double at_seconds = -1;      ///< when ≥ 0: seconds of script clock
  std::int64_t at_frame = -1;  ///< when ≥ 0: frame number (0 = the first frame)
  bool relative = false;       ///< times count from when the previous entry ran
  Kind kind = Kind::quit;
  std::string text;     ///< key name, preset, path
  double x = 0, y = 0;  ///< numeric arguments
  std::string source;   ///< the entry as written, for messages
};

/// Parses a script; throws InputError naming the entry on a syntax error or an unknown action or
/// key.
std::vector<ScriptAction> parse_script(const std::string& text);

/// Why `path` cannot take a screenshot, or "" when it can: the name must end in .png (any case),
/// must not be a folder, and its folder must exist.
std::string screenshot_path_problem(const std::string& path);

/// The GLFW key code of a key name ("space", "left", "a", "[", "home", ...), or -1.
int key_code(const std::string& name);

}  // namespace volreel::app
