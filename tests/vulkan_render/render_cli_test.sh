#!/bin/bash
# render_cli_test.sh: `volreel render` end to end on a small zfp container: a still tour renders
# the expected number of frames and metrics with sane values and reaches full detail, on the
# Vulkan device (or the CPU fallback where there is none) and with --cpu; a bad option is refused
# with a message naming it; --compare measures the frames against the original series.
# Without --realtime every frame, the first included, is drawn at full detail (it waits for its
# bricks); with --realtime on a slow simulated link the first frame is not.
# Usage: render_cli_test.sh path/to/volreel
set -euo pipefail
volreel=$1
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT

"$volreel" gen analytic --field blobs --dims 70x50x40 --frames 4 --out "$dir/series" > /dev/null 2>&1
"$volreel" encode "$dir/series" --codec zfp --out "$dir/test.vreel" > /dev/null 2>&1
cat > "$dir/tour.json" <<'JSON'
{"duration": 2, "fps": 10, "size": [48, 32], "playhead": [{"t": 0, "keyframe": 1.5}]}
JSON

check_run() {  # $1 output folder; the tour has 20 frames
  local out=$1
  local pngs
  pngs=$(ls "$out"/frame_*.png | wc -l)
  [ "$pngs" -eq 20 ] || { echo "expected 20 frames in $out, found $pngs"; exit 1; }
  [ "$(wc -l < "$out/metrics.csv")" -eq 21 ] || { echo "expected 21 lines in $out/metrics.csv"; exit 1; }
  head -1 "$out/metrics.csv" | grep -q "^frame,time_s,playhead,frame_ms,fps,schedule_ms,upload_ms,decode_ms,render_ms" \
    || { echo "unexpected metrics header"; exit 1; }
  head -1 "$out/metrics.csv" | grep -q ",errors,wait_ms" || { echo "no wait_ms column"; exit 1; }
  # Every row: playhead 1.5, fps > 0, occupancy in [0, 1], and at full detail: the first frame
  # waited for its bricks.
  awk -F, 'NR > 1 {
      if ($3 != 1.5 || $5 <= 0 || $13 < 0 || $13 > 1) { print "bad row: " $0; exit 1 }
      if ($19 != 1) { print "frame " $1 " drawn before its bricks arrived: " $0; exit 1 } }' \
    "$out/metrics.csv"
}

"$volreel" render "$dir/test.vreel" --tour "$dir/tour.json" --out "$dir/gpu" --renderer vulkan \
  > "$dir/gpu.log" 2>&1 \
  || { cat "$dir/gpu.log"; exit 1; }
check_run "$dir/gpu"
"$volreel" render "$dir/test.vreel" --tour "$dir/tour.json" --out "$dir/cpu" --cpu \
  --compare "$dir/series" > "$dir/cpu.log" 2>&1 || { cat "$dir/cpu.log"; exit 1; }
check_run "$dir/cpu"
grep -q "mean PSNR" "$dir/cpu.log" || { echo "no image quality summary"; cat "$dir/cpu.log"; exit 1; }
# Both renderers draw the same last frame (same scheduler state: a still view, fully loaded).
"$volreel" compare "$dir/gpu/frame_00019.png" "$dir/cpu/frame_00019.png" > "$dir/compare.log"
psnr=$(awk '/^PSNR/ {print $2}' "$dir/compare.log")
awk -v p="$psnr" 'BEGIN { exit !(p == "inf" || p >= 40) }' \
  || { echo "GPU and CPU frames differ: PSNR $psnr"; exit 1; }

# --realtime on a slow link draws what has arrived: the first frame is not complete yet.
"$volreel" render "$dir/test.vreel" --tour "$dir/tour.json" --out "$dir/rt" --realtime \
  --bandwidth 200kB/s --max-frames 2 > "$dir/rt.log" 2>&1 || { cat "$dir/rt.log"; exit 1; }
awk -F, 'NR == 2 { if ($19 >= 1) { print "realtime frame 0 complete on a 200 kB/s link: " $0; exit 1 } }' \
  "$dir/rt/metrics.csv"

# Without --realtime, frames still incomplete after --wait-timeout are drawn and written, and the
# exit status (3) says so.
status=0
"$volreel" render "$dir/test.vreel" --tour "$dir/tour.json" --out "$dir/late" --cpu \
  --bandwidth 20kB/s --wait-timeout 0.05 --max-frames 2 > "$dir/late.log" 2>&1 || status=$?
