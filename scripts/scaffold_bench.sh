#!/usr/bin/env bash
# Scaffold-GS (issue 51): encode the fitted HAC fixture run, then time frame decode and render
# at 1352x1014 with anchor culling on and off, from the fixture's 3 cameras (the whole scene in
# view) and from 8 orbit cameras close to the scene (--distance 0.4: part of it outside).
# Prints one line per view: "decoded N Gaussians in X ms, ..., rendered in Y ms".
# Usage: scripts/scaffold_bench.sh [OUT_DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-target/scaffold_bench}
mkdir -p "$OUT"
cargo build --release -q -p dlgs-cli
B=target/release/dlgs
RUN=tests/fixtures/scaffold_run
/usr/bin/time -f "encode: %e s" $B encode "$RUN" -o "$OUT/hac.dlgs"
for cull in "" "--no-cull"; do
  echo "== fixture cameras ${cull:-(culling on)}"
  $B render "$OUT/hac.dlgs" --cameras "$RUN/reference_decode/cameras.json" --width 1352 \
    --height 1014 --t 2.5 -o "$OUT/fixture.png" $cull
  echo "== 8 close orbit cameras ${cull:-(culling on)}"
  $B render "$OUT/hac.dlgs" --orbit 8 --distance 0.4 --width 1352 --height 1014 --t 2.5 \
    -o "$OUT/close.png" $cull
done
