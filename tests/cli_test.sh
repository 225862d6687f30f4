#!/usr/bin/env bash
# cli_test.sh: the volreel program end to end — generate, compare, benchmark — and its error
# messages for bad input. Usage: cli_test.sh PATH/TO/volreel
set -euo pipefail
volreel=$1
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
json() { /usr/bin/python3 -c "import json,math,sys; d=json.load(sys.stdin); print($1)"; }

grep -q "gen" <<< "$("$volreel" --help)" || fail "--help does not list gen"
grep -q "compare" <<< "$("$volreel" --help)" || fail "--help does not list compare"
grep -q "bench" <<< "$("$volreel" --help)" || fail "--help does not list bench"

# Generate two analytic series and a tiny turbulence run.
"$volreel" gen analytic --field blobs --dims 24x20x16 --frames 4 --out "$work/a" 2>/dev/null
"$volreel" gen analytic --field blobs --dims 24x20x16 --frames 4 --seed 2 --out "$work/b" 2>/dev/null
"$volreel" gen turbulence --size 16 --frames 2 --spinup 0.2 --interval 0.05 --out "$work/turb" > "$work/turb.txt" 2>/dev/null
grep -q "energy balance" "$work/turb.txt" || fail "gen turbulence printed no energy balance"
[ "$(ls "$work/turb" | grep -c '\.f32$')" = 2 ] || fail "gen turbulence did not write 2 frames"

# Identical series: perfect PSNR (null in JSON), SSIM 1.
out=$("$volreel" compare "$work/a" "$work/a" --json 2>/dev/null)
[ "$(echo "$out" | json 'd["sequence"]["psnr"]')" = None ] || fail "identical series should have infinite PSNR"
[ "$(echo "$out" | json 'round(d["sequence"]["ssim"], 6)')" = 1.0 ] || fail "identical series should have SSIM 1"
# Different series: finite PSNR, 4 frames.
out=$("$volreel" compare "$work/a" "$work/b" --json 2>/dev/null)
[ "$(echo "$out" | json 'len(d["frames"])')" = 4 ] || fail "expected 4 frames"
echo "$out" | json '1 if 0 < d["sequence"]["psnr"] < 60 else exit(1)' > /dev/null || fail "PSNR of different series out of range"
# Every frame is rated against the sequence's range, as 'all' and encode --psnr are.
echo "$out" | json '1 if all(abs(f["psnr"] - 20 * math.log10(d["sequence"]["range"] / f["rmse"])) < 1e-6 for f in d["frames"]) else exit(1)' > /dev/null \
  || fail "a frame's PSNR is not against the sequence's range: $out"
grep -q '^all,' <<< "$("$volreel" compare "$work/a" "$work/b" --csv 2>/dev/null)" || fail "CSV lacks the sequence row"
grep -q 'PSNR' <<< "$("$volreel" compare "$work/a" "$work/b" 2>/dev/null)" || fail "table lacks PSNR"
# A constant original: PSNR undefined, and the table says so.
/usr/bin/python3 -c "import struct,sys; open(sys.argv[1],'wb').write(struct.pack('<7680f', *[2.0]*7680))" "$work/const.raw"
"$volreel" compare "$work/const.raw" "$work/a/000000.f32" --dims 24x20x16 --no-ssim > "$work/const.txt" 2>&1 || fail "compare with a constant original"
grep -q "A is constant (its range is 0): PSNR is not defined for it" "$work/const.txt" || fail "compare with a constant original: $(cat "$work/const.txt")"

# A raw file read with --dims compares equal to the series frame it was copied from.
cp "$work/a/000002.f32" "$work/frame.raw"
out=$("$volreel" compare "$work/frame.raw" "$work/frame.raw" --dims 24x20x16 --json 2>/dev/null)
[ "$(echo "$out" | json 'd["frames"][0]["psnr"]')" = None ] || fail "raw self-compare"