[ "$status" = 3 ] || { echo "incomplete frames: exit status $status, expected 3"; cat "$dir/late.log"; exit 1; }
grep -q "frames were drawn incomplete after waiting --wait-timeout 0.05 s" "$dir/late.log" \
  || { cat "$dir/late.log"; exit 1; }
[ "$(ls "$dir/late"/frame_*.png | wc -l)" -eq 2 ] || { echo "the incomplete frames were not written"; exit 1; }

# Helpful errors.
if "$volreel" render "$dir/test.vreel" --out "$dir/bad" --size 12 > "$dir/bad.log" 2>&1; then
  echo "accepted --size 12"; exit 1
fi
grep -q -- "--size" "$dir/bad.log" || { cat "$dir/bad.log"; exit 1; }
if "$volreel" render "$dir/missing.vreel" --out "$dir/bad" > "$dir/bad.log" 2>&1; then
  echo "accepted a missing container"; exit 1
fi
grep -q "missing.vreel" "$dir/bad.log" || { cat "$dir/bad.log"; exit 1; }
# Rendering again into a folder of a longer render: its frames past this run's are removed.
"$volreel" render "$dir/test.vreel" --tour "$dir/tour.json" --out "$dir/cpu" --cpu --max-frames 3 \
  > "$dir/again.log" 2>&1 || { cat "$dir/again.log"; exit 1; }
[ "$(ls "$dir/cpu"/frame_*.png | wc -l)" -eq 3 ] || { echo "an earlier render's frames stayed: $(ls "$dir/cpu")"; exit 1; }
[ "$(wc -l < "$dir/cpu/metrics.csv")" -eq 4 ] || { echo "metrics.csv of 3 frames expected"; exit 1; }
grep -q "removed 17 frame_NNNNN.png past frame_00002.png" "$dir/again.log" || { cat "$dir/again.log"; exit 1; }
# --video is checked before the frames are rendered; an option found bad leaves no --out folder.
for video in /proc/x.mp4 "$dir/series" "$dir/series/000000.f32/x.mp4" "$dir/test.vreel/x.mp4"; do
  if "$volreel" render "$dir/test.vreel" --tour "$dir/tour.json" --out "$dir/novideo" --cpu \
    --video "$video" > "$dir/bad.log" 2>&1; then
    echo "accepted --video $video"; exit 1
  fi
  grep -q -- "--video" "$dir/bad.log" || { cat "$dir/bad.log"; exit 1; }
  ! grep -q "rendering" "$dir/bad.log" || { echo "--video $video refused after rendering"; exit 1; }
done
"$volreel" gen analytic --field blobs --dims 30x30x30 --frames 4 --out "$dir/small" > /dev/null 2>&1
if "$volreel" render "$dir/test.vreel" --out "$dir/nocompare" --compare "$dir/small" > "$dir/bad.log" 2>&1; then
  echo "accepted --compare of another size"; exit 1
fi
[ ! -e "$dir/nocompare" ] || { echo "a refused render left its --out folder"; exit 1; }
[ ! -e "$dir/novideo" ] || { echo "a refused render left its --out folder"; exit 1; }
if "$volreel" render "$dir/test.vreel" --out "$dir/bad" --transfer "$dir/tf/missing.json" > "$dir/bad.log" 2>&1; then
  echo "accepted a missing transfer function file"; exit 1
fi
grep -q "missing.json: no such file" "$dir/bad.log" || { cat "$dir/bad.log"; exit 1; }
# A damaged frame: render draws without it and exits 1, naming the failure once; so does bench play.
cp -r "$dir/test.vreel" "$dir/damaged.vreel"
truncate -s 3000 "$dir/damaged.vreel/frames/000001.vrf"
if "$volreel" render "$dir/damaged.vreel" --tour "$dir/tour.json" --out "$dir/damaged" --cpu > "$dir/bad.log" 2>&1; then
  echo "render of a damaged container exited 0"; exit 1
fi
grep -q "^volreel: error: 1 bricks or frames could not be read" "$dir/bad.log" || { cat "$dir/bad.log"; exit 1; }
[ "$(grep -c "warning: .*000001.vrf" "$dir/bad.log")" -eq 1 ] || { echo "the failure was not named once"; cat "$dir/bad.log"; exit 1; }
# metrics.csv counts it in the row of the frame during which it came (while waiting for the
# frame's bricks, or drawing it).
errors=$(awk -F, 'NR == 1 { for (i = 1; i <= NF; ++i) if ($i == "errors") c = i; next } { s += $c } END { print s + 0 }' "$dir/damaged/metrics.csv")
[ "$errors" -eq 1 ] || { echo "metrics.csv counts $errors read errors, not 1"; cat "$dir/damaged/metrics.csv"; exit 1; }
if "$volreel" bench play "$dir/damaged.vreel" --cpu --size 32x32 --frames-per-phase 2 --seeks 1 > "$dir/bad.log" 2>&1; then
  echo "bench play of a damaged container exited 0"; exit 1
