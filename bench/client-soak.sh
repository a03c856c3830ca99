#!/usr/bin/env bash
# Figures of the soak with a real client (docs/live.md): thorlabs-apt-device's KDC101 class
# (from PyPI, in target/client-venv) ⇄ `aptscope tap --view` in a tmux terminal ⇄ the
# simulator, for SECS seconds (default 600) with homing, a move every 5 s and a 1 MB burst every
# minute: the view's lag, the tap's byte check, the tap's and the simulator's memory. The test
# of tests/live.rs in release. Needs tmux and python3 with venv.
# Usage: bench/client-soak.sh [SECS]
set -euo pipefail
cd "$(dirname "$0")/.."
export APTSCOPE_CLIENT_SOAK_SECS=${1:-600}
export APTSCOPE_CLIENT_SOAK_BURST_SECS=60
cargo test -q --release --test live -- --exact \
  soak_with_a_real_client_loses_nothing_and_keeps_memory_flat \
  --nocapture 2>&1 | grep -E '^client soak:|panicked|FAILED' || true
