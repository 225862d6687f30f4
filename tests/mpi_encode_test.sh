#!/usr/bin/env bash
# mpi_encode_test.sh: `mpirun -n N volreel encode` writes the very container the serial encoder
# writes (every file byte for byte) for 2 and 4 ranks, with keyframe gaps, a PSNR target, zfp,
# training and frames shared by teams of ranks; a rank killed mid-encode fails the job with a
# message, and --resume under mpirun completes the same container. Usage: mpi_encode_test.sh PATH/TO/volreel PATH/TO/mpiexec
set -euo pipefail
volreel=$1
mpiexec=$2
work=$(mktemp -d)
trap 'pkill -9 -f "$work" 2>/dev/null || true; rm -rf "$work"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
# Containers and CI machines run this as root, which OpenMPI refuses unless told.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
# One thread per rank, as many ranks as asked even on a 2-core machine.
export OMP_NUM_THREADS=1
# Under AddressSanitizer the ranks run without leak detection: OpenMPI keeps allocations until
# the process ends, in plugins it unloads, which LeakSanitizer cannot tell from volreel's. The
# same encoder code is leak-checked in every serial test.
rank_asan="${ASAN_OPTIONS:+$ASAN_OPTIONS:}detect_leaks=0"
mpi() { local n=$1; shift; "$mpiexec" -n "$n" --oversubscribe -x ASAN_OPTIONS="$rank_asan" "$@"; }
same() {  # two containers, every file
  diff -r "$1" "$2" > /dev/null || fail "$3: $(diff -r "$1" "$2" | head -3)"
}

# A non-cube with a still region (the plume), 13 frames: stretches of gap 3 split unevenly.
"$volreel" gen analytic --field plume --dims 40x36x44 --frames 13 --out "$work/s" > /dev/null 2>&1

"$volreel" encode "$work/s" --out "$work/serial.vreel" --dictionary dct --max-keyframe-gap 3 \
  > /dev/null 2>&1
for n in 2 4; do
  mpi "$n" "$volreel" encode "$work/s" --out "$work/mpi$n.vreel" --dictionary dct \
    --max-keyframe-gap 3 > "$work/mpi$n.txt" 2>&1 || fail "mpirun -n $n: $(tail -5 "$work/mpi$n.txt")"
  same "$work/serial.vreel" "$work/mpi$n.vreel" "-n $n differs from the serial container"
done
# Without gaps (a rank does not code the frame before its share).
"$volreel" encode "$work/s" --out "$work/g1.vreel" --dictionary dct --max-keyframe-gap 1 \
  > /dev/null 2>&1
mpi 3 "$volreel" encode "$work/s" --out "$work/g1-3.vreel" --dictionary dct --max-keyframe-gap 1 \
  > /dev/null 2>&1
same "$work/g1.vreel" "$work/g1-3.vreel" "-n 3 without keyframe gaps differs"
# --overwrite over a container (written beside it, moved in once complete): the same container.
mpi 3 "$volreel" encode "$work/s" --out "$work/g1-3.vreel" --dictionary dct --max-keyframe-gap 3 \
  --overwrite > "$work/over3.txt" 2>&1 || fail "mpirun --overwrite: $(tail -5 "$work/over3.txt")"
same "$work/serial.vreel" "$work/g1-3.vreel" "-n 3 --overwrite over a container differs"
grep -q "2 MPI processes" "$work/mpi2.txt" || fail "rank 0 does not say it runs with 2 processes"
[ "$(grep -c '^wrote' "$work/mpi2.txt")" = 1 ] || fail "the report should be printed once"
grep -q "on 2 processes" "$work/mpi2.txt" || fail "the report does not count the processes"
grep -Eq "^peak resident memory per rank: [0-9]+ MiB [0-9]+ MiB$" "$work/mpi2.txt" ||
  fail "no peak memory of each of the 2 ranks: $(grep peak "$work/mpi2.txt")"
"$volreel" verify "$work/mpi4.vreel" > /dev/null 2>&1 || fail "verify refuses the -n 4 container"
# One progress bar for the job: every process's frames, not rank 0's share (5 of 13).
grep -Eq "encoding .* 13/13 frames" "$work/mpi2.txt" || fail "the progress bar does not reach 13/13 frames"
grep -Eq "encoding .* [0-9]+/[0-9] frames" "$work/mpi2.txt" && fail "a progress bar counts a share of the frames"
# Frames larger than --memory, coded piecewise by each rank.
"$volreel" gen analytic --field blobs --dims 40x36x120 --frames 5 --out "$work/tall" > /dev/null 2>&1
"$volreel" encode "$work/tall" --out "$work/tall1.vreel" --dictionary dct --memory 1200K > /dev/null 2>&1
mpi 2 "$volreel" encode "$work/tall" --out "$work/tall2.vreel" --dictionary dct --memory 1200K \
  > "$work/tall2.txt" 2>&1 || fail "mpirun piecewise: $(tail -5 "$work/tall2.txt")"