fi
grep -q "error: 1 bricks or frames could not be read.*figures above" "$dir/bad.log" || { cat "$dir/bad.log"; exit 1; }
# bench decode checks every payload before its threads decode them (a corrupt one ended the
# program); bench index exits 1 after failed reads.
cp -r "$dir/test.vreel" "$dir/flipped.vreel"
frame="$dir/flipped.vreel/frames/000001.vrf"
printf '\x5a' | dd of="$frame" bs=1 seek=$(($(stat -c %s "$frame") - 64)) conv=notrunc 2>/dev/null
set +e
"$volreel" bench decode "$dir/flipped.vreel" --min-seconds 0 > "$dir/bad.log" 2>&1; rc=$?
set -e
[ "$rc" -eq 1 ] && grep -q "000001.vrf: offset .*corrupt" "$dir/bad.log" || { echo "bench decode: rc $rc"; cat "$dir/bad.log"; exit 1; }
if "$volreel" bench index "$dir/flipped.vreel" --play-seconds 1 --seeks 1 > "$dir/bad.log" 2>&1; then
  echo "bench index exited 0 after failed reads"; exit 1
fi
grep -q "reads of bricks failed" "$dir/bad.log" || { cat "$dir/bad.log"; exit 1; }
# Numbers out of range or not finite are refused before any work (nan and inf ran for ever).
for args in "bench index --play-seconds nan" "bench index --seeks -1" "bench index --fps nan" \
  "bench index --atlas-mb 1e15" "bench decode --min-seconds inf" "bench decode --batch 0" \
  "bench decode --frames -3" "bench decode --upload-mib nan" "bench decode --atlas-mib -5"; do
  read -r command sub option value <<< "$args"
  if "$volreel" "$command" "$sub" "$dir/test.vreel" "$option" "$value" > "$dir/bad.log" 2>&1; then
    echo "accepted: $args"; exit 1
  fi
  grep -q -- "$option: expected a number in .*found '$value'" "$dir/bad.log" || { echo "$args:"; cat "$dir/bad.log"; exit 1; }
done
for bad in "--frames-per-phase 0" "--speed nan" "--speed 0" "--timeout -1"; do
  # shellcheck disable=SC2086
  if "$volreel" bench play "$dir/test.vreel" --cpu $bad > "$dir/bad.log" 2>&1; then echo "bench play accepted $bad"; exit 1; fi
  grep -q -- "${bad%% *}" "$dir/bad.log" || { cat "$dir/bad.log"; exit 1; }
done
# Refused before anything is drawn: --out inside the container, the --compare series' options
# without --compare, and the CPU ray caster with --decode or --renderer vulkan.
expect_refused() {  # PATTERN ARGS...: render exits 1 naming PATTERN
  local pattern=$1; shift
  if "$volreel" render "$dir/test.vreel" "$@" > "$dir/bad.log" 2>&1; then echo "render accepted $*"; exit 1; fi
  grep -q -e "$pattern" "$dir/bad.log" || { echo "render $*: no '$pattern' in:"; cat "$dir/bad.log"; exit 1; }
}
expect_refused "is inside the container" --out "$dir/test.vreel/frames" --max-frames 1
expect_refused "is inside the container" --out "$dir/test.vreel/renders" --max-frames 1
[ ! -e "$dir/test.vreel/renders" ] || { echo "a refused render made its folder in the container"; exit 1; }
expect_refused "--frames: options of the --compare series" --out "$dir/x" --frames 3
expect_refused "--decode gpu with the CPU ray caster" --out "$dir/x" --cpu --decode gpu
expect_refused "--cpu with --renderer vulkan" --out "$dir/x" --cpu --renderer vulkan
"$volreel" verify "$dir/test.vreel" > /dev/null 2>&1 || { echo "refused renders changed the container"; exit 1; }
# An atlas too small for the view: the frames are drawn coarser, and the summary says why.
"$volreel" render "$dir/test.vreel" --out "$dir/small_atlas" --size 64x64 --max-frames 2 --cpu --atlas-mb 0.02 \
  > "$dir/atlas.log" 2>&1 || { cat "$dir/atlas.log"; echo "render with a small atlas failed"; exit 1; }