# Bad input gives exit code 1 and a message that names the problem.
expect_error() {
  local pattern=$1; shift
  local msg
  if msg=$("$@" 2>&1 >/dev/null); then fail "expected failure: $*"; fi
  grep -q -e "$pattern" <<< "$msg" || fail "message for '$*' lacks '$pattern': $msg"
}
# A mistake on the command line: exit status 2, the message as every error's.
status=0
"$volreel" gen analytic --size 16 --size 17 --out "$work/x" > /dev/null 2> "$work/usage.err" || status=$?
[ "$status" = 2 ] || fail "a repeated option: exit status $status, expected 2"
grep -q "^volreel: error: --size" "$work/usage.err" || fail "a repeated option's message: $(cat "$work/usage.err")"
status=0
"$volreel" encod "$work/a" > /dev/null 2>&1 || status=$?
[ "$status" = 2 ] || fail "an unknown command: exit status $status, expected 2"
# Values the player's options refuse are command-line mistakes too, before anything is read.
for args in "render $work/none.vreel --out $work/r --size 0x0" "render $work/none.vreel --out $work/r --max-frames -1" \
            "play $work/none.vreel --latency 3parsecs" "bench play $work/none.vreel --bandwidth 5xb"; do
  status=0
  # shellcheck disable=SC2086
  "$volreel" $args > /dev/null 2>&1 || status=$?
  [ "$status" = 2 ] || fail "volreel $args: exit status $status, expected 2"
done
# A seed is a whole number written in digits: "-1" was taken as 2^64 - 1.
for seed in -1 1.5 abc; do
  expect_error "expected a seed, a whole number" "$volreel" gen turbulence --size 16 --frames 1 --seed "$seed" --out "$work/x"
