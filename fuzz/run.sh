#!/usr/bin/env bash
# Runs every fuzz target (or the ones named) for SECONDS each (default 60) with cargo-fuzz /
# libFuzzer, starting from the seeds in fuzz/corpus/<target>/ plus what earlier runs found
# (fuzz/work/<target>/, git-ignored). Fails if any target crashes, panics, times out or runs out
# of memory; the input that did it is in fuzz/artifacts/<target>/ and the log in
# fuzz/work/<target>.log.
#
#   fuzz/run.sh [SECONDS] [TARGET...]
#
# Needs cargo-fuzz (`cargo install cargo-fuzz`). On a stable toolchain, RUSTC_BOOTSTRAP=1 lets
# cargo-fuzz pass the nightly-only flags it needs (-Zsanitizer=address, sanitizer coverage).
set -uo pipefail
cd "$(dirname "$0")"
secs=${1:-60}
shift || true
export RUSTC_BOOTSTRAP=${RUSTC_BOOTSTRAP:-1}
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
  mapfile -t targets < <(cargo fuzz list)
fi
if ! cargo fuzz build; then
  echo "fuzz/run.sh: cargo fuzz build failed" >&2
  exit 2
fi
bin=target/x86_64-unknown-linux-gnu/release
failed=()
rows=()
for t in "${targets[@]}"; do
  mkdir -p "work/$t" "artifacts/$t"
  case "$t" in
    apt_framer | ell_framer | filter_parse | encode_roundtrip | ell_encode) max_len=16384 ;;
    units) max_len=1024 ;;
    *) max_len=65536 ;;
  esac
  start=$(date +%s)
  # The binaries built above, run directly (`cargo fuzz run` would rebuild whenever the crates
  # change under it). New inputs go to work/<target> (the first corpus folder); the seeds are
  # read only.
  if ASAN_OPTIONS=${ASAN_OPTIONS:-detect_odr_violation=0} "$bin/$t" "work/$t" "corpus/$t" \
    -artifact_prefix="artifacts/$t/" -max_total_time="$secs" -timeout=20 -rss_limit_mb=2048 \
    -max_len="$max_len" -print_final_stats=1 >"work/$t.log" 2>&1; then
    status=ok
  else
    status=FAILED
    failed+=("$t")
  fi
  took=$(($(date +%s) - start))
  # A crashed run prints no final stats: take the last progress line's count then.
  runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "work/$t.log" | grep -o '[0-9]*$')
  [ -n "$runs" ] || runs=$(grep -oE '^#[0-9]+' "work/$t.log" | tail -1 | tr -d '#')
  cov=$(grep -o 'cov: [0-9]*' "work/$t.log" | tail -1 | grep -o '[0-9]*$')
  printf '%-18s %-6s %5ss  %s runs  cov %s\n' "$t" "$status" "$took" "${runs:-?}" "${cov:-?}"
  if [ "$status" = FAILED ]; then
    grep -E 'panicked at|ERROR: libFuzzer|SUMMARY|Test unit written' "work/$t.log" | head -5 | sed 's/^/    /'
  fi
  rows+=("$(printf '| `%s` | %s | %s | %s | %s |' "$t" "$status" "$took" "${runs:-?}" "${cov:-?}")")
done
# The summary as a Markdown table (for the README's record of runs).
echo
echo "| target | status | seconds | executions | coverage |"
echo "|---|---|---:|---:|---:|"
printf '%s\n' "${rows[@]}"
echo
if [ ${#failed[@]} -gt 0 ]; then
  echo "fuzz/run.sh: failed: ${failed[*]} (logs in fuzz/work/, inputs in fuzz/artifacts/)" >&2
  exit 1
fi
echo "fuzz/run.sh: ${#targets[@]} target(s), ${secs}s each, no crash"
