#!/usr/bin/env bash
# stream_bench_cli_test.sh: `volreel bench stream` end to end on a tiny container — both policies
# run, the per-frame CSVs and the summary hold sane numbers (finite image PSNR above 10 dB at the
# end, every node at its target LOD with unlimited bandwidth, popping and seam error in range),
# PNGs are written, bad options give clear errors, and two runs on the simulated clock agree frame
# for frame. Usage: stream_bench_cli_test.sh PATH/TO/volreel
set -euo pipefail
volreel=$1
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
expect_error() {
  local pattern=$1; shift
  local msg
  if msg=$("$@" 2>&1 >/dev/null); then fail "expected failure: $*"; fi
  grep -q -e "$pattern" <<< "$msg" || fail "message for '$*' lacks '$pattern': $msg"
}

# A tiny container: 2 octree levels (root + 8 bricks), 6 frames.
"$volreel" gen analytic --field blobs --dims 60x60x60 --frames 6 --out "$work/s" 2>/dev/null
"$volreel" train "$work/s" --out "$work/dict.bin" --atoms 64 --coreset 200k --levels 2 --iterations 2 --psnr 45 > /dev/null 2>&1
"$volreel" encode "$work/s" --dictionary "$work/dict.bin" --out "$work/a.vreel" > /dev/null 2>&1

# 1. Unlimited bandwidth, both policies: the original series is found through the manifest.
"$volreel" bench stream "$work/a.vreel" --bandwidth 0 --latency 0 --duration 3 --size 48x48 --out "$work/u" \
  > "$work/u.txt" 2> "$work/u.err" || { cat "$work/u.txt" "$work/u.err" >&2; fail "bench stream (unlimited)"; }
grep -q "truth:   the original series" "$work/u.txt" || fail "ground truth is not the original series: $(cat "$work/u.txt")"
grep -q "nearest-keyframe-first" "$work/u.txt" || fail "no side-by-side table"
grep -q "patent's mean image PSNR higher than nearest-keyframe-first: " "$work/u.txt" || fail "no PSNR target line"
grep -q "no frame with a hole after the first root brick arrived: " "$work/u.txt" || fail "no hole target line"
grep -q "streaming (patent)" "$work/u.err" || fail "no progress bar"
for p in patent nearest; do
  csv="$work/u/stream_$p.csv"
  [ -s "$csv" ] || fail "missing $csv"
  /usr/bin/python3 - "$csv" <<'PY' || fail "bad numbers in $csv"
import csv, math, sys
rows = list(csv.DictReader(open(sys.argv[1])))
assert len(rows) >= 3, f"only {len(rows)} frames"
last = rows[-1]
psnr = float(last["psnr_db"])
assert math.isfinite(psnr) and psnr > 10, f"last PSNR {psnr}"
assert max(float(r["fraction_at_target"]) for r in rows) == 1.0, "never every node at target LOD"
assert float(last["fraction_at_target"]) == 1.0, f"last frame at {last['fraction_at_target']} of target LOD"
assert float(last["fraction_current"]) == 1.0, "last frame not at full quality"
assert int(last["holes"]) == 0, "holes in the last frame"
for r in rows:
    assert 0 <= float(r["fraction_at_target"]) <= 1 and 0 <= float(r["ssim"]) <= 1.0001
    assert float(r["time_s"]) <= 3.0 + 1e-9
# Popping: none for the first frame, a finite RMS in 8-bit units for every later one; the seam
# error where there is one (NaN where the frame had no level-of-detail boundary).
assert math.isnan(float(rows[0]["popping"])), f"first frame's popping {rows[0]['popping']}"
for r in rows[1:]:
    assert 0 <= float(r["popping"]) <= 255, f"popping {r['popping']}"
# Working-set popping (simulated clock): none for the first frame, then an RMS in 8-bit units,
# above 0 where arrivals changed the picture.
assert math.isnan(float(rows[0]["working_set_popping"])), "first frame's working-set popping"
for r in rows[1:]:
    w = float(r["working_set_popping"])
    assert 0 <= w <= 255, f"working-set popping {w}"
assert any(float(r["working_set_popping"]) > 0 for r in rows[1:] if int(r["uploads"]) > 0), \
    "no arrival changed the image"
for r in rows:
    seam = float(r["seam"])
    assert math.isnan(seam) or 0 <= seam <= 255, f"seam {seam}"