done
expect_error "does not exist" "$volreel" compare "$work/a" "$work/nowhere"
expect_error "--dims" "$volreel" compare "$work/frame.raw" "$work/frame.raw"
expect_error "is 30720 bytes.*needs 61440" "$volreel" compare "$work/frame.raw" "$work/frame.raw" --dims 24x20x32
# An option of another kind of input is refused, not ignored.
expect_error "is a series directory (series.json): leave out --variable (NetCDF)" "$volreel" compare "$work/a" "$work/a" --variable p
expect_error "is a raw file: leave out --dataset (HDF5)" "$volreel" compare "$work/frame.raw" "$work/frame.raw" --dims 24x20x16 --dataset p
"$volreel" gen analytic --dims 24x20x8 --frames 4 --out "$work/c" 2>/dev/null
expect_error "24x20x16.*24x20x8" "$volreel" compare "$work/a" "$work/c"
rm "$work/b/000003.f32"
expect_error "000003.f32.*missing" "$volreel" compare "$work/a" "$work/b"
expect_error "already holds a series" "$volreel" gen analytic --frames 2 --out "$work/a"
expect_error "unknown analytic field" "$volreel" gen analytic --field nope --out "$work/d"
# gen never writes into a folder of other files (its frames would replace the user's).
mkdir "$work/data" && echo keep > "$work/data/000000.f32" && echo keep > "$work/data/notes.txt"
expect_error "holds 'notes.txt' but no series.json" "$volreel" gen analytic --frames 2 --out "$work/data"
expect_error "holds 'notes.txt' but no series.json" "$volreel" gen analytic --frames 2 --out "$work/data" --overwrite
[ "$(cat "$work/data/000000.f32")" = keep ] || fail "gen replaced a file of a folder without a series"
# Frames without series.json (an interrupted gen's): replaced with --overwrite only.
rm "$work/data/notes.txt"
expect_error "holds frame files but no series.json.*--overwrite" "$volreel" gen analytic --frames 2 --out "$work/data"
"$volreel" gen analytic --dims 24x20x16 --frames 2 --out "$work/data" --overwrite > /dev/null 2>&1 || fail "gen --overwrite of an interrupted gen's frames"
expect_error "--frames: expected a number in \[1, 1e+08\], found '-1'" "$volreel" gen analytic --frames -1 --out "$work/neg"
[ ! -e "$work/neg" ] || fail "gen --frames -1 wrote $work/neg"
expect_error "--frames: expected a number in" "$volreel" gen turbulence --frames -1 --out "$work/neg"
expect_error "--frames: expected a number in" "$volreel" gen mosaic --from "$work/a" --size 8 --frames -2 --out "$work/neg.vreel"
expect_error "--at-bps: expected bits per voxel > 0" "$volreel" bench rd "$work/a" --at-bps nan
expect_error "not a PNG\|cannot\|PNG" "$volreel" compare "$work/frame.raw" "$work/frame.png"
# gen: sizes checked when parsed; a failed run leaves no folder behind; --overwrite with fewer
# frames leaves none of the old frames.
expect_error "--size: Value -4 not in range" "$volreel" gen analytic --size -4 --out "$work/neg"
expect_error "CFL number must be in (0, 2]" "$volreel" gen turbulence --size 16 --frames 1 --cfl 3 --out "$work/failed/run"
[ ! -e "$work/failed" ] || fail "a failed gen left $(ls -R "$work/failed")"
expect_error "--power: expected a number > 0" "$volreel" gen turbulence --size 16 --power 0 --out "$work/p0"
"$volreel" gen analytic --size 16 --frames 4 --out "$work/shrink" > /dev/null 2>&1
"$volreel" gen analytic --size 16 --frames 2 --out "$work/shrink" --overwrite > /dev/null 2>&1
[ "$(ls "$work/shrink" | tr '\n' ' ')" = "000000.f32 000001.f32 series.json " ] || fail "gen --overwrite left old frames: $(ls "$work/shrink")"
# --overwrite that fails leaves the old series whole (the new frames went to a folder of their own).
cp "$work/shrink/series.json" "$work/shrink.json"
expect_error "CFL number must be in (0, 2]" "$volreel" gen turbulence --size 16 --frames 1 --cfl 3 --out "$work/shrink" --overwrite
[ "$(ls -A "$work/shrink" | tr '\n' ' ')" = "000000.f32 000001.f32 series.json " ] || fail "a failed gen --overwrite left: $(ls -A "$work/shrink")"
cmp -s "$work/shrink/series.json" "$work/shrink.json" || fail "a failed gen --overwrite changed the old series.json"
expect_error "--resume excludes --overwrite" "$volreel" encode "$work/shrink" --resume --overwrite --out "$work/x.vreel"
expect_error "--replace-nan: expected a finite number of magnitude at most 1e33.*found 'nan'" "$volreel" encode "$work/shrink" --replace-nan nan --out "$work/x.vreel"
expect_error "--replace-nan: expected a finite number of magnitude at most 1e33.*found '1e39'" "$volreel" encode "$work/shrink" --replace-nan 1e39 --out "$work/x.vreel"
expect_error "--sparsities: Value 0 not in range 1 to 216" "$volreel" bench rd "$work/shrink" --sparsities 0
# A word that is no command is named, with the commands there are.
expect_error "'encod' is not a command of volreel (its commands: gen" "$volreel" encod "$work/a"
expect_error "'analytc' is not a command of volreel gen" "$volreel" gen analytc --out "$work/x"
expect_error "--coef-step: expected a number > 0, found '0'" "$volreel" bench rd "$work/a" --coef-step 0
# The player checks its options before it opens a window.
expect_error "at least 64x64" "$volreel" play "$work/none.vreel" --size 10x10
expect_error "WIDTHxHEIGHT" "$volreel" play "$work/none.vreel" --size big
expect_error "bandwidth: expected a rate" "$volreel" play "$work/none.vreel" --bandwidth 5xb
expect_error "latency: expected a duration" "$volreel" play "$work/none.vreel" --latency 3parsecs
expect_error "lod-fade: expected seconds" "$volreel" play "$work/none.vreel" --lod-fade -1
expect_error "lod-fade-out: expected seconds" "$volreel" play "$work/none.vreel" --lod-fade-out -1

