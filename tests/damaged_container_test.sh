#!/usr/bin/env bash
# damaged_container_test.sh: hostile containers and series, each refused with a message that names
# the file and what was wrong, never a crash, a hang or a silent success: FIFOs and devices where
# files belong, a deeply nested manifest, another container's frame or dictionary, a corrupt brick
# payload (decode and verify), values too large to code. Usage: damaged_container_test.sh VOLREEL
set -euo pipefail
volreel=$1
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
# Runs a command that must fail within 20 s (a hang is a failure) with a message matching $1.
expect_error() {
  local pattern=$1; shift
  local msg rc=0
  msg=$(timeout 20 "$@" 2>&1 >/dev/null) || rc=$?
  [ "$rc" != 0 ] || fail "expected failure: $*"
  [ "$rc" != 124 ] || fail "hung (killed after 20 s): $*"
  [ "$rc" -lt 128 ] || fail "crashed (status $rc): $*: $msg"
  grep -q -e "$pattern" <<< "$msg" || fail "message for '$*' lacks '$pattern': $msg"
}

"$volreel" gen analytic --field blobs --dims 40x36x30 --frames 3 --out "$work/s" > /dev/null 2>&1
"$volreel" encode "$work/s" --dictionary dct --out "$work/a.vreel" > /dev/null 2>&1
# The same data under another name: another container (the identifier hashes the settings, the
# variable's name among them, not the input's path) whose frames have the same sizes.
cp -r "$work/s" "$work/s2"
sed -i 's/"analytic-blobs"/"blobs-copy"/' "$work/s2/series.json"
"$volreel" encode "$work/s2" --dictionary dct --out "$work/other.vreel" > /dev/null 2>&1
"$volreel" verify "$work/a.vreel" > /dev/null 2>&1 || fail "verify of a good container"
fresh() { rm -rf "$work/b.vreel"; cp -r "$work/a.vreel" "$work/b.vreel"; }

# FIFOs and devices where files belong: refused at once, never a blocked open or an endless read.
fresh
rm "$work/b.vreel/frames/000001.vrf" && mkfifo "$work/b.vreel/frames/000001.vrf"
expect_error "000001.vrf: expected a regular file, found a FIFO" "$volreel" verify "$work/b.vreel"
expect_error "000001.vrf: expected a regular file, found a FIFO" "$volreel" decode "$work/b.vreel" --frame 1 --out "$work/x.f32"
fresh
rm "$work/b.vreel/dictionary.bin" && mkfifo "$work/b.vreel/dictionary.bin"
for cmd in verify info; do
  expect_error "dictionary.bin: expected a regular file, found a FIFO" "$volreel" $cmd "$work/b.vreel"
done
fresh
ln -sf /dev/zero "$work/b.vreel/manifest.json"
expect_error "manifest.json: expected a regular file, found a character device" "$volreel" info "$work/b.vreel"

# A manifest of 200,000 nested arrays: a message, not a stack overflow.
fresh
python3 -c "import sys; sys.stdout.write('[' * 200000 + ']' * 200000)" > "$work/b.vreel/manifest.json"
for cmd in verify info; do
  expect_error "manifest.json: expected JSON nested at most 64" "$volreel" $cmd "$work/b.vreel"
done

# An edited manifest (its own checksum), another container's frame or dictionary.
fresh
sed -i 's/"complete": true/"complete": false/' "$work/b.vreel/manifest.json"
expect_error "manifest_crc32c" "$volreel" info "$work/b.vreel"
fresh
cp "$work/other.vreel/frames/000001.vrf" "$work/b.vreel/frames/000001.vrf"
expect_error "000001.vrf: offset 128: expected container identifier" "$volreel" decode "$work/b.vreel" --frame 1 --out "$work/x.f32"
fresh
cp "$work/other.vreel/dictionary.bin" "$work/b.vreel/dictionary.bin"
expect_error "dictionary.bin: offset 120: expected container identifier .*the dictionary of another container" "$volreel" info "$work/b.vreel"

# One flipped byte inside a brick payload: decode names the brick, verify's last line says what.
fresh
frame="$work/b.vreel/frames/000002.vrf"
size=$(stat -c %s "$frame")
printf '\x5a' | dd of="$frame" bs=1 seek=$((size - 64)) conv=notrunc 2>/dev/null
expect_error "000002.vrf: offset [0-9]*: expected brick [0-9]* payload of CRC-32C" "$volreel" decode "$work/b.vreel" --frame 2 --out "$work/x.f32"
[ ! -e "$work/x.f32" ] || fail "decode left an output file behind after a corrupt brick"
expect_error "1 problem found: .*000002.vrf" "$volreel" verify "$work/b.vreel"
# A truncated frame that the steps around it take keyframes from: one problem, not one a step.
"$volreel" gen analytic --field rotating --dims 40x36x30 --frames 6 --out "$work/slow" > /dev/null 2>&1
"$volreel" encode "$work/slow" --dictionary dct --brick-size 18 --max-keyframe-gap 4 --out "$work/gaps.vreel" > /dev/null 2>&1
truncate -s 3000 "$work/gaps.vreel/frames/000002.vrf"
expect_error ": 1 problem found: .*000002.vrf: expected [0-9]* bytes (its size in manifest.json), found 3000" "$volreel" verify "$work/gaps.vreel"
# info reads indexes alone: a frame cut short past its index is found by its size.
expect_error "000002.vrf: expected [0-9]* bytes (its size in manifest.json), found 3000 (the file was cut short" "$volreel" info "$work/gaps.vreel"

# Values too large for float32 sums: refused before anything is written.
python3 -c "
import struct, sys
sys.stdout.buffer.write(struct.pack('<f', 1e38) * 4096 + struct.pack('<f', -1e38) * 4096)" > "$work/big.f32"
expect_error "big.f32.*expected values of magnitude at most 1e+33.*found values up to 1e+38" "$volreel" encode "$work/big.f32" --dims 16x16x16 --frames 2 --out "$work/big.vreel"
[ ! -e "$work/big.vreel/manifest.json" ] || fail "a refused encode left a manifest behind"

echo "damaged_container: all checks passed"
