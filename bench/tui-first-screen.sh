#!/usr/bin/env bash
# Time to the first screen of the terminal UI on a generated capture of 10 M frames (154 MB of
# mixed APT traffic), the time to index it all, the time to jump to the end and draw, and the
# peak resident memory of the process once indexed (`/usr/bin/time`). It opens the capture
# twice, with the index cache in a directory of its own: the first opening indexes and writes
# the cache, the second reads it back (`"cache":"read"`); the cache file's size is printed.
# Usage: bench/tui-first-screen.sh [MB] [--index-memory SIZE] [--no-cache]
# FORMAT=pcapng converts the generated raw capture to pcapng first (record bytes then go to the
# viewer's scratch file instead of being read back from the capture). The capture is made in a
# temporary directory (TMPDIR: a 4 GB one needs the room) and deleted at the end.
set -euo pipefail
cd "$(dirname "$0")/.."
mb=${1:-154}
shift || true
cargo build -q --release -p aptscope-dissector --example gen_stream
cargo build -q --release -p aptscope-tui --example first_screen
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
target/release/examples/gen_stream "$mb" > "$tmp/big.bin"
file=$tmp/big.bin
if [ "${FORMAT:-raw}" = pcapng ]; then
    cargo build -q --release --bin aptscope
    target/release/aptscope convert "$tmp/big.bin" "$tmp/big.pcapng" > /dev/null
    rm "$tmp/big.bin"
    file=$tmp/big.pcapng
fi
export XDG_CACHE_HOME=$tmp/cache
uptime
for opening in first second; do
    echo "$opening opening:"
    /usr/bin/time -f 'peak RSS %M KiB, CPU %U s user %S s sys, %e s wall' \
        target/release/examples/first_screen "$file" "$@"
done
ls -l "$XDG_CACHE_HOME"/aptscope/index/ 2>/dev/null || echo "no index cache"