# Rate-distortion benchmark on a small series: table, CSV and plot.
"$volreel" bench rd "$work/a" --out "$work/rd" --ssim-frames 1 > "$work/rd.txt" 2>/dev/null
grep -q "zfp fixed-accuracy" "$work/rd.txt" || fail "bench rd table lacks zfp fixed-accuracy"
grep -q "machine:" "$work/rd.txt" || fail "bench rd does not print the machine"
[ "$(wc -l < "$work/rd/rd.csv")" = 22 ] || fail "rd.csv should have a header and 21 rows"
grep -q "^At equal bps" "$work/rd.txt" || fail "bench rd prints no equal-bps table"
# zfp only: 7 bps rows x 2 zfp families, and a header.
[ "$(wc -l < "$work/rd/rd_equal_bps.csv")" = 15 ] || fail "rd_equal_bps.csv should have a header and 14 rows"
head -c 4 "$work/rd/rd.png" | grep -q PNG || fail "rd.png is not a PNG"
# Images: --min-psnr holds or fails like a volume's; --max-error is for volumes.
"$volreel" compare "$work/rd/rd.png" "$work/rd/rd.png" --min-psnr 100 > /dev/null 2>&1 || fail "an image equal to itself failed --min-psnr"
expect_error "bounds the values of volumes" "$volreel" compare "$work/rd/rd.png" "$work/rd/rd.png" --max-error 1
# With sparse keyframes: one curve per gap, every time step decoded as the player draws it. Gap 1
# stores every brick, so it delivers exactly the frame-by-frame variable rate's PSNR.
"$volreel" bench rd "$work/a" --out "$work/rdk" --dictionary dct --tolerances 0.004 --sparsities 2 \
  --keyframe-gaps 1 3 --ssim-frames 0 --no-plot > "$work/rdk.txt" 2>/dev/null
psnr_of() { awk -v f="$1" 'index($0, f) == 1 { print $(NF - 6); exit }' "$work/rdk.txt"; }
[ -n "$(psnr_of "volreel keyframes G=3")" ] || fail "bench rd lacks the gap-3 keyframe curve"
[ "$(psnr_of "volreel keyframes G=1")" = "$(psnr_of "volreel variable-rate")" ] ||
  fail "keyframes at gap 1 should deliver the frame-by-frame PSNR: $(cat "$work/rdk.txt")"
[ ! -e "$work/rdk/keyframes.vreel" ] || fail "bench rd left its keyframe container behind"
expect_error "--keyframe-gaps needs --dictionary" "$volreel" bench rd "$work/a" --keyframe-gaps 2
# A container of the user's where bench rd puts (and then removes) its own is refused.
mkdir -p "$work/rdk2/keyframes.vreel"; echo mine > "$work/rdk2/keyframes.vreel/notes.txt"
expect_error "notes.txt'.*--keyframe-gaps writes its containers" "$volreel" bench rd "$work/a" --out "$work/rdk2" --dictionary dct \
  --tolerances 0.004 --sparsities 2 --keyframe-gaps 2 --ssim-frames 0 --no-plot
[ -f "$work/rdk2/keyframes.vreel/notes.txt" ] || fail "bench rd removed a keyframes.vreel it did not write"
# ... but one a stopped run left (a container) is taken and removed.
"$volreel" encode "$work/a" --dictionary dct --out "$work/rdk3/keyframes.vreel" > /dev/null 2>&1
"$volreel" bench rd "$work/a" --out "$work/rdk3" --dictionary dct --tolerances 0.004 --sparsities 2 \
  --keyframe-gaps 2 --ssim-frames 0 --no-plot > /dev/null 2>&1 || fail "bench rd refused its own leftover keyframes.vreel"
[ ! -e "$work/rdk3/keyframes.vreel" ] || fail "bench rd left its keyframe container behind"
expect_error "--out is empty" "$volreel" bench rd "$work/a" --out ""

# Where a ksvd container's bits go: one row per level and one for all; gap, magnitude and sign
# bits add up to the bits per code; a zfp container is refused with the reason.
"$volreel" encode "$work/a" --dictionary dct --brick-size 12 --out "$work/k.vreel" > /dev/null 2>&1
"$volreel" bench codes "$work/k.vreel" > "$work/codes.txt" 2>/dev/null
levels=$("$volreel" info "$work/k.vreel" --json 2>/dev/null | json 'd["levels"]')
[ "$(grep -c '^[0-9]' "$work/codes.txt")" = "$levels" ] || fail "bench codes: expected $levels level rows: $(cat "$work/codes.txt")"
awk '$1 == "all" { t = $8; s = $9 + $10 + $11; if (t < 1 || s < t - 0.015 || s > t + 0.015) exit 1; ok = 1 }
     END { exit !ok }' "$work/codes.txt" || fail "bench codes: gap + magnitude + sign != bits per code: $(cat "$work/codes.txt")"
