#!/usr/bin/env bash
# The RD plot in docs/rd/: a SYNTHETIC dynamic model (no trained DLGStream model exists here)
# built on a REAL scene (gsplat_DATA_new, 22,589 Gaussians, SH 3): 2 GOPs x 60 frames,
# sequential binary voxel residuals, language, exact time features and lossless canonical
# Gaussians (the reference). `dlgs rd` then sweeps x265 crf x canonical quality and writes
# docs/rd/rd.csv and the two PNG plots. ~3 min on 2 cores.
# Usage: bash scripts/rd_docs.sh [OUT]   (default docs/rd; DLGS_BIN overrides the binary)
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-docs/rd}
DATA=${DLGS_DATA:-../shared/data}
if [ -z "${DLGS_BIN:-}" ]; then
  cargo build --release -q -p dlgs-cli
  DLGS_BIN=target/release/dlgs
fi
mkdir -p "$OUT" target/rd
"$DLGS_BIN" synth "$DATA/ply/gsplat_DATA_new_22589_sh3.ply" -o target/rd/model.dlgs \
  --gops 2 --language --residual-mode sequential --exact-features
"$DLGS_BIN" rd target/rd/model.dlgs --crf 6,10,14,18,24 --quality lossless,high,medium,low \
  --times 4 --orbit 8 -o "$OUT" | tee "$OUT/rd.txt"
