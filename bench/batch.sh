#!/usr/bin/env bash
# `aptscope decode` over many files on 1 and 2 threads: throughput, CPU time and peak RSS, for
# text, NDJSON and Parquet output, each -j 2 figure beside its -j 1 and Parquet beside NDJSON;
# then ONE large capture (raw, and the same as pcapng) on 1 and 2 threads, text, NDJSON and
# Parquet (one file: the decode chain on one thread, rendering, or Parquet encoding, on the
# others).
# Last, the two targets of #27 that are not `decode` runs: typed decoding (framing + every
# field, `dissector/examples/decode_file`, best of 10 runs in memory) and Python's `to_arrow()`
# (`python/examples/arrow_speed.py`, the call alone, threads=1 beside one per core, release
# module in target/bench-pyvenv, built here; and the call building no table, the decode chain
# that bounds it), then every target with its figure.
# Usage: bench/batch.sh   (env: FILES=50 files of MB=4.2 MB each, ≥ 200 MB; BIG=100 MB;
# ARROW_MB=10 MB for to_arrow(); RUNS=1 runs of each command, the median's figures (single
# runs on a busy machine move by a third); ARROW_RUNS=5 runs of each to_arrow() call (a
# second each), their median; the inputs and datasets go under $TMPDIR, default
# /tmp: a large capture of many kinds writes thousands of part files, so the file system's
# speed at creating files shows. Needs python3 with venv, and the network for PyPI the first
# time)
#
# The files are device→host streams of 27 common message forms with random field values
# (dissector/examples/gen_d2h.rs, one seed per file): what a controller's status logs look
# like, with a realistic number of message kinds per file (Parquet keeps one buffer per kind).
set -euo pipefail
cd "$(dirname "$0")/.."
FILES=${FILES:-50}
MB=${MB:-4.2}
BIG=${BIG:-100}
ARROW_MB=${ARROW_MB:-10}
RUNS=${RUNS:-1}
ARROW_RUNS=${ARROW_RUNS:-5}
cargo build -q --release --bin aptscope
cargo build -q --release -p aptscope-dissector --example gen_d2h --example gen_stream
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mkdir "$tmp/in"
for i in $(seq 1 "$FILES"); do
  target/release/examples/gen_d2h "$MB" "$i" > "$tmp/in/$(printf 'cap%03d' "$i").bin" 2>/dev/null