assert int(last["bytes_loaded"]) > 0, "nothing loaded"
assert float(last["time_s"]) == 3.0, "the tour did not run to its end"
PY
  ls "$work/u/frames_$p/"frame_*.png > /dev/null 2>&1 || fail "no PNG for $p"
done
/usr/bin/python3 - "$work/u/summary.json" <<'PY' || fail "bad summary.json"
import json, sys
d = json.load(open(sys.argv[1]))
assert [r["policy"] for r in d["runs"]] == ["patent", "nearest"]
for r in d["runs"]:
    assert r["frames"] >= 3 and r["mean_psnr_db"] > 10 and r["bytes_loaded"] > 0
    assert len(r["seeks"]) == 5
    assert r["mean_popping_all"] is not None and r["mean_popping_all"] >= 0
    assert (r["mean_popping"] is None) == (r["popping_frames"] == 0) == (r["max_popping"] is None)
    assert r["working_set_popping_frames"] > 0 and r["max_working_set_popping"] >= r["mean_working_set_popping"] >= 0
    assert (r["mean_seam"] is None) == (r["seam_frames"] == 0)
assert "target_higher_psnr" in d and "target_no_holes" in d
PY

# 2. A slow link and one policy: less loaded, still sane; the container's own decode as truth.
mv "$work/s" "$work/s-moved"
"$volreel" bench stream "$work/a.vreel" --bandwidth 20kB/s --latency 20ms --duration 2 --size 32x32 --policy patent \
  --spatial-blend true --lod-fade 0.5 --lod-fade-out 0.25 --out "$work/slow" > "$work/slow.txt" 2>/dev/null || fail "bench stream (slow)"
grep -q "the container's own finest-level decode" "$work/slow.txt" || fail "no notice of the fallback ground truth"
grep -q "due window first" "$work/slow.txt" || fail "no due-window line: $(cat "$work/slow.txt")"
/usr/bin/python3 - "$work/slow/stream_patent.csv" <<'PY' || fail "slow link numbers"
import csv, math, sys
rows = list(csv.DictReader(open(sys.argv[1])))
loaded = int(rows[-1]["bytes_loaded"])
assert 0 < loaded, "nothing loaded"
assert all(float(r["psnr_db"]) > 0 for r in rows)
assert all(0 <= int(r["blended_leaves"]) <= int(r["svo_leaves"]) for r in rows)
assert all(0 <= int(r["restricted_nodes"]) for r in rows)
PY
/usr/bin/python3 - "$work/slow/summary.json" <<'PY' || fail "blending settings not in summary.json"
import json, sys
d = json.load(open(sys.argv[1]))
assert d["spatial_blend"] is True and d["lod_fade_s"] == 0.5 and d["lod_fade_out_s"] == 0.25, d
assert d["restricted"] is True and d["restricted_drawing"] is True, d
PY
"$volreel" bench stream "$work/a.vreel" --series "$work/s-moved" --bandwidth 0 --duration 1 --size 32x32 --policy nearest \
  --out "$work/n" > "$work/n.txt" 2>/dev/null || fail "bench stream --series"
grep -q "truth:   the original series (--series" "$work/n.txt" || fail "--series not used: $(cat "$work/n.txt")"

# 3. The simulated clock (the default) makes a run repeatable: everything but the timings agrees.
for run in 1 2; do
  "$volreel" bench stream "$work/a.vreel" --series "$work/s-moved" --bandwidth 15kB/s --latency 40ms --duration 2 \
    --fps 8 --size 32x32 --policy patent --out "$work/r$run" > "$work/r$run.txt" 2>/dev/null || fail "bench stream run $run"
done
grep -q "simulated clock, 8 frames per tour second" "$work/r1.txt" || fail "no simulated-clock line: $(cat "$work/r1.txt")"
[ "$(wc -l < "$work/r1/stream_patent.csv")" -eq 18 ] || fail "expected 17 frames at 8 fps over 2 s, found $(($(wc -l < "$work/r1/stream_patent.csv") - 1))"
cut -d, -f1-26 "$work/r1/stream_patent.csv" > "$work/r1.cut"
cut -d, -f1-26 "$work/r2/stream_patent.csv" > "$work/r2.cut"
cmp -s "$work/r1.cut" "$work/r2.cut" || fail "two simulated runs differ: $(diff "$work/r1.cut" "$work/r2.cut" | head -5)"
/usr/bin/python3 - "$work/r1/stream_patent.csv" <<'PY' || fail "simulated clock: the link's bandwidth is not respected"
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
for r in rows:  # 15 kB/s after 40 ms of latency: never more bytes than the link can have delivered
    t = float(r["time_s"])
    assert int(r["bytes_loaded"]) <= 15000 * max(0.0, t - 0.04) + 1, (t, r["bytes_loaded"])
