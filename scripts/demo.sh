#!/usr/bin/env bash
# The main job, end to end on a real scene: encode -> inspect -> decode -> render -> RD numbers.
# Usage: bash scripts/demo.sh [SCENE] (default: the 45,624-Gaussian Mip-Splatting donut)
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cargo build --release -q -p dlgs-cli
DATA="${DLGS_DATA:-../shared/data}"
SCENE="${1:-$DATA/ply/v3dg_donut_mipsplatting_45624_sh0.ply}"
OUT=out/demo
mkdir -p "$OUT"
B=target/release/dlgs
echo "== encode $SCENE"
$B encode "$SCENE" -o "$OUT/scene.dlgs"
echo "== info"
$B info "$OUT/scene.dlgs"
$B verify "$OUT/scene.dlgs"
echo "== decode"
$B decode "$OUT/scene.dlgs" -o "$OUT/decoded.ply"
echo "== render (8 orbit views, 676x507)"
$B render "$OUT/scene.dlgs" --orbit 8 --width 676 --height 507 -o "$OUT/view.png"
echo "== RD: original vs decoded, same cameras"
$B compare "$SCENE" "$OUT/scene.dlgs" --orbit 8 --width 676 --height 507 --error-dir "$OUT/errors"
bytes=$(stat -c %s "$OUT/scene.dlgs")
n=$($B info "$OUT/scene.dlgs" --json | python3 -c 'import json,sys; h=json.load(sys.stdin)["header"]; print(h["n_static"]+h["n_dynamic"])')
echo "RD summary: $bytes bytes/frame, $(python3 -c "print(f'{$bytes*8/$n:.1f}')") bits/Gaussian (PSNR above; inf = lossless)"
echo "outputs in $OUT/"
