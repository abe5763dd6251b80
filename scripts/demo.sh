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
$B encode "$SCENE" -o "$OUT/scene.dlgs" --quality lossless
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
echo
echo "== canonical compression (CSOG: sorted quantised grids), three presets"
for q in high medium low; do
  $B encode "$SCENE" -o "$OUT/scene-$q.dlgs" --quality $q > /dev/null
  b=$(stat -c %s "$OUT/scene-$q.dlgs")
  psnr=$($B compare "$SCENE" "$OUT/scene-$q.dlgs" --orbit 8 --width 676 --height 507 --json | python3 -c 'import json,sys; print("%.2f" % json.load(sys.stdin)["mean_psnr"])')
  echo "RD $q: $b bytes, $(python3 -c "print(f'{$b*8/$n:.1f}')") bits/Gaussian, mean PSNR $psnr dB"
done
echo
echo "== dynamic: SYNTHETIC motion on the real plant scene (no trained DLGStream model exists here)"
PLANT="$DATA/splat/marcelpadilla_plant.splat"
$B synth "$PLANT" -o "$OUT/dynamic_exact.dlgs" --exact-features --language
echo "== encode: time features as 12-bit HEVC (libx265, crf 6)"
$B encode "$OUT/dynamic_exact.dlgs" -o "$OUT/dynamic.dlgs"
$B info "$OUT/dynamic.dlgs"
echo "== render at t = 1.2345 s (between frames 37 and 38) and decode that instant to PLY"
$B render "$OUT/dynamic.dlgs" --t 1.2345 --orbit 2 --width 676 --height 507 --features -o "$OUT/dynamic_t1.2345.png"
$B decode "$OUT/dynamic.dlgs" --t 1.2345 -o "$OUT/dynamic_t1.2345.ply"
echo "== RD: crf 6 vs exact features, same cameras, at a frame time and between frames"
for t in 0.5 1.2345; do
  echo "t = $t s"
  $B compare "$OUT/dynamic_exact.dlgs" "$OUT/dynamic.dlgs" --t $t --orbit 4 --width 676 --height 507
done
fb=$($B info "$OUT/dynamic.dlgs" --json | python3 -c 'import json,sys; d=json.load(sys.stdin); print(round(d["bytes_per_frame"]), d["chunk_bytes_by_type"]["TFEA"] // d["header"]["frame_count"])')
echo "RD summary (dynamic): bytes/frame total and of the time-feature stream: $fb"
echo "== residuals: 5 GOPs of 60 frames on the real lod2 tile, GOPs 1-4 carry GENERATED binary voxel residual fields (RNTC), parallel mode"
LOD2="$DATA/ply/gs3d-fork_lod2_tile_0_6831_sh3.ply"
$B synth "$LOD2" -o "$OUT/residual_exact.dlgs" --gops 5 --residual-mode parallel --exact-features
$B encode "$OUT/residual_exact.dlgs" -o "$OUT/residual.dlgs"
$B info "$OUT/residual.dlgs" | tail -6
echo "== PSNR at GOP boundaries (decoded vs model) and the jump across each boundary"
$B boundaries "$OUT/residual_exact.dlgs" "$OUT/residual.dlgs" --orbit 4 --width 676 --height 507
echo "== seek latency"
$B seek "$OUT/residual.dlgs" --count 10
echo "== open-vocabulary query on the real fruit-drops scene with its REAL per-Gaussian labels"
echo "   (SYNTHETIC language: one code per category and a constructed decoder; no CLIP model here)"
FRUIT="$DATA/ply/supersplat_fruit_drops_minimal_4721_sh3.ply"
$B labels "$FRUIT" --annotations "$DATA/ply/supersplat_fruit_drops_minimal.annotations.json" -o "$OUT/labels" | tail -3
$B encode "$OUT/labels/scene.ply" -o "$OUT/labels.dlgs" --quality lossless --lang-decoder "$OUT/labels/lang_decoder.safetensors" --negatives "$OUT/labels/negatives.npy"
$B query "$OUT/labels.dlgs" --text-embedding "$OUT/labels/category_4.npy" --view 0 -o "$OUT/query/category_4" --timing
$B export "$OUT/labels.dlgs" --select "$OUT/labels/category_4.npy" -o "$OUT/query/category_4.ply"
echo "== players: stream the 5-GOP residual file in real time, export frames as SPZ for other viewers"
$B play "$OUT/residual.dlgs"
cat "$OUT/residual.dlgs" | $B play - --max-speed
$B export "$OUT/residual.dlgs" --frames 118..122 --format spz -o "$OUT/frames_spz"
echo "== RD sweep of the time features (crf) x canonical quality on the dynamic model"
$B rd "$OUT/dynamic_exact.dlgs" --crf 6,18 --quality lossless,high --times 2 --orbit 2 --width 676 --height 507 -o "$OUT/rd"
echo "== ingest: a model in the reference implementation's exact output layout (fixture: SYNTHETIC content on a real scene)"
$B encode tests/fixtures/reference_run -o "$OUT/reference_run.dlgs"
$B encode tests/fixtures/reference_run -o "$OUT/reference_run_nl.dlgs" --quality near-lossless | tail -1
$B compare "$OUT/reference_run.dlgs" "$OUT/reference_run_nl.dlgs" --t 2.5 --orbit 4 --width 480 --height 360 | tail -1
echo "outputs in $OUT/"
