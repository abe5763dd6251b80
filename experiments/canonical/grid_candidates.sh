#!/usr/bin/env bash
# Lossless image coders (PNG, WebP, JPEG XL via PyPI imagecodecs) beside dlgs's own grid codecs,
# on the quantised grids of every real scene (issue 5, docs/benchmarks/canonical-levers.md "Grid coder candidates").
# Usage: bash experiments/canonical/grid_candidates.sh [QUALITY]   (~10 min; installs imagecodecs in a venv)
set -euo pipefail
cd "$(dirname "$0")/../.."
DATA=${DLGS_DATA:-../shared/data}
QUALITY=${1:-high}
VENV=${DLGS_VENV:-target/pyvenv}
[ -x "$VENV/bin/python" ] || python3 -m venv "$VENV"
"$VENV/bin/python" -c 'import imagecodecs, numpy' 2>/dev/null || "$VENV/bin/pip" install -q numpy imagecodecs
cargo build --release -q -p dlgs-encoder --example grid_candidates
source scripts/real_scenes.sh
for s in "${SCENES[@]}"; do
  out="target/grid_candidates/$(basename "${s%.*}")-$QUALITY"
  target/release/examples/grid_candidates "$DATA/$s" "$out" "$QUALITY" > /dev/null
  "$VENV/bin/python" experiments/canonical/grid_candidates.py "$out"
  echo
done
