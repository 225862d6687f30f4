#!/usr/bin/env bash
# play_input_test.sh: `volreel play` driven by real X input under Xvfb with a window manager (twm):
# xdotool sends pointer events (a left drag, a right drag, wheel clicks) and a key press to the
# window, and minimizes and restores it through the window manager (ICCCM WM_CHANGE_STATE; Xvfb
# alone has no window manager, so iconifying would do nothing). Checks, from the camera the
# player reports after each gesture: the left drag orbits (azimuth and elevation change, distance
# and target do not), the right drag pans (the target moves, the angles do not), the wheel zooms
# in (distance × 0.9 per click); then that no frame is rendered while the window is minimized and
# rendering resumes after it is restored, and that the real `q` key quits with a final frame that
# is not blank and differs from the one before the gestures.
# Exits 77 (skipped) without xvfb-run, xdotool or twm, or without a Vulkan device that can present.
# Usage: play_input_test.sh PATH/TO/volreel
set -euo pipefail
volreel=$1
# shellcheck source=window_test_lib.sh
. "$(dirname "$0")/window_test_lib.sh"
command -v xvfb-run > /dev/null || skip "xvfb-run is not installed (Debian: apt install xvfb)"
command -v xdotool > /dev/null || skip "xdotool is not installed (Debian: apt install xdotool): real mouse input and minimize not tested"
command -v twm > /dev/null || skip "twm is not installed (Debian: apt install twm): minimize needs a window manager"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

"$volreel" gen analytic --field blobs --dims 40x36x30 --frames 3 --out "$work/s" 2>/dev/null
"$volreel" train "$work/s" --out "$work/dict.bin" --atoms 64 --coreset 200k --levels 2 --iterations 2 --psnr 45 > /dev/null 2>&1
"$volreel" encode "$work/s" --dictionary "$work/dict.bin" --out "$work/a.vreel" > /dev/null 2>&1

# twm: place windows without asking for a click, no title bars.
printf 'RandomPlacement\nNoTitle\n' > "$work/twmrc"

# The session inside the virtual display: window manager, player, then xdotool's events. Each
# step waits for the player's report of the previous one (polling its stdout).
cat > "$work/session.sh" <<'SESSION'
#!/usr/bin/env bash
set -euo pipefail
work=$1
volreel=$2
twm -f "$work/twmrc" > "$work/twm.log" 2>&1 &
wm=$!
player=
cleanup() {
  [ -n "$player" ] && kill "$player" 2> /dev/null || true
  kill "$wm" 2> /dev/null || true
}
trap cleanup EXIT
sleep 0.5
"$volreel" play "$work/a.vreel" --size 320x240 --fixed-frame-time 0.05 \
  --script-inline "0 key h; 0 settle 30; 0 camera; 0 screenshot $work/before.png" \
  --screenshot-on-exit "$work/exit.png" ${VOLREEL_PLAY_TEST_ARGS:-} > "$work/out.txt" 2> "$work/err.txt" &
