#!/usr/bin/env bash
# Runs the fuzz targets built by `make fuzz` (fuzz/CMakeLists.txt, in build/fuzz).
#
#   fuzz/run.sh [TARGET|all] [SECONDS]          long run (default: all targets, 600 s each): the
#       corpus grows in build/fuzz/corpus/TARGET and is kept between runs; findings (crash-*,
#       leak-*, timeout-*, oom-*) land in build/fuzz/artifacts/TARGET; prints the inputs run.
#   fuzz/run.sh --smoke TARGET SECONDS          the bounded run of `make test`: a fresh corpus,
#       the seeds, SECONDS of fuzzing; fails on any finding (kept in build/fuzz/artifacts).
#
# Targets: mesh_io, store, requests, design. Reproduce a finding with
#   build/fuzz/bin/TARGET_fuzzer build/fuzz/artifacts/TARGET/crash-...
# Environment: FUZZ_BUILD_DIR (default build/fuzz), FUZZ_FLAGS (extra libFuzzer flags).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
build="${FUZZ_BUILD_DIR:-$root/build/fuzz}"
smoke=0
if [ "${1:-}" = "--smoke" ]; then smoke=1; shift; fi
target="${1:-all}"
seconds="${2:-600}"
targets=(mesh_io store requests design)
if [ "$target" = "all" ]; then
  [ "$smoke" -eq 0 ] || { echo "run.sh: --smoke takes one target" >&2; exit 2; }
  for t in "${targets[@]}"; do "$0" "$t" "$seconds"; done
  exit 0
fi
binary="$build/bin/${target}_fuzzer"
seeds="$build/seeds/$target"
if [ ! -x "$binary" ] || [ ! -d "$seeds" ]; then
  echo "run.sh: $binary or $seeds missing: run 'make fuzz' first (targets: ${targets[*]})" >&2
  exit 2
fi
artifacts="$build/artifacts/$target"
if [ "$smoke" -eq 1 ]; then
  corpus="$(mktemp -d)"
  trap 'rm -rf "$corpus"' EXIT
else
  corpus="$build/corpus/$target"
fi
mkdir -p "$corpus" "$artifacts"
log="$(mktemp)"
set +e
# -timeout: an input running longer is a finding (hang); -rss_limit_mb: so is a 2 GB process.
# shellcheck disable=SC2086
"$binary" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 \
  -artifact_prefix="$artifacts/" ${FUZZ_FLAGS:-} "$corpus" "$seeds" 2>"$log"
status=$?
set -e
runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log")
rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log")
if [ "$status" -ne 0 ]; then
  tail -n 60 "$log" >&2
  echo "run.sh: $target: FINDING (exit $status) after ${runs:-?} inputs; see $artifacts" >&2
  rm -f "$log"
  exit 1
fi
corpus_size=$(find "$corpus" -maxdepth 1 -type f | wc -l)
echo "run.sh: $target: ${runs:-?} inputs in ${seconds} s (${rate:-?} exec/s), 0 findings," \
  "corpus $corpus_size files"
rm -f "$log"