assert int(rows[-1]["bytes_loaded"]) > 0.5 * 15000 * (2 - 0.04), "the link sat idle"
PY

# 4. Several tours (--seeds): one folder per seed, each with both policies, and the targets on the
#    mean over the tours, which is the mean of the tours' own means.
"$volreel" bench stream "$work/a.vreel" --series "$work/s-moved" --bandwidth 40kB/s --duration 1 --size 32x32 \
  --seeds 2 --seed 3 --out "$work/m" > "$work/m.txt" 2>/dev/null || fail "bench stream --seeds"
grep -q "higher than nearest-keyframe-first (mean over the tours): " "$work/m.txt" || fail "no mean target line: $(cat "$work/m.txt")"
grep -q "tour seed 4:" "$work/m.txt" || fail "no table for the second tour"
/usr/bin/python3 - "$work/m" <<'PY' || fail "bad --seeds output"
import csv, json, os, sys
out = sys.argv[1]
d = json.load(open(os.path.join(out, "summary.json")))
assert [t["seed"] for t in d["tours"]] == [3, 4]
means = {}
for t in d["tours"]:
    tour = json.load(open(os.path.join(out, f"seed_{t['seed']}", "tour.json")))
    assert tour["playhead"], "empty tour"
    for r in t["runs"]:
        rows = list(csv.DictReader(open(os.path.join(out, f"seed_{t['seed']}", f"stream_{r['policy']}.csv"))))
        assert len(rows) == r["frames"] >= 3
        assert abs(sum(float(x["psnr_db"]) for x in rows) / len(rows) - r["mean_psnr_db"]) < 1e-3
        means.setdefault(r["policy"], []).append(r["mean_psnr_db"])
# The two tours seek to different time steps.
t3 = json.load(open(os.path.join(out, "seed_3", "tour.json")))
t4 = json.load(open(os.path.join(out, "seed_4", "tour.json")))
assert t3["playhead"] != t4["playhead"], "same playhead keys"
assert d["target_higher_psnr"] == (sum(means["patent"]) > sum(means["nearest"]))
PY
expect_error "drop --tour or --seeds" "$volreel" bench stream "$work/a.vreel" --seeds 2 --tour "$work/m/seed_3/tour.json"
expect_error "1..100 tours" "$volreel" bench stream "$work/a.vreel" --seeds 0

# 5. A damaged container: the runs complete and say which file failed; the exit status is 1.
cp -r "$work/a.vreel" "$work/damaged.vreel"
truncate -s 3000 "$work/damaged.vreel/frames/000001.vrf"
expect_error "reads of bricks or frames failed while streaming" "$volreel" bench stream "$work/damaged.vreel" \
  --series "$work/s-moved" --duration 1 --size 32x32 --out "$work/damaged"
[ -s "$work/damaged/summary.json" ] || fail "a run with a damaged frame wrote no summary"

# 6. A source recorded relative to where the encode ran is looked for next to the container
# first: a series of another size under that name in the current folder is not taken.
(cd "$work" && "$volreel" encode s-moved --dictionary dct --out rel.vreel > /dev/null 2>&1)
mkdir "$work/elsewhere"
"$volreel" gen analytic --field blobs --dims 30x30x30 --frames 6 --out "$work/elsewhere/s-moved" > /dev/null 2>&1
(cd "$work/elsewhere" && "$volreel" bench stream ../rel.vreel --duration 1 --size 32x32 --out ../rel) \
  > "$work/rel.txt" 2>&1 || { cat "$work/rel.txt" >&2; fail "bench stream of a container with a relative source"; }
grep -q "truth:   the original series.*$work/s-moved)" "$work/rel.txt" || fail "the wrong series was taken: $(grep truth "$work/rel.txt")"

