#!/usr/bin/env bash
# Does this checkout decode exactly as another revision does? `decode` (text) and
# `decode --json` of every sample (every capture format) and of generated streams (random
# frames of every form with garbage between them; a device→host status stream; Elliptec),
# by a release build of each, compared byte for byte, with -j 1 and with -j 2.
# Usage: bench/same-output.sh REV   (e.g. the commit a refactoring started from)
# Exit 0 when every output is identical; else the first differing lines of each difference.
set -euo pipefail
cd "$(dirname "$0")/.."
rev=${1:?usage: bench/same-output.sh REV}
base=$(git rev-parse --short "$rev")
tmp=$(mktemp -d)
trap 'git worktree remove --force "$tmp/base" >/dev/null 2>&1 || true; rm -rf "$tmp"' EXIT
git worktree add -q --detach "$tmp/base" "$base"
# The base builds in a target directory of its own, kept between runs (a rebuild is quick).
base_target="target/same-output-$base"
(cd "$tmp/base" && cargo build -q --release --bin aptscope --target-dir "$OLDPWD/$base_target")
cargo build -q --release --bin aptscope
cargo build -q --release -p aptscope-dissector --example gen_stream --example gen_d2h
old="$base_target/release/aptscope"
new=target/release/aptscope

mkdir "$tmp/in"
target/release/examples/gen_stream 3 7 > "$tmp/in/every-form.bin"
target/release/examples/gen_d2h 3 11 > "$tmp/in/d2h.bin" 2>/dev/null
# Garbage between frames and a cut last frame: every 997th byte replaced, 5 bytes cut off.
python3 - "$tmp/in/every-form.bin" "$tmp/in/garbled.bin" <<'EOF'
import sys
b = bytearray(open(sys.argv[1], 'rb').read()[:1_000_000])
for i in range(0, len(b), 997):
    b[i] = (b[i] * 31 + 7) & 0xFF
open(sys.argv[2], 'wb').write(bytes(b[:-5]))
EOF

inputs=()
while IFS= read -r f; do inputs+=("$f"); done < <(find samples -type f ! -name '*.sh' ! -name '*.py' ! -name '*.md' | sort)
inputs+=("$tmp/in/every-form.bin" "$tmp/in/d2h.bin" "$tmp/in/garbled.bin")

same=0
differ=0
for f in "${inputs[@]}"; do
  for args in "" "--json" "-j 2" "--json -j 2"; do
    # shellcheck disable=SC2086
    "$old" decode $args "$f" > "$tmp/old" 2> "$tmp/old.err" && oc=0 || oc=$?
    # shellcheck disable=SC2086
    "$new" decode $args "$f" > "$tmp/new" 2> "$tmp/new.err" && nc=0 || nc=$?
    if cmp -s "$tmp/old" "$tmp/new" && cmp -s "$tmp/old.err" "$tmp/new.err" && [ "$oc" = "$nc" ]; then
      same=$((same + 1))
    else
      differ=$((differ + 1))
      echo "DIFFERS: decode $args $f (exit $oc → $nc)"
      diff <(cat "$tmp/old" "$tmp/old.err") <(cat "$tmp/new" "$tmp/new.err") | head -n 6 || true
    fi
  done
done
echo "$same outputs identical to $base, $differ different (${#inputs[@]} inputs × text/NDJSON × -j 1/2)"
[ "$differ" = 0 ]
