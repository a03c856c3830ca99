#!/usr/bin/env bash
# Figures of the live view (README, "Live view"): the soak test of tests/live.rs in release —
# simulator ⇄ `aptscope tap --view` in a tmux terminal ⇄ a scripted host sending 6000 status
# requests (ten minutes at the controller's 10 per second) compressed into SECS seconds plus
# two 1 MB bursts — printing the view's lag behind the file (sampled every 100 ms), the
# catch-up after the last reply and the tap process's memory. Needs tmux.
# Usage: bench/live-view.sh [SECS]   (default 20)
set -euo pipefail
cd "$(dirname "$0")/.."
export APTSCOPE_SOAK_SECS=${1:-20}
cargo test -q --release --test live -- --exact \
  soak_of_the_live_view_loses_nothing_lags_under_a_second_and_keeps_memory_flat \
  --nocapture 2>&1 | grep -E '^soak:|panicked|FAILED' || true
