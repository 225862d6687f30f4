#!/usr/bin/env bash
# play_window_test.sh: `volreel play` in a window under Xvfb. Makes a small container (gen →
# train → encode), then plays it with a script: the panels hidden, a screenshot of keyframe 0, a
# step (right arrow), play for three frames and pause (space), a seek back to 0, End, window
# resizes, and screenshots with the panels at 400x300, 320x240 and 1280x720. Checks that the
# frames are not blank, that stepping and playing change the picture, that seeking back
# reproduces keyframe 0's picture, that the script ran in order and the swapchain followed the
# resizes, that the panels (HUD, timeline, side panel, as reported by the `layout` script action)
# stay inside the window without overlapping at each size (and, where the validation layer is
# installed, that it reports no error). Then: the CPU reference renderer in the same window draws
# keyframe 0 like the Vulkan ray caster (PSNR > 30 dB); a copy with a truncated frame file plays to
# the end with the problem reported, and a settle at that frame ends when nothing more can load;
# without a display the command says how to get one. Real mouse input and minimizing are tested
# by play_input_test.sh. Frame-time control: while playing
# the volume image is smaller, paused and settled it is at full size.
# Exits 77 (skipped) without xvfb-run or without a Vulkan device that can present to a window.
# Usage: play_window_test.sh PATH/TO/volreel
set -euo pipefail
volreel=$1
# shellcheck source=window_test_lib.sh
. "$(dirname "$0")/window_test_lib.sh"
command -v xvfb-run > /dev/null || skip "xvfb-run is not installed (Debian: apt install xvfb)"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

"$volreel" gen analytic --field blobs --dims 40x36x30 --frames 4 --out "$work/s" 2>/dev/null
"$volreel" train "$work/s" --out "$work/dict.bin" --atoms 64 --coreset 200k --levels 2 --iterations 2 --psnr 45 > /dev/null 2>&1
"$volreel" encode "$work/s" --dictionary "$work/dict.bin" --out "$work/a.vreel" > /dev/null 2>&1

cat > "$work/script.txt" <<SCRIPT
# the panels off: screenshots show the volume alone
0 key h
0 settle 30
0 screenshot $work/s0.png
0 key right
0 settle 30
0 screenshot $work/s1.png
0 key space
+3f key space
0 settle 30
0 screenshot $work/s2.png
0 seek 0
0 settle 30
0 screenshot $work/s3.png
0 key end
0 key h
0 resize 400 300
+2f settle 30
0 screenshot $work/ui.png
0 layout
0 resize 320 240
+2f settle 30
0 layout
0 screenshot $work/ui320.png
0 resize 1280 720
+2f settle 30
0 layout
0 screenshot $work/ui1280.png
0 quit
SCRIPT

# Where the Khronos validation layer is installed, the window's Vulkan use is checked by it
# (VOLREEL_PLAY_TEST_VALIDATION=0 turns that off).
validation=0
for d in /usr/share/vulkan/explicit_layer.d /etc/vulkan/explicit_layer.d; do
  [ -e "$d/VkLayer_khronos_validation.json" ] && validation=1
done
validation=${VOLREEL_PLAY_TEST_VALIDATION:-$validation}

set +e
VOLREEL_VULKAN_VALIDATION=$validation timeout 120 xvfb-run -a -s "-screen 0 1280x800x24" "$volreel" play "$work/a.vreel" --size 320x240 --renderer vulkan \
  --script "$work/script.txt" --fixed-frame-time 0.05 --screenshot-on-exit "$work/exit.png" \
  ${VOLREEL_PLAY_TEST_ARGS:-} > "$work/out.txt" 2> "$work/err.txt"
rc=$?
set -e
cat "$work/out.txt"
check_player_exit $rc "$work/err.txt" "volreel play" "$work/err.txt"
grep -q "settle timed out" "$work/err.txt" && fail "streaming did not settle: $(cat "$work/err.txt")"
grep -q "Validation Error" "$work/err.txt" && fail "Vulkan validation errors: $(cat "$work/err.txt")"
for f in s0 s1 s2 s3 ui ui320 ui1280 exit; do [ -s "$work/$f.png" ] || fail "no screenshot $f.png"; done

# The playhead: keyframe 1 after the step, further on after playing, 0 after the seek.
keyframe_at() { grep "screenshot $work/$1.png" "$work/out.txt" | sed -E 's/.*keyframe ([0-9.]+):.*/\1/'; }
[ "$(keyframe_at s0)" = 0.000 ] || fail "s0 at keyframe $(keyframe_at s0), expected 0"
[ "$(keyframe_at s1)" = 1.000 ] || fail "s1 at keyframe $(keyframe_at s1), expected 1 after a step"
/usr/bin/python3 -c "import sys; sys.exit(0 if $(keyframe_at s2) > 1 else 1)" || fail "s2 at keyframe $(keyframe_at s2): playing did not move on"
[ "$(keyframe_at s3)" = 0.000 ] || fail "s3 at keyframe $(keyframe_at s3), expected 0 after the seek"

