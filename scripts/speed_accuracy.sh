#!/usr/bin/env bash
# What accuracy costs in decode time, one table per decode stage (issue 55), on a real scene
# made dynamic with SYNTHETIC motion and language (no trained DLGStream model exists here):
#   1. time features (TFEA): exact / HEVC lossless / crf 6 (default; and without fast start) /
#      12 / 20 / intra-only
#      crf 6: bytes per frame, the features' share of a GOP decode (median over GOPs, from
#      `dlgs play --max-speed --json`), and PSNR against the exact-feature model;
#   2. canonical state: lossless / near-lossless / high / medium, and high with --max-compression:
#      bytes, GOP 0 decode (decode_timing example, median of 7), PSNR against lossless;
#   3. frames: colour, colour + language: frame decode mean from `dlgs play --max-speed`.
# The renderer's knobs have their own table in docs/benchmarks/render.md.
#   scripts/speed_accuracy.sh [SCENE]      (about 10 minutes on the 2-core machine)
set -euo pipefail
cd "$(dirname "$0")/.."
scene=${1:-../shared/data/splat/marcelpadilla_plant.splat}
cargo build --release -q -p dlgs-cli
cargo build --release -q -p dlgs-decoder --example decode_timing
dlgs=target/release/dlgs
timing=target/release/examples/decode_timing
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
json() { python3 -c "import json,sys; d=json.load(sys.stdin); print($1)"; }
psnr() { # mean PSNR of $2 against $1 over 4 orbit views at t = 0.5 s and t = 1.2345 s
  local a b
  a=$($dlgs compare "$1" "$2" --t 0.5 --orbit 4 --width 676 --height 507 --json | json '"%.2f" % d["mean_psnr"]')
  b=$($dlgs compare "$1" "$2" --t 1.2345 --orbit 4 --width 676 --height 507 --json | json '"%.2f" % d["mean_psnr"]')
  echo "$a / $b"
}
play_field() { # median of a per-GOP list, or a scalar, from `dlgs play --max-speed --json`
  $dlgs play "$1" --max-speed --json ${3:-} | json "(lambda v: '%.1f' % (sorted(v)[len(v)//2] if isinstance(v, list) else v))(d['$2'])"
}

echo "scene: $scene ($(uptime | sed 's/.*load/load/'))"
$dlgs synth "$scene" -o "$work/exact.dlgs" --exact-features --language --gops 3 >/dev/null
frames=$($dlgs info --json "$work/exact.dlgs" | json 'd["header"]["frame_count"]')

echo
echo "## Time features (3 GOPs of 60 frames)"
echo "| setting | TFEA bytes/frame | time features per GOP (median) | key preparation per GOP (median; the keys' geometry) | PSNR t = 0.5 / 1.2345 s vs exact |"
echo "|---|---|---|---|---|"
for setting in "--exact-features" "--lossless-features" "--crf 6" "--crf 6 --fast-start off" "--crf 12" "--crf 20" "--intra-features --crf 6"; do
  # shellcheck disable=SC2086
  $dlgs encode "$work/exact.dlgs" -o "$work/f.dlgs" $setting >/dev/null
  bytes=$($dlgs info --json "$work/f.dlgs" | json 'd["chunk_bytes_by_type"]["TFEA"]')
  ms=$(play_field "$work/f.dlgs" gop_features_ms)
  keys=$(play_field "$work/f.dlgs" gop_keys_ms)
  if [ "$setting" = "--exact-features" ]; then p="inf (reference)"; else p=$(psnr "$work/exact.dlgs" "$work/f.dlgs"); fi
  printf "| \`%s\` | %.0f | %s ms | %s ms | %s |\n" "$setting" "$(python3 -c "print($bytes/$frames)")" "$ms" "$keys" "$p"
done

echo
echo "## Canonical state (the still scene)"
echo "| setting | bytes | GOP 0 decode, median of 7 | PSNR vs lossless (8 views) |"
echo "|---|---|---|---|"
$dlgs encode "$scene" -o "$work/lossless.dlgs" --quality lossless >/dev/null
for setting in "--quality lossless" "--quality near-lossless" "--quality high" "--quality high --max-compression" "--quality medium" "--quality medium --max-compression"; do
  # shellcheck disable=SC2086
  $dlgs encode "$scene" -o "$work/c.dlgs" $setting >/dev/null
  bytes=$(stat -c %s "$work/c.dlgs")
  ms=$($timing "$work/c.dlgs" 7 | grep -o 'median [0-9.]* ms' | head -1 | sed 's/median //')
  if [ "$setting" = "--quality lossless" ]; then p="inf (reference)"; else
    p=$($dlgs compare "$work/lossless.dlgs" "$work/c.dlgs" --orbit 8 --json | json '"%.2f dB" % d["mean_psnr"]'); fi
  printf "| \`%s\` | %s | %s | %s |\n" "$setting" "$bytes" "$ms" "$p"
done

echo
echo "## Frames (the crf 6 file, 2 threads)"
echo "| setting | frame decode mean | shown per wall second (GOPs decoded ahead) |"
echo "|---|---|---|"
$dlgs encode "$work/exact.dlgs" -o "$work/f.dlgs" --crf 6 >/dev/null
for lang in "" "--language"; do
  printf "| colour%s | %s ms | %s |\n" "${lang:+ + language}" \
    "$(play_field "$work/f.dlgs" frame_decode_ms_mean "$lang")" "$(play_field "$work/f.dlgs" wall_fps "$lang")"
done