grep -q "the view wants more bricks than the atlas's [0-9]* slots hold; give a larger --atlas-mb" "$dir/atlas.log" \
  || { cat "$dir/atlas.log"; echo "render with a small atlas: no warning"; exit 1; }
# play's --screenshot-on-exit is checked before the window opens (no display needed for this).
for bad in "$dir/shot.jpg:give a name ending in .png" "$dir:is a folder" "$dir/nowhere/shot.png:does not exist"; do
  if "$volreel" play "$dir/test.vreel" --screenshot-on-exit "${bad%%:*}" > "$dir/bad.log" 2>&1; then
    echo "play accepted --screenshot-on-exit ${bad%%:*}"; exit 1
  fi
  grep -q -e "${bad#*:}" "$dir/bad.log" || { echo "play --screenshot-on-exit ${bad%%:*}:"; cat "$dir/bad.log"; exit 1; }
done
# A constant sequence (an empty value range) renders with the default tour, as play does.
mkdir -p "$dir/const"
/usr/bin/python3 -c "import struct,sys; open(sys.argv[1],'wb').write(struct.pack('<1728f', *[2.5]*1728))" "$dir/const/c.f32"
"$volreel" encode "$dir/const/c.f32" --dims 12x12x12 --frames 1 --codec zfp --out "$dir/const.vreel" > /dev/null 2>&1
"$volreel" render "$dir/const.vreel" --out "$dir/const_r" --size 32x32 --max-frames 1 --cpu > "$dir/const.log" 2>&1 \
  || { cat "$dir/const.log"; echo "render of a constant container failed"; exit 1; }
# SIGTERM (as Ctrl-C): it stops between frames and says what it left. Into a folder of its own
# every PNG it kept has its row; over an earlier render, which it would replace, the earlier one
# stays as it was (the new frames were drawn aside) and nothing of the new one is left.
interrupt_render() {  # OUT: render into OUT in real time, stopped once FILE is there
  local out=$1 file=$2
  "$volreel" render "$dir/test.vreel" --out "$out" --size 64x64 --cpu --realtime > /dev/null 2> "$dir/int.log" &
  local pid=$!
  for _ in $(seq 600); do [ -e "$file" ] && break; sleep 0.1; done
  kill -TERM "$pid"
  status=0
  wait "$pid" || status=$?
  [ "$status" = 143 ] || { cat "$dir/int.log"; echo "an interrupted render: exit status $status, expected 143"; exit 1; }
}
interrupt_render "$dir/int" "$dir/int/frame_00002.png"
grep -q "interrupted after [0-9]* of [0-9]* frames: .* holds frame_00000.png .. frame_000[0-9]*.png, each with its row of metrics.csv" "$dir/int.log" \
  || { cat "$dir/int.log"; echo "an interrupted render said nothing"; exit 1; }
pngs=$(ls "$dir/int"/frame_*.png | wc -l)
rows=$(($(wc -l < "$dir/int/metrics.csv") - 1))
[ "$pngs" = "$rows" ] || { echo "an interrupted render left $pngs frames and $rows rows"; exit 1; }
"$volreel" render "$dir/test.vreel" --tour "$dir/tour.json" --out "$dir/int2" --cpu > /dev/null 2>&1
cp "$dir/int2/metrics.csv" "$dir/int2.csv"
cp "$dir/int2/frame_00001.png" "$dir/int2-1.png"
interrupt_render "$dir/int2" "$dir/int2/.volreel-new/frame_00002.png"
grep -q "interrupted after [0-9]* of [0-9]* frames, which are not kept: .*int2 holds the earlier render's frame_00000.png .. frame_[0-9]*.png and metrics.csv as they were" "$dir/int.log" \
  || { cat "$dir/int.log"; echo "an interrupted render over an earlier one said nothing"; exit 1; }
cmp -s "$dir/int2/metrics.csv" "$dir/int2.csv" || { echo "an interrupted render changed the earlier metrics.csv"; exit 1; }
cmp -s "$dir/int2/frame_00001.png" "$dir/int2-1.png" || { echo "an interrupted render changed an earlier frame"; exit 1; }
[ ! -e "$dir/int2/.volreel-new" ] || { echo "an interrupted render left its frames aside"; exit 1; }
echo "render CLI: OK"
