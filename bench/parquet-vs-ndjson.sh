#!/usr/bin/env bash
# `decode --to parquet` against `decode --json` on one capture and one thread, in alternating
# runs (the machine's speed drifts; a ratio is taken pair by pair): NDJSON both written to a
# file beside the dataset (what a batch job does: both outputs land on the same disk) and sent
# to /dev/null (rendering alone, no output written). Prints each run's CPU seconds (user +
# system) and wall seconds, then the medians and the median ratios.
# Usage: bench/parquet-vs-ndjson.sh [CAPTURE] [RUNS]   (default: a 10 MB status log made by
# dissector/examples/gen_d2h, 9 runs; outputs under $TMPDIR, default /tmp)
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build -q --release --bin aptscope
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cap=${1:-}
if [ -z "$cap" ]; then
  cargo build -q --release -p aptscope-dissector --example gen_d2h
  cap="$tmp/status.bin"
  target/release/examples/gen_d2h 10 1 > "$cap" 2>/dev/null
fi
runs=${2:-9}
bin=target/release/aptscope
printf 'capture: %s (%d bytes); %s, %d cores; load %s\n' "$cap" "$(stat -c %s "$cap")" \
  "$(lscpu | sed -n 's/^Model name: *//p' | head -n1)" "$(nproc)" "$(cut -d' ' -f1-3 /proc/loadavg)"
# One run: "CPU-seconds wall-seconds".
measure() {
  /usr/bin/time -o "$tmp/time" -f '%U %S %e' "$@" > /dev/null 2>/dev/null
  awk '{ printf "%.3f %.3f\n", $1 + $2, $3 }' "$tmp/time"
}
: > "$tmp/runs"
for i in $(seq 1 "$runs"); do
  p=$(measure "$bin" decode -j 1 --to parquet --force -o "$tmp/dataset" "$cap")
  f=$(measure sh -c "exec $bin decode -j 1 --json '$cap' > '$tmp/out.ndjson'")
  n=$(measure "$bin" decode -j 1 --json "$cap")
  echo "$p $f $n" >> "$tmp/runs"
  printf 'run %d: parquet %s | ndjson to a file %s | ndjson to /dev/null %s (CPU-s wall-s)\n' \
    "$i" "$p" "$f" "$n"
done
printf 'dataset %s, NDJSON %s\n' "$(du -sh "$tmp/dataset" | cut -f1)" "$(du -sh "$tmp/out.ndjson" | cut -f1)"
echo "load: $(cut -d' ' -f1-3 /proc/loadavg)"
# Medians of each column and of the ratios parquet/ndjson, pair by pair.
awk '
  function median(a, n,   i, j, t) {
    for (i = 1; i <= n; i++) for (j = i + 1; j <= n; j++) if (a[j] < a[i]) { t = a[i]; a[i] = a[j]; a[j] = t }
    return n % 2 ? a[(n + 1) / 2] : (a[n / 2] + a[n / 2 + 1]) / 2
  }
  { n++; pc[n] = $1; pw[n] = $2; fc[n] = $3; fw[n] = $4; nc[n] = $5; nw[n] = $6
    rfc[n] = $1 / $3; rfw[n] = $2 / $4; rnc[n] = $1 / $5; rnw[n] = $2 / $6 }
  END {
    printf "median CPU-s: parquet %.3f, ndjson to a file %.3f, to /dev/null %.3f\n", median(pc, n), median(fc, n), median(nc, n)
    printf "median wall-s: parquet %.3f, ndjson to a file %.3f, to /dev/null %.3f\n", median(pw, n), median(fw, n), median(nw, n)
    printf "parquet / ndjson to a file: CPU %.2fx, wall %.2fx\n", median(rfc, n), median(rfw, n)
    printf "parquet / ndjson to /dev/null: CPU %.2fx, wall %.2fx\n", median(rnc, n), median(rnw, n)
  }' "$tmp/runs"