/usr/bin/python3 - "$work" <<'PY' || fail "screenshot checks"
import sys
import numpy as np
from PIL import Image
work = sys.argv[1]
img = {n: np.asarray(Image.open(f"{work}/{n}.png").convert("RGB")).astype(np.float64)
       for n in ("s0", "s1", "s2", "s3", "ui")}
ok = True
def check(cond, msg):
    global ok
    print(("ok:   " if cond else "FAIL: ") + msg)
    ok = ok and cond
for n in ("s0", "s1", "s2"):
    a = img[n]
    check(a.shape == (240, 320, 3), f"{n}: 320x240 RGB, found {a.shape}")
    lit = (a.max(axis=2) > 24).mean()
    check(a.std() > 5 and 0.02 < lit < 0.98, f"{n}: not blank (std {a.std():.1f}, lit {lit:.2f})")
def mad(a, b):
    return np.abs(img[a] - img[b]).mean()
check(mad("s0", "s1") > 0.5, f"a step changes the picture (mean |s1 - s0| = {mad('s0', 's1'):.2f})")
check(mad("s1", "s2") > 0.5, f"playing changes the picture (mean |s2 - s1| = {mad('s1', 's2'):.2f})")
check(mad("s0", "s3") < 0.5, f"seeking back reproduces keyframe 0 (mean |s3 - s0| = {mad('s0', 's3'):.2f})")
ui = img["ui"]
check(ui.shape == (300, 400, 3), f"ui: 400x300 after resizing the window, found {ui.shape}")
panel = ui[-60:, :, :]  # the timeline panel along the bottom edge
check(panel.std() > 10, f"ui: the panels show when turned on (std of the timeline strip {panel.std():.1f})")
check(np.asarray(Image.open(f"{work}/ui320.png")).shape[:2] == (240, 320), "ui320: 320x240")
check(np.asarray(Image.open(f"{work}/ui1280.png")).shape[:2] == (720, 1280), "ui1280: 1280x720")

# The panels' rectangles (the `layout` script action): inside the window, none over another.
import re
layouts = [l for l in open(f"{work}/out.txt") if l.startswith("layout ")]
check([l.split(":")[0] for l in layouts] == ["layout 400x300", "layout 320x240", "layout 1280x720"],
      f"layout reported at 400x300, 320x240, 1280x720 (found {[l.split(':')[0] for l in layouts]})")
for l in layouts:
    size, rest = l.split(":", 1)
    w, h = (float(v) for v in size.split()[1].split("x"))
    rects = {}
    for part in rest.split(";"):
        words = part.split()
        if len(words) >= 5:
            rects[words[0]] = [float(v) for v in words[1:5]]
    check(set(rects) == {"hud", "timeline", "panel"}, f"{size}: all three panels shown ({sorted(rects)})")
    for name, (x, y, rw, rh) in rects.items():
        check(x >= 0 and y >= 0 and x + rw <= w and y + rh <= h, f"{size}: {name} {x:.0f},{y:.0f} {rw:.0f}x{rh:.0f} inside the window")
    names = sorted(rects)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            ax, ay, aw, ah = rects[a]
            bx, by, bw, bh = rects[b]
            overlap = ax < bx + bw and bx < ax + aw and ay < by + bh and by < ay + ah
            check(not overlap, f"{size}: {a} and {b} do not overlap")
sys.exit(0 if ok else 1)
PY

# The CPU reference renderer in the same window draws the same picture of keyframe 0.
timeout 60 xvfb-run -a -s "-screen 0 1280x800x24" "$volreel" play "$work/a.vreel" --size 320x240 \
  --renderer cpu --script-inline "0 key h; 0 settle 30; 0 screenshot $work/cpu.png; 0 quit" \
  > "$work/out_cpu.txt" 2> "$work/err_cpu.txt" || fail "play --renderer cpu: $(cat "$work/err_cpu.txt")"
# A screenshot that cannot be written is an error of the run (exit status 1), not only a message.
if timeout 60 xvfb-run -a -s "-screen 0 1280x800x24" "$volreel" play "$work/a.vreel" --size 320x240 \
  --renderer cpu --script-inline "0 screenshot /proc/volreel-test.png; 0 quit" \
  > /dev/null 2> "$work/err_shot.txt"; then fail "play exited 0 after a screenshot failed"; fi
