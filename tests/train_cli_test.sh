#!/usr/bin/env bash
# train_cli_test.sh: `volreel train` and `volreel bench train` end to end on a small analytic
# series — the dictionary file, the progress lines, and clear errors for bad input.
# Usage: train_cli_test.sh PATH/TO/volreel
set -euo pipefail
volreel=$1
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }

grep -q "train" <<< "$("$volreel" --help)" || fail "--help does not list train"
grep -q -- "--tolerance" <<< "$("$volreel" train --help)" || fail "train --help lacks --tolerance"
grep -q "train" <<< "$("$volreel" bench --help)" || fail "bench --help does not list train"

"$volreel" gen analytic --field blobs --size 48 --frames 6 --out "$work/a" > /dev/null 2>&1

# Hierarchical: 4 levels x 2 iterations, a line each, then the final evaluation; K = 256 atoms of
# 6^3 floats make a file of 128 + 256*216*4 + 4 bytes.
"$volreel" train "$work/a" --out "$work/d.bin" --atoms 256 --coreset 400k --levels 3 --iterations 2 \
  > "$work/train.txt" 2>/dev/null || fail "train failed"
[ "$(grep -c '^level [1-4]/4 iteration  [12]/2' "$work/train.txt")" = 8 ] || fail "expected 8 progress lines"
grep -q "^final .*met eps" "$work/train.txt" || fail "no final line"
grep -q "PSNR >= 50.00 dB" "$work/train.txt" || fail "default --psnr 50 not reported"
[ "$(stat -c %s "$work/d.bin")" = 221316 ] || fail "dictionary file has the wrong size"
[ "$(head -c 8 "$work/d.bin")" = VREELDIC ] || fail "dictionary file lacks its magic"

# Flat: one level, 8 iterations; an explicit tolerance.
"$volreel" train "$work/a" --out "$work/f.bin" --atoms 256 --coreset 400k --levels 3 --iterations 2 --flat \
  --tolerance 0.01 > "$work/flat.txt" 2>/dev/null || fail "train --flat failed"
grep -q "^level 1/1 iteration  8/8" "$work/flat.txt" || fail "flat training should run 8 iterations on one level"
grep -q "tolerance eps = 0.01 " "$work/flat.txt" || fail "--tolerance not used"

# Same seed, same bytes; folders of --out that do not exist yet are made.
"$volreel" train "$work/a" --out "$work/new/sub/d2.bin" --atoms 256 --coreset 400k --levels 3 --iterations 2 > /dev/null 2>&1 \
  || fail "train into folders that do not exist yet"
cmp -s "$work/d.bin" "$work/new/sub/d2.bin" || fail "training is not deterministic for a seed"

# Bad input: clear messages, non-zero exit.
expect_error() {  # expect_error "message fragment" volreel-args...
  local fragment=$1
  shift
  if "$volreel" "$@" > "$work/out.txt" 2> "$work/err.txt"; then fail "accepted: $*"; fi
  grep -q "$fragment" "$work/err.txt" || fail "for '$*' expected '$fragment', got: $(cat "$work/err.txt")"
}
expect_error "does not exist" train "$work/nope" --out "$work/x.bin"
expect_error "fewer than the 2^6" train "$work/a" --out "$work/x.bin" --coreset 10k
expect_error "expected a count of voxels in 1 .. 1e15" train "$work/a" --out "$work/x.bin" --coreset 1e30
expect_error "eval-frames 6 holds out every frame of 6.*--eval-frames 5 or fewer" bench train "$work/a" --eval-frames 6
expect_error "flat-iterations: expected a number in \[1, 1e+06\], found '0'" bench train "$work/a" --flat-iterations 0
expect_error "coarse-tolerance: expected a number in \[1, 1e+06\], found 'nan'" train "$work/a" --out "$work/x.bin" --coarse-tolerance nan
expect_error "unknown suffix" train "$work/a" --out "$work/x.bin" --coreset 10q
head -c 16384 /dev/zero > "$work/zeros.raw"
# Checked before the frames are read and the dictionary trained: the output and the options.
echo old > "$work/taken.bin"
expect_error "already exists: give --overwrite" train "$work/a" --out "$work/taken.bin" --atoms 64
[ "$(cat "$work/taken.bin")" = old ] || fail "train replaced an existing --out without --overwrite"
# A FIFO (or a device) is never renamed over, --overwrite or not.
mkfifo "$work/fifo"
expect_error "it is a FIFO (named pipe), and volreel writes a new file" train "$work/a" --out "$work/fifo" --atoms 64
expect_error "it is a FIFO (named pipe), and volreel writes a new file" train "$work/a" --out "$work/fifo" --atoms 64 --overwrite
[ -p "$work/fifo" ] || fail "train --overwrite replaced a FIFO"
expect_error "is a directory" train "$work/a" --out "$work/a"
expect_error "cannot write it (--out)" train "$work/a" --out /proc/volreel-test.bin
expect_error "iterations: Value 0 not in range" train "$work/a" --out "$work/x.bin" --iterations 0
expect_error "convergence: expected a number >= 0, found '-1'" train "$work/a" --out "$work/x.bin" --convergence -1
expect_error "max-atoms 100: blocks of 2^3 have 8 values, so at most 8" train "$work/a" --out "$work/x.bin" --block 2 --max-atoms 100
! grep -q "coreset" "$work/out.txt" || fail "an option was refused after the coreset was drawn"
"$volreel" train "$work/a" --out "$work/taken.bin" --overwrite --atoms 64 --coreset 200k --levels 1 \
  --iterations 1 > /dev/null 2>&1 || fail "train --overwrite failed"
[ "$(head -c 8 "$work/taken.bin")" = VREELDIC ] || fail "train --overwrite did not replace the file"
expect_error "flat (constant)" train "$work/zeros.raw" --dims 16x16x16 --out "$work/x.bin" --coreset 20k --levels 2 --tolerance 0.1

# The benchmark: hierarchical, flat and two plain runs, evaluation on held-out frames, throughput.
"$volreel" bench train "$work/a" --atoms 128 --coreset 200k --levels 2 --iterations 2 --eval-frames 2 \
  > "$work/bench.txt" 2>/dev/null || fail "bench train failed"
grep -q "^machine: " "$work/bench.txt" || fail "bench prints no machine"
grep -q "evaluation frames (not used for training):" "$work/bench.txt" || fail "bench names no evaluation frames"
grep -q "hierarchical vs flat 6 " "$work/bench.txt" || fail "bench compares no flat run of 6 iterations"
grep -q "hierarchical vs plain 6 " "$work/bench.txt" || fail "bench compares no plain run of 6 iterations"
grep -q "hierarchical vs plain 12 " "$work/bench.txt" || fail "bench compares no plain run of 12 iterations"
grep -q "blocks/s .* MVoxel/s" "$work/bench.txt" || fail "bench prints no throughput"
echo "train CLI OK"
