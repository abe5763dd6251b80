#!/usr/bin/env bash
# Convert every real scene of ../shared/data with the peer formats, for the canonical compression
# comparison (docs/benchmarks/canonical.md): PlayCanvas SOG v2 and SPZ v4, both with
# `@playcanvas/splat-transform` 2.7.1 (npm), CPU only, then back to PLY so our renderer can
# measure them. Output: $OUT/<scene>.{sog,spz}, $OUT/<scene>.{sog,spz}.ply, $OUT/times.tsv.
# Usage: bash scripts/peers.sh [OUT]   (default target/peers; needs node/npx)
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-target/peers}
DATA=${DLGS_DATA:-../shared/data}
mkdir -p "$OUT"
ST=(npx -y @playcanvas/splat-transform@2.7.1)
source scripts/real_scenes.sh
printf 'scene\tformat\tbytes\tencode_s\n' > "$OUT/times.tsv"
for s in "${SCENES[@]}"; do
  name=$(basename "${s%.*}")
  for fmt in spz sog; do
    out="$OUT/$name.$fmt"
    start=$(date +%s.%N)
    # SOG's SH palette k-means runs on the CPU here (no GPU): slow for SH 3 scenes.
    extra=()
    [ "$fmt" = sog ] && extra=(-g cpu)
    "${ST[@]}" -q -w "${extra[@]}" "$(scene_path "$s")" "$out"
    end=$(date +%s.%N)
    printf '%s\t%s\t%s\t%.1f\n' "$name" "$fmt" "$(stat -c %s "$out")" "$(echo "$end - $start" | bc)" >> "$OUT/times.tsv"
    "${ST[@]}" -q -w "$out" "$out.ply"
  done
done
cat "$OUT/times.tsv"