grep -q "coded piecewise" "$work/tall2.txt" || fail "-n 2 --memory 1200K did not code piecewise"
same "$work/tall1.vreel" "$work/tall2.vreel" "piecewise under -n 2 differs"
# Fewer keyframe stretches than ranks: a team of ranks codes each frame together, brick by brick
# (one frame, -n 2 and -n 3; three frames, two stretches, -n 4: two teams of 2), with a PSNR
# target whose retries the team decides on together; a team resumes what a team wrote.
"$volreel" gen analytic --field blobs --dims 40x36x120 --frames 1 --out "$work/one" > /dev/null 2>&1
"$volreel" encode "$work/one" --out "$work/one1.vreel" --dictionary dct --memory 1200K > /dev/null 2>&1
for n in 2 3; do
  mpi "$n" "$volreel" encode "$work/one" --out "$work/one$n.vreel" --dictionary dct --memory 1200K \
    > "$work/one$n.txt" 2>&1 || fail "mpirun -n $n, one frame: $(tail -5 "$work/one$n.txt")"
  grep -q "each frame coded by $n processes together" "$work/one$n.txt" ||
    fail "-n $n did not share the frame: $(grep wrote "$work/one$n.txt")"
  same "$work/one1.vreel" "$work/one$n.vreel" "one frame shared by $n ranks differs"
done
"$volreel" gen analytic --field blobs --dims 40x36x120 --frames 3 --out "$work/three" > /dev/null 2>&1
targs=(encode "$work/three" --dictionary dct --memory 1200K --psnr 62)
"$volreel" "${targs[@]}" --out "$work/three1.vreel" > "$work/three1.txt" 2>&1
grep -q "coded again" "$work/three1.txt" || fail "the shared PSNR case should code frames again"
mpi 4 "$volreel" "${targs[@]}" --out "$work/three4.vreel" > "$work/three4.txt" 2>&1 ||
  fail "mpirun -n 4, teams: $(tail -5 "$work/three4.txt")"
grep -q "each frame coded by 2 processes together" "$work/three4.txt" || fail "-n 4 formed no teams of 2"
same "$work/three1.vreel" "$work/three4.vreel" "teams of 2 with a PSNR target differ"
rm "$work/three4.vreel/frames/000001.vrf"
mpi 4 "$volreel" "${targs[@]}" --out "$work/three4.vreel" --resume > "$work/three4r.txt" 2>&1 ||
  fail "--resume with teams: $(tail -5 "$work/three4r.txt")"
grep -q "(1 encoded, 2 already there)" "$work/three4r.txt" || fail "teams did not resume the one frame missing"
same "$work/three1.vreel" "$work/three4.vreel" "teams' resumed container differs"

# A PSNR target (frames coded again at smaller tolerances) and zfp.
"$volreel" encode "$work/s" --out "$work/psnr.vreel" --dictionary dct --psnr 62 \
  --max-keyframe-gap 4 > "$work/psnr.txt" 2>&1
mpi 3 "$volreel" encode "$work/s" --out "$work/psnr3.vreel" --dictionary dct --psnr 62 \
  --max-keyframe-gap 4 > "$work/psnr3.txt" 2>&1 || fail "mpirun --psnr: $(tail -5 "$work/psnr3.txt")"
same "$work/psnr.vreel" "$work/psnr3.vreel" "--psnr under -n 3 differs"
grep -q "coded again" "$work/psnr.txt" || fail "the PSNR case should code frames again"
"$volreel" encode "$work/s" --out "$work/zfp.vreel" --codec zfp > /dev/null 2>&1
mpi 2 "$volreel" encode "$work/s" --out "$work/zfp2.vreel" --codec zfp > /dev/null 2>&1
same "$work/zfp.vreel" "$work/zfp2.vreel" "zfp under -n 2 differs"

