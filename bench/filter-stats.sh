#!/usr/bin/env bash
# `decode -Y FILTER --json` and `stats` end to end on a synthetic stream, best of RUNS runs.
# Usage: bench/filter-stats.sh [MB] [OTHER_BINARY]   (env RUNS=3)
# With OTHER_BINARY (e.g. an older build of aptscope) both are timed on the same input.
set -euo pipefail
cd "$(dirname "$0")/.."
mb=${1:-20}
other=${2:-}
runs=${RUNS:-3}
cargo build -q --release --bin aptscope
cargo build -q --release -p aptscope-dissector --example gen_stream
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
target/release/examples/gen_stream "$mb" > "$tmp/s.bin"
best() { # best wall time of "$@" in seconds, output discarded
  local b=999999 s e t
  for _ in $(seq "$runs"); do
    s=$(date +%s.%N); "$@" > /dev/null; e=$(date +%s.%N)
    t=$(echo "$e - $s" | bc -l)
    if (( $(echo "$t < $b" | bc -l) )); then b=$t; fi
  done
  echo "$b"
}
bins=(target/release/aptscope)
[ -n "$other" ] && bins+=("$other")
for bin in "${bins[@]}"; do
  echo "== $bin ($mb MB)"
  for f in 'apt.name ~ "^MOT_MOVE_"' 'apt.position > 1000' 'dir == d2h || diag'; do
    t=$(best "$bin" decode --json -Y "$f" "$tmp/s.bin")
    printf '  decode --json -Y %-28s %6.2f s  %6.1f MB/s\n' "'$f'" "$t" "$(echo "$mb / $t" | bc -l)"
  done
  t=$(best "$bin" decode --json "$tmp/s.bin")
  printf '  decode --json (no filter)              %6.2f s  %6.1f MB/s\n' "$t" "$(echo "$mb / $t" | bc -l)"
  t=$(best "$bin" stats "$tmp/s.bin")
  printf '  stats                                  %6.2f s  %6.1f MB/s\n' "$t" "$(echo "$mb / $t" | bc -l)"
  t=$(best "$bin" stats -Y 'apt.position > 1000' "$tmp/s.bin")
  printf '  stats -Y apt.position > 1000           %6.2f s  %6.1f MB/s\n' "$t" "$(echo "$mb / $t" | bc -l)"
done
