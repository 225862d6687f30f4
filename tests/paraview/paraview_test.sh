#!/usr/bin/env bash
# paraview_test.sh VOLREEL PYTHONPATH SCREENSHOT_DIR: ParaView's pvpython (under Xvfb: Debian's
# ParaView renders through X) opens a container with volreel's reader, checks time step 3 against
# `volreel decode`, switches the level of detail and saves a screenshot.
set -euo pipefail
volreel=$1
export PYTHONPATH=$2
shots=$3
here=$(cd "$(dirname "$0")" && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$volreel" gen analytic --field blobs --dims 40x36x24 --frames 6 --out "$work/s" > /dev/null 2>&1
# Bricks of 36^3: two levels, so that the reader's coarse level is smaller.
"$volreel" encode "$work/s" --out "$work/c.vreel" --psnr 45 --atoms 64 --brick-size 36 > /dev/null 2>&1
"$volreel" decode "$work/c.vreel" --frame 3 --out "$work/t3.f32" > /dev/null
mkdir -p "$shots"
# A 24-bit screen for OpenGL. On a loaded machine pvpython has failed to connect to a fresh Xvfb
# ("bad X server connection") three times in a row: that, and only that, is tried again with a
# new server, after a longer wait each time.
for attempt in 1 2 3 4 5; do
  if xvfb-run -a -s "-screen 0 1280x800x24" pvpython "$here/paraview_check.py" "$work/c.vreel" \
      "$work/t3.f32" "$shots/paraview_reader.png" > "$work/pv.log" 2>&1; then
    cat "$work/pv.log"
    break
  fi
  cat "$work/pv.log"
  grep -q "bad X server connection" "$work/pv.log" && [ $attempt -lt 5 ] || exit 1
  echo "paraview_test: no X connection (attempt $attempt); trying again with a new Xvfb"
  sleep $((2 * attempt))
done
test -s "$shots/paraview_reader.png"