"$volreel" encode "$work/a" --codec zfp --out "$work/z.vreel" > /dev/null 2>&1
expect_error "reads ksvd containers" "$volreel" bench codes "$work/z.vreel"

# A raw file of every frame against the series it came from: the raw options are the raw side's.
cat "$work/a"/00000[0-3].f32 > "$work/all.raw"
out=$("$volreel" compare "$work/all.raw" "$work/a" --dims 24x20x16 --frames 4 --no-ssim --json 2>/dev/null) \
  || fail "compare of a raw file with a series directory"
[ "$(echo "$out" | json 'd["sequence"]["psnr"]')" = None ] || fail "raw file against its series: $out"
"$volreel" encode "$work/a" --dictionary dct --out "$work/ab.vreel" > /dev/null 2>&1
expect_error "is a volreel container: compare takes the original as A" "$volreel" compare "$work/ab.vreel" "$work/a"
# A container of the first frames of A: compared over those, with a note naming the rest.
"$volreel" encode "$work/a" --dictionary dct --max-frames 2 --out "$work/a2.vreel" > /dev/null 2>&1
"$volreel" compare "$work/a" "$work/a2.vreel" --no-ssim > /dev/null 2> "$work/a2.err" || fail "compare with a 2-frame container"
grep -q "the container holds 2 of the 4 frames.*frames 2..3 of A are not compared" "$work/a2.err" \
  || fail "compare of fewer frames: no note: $(cat "$work/a2.err")"
# info on a container with a damaged frame: the figures of the frames it can read, then the
# error (exit 1).
cp -r "$work/ab.vreel" "$work/abd.vreel"
truncate -s 100 "$work/abd.vreel/frames/000001.vrf"
if "$volreel" info "$work/abd.vreel" > "$work/info.txt" 2> "$work/info.err"; then
  fail "info of a container with a truncated frame exited 0"
fi
grep -q "^volume   24x20x16" "$work/info.txt" || fail "info printed nothing before its error: $(cat "$work/info.txt")"
grep -q "error: 1 of the [0-9]* frames written could not be read.*000001.vrf: expected [0-9]* bytes (its size in manifest.json), found 100" "$work/info.err" \
  || fail "info's error: $(cat "$work/info.err")"
# An output that is part of the input is refused, --overwrite or not: train would write its
# dictionary over a frame of the series, decode its volume over a frame of the container.
cp "$work/a/000001.f32" "$work/a1.copy"
expect_error "is part of the input.*written over the data" \
  "$volreel" train "$work/a" --atoms 8 --out "$work/a/000001.f32" --overwrite
expect_error "is part of the input" \
  "$volreel" train "$work/a/000001.f32" --dims 24x20x16 --atoms 8 --out "$work/a/000001.f32" --overwrite
expect_error "is part of the input" \
  "$volreel" train "$work/a/0*.f32" --dims 24x20x16 --atoms 8 --out "$work/a/000001.f32" --overwrite
(cd "$work/a" && expect_error "is part of the input" \
  "$volreel" train series.json --atoms 8 --out 000001.f32 --overwrite)
cmp -s "$work/a/000001.f32" "$work/a1.copy" || fail "train changed its input frame"
# Many more atoms than distinct training blocks: trained, with a warning that says how many fit.
"$volreel" train "$work/a" --atoms 1024 --out "$work/many.bin" > /dev/null 2> "$work/many.err" || fail "train --atoms 1024: $(cat "$work/many.err")"
grep -q "warning: K = 1024 atoms from [0-9]* distinct training blocks.*train fewer (e.g. --atoms [0-9]*)" "$work/many.err" \
  || fail "no warning for 1024 atoms from a few blocks: $(cat "$work/many.err")"
