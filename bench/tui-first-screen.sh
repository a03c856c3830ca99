#!/usr/bin/env bash
# Time to the first screen of the terminal UI on a generated capture of 10 M frames (154 MB of
# mixed APT traffic), the time to index it all, and the peak resident memory of the process
# once indexed (`/usr/bin/time`). Usage: bench/tui-first-screen.sh [MB]
set -euo pipefail
cd "$(dirname "$0")/.."
mb=${1:-154}
cargo build -q --release -p aptscope-dissector --example gen_stream
cargo build -q --release -p aptscope-tui --example first_screen
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
target/release/examples/gen_stream "$mb" > "$tmp/big.bin"
/usr/bin/time -f 'peak RSS %M KiB' target/release/examples/first_screen "$tmp/big.bin"
