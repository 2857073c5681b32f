#!/bin/sh
# Makes every picture in docs/images/ with the project's own commands and render's defaults
# (automatic view, no camera or colour tuned by hand), against a running fieldspaced:
#
#   docs/images/make_pictures.sh [HOST:PORT]     # default $FIELDSPACE_SERVER or 127.0.0.1:50051
#
# The meshes come from $MESHES (default ../shared/meshes next to the checkout); `fieldspace` is
# found on PATH or given as $FIELDSPACE (e.g. build/bin/fieldspace). About a minute on 2 cores.
set -eu
HERE=$(cd "$(dirname "$0")" && pwd)
MESHES=${MESHES:-$HERE/../../../shared/meshes}
SERVER=${1:-${FIELDSPACE_SERVER:-127.0.0.1:50051}}
FS="${FIELDSPACE:-fieldspace} --server $SERVER"
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
id() { python3 -c 'import json, sys; print(json.load(sys.stdin)["id"])'; }

# fertility_28k (genus 4) hatched along its curvature-aligned line field (paper Fig. 17),
# singular vertices as spheres: README.md and docs/exports.md.
MESH=$($FS upload "$MESHES/fertility_28k.obj" | id)
LINES=$($FS build "$MESH" --field nfield --n 2 --dim 400 | id)
$FS align "$LINES" --curvature --n 2 --out "$WORK/lines.txt" > "$WORK/aligned.json"
$FS singularities "$LINES" "$WORK/aligned.json" > "$WORK/lines_sing.json"
$FS render "$MESH" "$WORK/lines.txt" --out "$HERE/fertility_hatching.png" --style hatching \
  --singularities "$WORK/lines_sing.json"

# The smoothest cross field (4-field) of the Stanford bunny: glyphs, then its line integral
# convolution, singular vertices as spheres: docs/exports.md.
MESH=$($FS upload "$MESHES/bunny_70k.obj" | id)
CROSS=$($FS build "$MESH" --field nfield --n 4 --dim 300 | id)
$FS smoothest "$CROSS" --out "$WORK/cross.txt" > "$WORK/smoothest.json"
$FS singularities "$CROSS" "$WORK/smoothest.json" > "$WORK/cross_sing.json"
$FS render "$MESH" "$WORK/cross.txt" --out "$HERE/bunny_cross_glyphs.png" \
  --singularities "$WORK/cross_sing.json"
$FS render "$MESH" "$WORK/cross.txt" --out "$HERE/bunny_cross_lic.png" --style lic \
  --singularities "$WORK/cross_sing.json"
echo "wrote $HERE/fertility_hatching.png bunny_cross_glyphs.png bunny_cross_lic.png"
