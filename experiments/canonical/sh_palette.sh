#!/usr/bin/env bash
# SOG-style palette for SH bands 1-3 against dlgs's scalar bands on the real SH 3 scenes whose
# bands are not all zero (fruit, gsplat; issue 5, docs/benchmarks/canonical-levers.md "SH bands"). Per scene: dlgs at
# `high` and down a ladder of fewer band bits (real files), then the `high` file with its bands
# replaced by a K-entry k-means palette (bytes estimated in the palette's favour, see
# experiments/canonical/sh_palette.py). Usage: bash experiments/canonical/sh_palette.sh   (~16 min; installs numpy and scipy in a venv)
set -euo pipefail
cd "$(dirname "$0")/../.."
DATA=${DLGS_DATA:-../shared/data}
VENV=${DLGS_VENV:-target/pyvenv}
[ -x "$VENV/bin/python" ] || python3 -m venv "$VENV"
"$VENV/bin/python" -c 'import numpy, scipy' 2>/dev/null || "$VENV/bin/pip" install -q numpy scipy
cargo build --release -q -p dlgs-cli
DLGS=target/release/dlgs
OUT=target/sh_palette
mkdir -p "$OUT"
psnr() { $DLGS compare "$1" "$2" --json | python3 -c 'import json,sys; print("%.2f" % json.load(sys.stdin)["mean_psnr"])'; }
for s in supersplat_fruit_drops_minimal_4721_sh3 gsplat_DATA_new_22589_sh3; do
  src="$DATA/ply/$s.ply"
  echo "## $s"
  for opts in "--quality high" "--quality high --shape 0.1" "--quality high --bits sh_rest=5,sh_high=4" \
      "--quality high --bits sh_rest=4,sh_high=3" "--quality high --bits sh_rest=3,sh_high=2" \
      "--quality medium" "--quality low"; do
    # shellcheck disable=SC2086
    $DLGS encode "$src" -o "$OUT/$s.dlgs" $opts > /dev/null
    echo "dlgs $opts: $(stat -c %s "$OUT/$s.dlgs") B; PSNR $(psnr "$src" "$OUT/$s.dlgs") dB"
  done
  $DLGS encode "$src" -o "$OUT/$s-high.dlgs" --quality high > /dev/null
  $DLGS decode "$OUT/$s-high.dlgs" -o "$OUT/$s-high.ply" > /dev/null
  "$VENV/bin/python" experiments/canonical/sh_palette.py strip "$src" "$OUT/$s-sh0.ply"
  $DLGS encode "$OUT/$s-sh0.ply" -o "$OUT/$s-sh0.dlgs" --quality high > /dev/null
  "$VENV/bin/python" experiments/canonical/sh_palette.py "$DLGS" "$src" "$OUT/$s-high.ply" \
    "$(stat -c %s "$OUT/$s-sh0.dlgs")" "$OUT/$s-palette" 64,256,1024
  echo
done