# A size target at which the learned atoms pay in no sampled brick (atoms learned on noise, for
# the plume): rank 0 decides to skip their pursuit and tells the others; the same container.
"$volreel" gen analytic --field noise --dims 24x24x24 --frames 2 --out "$work/noise" > /dev/null 2>&1
"$volreel" train "$work/noise" --out "$work/noise.bin" --atoms 64 --coreset 200k --levels 2 --iterations 2 \
  --psnr 45 > /dev/null 2>&1
"$volreel" encode "$work/s" --out "$work/skip.vreel" --dictionary "$work/noise.bin" --bps 2 --max-frames 4 \
  > "$work/skip.txt" 2>&1
grep -q "learned atoms: kept in none" "$work/skip.txt" || fail "the learned pursuit was not skipped: $(cat "$work/skip.txt")"
mpi 2 "$volreel" encode "$work/s" --out "$work/skip2.vreel" --dictionary "$work/noise.bin" --bps 2 \
  --max-frames 4 > "$work/skip2.txt" 2>&1 || fail "mpirun --bps: $(tail -5 "$work/skip2.txt")"
same "$work/skip.vreel" "$work/skip2.vreel" "the skipped learned pursuit under -n 2 differs"

# Training: each rank draws the coreset from its share of the frames, rank 0 merges the draws and
# trains, the others receive the dictionary; the same dictionary and container as one process
# (-n 3: shares of 2, 1 and 1 frames). K given, since the automatic choice trains four
# dictionaries (the same code on rank 0).
"$volreel" encode "$work/s" --out "$work/train.vreel" --max-frames 4 --atoms 64 > /dev/null 2>&1
mpi 3 "$volreel" encode "$work/s" --out "$work/train2.vreel" --max-frames 4 --atoms 64 \
  > /dev/null 2>&1
same "$work/train.vreel" "$work/train2.vreel" "training under -n 3 differs"

# An error on rank 0 ends the job with its message (no rank left waiting).
if out=$(timeout 120 "$mpiexec" -n 2 --oversubscribe -x ASAN_OPTIONS="$rank_asan" "$volreel" \
  encode "$work/s" --out "$work/mpi2.vreel" --dictionary dct 2>&1); then
  fail "encoding over an existing container should fail"
fi
grep -q "already holds a container" <<< "$out" || fail "no message for an existing container: $out"

# A rank killed mid-encode: the job fails; --resume under mpirun completes the same container.
# Enough frames that the kill, a poll after the second frame is written, lands long before the
# last one however fast the frames encode (with 40 it sometimes came too late on a loaded machine).
total_frames=120
"$volreel" gen analytic --field noise --size 36 --frames "$total_frames" --out "$work/n" > /dev/null 2>&1
args=(encode "$work/n" --dictionary dct --max-keyframe-gap 2 --tolerance 0.002)
"$volreel" "${args[@]}" --out "$work/whole.vreel" > /dev/null 2>&1
( mpi 2 "$volreel" "${args[@]}" --out "$work/killed.vreel" > "$work/killed.txt" 2>&1
  echo "rc=$?" >> "$work/killed.txt" ) &
job=$!
killed=
for _ in $(seq 1 600); do
  frames=$(find "$work/killed.vreel/frames" -name '*.vrf' 2> /dev/null | wc -l || true)
  if [ "$frames" -ge 2 ]; then
    for pid in $(pgrep -f "$work/killed.vreel"); do
      if grep -qx "OMPI_COMM_WORLD_RANK=1" <<< "$(tr "\0" "\n" < "/proc/$pid/environ" 2> /dev/null)"; then
        kill -9 "$pid" && killed=$pid
      fi
    done
    [ -n "$killed" ] && break
  fi
  sleep 0.05
done
wait "$job" || true
[ -n "$killed" ] || fail "found no rank 1 to kill: $(cat "$work/killed.txt")"
grep -q "rc=0" "$work/killed.txt" && fail "the job should fail when a rank is killed"
written=$(find "$work/killed.vreel/frames" -name '*.vrf' | wc -l)
[ "$written" -lt "$total_frames" ] || fail "the killed job wrote every frame; kill came too late"
mpi 2 "$volreel" "${args[@]}" --out "$work/killed.vreel" --resume > "$work/resumed.txt" 2>&1 ||
  fail "--resume under mpirun: $(tail -5 "$work/resumed.txt")"
grep -q "already there" "$work/resumed.txt" || fail "resume did not keep the frames written"
same "$work/whole.vreel" "$work/killed.vreel" "the resumed container differs from the serial one"

echo "mpi_encode: all checks passed"
