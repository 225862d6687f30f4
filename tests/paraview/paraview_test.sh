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
"$volreel" encode "$work/s" --out "$work/c.vreel" --psnr 45 --atoms 64 > /dev/null 2>&1
"$volreel" decode "$work/c.vreel" --frame 3 --out "$work/t3.f32" > /dev/null
mkdir -p "$shots"
xvfb-run -a pvpython "$here/paraview_check.py" "$work/c.vreel" "$work/t3.f32" \
  "$shots/paraview_reader.png"
test -s "$shots/paraview_reader.png"