# 7. Errors.
expect_error "expected a rate such as 20MB/s" "$volreel" bench stream "$work/a.vreel" --bandwidth fast
expect_error "expected a duration such as 50ms" "$volreel" bench stream "$work/a.vreel" --latency soon
expect_error "expected WIDTHxHEIGHT" "$volreel" bench stream "$work/a.vreel" --size 100
expect_error "both, patent or nearest" "$volreel" bench stream "$work/a.vreel" --policy fastest
expect_error "simulated or wall" "$volreel" bench stream "$work/a.vreel" --clock sundial
expect_error "not a container folder" "$volreel" bench stream "$work/missing.vreel"
expect_error "no such file or folder" "$volreel" bench stream "$work/a.vreel" --series "$work/nothing"
expect_error "seconds in \[0, 60\]" "$volreel" bench stream "$work/a.vreel" --lookahead -1
expect_error "seconds in \[0, 60\]" "$volreel" bench stream "$work/a.vreel" --speculative-link 100
expect_error "an exponent in \[0, 64\]" "$volreel" bench stream "$work/a.vreel" --ancestor-handicap -2
expect_error "seconds in \[0, 60\]" "$volreel" bench stream "$work/a.vreel" --lod-fade -0.5
expect_error "lod-fade-out.*seconds in \[0, 60\]" "$volreel" bench stream "$work/a.vreel" --lod-fade-out 61
# A disk cache would let every run after the first start warm: one policy, one tour with it.
expect_error "--cache with --policy both: every run after the first" "$volreel" bench stream http://127.0.0.1:9/a.vreel --cache "$work/cache"
expect_error "--cache with --seeds 2" "$volreel" bench stream http://127.0.0.1:9/a.vreel --policy patent --seeds 2 --cache "$work/cache"
# SIGTERM (or Ctrl-C) during a run: it stops at the next step, removes the folder it created and
# ends by the signal.
# shellcheck source=../interrupt_lib.sh
. "$(dirname "$0")/../interrupt_lib.sh"
expect_stopped_by_sigterm "$work/int/b/tour.json" "$work/int" \
  "$volreel" bench stream "$work/a.vreel" --duration 600 --size 32x32 --out "$work/int/b"
# Into a folder that exists the run writes beside it and moves its files in once all are written:
# interrupted, the folder keeps what it held and nothing of the run; completed, the run's files
# replace those of the same names.
mkdir -p "$work/ex"; echo old > "$work/ex/keep.txt"; echo old > "$work/ex/tour.json"
"$volreel" bench stream "$work/a.vreel" --duration 600 --size 32x32 --out "$work/ex" > /dev/null 2>&1 &
bench=$!
for _ in $(seq 600); do compgen -G "$work/ex.partial-*/tour.json" > /dev/null && break; sleep 0.1; done
compgen -G "$work/ex.partial-*/tour.json" > /dev/null || fail "bench stream staged no tour.json in 60 s"
kill -TERM "$bench"
status=0; wait "$bench" || status=$?
[ "$status" = 143 ] || fail "bench stream into an existing folder, interrupted: exit status $status"
[ "$(ls "$work/ex")" = "$(printf 'keep.txt\ntour.json')" ] && [ "$(cat "$work/ex/tour.json")" = old ] ||
  fail "an interrupted run changed the existing folder: $(ls "$work/ex")"
! compgen -G "$work/ex.partial-*" > /dev/null || fail "an interrupted run left its staging folder"
"$volreel" bench stream "$work/a.vreel" --duration 1 --size 32x32 --policy patent --out "$work/ex" > "$work/ex.txt" 2>&1 ||
  fail "bench stream into an existing folder: $(cat "$work/ex.txt")"
[ -s "$work/ex/summary.json" ] && [ -f "$work/ex/keep.txt" ] && [ "$(cat "$work/ex/tour.json")" != old ] ||
  fail "a completed run did not replace its files in the existing folder: $(ls "$work/ex")"
! compgen -G "$work/ex.partial-*" > /dev/null || fail "a completed run left its staging folder"
grep -q "wrote $work/ex:" "$work/ex.txt" || fail "the report names the staging folder: $(tail -2 "$work/ex.txt")"
"$volreel" bench stream --help > "$work/help.txt" && grep -q -e "--bandwidth" "$work/help.txt" || fail "--help lacks --bandwidth"
for o in --due-window --lookahead --speculative-link --ancestor-handicap --sse-priority --seeds --lod-fade --lod-fade-out --spatial-blend; do grep -q -e "$o" "$work/help.txt" || fail "--help lacks $o"; done
echo "stream bench CLI: OK"
