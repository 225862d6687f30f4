# interrupt_lib.sh: sourced by the command-line tests (which define fail).
# expect_stopped_by_sigterm MARKER FOLDER COMMAND...: runs COMMAND in the background, waits up to
# 60 s for the file MARKER (its output has begun), sends SIGTERM (as Ctrl-C's SIGINT would, which a
# background job ignores), and fails unless the command ends by the signal (exit status 143), says
# nothing half-written was left, and FOLDER (what it was writing) is gone.
expect_stopped_by_sigterm() {
  local marker=$1 folder=$2; shift 2
  local err
  err=$(mktemp)
  "$@" > /dev/null 2> "$err" &
  local pid=$!
  for _ in $(seq 600); do [ -e "$marker" ] && break; sleep 0.1; done
  if [ ! -e "$marker" ]; then
    kill "$pid" 2> /dev/null; wait "$pid" 2> /dev/null; rm -f "$err"
    fail "$1 $2 wrote no $marker in 60 s"
  fi
  kill -TERM "$pid"
  local status=0
  wait "$pid" || status=$?
  [ "$status" = 143 ] || fail "$1 $2 interrupted: exit status $status, expected 143 (SIGTERM): $(cat "$err")"
  [ ! -e "$folder" ] || fail "an interrupted $1 $2 left $(ls "$folder" | wc -l) files in $folder"
  grep -q "interrupted; nothing half-written was left" "$err" || fail "no message: $(cat "$err")"
  rm -f "$err"
}
