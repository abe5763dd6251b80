#!/usr/bin/env bash
# Issue 5's side-by-side on a larger scene built from the real ones: the 272,920-Gaussian
# scene of the renderer and decode benchmarks (the plant capture twice plus the donut PLY, side
# by side; testkit/src/bench_scenes.rs). SPZ and SOG via splat-transform (scripts/peers.sh), then
# the canonical_rd.sh rows (raw PLY, SPZ, SOG, dlgs) on it.
# Usage: bash scripts/large_scene_rd.sh [OUT_DIR]  (default target/peers-large; ~3 min)
# MOSAIC=1: the 209,435-Gaussian mosaic of every real scene once instead (bench_scenes::mosaic,
# target/mosaic.ply; default OUT_DIR target/peers-mosaic). The 273k scene repeats the plant
# exactly, and SOG codes the repeat for 70 % of the first copy's bytes (dlgs: 91 %; docs/benchmarks/canonical-large.md);
# the mosaic has no repeats.
# SETTINGS="..." picks the dlgs rows as in canonical_rd.sh (default: the presets, with and
# without tiers; --reallocate-bits on 273k Gaussians takes minutes per row).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ -n "${MOSAIC:-}" ]; then
  OUT=${1:-target/peers-mosaic}; SCENE=$PWD/target/mosaic.ply; KIND=--mosaic
else
  OUT=${1:-target/peers-large}; SCENE=$PWD/target/big.ply; KIND=
fi
[ -f "$SCENE" ] || cargo run --release -q -p dlgs-render --example write_big_scene -- $KIND "$SCENE"
export DLGS_SCENES=$SCENE
export SETTINGS=${SETTINGS:-"high medium low high+tiers medium+tiers low+tiers"}
bash scripts/peers.sh "$OUT" >&2
bash scripts/canonical_rd.sh "$OUT"
