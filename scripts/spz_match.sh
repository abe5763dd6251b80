#!/usr/bin/env bash
# Issue 5, the SPZ half of the goal read at SPZ's own quality: for every real scene, the smallest
# dlgs file (presets and a ladder of lower bit settings, with and without --shape) whose rendered PSNR against the
# uncompressed scene is at least SPZ's, and its size as a fraction of the SPZ file.
# Usage: bash scripts/spz_match.sh [PEERS_DIR]  (run scripts/peers.sh PEERS_DIR first)
set -euo pipefail
cd "$(dirname "$0")/.."
PEERS=${1:-target/peers}
DATA=${DLGS_DATA:-../shared/data}
OUT=target/spz_match
mkdir -p "$OUT"
cargo build --release -q -p dlgs-cli
DLGS=target/release/dlgs
psnr() { $DLGS compare "$1" "$2" --json | python3 -c 'import json,sys; print("%.2f" % json.load(sys.stdin)["mean_psnr"])'; }
# From finest to coarsest; each row: label, then `dlgs encode` options.
LADDER=(
  "high|--quality high"
  "medium|--quality medium"
  "low|--quality low"
  "L1|--quality low --bits position=11,log_scale=5,rotation=6,opacity=5,sh_dc=6,sh_rest=3,sh_high=2"
  "L2|--quality low --bits position=11,log_scale=5,rotation=5,opacity=5,sh_dc=5,sh_rest=2,sh_high=1"
  "L3|--quality low --bits position=10,log_scale=4,rotation=5,opacity=4,sh_dc=5,sh_rest=2,sh_high=1"
  "L4|--quality low --bits position=9,log_scale=4,rotation=4,opacity=4,sh_dc=4,sh_rest=1,sh_high=1"
)
echo "| scene | SPZ bytes | SPZ PSNR dB | smallest dlgs at >= SPZ's PSNR | bytes | PSNR dB | % of SPZ |"
echo "|---|---|---|---|---|---|---|"
source scripts/real_scenes.sh
for s in "${SCENES[@]}"; do
  src="$(scene_path "$s")"; name=$(basename "${s%.*}")
  spz_bytes=$(stat -c %s "$PEERS/$name.spz")
  spz_psnr=$(psnr "$src" "$PEERS/$name.spz.ply")
  best="none|-|-"
  # The ladder as it is, then with level shaping (--shape 0.1); each stops at its first rung
  # below SPZ's PSNR; the smallest passing file of either wins.
  for shape in "" "0.1"; do
    for rung in "${LADDER[@]}"; do
      label=${rung%%|*}; read -r -a opts <<< "${rung#*|}"
      if [ -n "$shape" ]; then label="$label+shape"; opts+=(--shape "$shape"); fi
      f="$OUT/$name-$label.dlgs"
      $DLGS encode "$src" -o "$f" "${opts[@]}" > /dev/null
      p=$(psnr "$src" "$f")
      if python3 -c "import sys; sys.exit(0 if $p >= $spz_psnr else 1)"; then
        size=$(stat -c %s "$f"); prev=$(cut -d'|' -f2 <<< "$best")
        if [ "$prev" = "-" ] || [ "$size" -lt "$prev" ]; then best="$label|$size|$p"; fi
      else
        break
      fi
    done
  done
  IFS='|' read -r label bytes p <<< "$best"
  pct="-"; [ "$bytes" != "-" ] && pct="$(python3 -c "print('%.0f %%' % (100 * $bytes / $spz_bytes))")"
  echo "| $name | $spz_bytes | $spz_psnr | $label | $bytes | $p | $pct |"
done