done
total=$(du -cb "$tmp"/in/*.bin | tail -n1 | cut -f1)
printf 'input: %d files, %.1f MB; %s, %d cores\n' "$FILES" "$(echo "$total / 1000000" | bc -l)" \
  "$(lscpu | sed -n 's/^Model name: *//p' | head -n1)" "$(nproc)"
declare -A rate cpus big_json big_pq big_pqnd
# The median of lines read (RUNS of them), by their first number.
median() { sort -n | sed -n "$(( (RUNS + 1) / 2 ))p"; }
run() { # label, jobs, command...   (MB/s of $total bytes)
  local label=$1 jobs=$2
  shift 2
  local out wall cpu rss runs=()
  # Whole process: wall and CPU seconds (user + system), peak RSS; the run of median wall
  # time of $RUNS.
  for _ in $(seq 1 "$RUNS"); do
    out=$( { /usr/bin/time -f '%e %U %S %M' "$@" > /dev/null; } 2>&1 | tail -n1 )
    runs+=("$out")
  done
  out=$(printf '%s\n' "${runs[@]}" | median)
  read -r wall user sys rss <<< "$out"
  cpu=$(echo "$user + $sys" | bc -l)
  rate[$label.$jobs]=$(echo "$total / 1000000 / $wall" | bc -l)
  cpus[$label.$jobs]=$cpu
  printf '%-7s -j %s: %6.1f MB/s (%5.2f s wall, %5.2f CPU-s), peak RSS %6d KiB' "$label" "$jobs" \
    "${rate[$label.$jobs]}" "$wall" "$cpu" "$rss"
  if [ "$jobs" != 1 ]; then
    printf ', %.2f× -j 1 (CPU %.2f×)' "$(echo "${rate[$label.$jobs]} / ${rate[$label.1]}" | bc -l)" \
      "$(echo "$cpu / ${cpus[$label.1]}" | bc -l)"
  fi
  printf '\n'
}
echo "load: $(cut -d' ' -f1-3 /proc/loadavg)"
for j in 1 2; do
  run text "$j" target/release/aptscope decode -j "$j" "$tmp"/in/*.bin
  run ndjson "$j" target/release/aptscope decode --json -j "$j" "$tmp"/in/*.bin
  run parquet "$j" target/release/aptscope decode --to parquet --force -o "$tmp/out" -j "$j" "$tmp"/in/*.bin
done
for j in 1 2; do
  printf 'parquet/ndjson -j %s: %.2f\n' "$j" "$(echo "${rate[parquet.$j]} / ${rate[ndjson.$j]}" | bc -l)"
done
# Kept for the summary: the next section reuses the labels.
files_json=$(echo "${rate[ndjson.2]} / ${rate[ndjson.1]}" | bc -l)
files_pq=$(echo "${rate[parquet.1]} / ${rate[ndjson.1]}" | bc -l)
echo "load: $(cut -d' ' -f1-3 /proc/loadavg)"
printf 'dataset: %s in %d files\n' "$(du -sh "$tmp/out" | cut -f1)" "$(find "$tmp/out" -name '*.parquet' | wc -l)"

# One large capture: random frames of every form (dissector/examples/gen_stream.rs), raw and
# converted to pcapng (timestamps and directions per packet).
target/release/examples/gen_stream "$BIG" > "$tmp/big.bin"
target/release/aptscope convert "$tmp/big.bin" "$tmp/big.pcapng"
rm -rf "$tmp/in" "$tmp/out"
for kind in bin pcapng; do
  total=$(stat -c %s "$tmp/big.$kind")
  printf 'one %s capture: %.1f MB\n' "$kind" "$(echo "$total / 1000000" | bc -l)"
  echo "load: $(cut -d' ' -f1-3 /proc/loadavg)"
  for j in 1 2; do
    run "text" "$j" target/release/aptscope decode -j "$j" "$tmp/big.$kind"
    run "ndjson" "$j" target/release/aptscope decode --json -j "$j" "$tmp/big.$kind"
    run "parquet" "$j" target/release/aptscope decode --to parquet --force -o "$tmp/out" -j "$j" "$tmp/big.$kind"
  done
  for j in 1 2; do
    printf 'parquet/ndjson -j %s: %.2f\n' "$j" "$(echo "${rate[parquet.$j]} / ${rate[ndjson.$j]}" | bc -l)"
  done
  big_json[$kind]=$(echo "${rate[ndjson.2]} / ${rate[ndjson.1]}" | bc -l)
  big_pq[$kind]=$(echo "${rate[parquet.2]} / ${rate[parquet.1]}" | bc -l)
  big_pqnd[$kind]=$(echo "${rate[parquet.1]} / ${rate[ndjson.1]}" | bc -l)
done
rm -rf "$tmp/out" "$tmp"/big.*
echo "load: $(cut -d' ' -f1-3 /proc/loadavg)"

# Typed decoding: frames and every field of a status log held in memory, best of 10 runs.
cargo build -q --release -p aptscope-dissector --example decode_file
target/release/examples/gen_d2h 20 > "$tmp/d2h.bin" 2>/dev/null
typed=$(target/release/examples/decode_file "$tmp/d2h.bin" $((10 * RUNS)) \
  | sed -n 's/.*"mb_per_s":\([0-9.]*\).*/\1/p')
printf 'typed decode (20 MB status log, best of %d): %.0f MB/s\n' $((10 * RUNS)) "$typed"

# to_arrow(): the release module in a venv of its own (the tests' is a debug build).
venv=target/bench-pyvenv
[ -x "$venv/bin/python" ] || python3 -m venv "$venv"
CARGO_TARGET_DIR="$PWD/target" "$venv/bin/pip" install -q --disable-pip-version-check ./python
target/release/examples/gen_d2h "$ARROW_MB" > "$tmp/arrow.bin" 2>/dev/null
# Beside the random status log, a real session (samples/kdc101-session.bin: a KDC101's
# requests and replies) repeated to ARROW_MB: one device's traffic, whose units, channels and
# status words repeat as a device's do (the random log's fields are noise: a diagnostic in
# four rows of five, sixteen status flags a row).
python3 -c 'import sys; d = open(sys.argv[1], "rb").read(); sys.stdout.buffer.write(d * (int(float(sys.argv[2]) * 1e6) // len(d) + 1))' \
  samples/kdc101-session.bin "$ARROW_MB" > "$tmp/session.bin"
echo "load: $(cut -d' ' -f1-3 /proc/loadavg)"
# ARROW_RUNS runs of `arrow_speed.py MODE` on FILE with THREADS threads, each run's line
# printed after LABEL; their median rate (M records per second of wall time) left in $rate.
arrow_rate() {
  local file=$1 mode=$2 threads=$3 label=$4 rates=() out
  for _ in $(seq 1 "$ARROW_RUNS"); do
    out=$("$venv/bin/python" python/examples/arrow_speed.py "$file" "$mode" "$threads")
    echo "$label: $out"
    rates+=("$(sed -n 's/.*, \([0-9.]*\) M per second.*/\1/p' <<< "$out")")
  done
  rate=$(printf '%s\n' "${rates[@]}" | RUNS=$ARROW_RUNS median)
}
declare -A arrow
for input in arrow session; do
  for t in 1 "$(nproc)"; do
    arrow_rate "$tmp/$input.bin" to_arrow "$t" "to_arrow() $input threads=$t"
    arrow[$input$t]=$rate
  done
done
# The bound of those calls: the decode chain (reading, framing, decoding, pairing, numbering,
# units) with no row built, on the one thread it runs on in every call.
arrow_rate "$tmp/arrow.bin" chain 1 "to_arrow(tables=[]) arrow threads=1"
chain=$rate
echo "load: $(cut -d' ' -f1-3 /proc/loadavg)"

# Every target of #27 beside its figure from this run.
met() { if [ "$(echo "$1 >= $2" | bc -l)" = 1 ]; then echo met; else echo "NOT met"; fi; }
echo "== targets"
printf '%-50s %8s  %-6s\n' "what" "figure" "target"
row() { printf '%-50s %8.2f  %-8s %s\n' "$1" "$2" "$3" "$(met "$2" "${3#≥ }")"; }
row "decode --json -j 2 / -j 1, $FILES files" "$files_json" "≥ 1.8"
row "decode --json -j 2 / -j 1, one raw capture" "${big_json[bin]}" "≥ 1.7"
row "the same, pcapng" "${big_json[pcapng]}" "≥ 1.7"
row "decode --to parquet -j 2 / -j 1, one raw capture" "${big_pq[bin]}" "≥ 1.7"
row "the same, pcapng" "${big_pq[pcapng]}" "≥ 1.7"
row "Parquet / NDJSON throughput, -j 1, $FILES files" "$files_pq" "≥ 1"
row "the same, one raw capture of every form" "${big_pqnd[bin]}" "≥ 1"
row "to_arrow(), M records/s, threads=$(nproc), status log" "${arrow[arrow$(nproc)]}" "≥ 3"
row "the same, a real session repeated" "${arrow[session$(nproc)]}" "≥ 3"
printf '%-50s %8.2f  (no target: the decode chain alone, no row built)\n' \
  "to_arrow(tables=[]), M records/s, status log" "$chain"
row "typed decode, MB/s" "$typed" "≥ 400"
