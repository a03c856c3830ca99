#!/usr/bin/env bash
# Peak RSS of `aptscope decode --json` (and of `aptscope stats`) on 10 MB and 100 MB synthetic
# streams: it must be the same (streaming, constant memory). Usage: bench/memory.sh
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
  rss=$( { /usr/bin/time -f %M target/release/aptscope stats "$tmp/s.bin" > /dev/null; } 2>&1 )
  printf '%4s MB input: peak RSS %6s KiB (stats)\n' "$mb" "$rss"
done

# The same through capture files: a 100 MB stream converted to pcapng and MCAP, then decoded.
target/release/examples/gen_stream 100 > "$tmp/s.bin"
for fmt in pcapng mcap; do
  target/release/aptscope convert --force "$tmp/s.bin" "$tmp/s.$fmt" 2>/dev/null
  start=$(date +%s.%N)
  rss=$( { /usr/bin/time -f %M target/release/aptscope decode --json "$tmp/s.$fmt" > /dev/null; } 2>&1 )
  end=$(date +%s.%N)
  printf '%6s 100 MB: peak RSS %6s KiB, %.1f MB/s\n' "$fmt" "$rss" "$(echo "100 / ($end - $start)" | bc -l)"
done
