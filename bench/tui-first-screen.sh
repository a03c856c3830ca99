#!/usr/bin/env bash
# Time to the first screen of the terminal UI on a generated capture of 10 M frames (154 MB of
# mixed APT traffic), and the time to index it all. Usage: bench/tui-first-screen.sh [MB]
set -euo pipefail
cd "$(dirname "$0")/.."
mb=${1:-154}
cargo build -q --release -p aptscope-dissector --example gen_stream
cargo build -q --release -p aptscope-tui --example first_screen
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
target/release/examples/gen_stream "$mb" > "$tmp/big.bin"
target/release/examples/first_screen "$tmp/big.bin"
