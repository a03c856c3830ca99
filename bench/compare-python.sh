#!/usr/bin/env bash
# aptscope vs the Python package thorlabs-apt-protocol (its Unpacker), on the same stream of
# device→host messages that both decode: typed decoding of every field, timed in one run.
# Usage: bench/compare-python.sh   (env: MB=20 stream size, PY_SECONDS=6 per Python run,
#                                   PY_RUNS=3, RS_RUNS=10; each side reports its best run)
#
# The stream (dissector/examples/gen_d2h.rs): 25 common device→host messages (27 forms) that the
# Unpacker parses with the same byte layout as aptscope, random field values, to the host from
# the addresses the Unpacker accepts. aptscope (dissector/examples/decode_file.rs) frames it, decodes
# every frame and reads every field; Python times Unpacker.feed() + iterating every message (the
# Unpacker decodes every field into a namedtuple). Both read the file into memory first.
# Python decodes a prefix of the same stream (~PY_SECONDS per run) when all of it would take
# longer; each side's throughput is on the bytes it decoded.
# The Unpacker builds a new namedtuple class for every message, which is most of its time; a
# second Python run caches that class per message kind, to show the ratio without it.
set -euo pipefail
cd "$(dirname "$0")/.."
MB=${MB:-20}
PY_SECONDS=${PY_SECONDS:-6}
PY_RUNS=${PY_RUNS:-3}
RS_RUNS=${RS_RUNS:-10}

venv=target/bench-venv
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
fi
"$venv/bin/pip" install -q --disable-pip-version-check thorlabs-apt-protocol
py="$venv/bin/python"

cargo build -q --release -p aptscope-dissector --example gen_d2h --example decode_file
bin=target/release/examples

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
"$bin/gen_d2h" "$MB" 2>&1 > "$tmp/stream.bin"
# The first ~100 kB of the same stream (same seed), cut at a frame boundary.
"$bin/gen_d2h" 0.1 > "$tmp/sample.bin" 2>/dev/null

echo "== do both decoders agree? (sample: the start of the stream)"
"$bin/decode_file" "$tmp/sample.bin" --dump > "$tmp/sample.ndjson"
"$py" bench/compare_python.py check "$tmp/sample.bin" "$tmp/sample.ndjson"

echo "== timing"
"$bin/decode_file" "$tmp/stream.bin" "$RS_RUNS" > "$tmp/rs.json"
"$py" bench/compare_python.py time "$tmp/stream.bin" "$PY_SECONDS" "$PY_RUNS" > "$tmp/py.json"
"$py" bench/compare_python.py time "$tmp/stream.bin" "$PY_SECONDS" "$PY_RUNS" --cached-namedtuple \
  > "$tmp/py-cached.json"

cpu=$(lscpu | sed -n 's/^Model name: *//p' | head -n1)
ver=$("$py" -c 'import thorlabs_apt_protocol as t; print(t.__version__)')
pyver=$("$py" -c 'import platform; print(platform.python_version())')
"$py" - "$tmp/rs.json" "$tmp/py.json" "$tmp/py-cached.json" "$cpu" "$(nproc)" "$ver" "$pyver" \
  "$RS_RUNS" <<'EOF'
import json, sys
rs, py, pyc = (json.load(open(p)) for p in sys.argv[1:4])
cpu, cores, ver, pyver, rs_runs = sys.argv[4:9]
print(f"machine: {cpu}, {cores} cores; Python {pyver}, thorlabs-apt-protocol {ver}")
w = 48
print(f"{'decoder':<{w}} {'bytes':>11} {'messages':>9} {'seconds':>8} {'MB/s':>9} {'messages/s':>12}")
for name, r in (("aptscope (typed decode, every field)", rs),
                ("thorlabs-apt-protocol Unpacker (Python)", py),
                ("  same, namedtuple class cached per kind", pyc)):
    print(f"{name:<{w}} {r['bytes']:>11} {r['messages']:>9} {r['seconds']:>8.3f} "
          f"{r['mb_per_s']:>9.3f} {r['msgs_per_s']:>12.0f}")
if min(py["bytes"], pyc["bytes"]) < rs["bytes"]:
    print(f"(Python decoded the first {py['bytes']} and {pyc['bytes']} bytes of the "
          f"{rs['bytes']}; each throughput is on the bytes that decoder decoded)")
print(f"(best of {rs_runs} runs for aptscope, of {py['runs']} for Python)")
for what, p in (("thorlabs-apt-protocol (Unpacker)", py),
                ("the Unpacker with its namedtuple class cached", pyc)):
    print(f"aptscope is {rs['mb_per_s'] / p['mb_per_s']:.0f}x faster than {what} "
          f"(per byte; {rs['msgs_per_s'] / p['msgs_per_s']:.0f}x per message)")
EOF
