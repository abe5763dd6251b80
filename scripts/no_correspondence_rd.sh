#!/usr/bin/env bash
# Issue 65's fallback: a per-frame sequence with NO correspondence between frames (each frame an
# independent reconstruction: `dlgs synth-frames --independent 0.5`, every Gaussian moved by half a
# neighbour spacing at random per axis, its scale, opacity and colour perturbed, 5 % left out, drawn
# anew each frame; fast articulated motion of 10 spacings per frame; the donut, every 4th Gaussian,
# 60 frames = 2 GOPs), coded by the default fallback (`resample`: one set per GOP carried by the
# fitted motion), by `--fallback cut` (every frame's own Gaussians) and per frame (CSOG high and
# low, every 10th frame). PSNR (8 orbit views, every 10th frame) against the noisy source frames
# and against the noise-free frames (what the reconstructions are of); the source frames' own
# PSNR against the noise-free ones is the floor a 4D file of one moving set can reach.
# Usage: bash scripts/no_correspondence_rd.sh [OUT]  (~15 min on 2 cores)
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-target/no_correspondence}
DATA=${DLGS_DATA:-../shared/data}
SCENE=$DATA/ply/v3dg_donut_mipsplatting_45624_sh0.ply
FRAMES=${FRAMES:-60}
mkdir -p "$OUT"
cargo build --release -q -p dlgs-cli
B=$(pwd)/target/release/dlgs
export RUST_BACKTRACE=0
common=(--frames "$FRAMES" --speed 10 --every 4 --motion articulated)
$B synth-frames "$SCENE" -o "$OUT/noisy" "${common[@]}" --independent 0.5 | tee "$OUT/noisy.txt"
$B synth-frames "$SCENE" -o "$OUT/clean" "${common[@]}" > /dev/null
# mean_psnr REF TARGET [--t T]
psnr() { $B compare "$@" --json | python3 -c 'import json,sys; print(json.load(sys.stdin)["mean_psnr"])'; }
# every10 KIND TARGET: mean over every 10th frame against the noisy (KIND=noisy) or clean frames.
every10() {
  local kind=$1 target=$2 sum=0 n=0 t f p
  for ((t = 0; t < FRAMES; t += 10)); do
    f=$(printf "frame_%04d.ply" "$t")
    if [ -d "$target" ]; then p=$(psnr "$OUT/$kind/$f" "$target/$f")
    else p=$(psnr "$OUT/$kind/$f" "$target" --t "$(python3 -c "print($t/30)")"); fi
    sum=$(python3 -c "print($sum + $p)"); n=$((n + 1))
  done
  python3 -c "print(f'{$sum / $n:.2f}')"
}
echo "coding,bytes_per_frame,psnr_vs_source_db,psnr_vs_noise_free_db,encode_s_per_frame" | tee "$OUT/rd.csv"
echo "source frames themselves,,,$(every10 clean "$OUT/noisy"),"  | tee -a "$OUT/rd.csv"
for spec in "resample:" "cut:--fallback cut"; do
  name=${spec%%:*}
  start=$(date +%s.%N)
  # shellcheck disable=SC2086
  $B encode "$OUT/noisy" -o "$OUT/$name.dlgs" ${spec#*:} | grep -v '^  GOP' > "$OUT/$name.log"
  secs=$(python3 -c "print(f'{($(date +%s.%N) - $start) / $FRAMES:.2f}')")
  bytes=$(stat -c %s "$OUT/$name.dlgs")
  echo "ours $name,$((bytes / FRAMES)),$(every10 noisy "$OUT/$name.dlgs"),$(every10 clean "$OUT/$name.dlgs"),$secs" | tee -a "$OUT/rd.csv"
done
for q in high low; do
  sum=0; n=0; ps=0; pc=0
  start=$(date +%s.%N)
  for ((t = 0; t < FRAMES; t += 10)); do
    f=$(printf "frame_%04d" "$t")
    $B encode "$OUT/noisy/$f.ply" -o "$OUT/pf.dlgs" --quality "$q" > /dev/null
    sum=$((sum + $(stat -c %s "$OUT/pf.dlgs"))); n=$((n + 1))
    ps=$(python3 -c "print($ps + $(psnr "$OUT/noisy/$f.ply" "$OUT/pf.dlgs"))")
    pc=$(python3 -c "print($pc + $(psnr "$OUT/clean/$f.ply" "$OUT/pf.dlgs"))")
  done
  echo "per-frame CSOG $q,$((sum / n)),$(python3 -c "print(f'{$ps / $n:.2f}')"),$(python3 -c "print(f'{$pc / $n:.2f}')")," | tee -a "$OUT/rd.csv"
done
