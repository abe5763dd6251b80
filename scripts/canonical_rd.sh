#!/usr/bin/env bash
# Canonical compression side by side on every real scene (issue 5, docs/benchmarks/canonical.md): raw PLY,
# SPZ v4 and PlayCanvas SOG v2 (from scripts/peers.sh), and dlgs CSOG at high/medium/low, with
# and without bit reallocation, level shaping and importance tiers.
# Rendered PSNR/SSIM against the uncompressed scene from 8 orbit cameras (dlgs compare).
# Usage: bash scripts/canonical_rd.sh [PEERS_DIR]  (run scripts/peers.sh PEERS_DIR first)
set -euo pipefail
cd "$(dirname "$0")/.."
PEERS=${1:-target/peers}
DATA=${DLGS_DATA:-../shared/data}
OUT=target/canonical_rd
mkdir -p "$OUT"
# `--example` alone would build only the example, not the `dlgs` binary.
cargo build --release -q -p dlgs-cli
cargo build --release -q -p dlgs-decoder --example decode_timing
DLGS=target/release/dlgs
export RUST_BACKTRACE=0
metric() { $DLGS compare "$1" "$2" --json | python3 -c 'import json,sys; d=json.load(sys.stdin); print("%.2f | %.4f" % (d["mean_psnr"], d["mean_ssim"]))'; }
echo "| scene | N | format | bytes | bits/G | % of SOG | PSNR dB | SSIM | encode s | decode ms |"
echo "|---|---|---|---|---|---|---|---|---|---|"
source scripts/real_scenes.sh
for s in "${SCENES[@]}"; do
  src="$(scene_path "$s")"; name=$(basename "${s%.*}")
  n=$(scene_count "$src")
  sog=$(awk -F'\t' -v n="$name" '$1==n && $2=="sog" {print $3}' "$PEERS/times.tsv")
  row() { # format bytes psnr|ssim enc dec
    printf '| %s | %s | %s | %s | %.1f | %.0f %% | %s | %s | %s |\n' "$name" "$n" "$1" "$2" \
      "$(echo "$2 * 8 / $n" | bc -l)" "$(echo "100 * $2 / $sog" | bc -l)" "$3" "$4" "$5"
  }
  row "source file" "$(stat -c %s "$src")" "inf | 1.0000" "-" "-"
  for fmt in spz sog; do
    enc=$(awk -F'\t' -v n="$name" -v f="$fmt" '$1==n && $2==f {print $4}' "$PEERS/times.tsv")
    row "$fmt" "$(stat -c %s "$PEERS/$name.$fmt")" "$(metric "$src" "$PEERS/$name.$fmt.ply")" "$enc" "-"
  done
  # Presets as they are; +realloc: up to 4 bits moved between attribute groups by rendering
  # (--reallocate-bits: its own 5 views, not these 8); +shape: levels chosen by estimated bits
  # plus importance-weighted error (--shape 0.1: importance over 36 views of its own).
  # +tiers: the least important Gaussians holding 4 % of the blending weight one bit coarser
  # (--tiers 0.04: importance over the same 36 views). SETTINGS="a b .." runs only those.
  for setting in ${SETTINGS:-high medium low high+realloc medium+realloc high+shape medium+shape \
      low+shape high+realloc+shape medium+realloc+shape low+realloc+shape high+tiers medium+tiers \
      low+tiers high+realloc+tiers medium+realloc+tiers low+realloc+tiers}; do
    q=${setting%%+*}; extra=()
    [[ "$setting" == *realloc* ]] && extra+=(--reallocate-bits 4)
    [[ "$setting" == *shape* ]] && extra+=(--shape 0.1)
    [[ "$setting" == *tiers* ]] && extra+=(--tiers 0.04)
    f="$OUT/$name-$setting.dlgs"
    start=$(date +%s.%N); $DLGS encode "$src" -o "$f" --quality "$q" "${extra[@]}" > /dev/null; end=$(date +%s.%N)
    dec=$(target/release/examples/decode_timing "$f" 5 | grep -o 'median [0-9.]*' | cut -d' ' -f2)
    row "dlgs $setting" "$(stat -c %s "$f")" "$(metric "$src" "$f")" "$(printf '%.2f' "$(echo "$end - $start" | bc)")" "$dec"
  done
done
