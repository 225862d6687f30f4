#!/bin/bash
# render_video_test.sh: `volreel render --video`. Without ffmpeg on PATH the command refuses
# before rendering anything: exit status 1, a message that names ffmpeg and how to install it,
# and no PNG frames. With ffmpeg: a 20-frame tour writes an H.264 MP4 whose frame count (ffprobe)
# and size equal the tour's, even when the output folder (named with a '%', which ffmpeg's
# image-sequence pattern must not take for a placeholder) still holds more frames from an
# earlier, longer run. Exits 77 (skipped) for the second part when ffmpeg or ffprobe is not installed.
# Usage: render_video_test.sh path/to/volreel
set -euo pipefail
volreel=$1
fail() { echo "FAIL: $*" >&2; exit 1; }
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT

"$volreel" gen analytic --field blobs --dims 40x36x30 --frames 3 --out "$dir/series" > /dev/null 2>&1
"$volreel" encode "$dir/series" --codec zfp --out "$dir/test.vreel" > /dev/null 2>&1
cat > "$dir/tour.json" <<'JSON'
{"duration": 2, "fps": 10, "size": [48, 32], "playhead": [{"t": 0, "keyframe": 0}, {"t": 2, "keyframe": 2}]}
JSON

# 1. No ffmpeg on PATH (an empty PATH: volreel runs no other program).
mkdir "$dir/empty_path"
set +e
PATH="$dir/empty_path" "$volreel" render "$dir/test.vreel" --tour "$dir/tour.json" --out "$dir/noff" \
  --video "$dir/noff.mp4" > "$dir/noff.log" 2>&1
rc=$?
set -e
cat "$dir/noff.log"
[ $rc = 1 ] || fail "without ffmpeg: exit status $rc, expected 1"
grep -q "needs ffmpeg" "$dir/noff.log" || fail "without ffmpeg: no message naming ffmpeg"
grep -q "apt-get install ffmpeg" "$dir/noff.log" || fail "without ffmpeg: no hint how to install it"
[ ! -e "$dir/noff.mp4" ] || fail "without ffmpeg: a video was written"
[ -z "$(ls "$dir"/noff/frame_*.png 2> /dev/null)" ] || fail "without ffmpeg: frames were rendered before refusing"

# 2. With ffmpeg.
command -v ffmpeg > /dev/null && command -v ffprobe > /dev/null || {
  echo "SKIP: ffmpeg/ffprobe not installed (Debian: apt-get install ffmpeg): --video encoding not tested"
  exit 77
}
# An earlier, longer run left frames 20..24 in the folder: the video must not pick them up.
mkdir -p "$dir/100%_video"
"$volreel" render "$dir/test.vreel" --tour "$dir/tour.json" --out "$dir/100%_video" > /dev/null 2>&1
for i in 20 21 22 23 24; do cp "$dir/100%_video/frame_00000.png" "$dir/100%_video/frame_000$i.png"; done
"$volreel" render "$dir/test.vreel" --tour "$dir/tour.json" --out "$dir/100%_video" --video "$dir/sub dir/tour.mp4" \
  > "$dir/100%_video.log" 2>&1 || { cat "$dir/100%_video.log"; fail "render --video failed"; }
grep -q "wrote $dir/sub dir/tour.mp4 (20 frames" "$dir/100%_video.log" || { cat "$dir/100%_video.log"; fail "no 'wrote' line for the video"; }
[ -s "$dir/sub dir/tour.mp4" ] || fail "no video written"
frames=$(ffprobe -v error -count_frames -select_streams v:0 -show_entries stream=nb_read_frames -of csv=p=0 "$dir/sub dir/tour.mp4")
[ "$frames" = 20 ] || fail "the video has $frames frames, the tour 20"
size=$(ffprobe -v error -select_streams v:0 -show_entries stream=codec_name,width,height -of csv=p=0 "$dir/sub dir/tour.mp4")
[ "$size" = "h264,48,32" ] || fail "the video is '$size', expected h264,48,32"
# The video shows the frames: its first decoded frame matches frame_00000.png (lossy: PSNR > 25 dB).
ffmpeg -nostdin -v error -i "$dir/sub dir/tour.mp4" -frames:v 1 "$dir/first.png"
"$volreel" compare "$dir/100%_video/frame_00000.png" "$dir/first.png" > "$dir/compare.log"
psnr=$(awk '/^PSNR/ {print $2}' "$dir/compare.log")
awk -v p="$psnr" 'BEGIN { exit !(p == "inf" || p > 25) }' || fail "the video's first frame differs from frame_00000.png: PSNR $psnr"
[ ! -e "$dir/sub dir/tour.partial.mp4" ] || fail "the video's temporary file was left"
# A video not named as one (here as one of the frames, which it would overwrite): refused
# before rendering, with status 2 (ffmpeg chooses the container by the name, after the frames).
status=0
"$volreel" render "$dir/test.vreel" --tour "$dir/tour.json" --out "$dir/100%_video" \
  --video "$dir/100%_video/frame_00000.png" > "$dir/clash.log" 2>&1 || status=$?
[ "$status" = 2 ] || fail "a --video named as a frame: exit status $status, expected 2"
grep -q -- "--video: expected a video file named .mp4, .mkv or .mov" "$dir/clash.log" || { cat "$dir/clash.log"; fail "no message for a --video named as a frame"; }
echo "render --video: OK (20 frames, 48x32 H.264, first frame PSNR $psnr dB)"
