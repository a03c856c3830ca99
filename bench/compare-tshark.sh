#!/usr/bin/env bash
# `aptscope decode --json` of a pcapng against `tshark -T json -r` of the same file. tshark only
# dissects the container (our link type is USER0), so this is a lower bound on what users
# compare with. Usage: bench/compare-tshark.sh [MB]
set -euo pipefail
cd "$(dirname "$0")/.."
mb=${1:-20}
command -v tshark >/dev/null || { echo "tshark is not installed"; exit 1; }
cargo build -q --release --bin aptscope
cargo build -q --release -p aptscope-dissector --example gen_stream
cargo build -q --release -p aptscope-capture --example frames_to_pcapng
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
target/release/examples/gen_stream "$mb" > "$tmp/s.bin"
# One packet per frame, as a tap records them.
target/release/examples/frames_to_pcapng "$tmp/s.bin" "$tmp/s.pcapng"
packets=$(tshark -r "$tmp/s.pcapng" -T fields -e frame.number 2>/dev/null | wc -l)
t() { local s e; s=$(date +%s.%N); "$@" > /dev/null 2>&1; e=$(date +%s.%N); echo "$e - $s" | bc -l; }
ta=$(t target/release/aptscope decode --json "$tmp/s.pcapng")
tt=$(t tshark -T json -r "$tmp/s.pcapng")
printf 'pcapng of %s MB (%s packets)\n' "$mb" "$packets"
printf 'aptscope decode --json: %6.2f s (%6.1f MB/s), every APT frame decoded\n' "$ta" "$(echo "$mb / $ta" | bc -l)"
printf 'tshark -T json -r:      %6.2f s (%6.1f MB/s), container only\n' "$tt" "$(echo "$mb / $tt" | bc -l)"
printf 'ratio: aptscope is %.1fx faster\n' "$(echo "$tt / $ta" | bc -l)"
