#!/usr/bin/env bash
# leak_check_test.sh PROBE: LeakSanitizer in a Vulkan program (sanitizer builds only). Memory the
# Vulkan driver and the validation layer keep for themselves must not fail a test, and a leak of
# volreel's own code must still fail one, named by its function and size. PROBE is leak_probe.
set -u
probe=$1
fail() { echo "FAIL: $*" >&2; exit 1; }
export ASAN_OPTIONS=detect_leaks=1
out=$(mktemp)
trap 'rm -f "$out"' EXIT

# 1. A context and nothing else, with and without the validation layer: no leak reported.
for validation in 0 1; do
  VOLREEL_VULKAN_VALIDATION=$validation "$probe" > "$out" 2>&1
  rc=$?
  if [ "$rc" = 77 ]; then cat "$out"; echo "SKIP: no Vulkan device"; exit 77; fi
  [ "$rc" = 0 ] || { cat "$out" >&2; fail "a Vulkan context alone (validation=$validation) exited with $rc"; }
  grep -q "LeakSanitizer" "$out" && { cat "$out" >&2; fail "leak report without --leak"; }
done
echo "a Vulkan context alone: no leak reported, with and without validation"

# 2. The probe's own leak, in the same program: reported and fatal, and the only one reported.
VOLREEL_VULKAN_VALIDATION=1 "$probe" --leak > "$out" 2>&1
rc=$?
[ "$rc" != 0 ] || { cat "$out" >&2; fail "an intentional leak was not caught (exit 0)"; }
grep -q "LeakSanitizer: detected memory leaks" "$out" || { cat "$out" >&2; fail "no leak report (exit $rc)"; }
grep -q "Direct leak of 4321 byte(s) in 1 object(s)" "$out" || { cat "$out" >&2; fail "the report does not list the 4321-byte leak"; }
grep -q "leak_on_purpose" "$out" || { cat "$out" >&2; fail "the report does not name leak_on_purpose"; }
grep -q "SUMMARY: AddressSanitizer: 4321 byte(s) leaked in 1 allocation(s)" "$out" ||
  { cat "$out" >&2; fail "the report lists more than the intentional leak"; }
echo "an intentional leak: reported (exit $rc), named, and the only one"