"$volreel" train "$work/a" --atoms 8 --out "$work/many.bin" --overwrite > /dev/null 2> "$work/many.err" || fail "train --atoms 8"
! grep -q "warning" "$work/many.err" || fail "a warning for 8 atoms: $(cat "$work/many.err")"
expect_error "is a file of the container.*choose another --out" \
  "$volreel" decode "$work/ab.vreel" --out "$work/ab.vreel/frames/000000.vrf"
"$volreel" verify "$work/ab.vreel" > /dev/null 2>&1 || fail "decode --out into its container damaged it"
# Into one pipe (a log of 2>&1) the report's lines come before the error that follows them.
("$volreel" info "$work/abd.vreel" 2>&1 || true) | cat > "$work/info.log"
tail -n 1 "$work/info.log" | grep -q "error: 1 of the" \
  || fail "info 2>&1 into a pipe: the error is not the last line: $(cat "$work/info.log")"
# Volumes smaller than SSIM's window: the other metrics, and a note that says why SSIM is not
# among them (null in JSON).
"$volreel" gen analytic --dims 4x4x4 --frames 2 --out "$work/tiny" > /dev/null 2>&1
"$volreel" encode "$work/tiny" --dictionary dct --out "$work/tiny.vreel" > /dev/null 2>&1 \
  || fail "encode of a 4x4x4 series"
out=$("$volreel" compare "$work/tiny" "$work/tiny.vreel" --json 2> "$work/tiny.err") \
  || fail "compare of a 4x4x4 series with its container: $(cat "$work/tiny.err")"
grep -q "SSIM not computed: axis x has 4 voxels, fewer than the 11-voxel window" "$work/tiny.err" \
  || fail "compare of tiny volumes: no note on SSIM: $(cat "$work/tiny.err")"
[ "$(echo "$out" | json 'd["sequence"]["ssim"]')" = None ] || fail "tiny volumes' SSIM: $out"
[ "$(echo "$out" | json 'd["sequence"]["psnr"] > 20')" = True ] || fail "tiny volumes' PSNR: $out"
"$volreel" compare "$work/tiny" "$work/tiny" --no-ssim > /dev/null 2>&1 || fail "compare --no-ssim of tiny volumes"
# bench rd on a volume thinner than SSIM's window: every family measured (keyframe gaps too, which
# stopped at the SSIM), and the table says why SSIM is nan.
"$volreel" gen analytic --field noise --dims 8x40x40 --frames 2 --out "$work/thin" > /dev/null 2>&1
"$volreel" bench rd "$work/thin" --out "$work/rd-thin" --dictionary dct --no-plot --keyframe-gaps 2 \
  > "$work/rd-thin.txt" 2>&1 || fail "bench rd of a thin volume: $(tail -3 "$work/rd-thin.txt")"
grep -q "SSIM = nan: not computed (an axis shorter than its 11-voxel window" "$work/rd-thin.txt" \
  || fail "bench rd's note on SSIM: $(grep "SSIM =" "$work/rd-thin.txt")"
# A container's manifest named for its folder; a URL where a path belongs; remote options on a
# folder, said to be ignored.
"$volreel" info "$work/tiny.vreel/manifest.json" > /dev/null || fail "info of a container's manifest.json"
expect_error "http://127.0.0.1:9/c.vreel: a URL, where this reads series and containers on this machine" \
  "$volreel" compare "$work/tiny" http://127.0.0.1:9/c.vreel
"$volreel" info "$work/tiny.vreel" --tries 3 --cache "$work/cache" > /dev/null 2> "$work/ignored.err"
grep -q "tiny.vreel is a folder on this machine, and --cache, --tries apply to a URL only: ignored" \
  "$work/ignored.err" || fail "remote options on a folder: $(cat "$work/ignored.err")"
# SIGTERM (or Ctrl-C's SIGINT, which a background job ignores) in gen: it stops at the next
# step, removes the frames it wrote and ends by the signal, as a shell expects.
# shellcheck source=interrupt_lib.sh
. "$(dirname "$0")/interrupt_lib.sh"
expect_stopped_by_sigterm "$work/int/000001.f32" "$work/int" \
  "$volreel" gen turbulence --size 32 --frames 400 --spinup 0 --interval 0.5 --out "$work/int"

echo "cli_end_to_end: all checks passed"
