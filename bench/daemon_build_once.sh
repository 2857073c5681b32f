#!/bin/bash
# One basis build in a fresh daemon, as a user runs it (bench/RESULTS.md, Session 27):
# starts build/bin/fieldspaced (2 threads, a fresh store), uploads MESH with the CLI, builds with
# the given flags, prints the daemon's VmHWM and exits. Its whole process is what
# `farm-bench ... -- bench/daemon_build_once.sh BUILD_DIR PORT MESH ...` times, and its peak is the
# daemon's.
# Usage: bench/daemon_build_once.sh BUILD_DIR PORT MESH [fieldspace build flags...]
#        (default flags: --field vector --dim 2000)
set -euo pipefail
B=$1
PORT=$2
MESH=$3
shift 3
FLAGS=("$@")
if [ ${#FLAGS[@]} -eq 0 ]; then FLAGS=(--field vector --dim 2000); fi
STORE=$(mktemp -d)
"$B/bin/fieldspaced" --listen "127.0.0.1:$PORT" --store "$STORE" --threads 2 \
  --memory-budget-mb 16000 >"$STORE.log" 2>&1 &
PID=$!
trap 'kill $PID 2>/dev/null || true; wait $PID 2>/dev/null || true; rm -rf "$STORE" "$STORE.log"' EXIT
CLI=("$B/bin/fieldspace" --server "127.0.0.1:$PORT" --timeout 3600)
for _ in $(seq 50); do "${CLI[@]}" health >/dev/null 2>&1 && break; sleep 0.1; done
ID=$("${CLI[@]}" upload "$MESH" | /usr/bin/python3 -c 'import json,sys; print(json.load(sys.stdin)["id"])')
"${CLI[@]}" build "$ID" "${FLAGS[@]}" 2>/dev/null |
  /usr/bin/python3 -c 'import json,sys; d=json.load(sys.stdin); print("build_seconds", d.get("build_seconds"))'
echo "daemon $(grep VmHWM /proc/$PID/status)"