grep -q "1 screenshot(s) could not be written" "$work/err_shot.txt" || fail "no message for the failed screenshot: $(cat "$work/err_shot.txt")"
/usr/bin/python3 - "$work" <<'PY' || fail "the CPU renderer's picture differs from the Vulkan one"
import sys
import numpy as np
from PIL import Image
work = sys.argv[1]
a, b = (np.asarray(Image.open(f"{work}/{n}.png").convert("RGB")).astype(np.float64) for n in ("s0", "cpu"))
mse = ((a - b) ** 2).mean()
psnr = 10 * np.log10(255 ** 2 / max(mse, 1e-12))
print(f"CPU vs Vulkan renderer in the window: PSNR {psnr:.1f} dB")
sys.exit(0 if psnr > 30 else 1)
PY

# Frame-time control: while playing, the volume image is rendered smaller to hold --frame-ms (here
# an unreachable 1 ms: the smallest scale, 1/8 of the side) and scaled up; paused and settled,
# at the window's full size.
timeout 60 xvfb-run -a -s "-screen 0 1280x800x24" "$volreel" play "$work/a.vreel" --size 320x240 \
  --frame-ms 1 --fixed-frame-time 0.05 --loop ${VOLREEL_PLAY_TEST_ARGS:-} --script-inline \
  "0 key h; 0 key space; 12f screenshot $work/busy.png; +1f key space; 0 settle 30; 0 screenshot $work/still.png; 0 quit" \
  > "$work/out_res.txt" 2> "$work/err_res.txt" || fail "play --frame-ms 1: $(cat "$work/err_res.txt")"
grep -q "screenshot: $work/busy.png (volume image 40x30)" "$work/out_res.txt" \
  || fail "playing did not reduce the volume image to 40x30: $(grep "screenshot:" "$work/out_res.txt")"
grep -q "screenshot: $work/still.png (volume image 320x240)" "$work/out_res.txt" \
  || fail "the still view is not at full size: $(grep "screenshot:" "$work/out_res.txt")"
echo "frame-time control: busy 40x30, still 320x240"

# A truncated frame file: reported (HUD and stderr), playback continues to the last keyframe, and
# the session ends with status 1 and the count of what could not be read.
cp -r "$work/a.vreel" "$work/b.vreel"
truncate -s 100 "$work/b.vreel/frames/000002.vrf"
status=0
timeout 60 xvfb-run -a -s "-screen 0 1280x800x24" "$volreel" play "$work/b.vreel" --size 200x150 \
  --fixed-frame-time 0.05 --script-inline "0 key space; 20f quit" ${VOLREEL_PLAY_TEST_ARGS:-} \
  > "$work/out_b.txt" 2> "$work/err_b.txt" || status=$?
[ "$status" = 1 ] || fail "play with a damaged frame exited with $status, expected 1: $(cat "$work/err_b.txt")"
grep -q "000002.vrf" "$work/err_b.txt" || fail "the truncated frame was not reported: $(cat "$work/err_b.txt")"
grep -q "[1-9][0-9]* bricks or frames could not be read (the messages above name them)" "$work/err_b.txt" \
  || fail "no count of what could not be read: $(tail -2 "$work/err_b.txt")"
tail -1 "$work/out_b.txt" | grep -q "keyframe 3.00" || fail "playback stopped early: $(tail -1 "$work/out_b.txt")"
tail -1 "$work/out_b.txt" | grep -Eq "errors [1-9]" || fail "no error counted: $(tail -1 "$work/out_b.txt")"
# A settle at the damaged keyframe ends once nothing more can be loaded, not at its timeout.
status=0
timeout 60 xvfb-run -a -s "-screen 0 1280x800x24" "$volreel" play "$work/b.vreel" --size 200x150 \
  --fixed-frame-time 0.05 --script-inline "0 seek 2; 0 settle 40; 0 quit" ${VOLREEL_PLAY_TEST_ARGS:-} \
  > "$work/out_c.txt" 2> "$work/err_c.txt" || status=$?
[ "$status" = 1 ] || fail "settle at a damaged frame exited with $status, expected 1: $(cat "$work/err_c.txt")"
grep -q "settle ended after .* nothing more to load (read errors: [1-9]" "$work/err_c.txt" ||
  fail "settle at a damaged frame: $(cat "$work/err_c.txt")"
grep -q "settle timed out" "$work/err_c.txt" && fail "settle at a damaged frame timed out: $(cat "$work/err_c.txt")"

# No display: a clear message and exit code 3.
set +e
msg=$(env -u DISPLAY -u WAYLAND_DISPLAY "$volreel" play "$work/a.vreel" 2>&1)
rc=$?
set -e
[ $rc = 3 ] || fail "without a display: exit code $rc, expected 3"
grep -q "xvfb-run" <<< "$msg" || fail "without a display, no hint at xvfb-run: $msg"

echo "play_window: all checks passed"