player=$!
seen() { grep -q -- "$1" "$work/out.txt"; }
past_frame() {  # N: a status line reports frame N or later
  awk -v n="$1" '/^frame [0-9]+  keyframe/ && $2 + 0 >= n { found = 1 } END { exit !found }' "$work/out.txt"
}
wait_for() {  # PATTERN [COMMAND...]: wait up to 60 s for a line of the player's stdout (or COMMAND)
  local what=$1
  [ $# -gt 1 ] && shift || set -- seen "$1"
  for _ in $(seq 1 240); do
    "$@" && return 0
    if ! kill -0 "$player" 2> /dev/null; then
      wait "$player" || exit $?  # exit codes 3 and 4: no display / no Vulkan device (skips)
      echo "the player exited while waiting for '$what'" >&2
      exit 1
    fi
    sleep 0.25
  done
  echo "timed out waiting for '$what'" >&2
  exit 1
}
wait_for "screenshot: $work/before.png"
wid=$(xdotool search --sync --onlyvisible --name '^volreel' | head -1)
[ -n "$wid" ] || { echo "no player window found" >&2; exit 1; }
drag() {  # BUTTON: press at the centre, move in four steps, release (a frame sees each step)
  xdotool mousemove --window "$wid" 160 120
  sleep 0.3
  xdotool mousedown "$1"
  for step in 1 2 3 4; do
    sleep 0.25
    xdotool mousemove --window "$wid" $((160 + 15 * step)) $((120 + 5 * step))
  done
  sleep 0.3
  xdotool mouseup "$1"
}
drag 1
wait_for "camera (left drag: orbit)"
drag 3
wait_for "camera (right drag: pan)"
xdotool mousemove --window "$wid" 160 120
for _ in 1 2 3; do
  xdotool click 4
  sleep 0.3
done
wait_for "camera (wheel: zoom)"

xdotool windowminimize --sync "$wid"
wait_for "window minimized at frame"
sleep 2.5  # a status line would be printed every second if frames were rendered
xdotool windowmap --sync "$wid"
wait_for "window restored after"
# Rendering resumes: wait for a status line five frames on.
resumed=$(sed -nE 's/^window restored after .* at frame ([0-9]+)$/\1/p' "$work/out.txt")
wait_for "frame $((resumed + 5))" past_frame $((resumed + 5))
xdotool mousemove --window "$wid" 160 120
xdotool key q
for _ in $(seq 1 120); do
  kill -0 "$player" 2> /dev/null || break
  sleep 0.25
done
kill -0 "$player" 2> /dev/null && { echo "the player did not quit on the q key" >&2; exit 1; }
wait "$player"
SESSION
chmod +x "$work/session.sh"

set +e
timeout 150 xvfb-run -a -s "-screen 0 1024x768x24" "$work/session.sh" "$work" "$volreel" > "$work/session.txt" 2>&1
rc=$?
set -e
cat "$work/out.txt" 2> /dev/null || true
check_player_exit $rc "$work/err.txt" "the session" "$work/session.txt" "$work/err.txt"
grep -q "Validation Error" "$work/err.txt" && fail "Vulkan validation errors: $(cat "$work/err.txt")"
for f in before exit; do [ -s "$work/$f.png" ] || fail "no screenshot $f.png"; done

/usr/bin/python3 - "$work" <<'PY' || fail "input checks"
import re, sys
import numpy as np
from PIL import Image
work = sys.argv[1]
lines = open(f"{work}/out.txt").read().splitlines()
ok = True
def check(cond, msg):
    global ok
    print(("ok:   " if cond else "FAIL: ") + msg)
    ok = ok and cond
cam_re = re.compile(r"camera \((.*)\): azimuth (\S+) deg elevation (\S+) deg distance (\S+) target (\S+) (\S+) (\S+)")
cams = []
for l in lines:
    m = cam_re.match(l)
    if m:
        cams.append((m.group(1), np.array([float(x) for x in m.groups()[1:]])))
def first(cause):
    return next((i for i, (c, _) in enumerate(cams) if c == cause), None)
i0, i1, i2 = first("script"), first("left drag: orbit"), first("right drag: pan")
zooms = [v for c, v in cams if c == "wheel: zoom"]
check(None not in (i0, i1, i2) and zooms, f"camera reports: script, orbit, pan, zoom (found {[c for c, _ in cams]})")
if ok:
    home, orbit, pan = cams[i0][1], cams[i1][1], cams[i2][1]
    # [azimuth, elevation, distance, tx, ty, tz]; a 60 x 20 px left drag: 0.01 rad per pixel.
    check(abs(orbit[0] - home[0]) > 10 and abs(orbit[1] - home[1]) > 3,
          f"left drag orbits: azimuth {home[0]:.1f} -> {orbit[0]:.1f}, elevation {home[1]:.1f} -> {orbit[1]:.1f}")
    check(np.allclose(orbit[2:], home[2:]), "left drag keeps the distance and target")
    check(np.linalg.norm(pan[3:] - orbit[3:]) > 1e-3 * home[2] and np.allclose(pan[:3], orbit[:3]),
          f"right drag pans: target {orbit[3:]} -> {pan[3:]}, angles and distance kept")
    # Three wheel clicks, 0.9 x the distance each (clicks within one frame are reported together).
    got = np.array([z[2] for z in zooms])
    steps = np.log(got / pan[2]) / np.log(0.9)
    check(np.allclose(steps, np.round(steps), atol=1e-3) and np.all(np.diff(got) < 0) and abs(steps[-1] - 3) < 1e-3,
          f"the wheel zooms in: distance {pan[2]:.3f} -> {got} ({steps.round(3)} clicks)")
    check(np.allclose(zooms[-1][[0, 1, 3, 4, 5]], pan[[0, 1, 3, 4, 5]]), "the wheel keeps the angles and target")
# Minimized: no frame in between, rendering resumes after.
status_re = re.compile(r"^frame (\d+)  keyframe")
mini = next((i for i, l in enumerate(lines) if l.startswith("window minimized at frame")), None)
rest = next((i for i, l in enumerate(lines) if l.startswith("window restored after")), None)
check(mini is not None and rest is not None and mini < rest, "minimize and restore reported in order")
if mini is not None and rest is not None:
    f_min = int(re.search(r"at frame (\d+)", lines[mini]).group(1))
    f_rest = int(re.search(r"at frame (\d+)", lines[rest]).group(1))
    away = float(re.search(r"after (\S+) s", lines[rest]).group(1))
    check(away >= 2.0, f"minimized for {away} s")
    check(f_min == f_rest, f"no frame rendered while minimized (frame {f_min} at minimize, {f_rest} at restore)")
    between = [l for l in lines[mini + 1:rest] if status_re.match(l)]
    check(not between, f"no status line while minimized ({len(between)} found)")
    after = [int(status_re.match(l).group(1)) for l in lines[rest + 1:] if status_re.match(l)]
    check(bool(after) and max(after) >= f_rest + 5, f"rendering resumed after restore (frames after: {after})")
a, b = (np.asarray(Image.open(f"{work}/{n}.png").convert("RGB")).astype(np.float64) for n in ("before", "exit"))
check(b.std() > 5, f"the final frame is not blank (std {b.std():.1f})")
check(np.abs(a - b).mean() > 0.5, f"the camera moves changed the picture (mean |exit - before| = {np.abs(a - b).mean():.2f})")
sys.exit(0 if ok else 1)
PY
echo "play_input: all checks passed"
