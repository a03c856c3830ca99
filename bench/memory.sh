#!/usr/bin/env bash
# Peak RSS of `aptscope decode --json` on 10 MB and 100 MB synthetic streams: it must be the same
# (streaming, constant memory). Usage: bench/memory.sh
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build -q --release --bin aptscope
cargo build -q --release -p aptscope-dissector --example gen_stream
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
for mb in 10 100; do
  target/release/examples/gen_stream "$mb" > "$tmp/s.bin"
  start=$(date +%s.%N)
  rss=$( { /usr/bin/time -f %M target/release/aptscope decode --json "$tmp/s.bin" > /dev/null; } 2>&1 )
  end=$(date +%s.%N)
  printf '%4s MB input: peak RSS %6s KiB, %.1f MB/s\n' "$mb" "$rss" "$(echo "$mb / ($end - $start)" | bc -l)"
done
