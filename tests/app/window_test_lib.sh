# window_test_lib.sh: what the window tests under Xvfb share (sourced, not run).
fail() { echo "FAIL: $*" >&2; exit 1; }
skip() { echo "SKIP: $*"; exit 77; }

# check_player_exit RC ERR_FILE WHAT [FILE...]: exit code RC of WHAT (the player, or a session
# running it): 0 passes; volreel play's 3 (no display) and 4 (no Vulkan device that can present)
# skip with ERR_FILE's text; anything else prints the FILEs and fails.
check_player_exit() {
  local rc=$1 err=$2 what=$3
  shift 3
  case $rc in
    0) ;;
    3) skip "no display under xvfb-run: $(cat "$err")" ;;
    4) skip "no Vulkan device that can present: $(cat "$err")" ;;
    *) cat "$@" >&2; fail "$what exited with $rc" ;;
  esac
}
