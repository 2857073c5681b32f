#!/usr/bin/env bash
# Runs the benchmarks recorded in bench/RESULTS.md, one after the other (they use every core, so
# never run two at once), and appends "$ command" and its JSON output to LOG.
#   bench/run-benchmarks.sh [basis|approx|eigen|design|serve-load|serve-load-router|all] [LOG]
# Meshes come from $FIELDSPACE_MESH_DIR or ../shared/meshes; binaries from build/bin.
set -uo pipefail
cd "$(dirname "$0")/.."
what=${1:-all}
log=${2:-build/bench-log.txt}
M=${FIELDSPACE_MESH_DIR:-../shared/meshes}
B=build/bin/fieldspace-bench
mkdir -p "$(dirname "$log")"

run() {
  echo "\$ $*" | tee -a "$log"
  /usr/bin/time -f '# wall %e s, cpu %U s, max rss %M KB' "$@" 2>>"$log.stderr" | tee -a "$log"
  tail -n 1 "$log.stderr" >>"$log"
}

if [[ $what == basis || $what == all ]]; then
  for f in "vector" "nfield --n 4" "tensor"; do
    run $B basis $M/armadillo_loop2_1384k.ply --field $f --dim 2000 --stats
  done
  for mesh in igea_269k.obj fertility_loop3_1789k.ply; do
    run $B basis $M/$mesh --field vector --dim 2000 --stats
  done
  for d in 500 10000; do
    run $B basis $M/armadillo_loop2_1384k.ply --field vector --dim $d --stats
  done
fi

if [[ $what == approx || $what == all ]]; then
  for mesh in armadillo_86k.obj fertility_60k.obj kitten_29k.obj; do
    run $B approx $M/$mesh --field vector --dim 2000 --tests 10 --seed 1
  done
  for f in "nfield --n 4" "tensor"; do
    run $B approx $M/armadillo_86k.obj --field $f --dim 2000 --tests 10 --seed 1
  done
  # The global eigenbasis (section 7) at equal dimension. Not at d = 2000: Spectra would need a
  # 172k x 4000 Lanczos basis (5.5 GB) and hours here.
  for b in local eigen; do
    run $B approx $M/kitten_29k.obj --field vector --dim 300 --tests 10 --seed 1 --basis $b
  done
fi

if [[ $what == eigen || $what == all ]]; then
  for mesh in armadillo_86k.obj fertility_60k.obj; do
    for d in 100 2000; do
      run $B eigen $M/$mesh --field vector --count 50 --dim $d --full
    done
  done
  run $B eigen $M/armadillo_86k.obj --field vector --count 500 --dim 1000
fi

if [[ $what == design || $what == all ]]; then
  run $B design $M/armadillo_loop2_1384k.ply --field vector --dim 2000 --edits 1000 --seed 1
fi

if [[ $what == serve-load || $what == all ]]; then
  # closed loop (each session sends its next edit when the answer arrives: saturation), then
  # paced like users dragging constraints at 30 edits/s each
  run $B serve-load $M/armadillo_loop2_1384k.ply --dim 2000 --sessions 16 --edits 200
  run $B serve-load $M/armadillo_loop2_1384k.ply --dim 2000 --sessions 16 --edits 300 --rate 30
fi
if [[ $what == serve-load-router || $what == all ]]; then
  # 3 --shared-store replicas behind nginx vs the replica directly vs a plain daemon (needs nginx)
  run /usr/bin/python3 bench/serve_load_router.py --mesh $M/armadillo_86k.obj --dim 2000 \
      --sessions 16 --edits 200 --rounds 3 --single
  run /usr/bin/python3 bench/serve_load_router.py --mesh $M/armadillo_86k.obj --dim 2000 \
      --sessions 16 --edits 300 --rate 30 --rounds 2 --single
fi
