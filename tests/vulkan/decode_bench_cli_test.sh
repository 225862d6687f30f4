#!/bin/bash
# decode_bench_cli_test.sh: `volreel bench decode` end to end on small ksvd and zfp containers:
# the 16-bit atlas formats agree with the CPU decoder, every throughput figure is a positive
# number, ksvd containers report the share of the time spent reading the codes (zfp ones do not),
# both Vulkan kernels decode bricks that code a box of their blocks as the CPU decoder does, and a
# missing container is refused with a message naming it.
# Usage: decode_bench_cli_test.sh path/to/volreel
set -euo pipefail
volreel=$1
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }

"$volreel" gen analytic --field blobs --dims 40x36x30 --frames 2 --out "$dir/series" > /dev/null 2>&1
"$volreel" encode "$dir/series" --dictionary dct --brick-size 12 --out "$dir/k.vreel" > /dev/null 2>&1
"$volreel" encode "$dir/series" --codec zfp --brick-size 12 --out "$dir/z.vreel" > /dev/null 2>&1

run() {  # $1 container; prints the report
  "$volreel" bench decode "$1" --batch 1,4 --min-seconds 0.05 2> "$dir/err.txt" ||
    { cat "$dir/err.txt" >&2; fail "bench decode $1 failed"; }
}
check_common() {  # $1 report
  local report=$1
  # The atlas formats against the CPU decoder: R16_UNORM to better than 60 dB.
  psnr=$(grep -oP 'R16_UNORM .*PSNR \K[0-9.]+' <<< "$report") || fail "no R16_UNORM line"
  python3 -c "import sys; sys.exit(0 if float('$psnr') > 60 else 1)" || fail "R16_UNORM PSNR $psnr dB"
  rate=$(grep -oP 'CPU reference decoder, 1 thread: \K[0-9.]+' <<< "$report") || fail "no 1-thread line"
  python3 -c "import sys; sys.exit(0 if float('$rate') > 0 else 1)" || fail "1-thread rate $rate"
  # One row per batch size: batch, CPU MVoxel/s and bricks/s, Vulkan MVoxel/s, bricks/s, MB/s.
  for b in 1 4; do
    grep -qP "^ +$b \| +[0-9.]+ +[0-9]+ \| +[0-9.]+ +[0-9]+ +[0-9.]+" <<< "$report" || fail "no row for batch $b"
  done
}

report=$(run "$dir/k.vreel")
check_common "$report"
share=$(grep -oP 'of which reading the codes \(check_ksvd_payload alone\): \K[0-9]+' <<< "$report") ||
  fail "a ksvd container reports no reading share"
[ "$share" -gt 0 ] && [ "$share" -le 100 ] || fail "reading share $share %"

# Bricks of 18³ on 40 voxels in x: the last column codes 2 of its 3 block layers (the box word,
# format/SPEC.md "Coded blocks"). Both Vulkan kernels decode the encoder's bricks as the CPU
# decoder does.
"$volreel" encode "$dir/series" --dictionary dct --brick-size 18 --out "$dir/b.vreel" > /dev/null 2>&1
for kernel in image:image_store copy:buffer_copy; do
  name=${kernel#*:} kernel=${kernel%%:*}
  report=$("$volreel" bench decode "$dir/b.vreel" --batch 4 --min-seconds 0.05 --kernel $kernel 2> "$dir/err.txt") ||
    { cat "$dir/err.txt" >&2; fail "bench decode --kernel $kernel failed"; }
  grep -q "kernel $name" <<< "$report" || fail "--kernel $kernel not used: $report"
  psnr=$(grep -oP 'R16_UNORM .*PSNR \K[0-9.]+' <<< "$report") || fail "no R16_UNORM line (--kernel $kernel)"
  python3 -c "import sys; sys.exit(0 if float('$psnr') > 60 else 1)" || fail "--kernel $kernel: R16_UNORM PSNR $psnr dB"
done

report=$(run "$dir/z.vreel")
check_common "$report"
grep -q "reading the codes" <<< "$report" && fail "a zfp container reports a reading share"

# A missing container: exit code 1 and its name in the message.
if "$volreel" bench decode "$dir/none.vreel" > /dev/null 2> "$dir/err.txt"; then fail "a missing container was accepted"; fi
grep -q "none.vreel" "$dir/err.txt" || fail "the error does not name the container: $(cat "$dir/err.txt")"
echo "decode_bench_cli_test: ok"
