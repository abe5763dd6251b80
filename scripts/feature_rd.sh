#!/usr/bin/env bash
# Start of the time-feature RD curve: bytes/frame of the TFEA stream vs x265 crf, with the
# rendered PSNR against the exact-feature model. The dynamic model is SYNTHETIC motion on a
# real scene (no trained DLGStream model exists here).
#   [EXTRA="--fast-start off"] scripts/feature_rd.sh [SCENE] [CRFS...]
# (EXTRA: more `dlgs encode` flags for every row.)
set -euo pipefail
cd "$(dirname "$0")/.."
scene=${1:-../shared/data/splat/marcelpadilla_plant.splat}
shift || true
crfs=${*:-6 8 12 16 20 24}
cargo build --release -q -p dlgs-cli
dlgs=target/release/dlgs
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
$dlgs synth "$scene" -o "$work/exact.dlgs" --exact-features >/dev/null
frames=$($dlgs info --json "$work/exact.dlgs" | python3 -c 'import json,sys; print(json.load(sys.stdin)["header"]["frame_count"])')
printf "%-6s %14s %12s %12s\n" crf "TFEA B/frame" "PSNR t=0.5" "PSNR t=1.23"
for crf in $crfs; do
  # shellcheck disable=SC2086
  $dlgs encode "$work/exact.dlgs" -o "$work/c.dlgs" --crf "$crf" ${EXTRA:-} >/dev/null
  bytes=$($dlgs info --json "$work/c.dlgs" | python3 -c 'import json,sys; d=json.load(sys.stdin); print(d["chunk_bytes_by_type"]["TFEA"])')
  p1=$($dlgs compare "$work/exact.dlgs" "$work/c.dlgs" --t 0.5 --orbit 4 --width 676 --height 507 --json | python3 -c 'import json,sys; print("%.2f" % json.load(sys.stdin)["mean_psnr"])')
  p2=$($dlgs compare "$work/exact.dlgs" "$work/c.dlgs" --t 1.2345 --orbit 4 --width 676 --height 507 --json | python3 -c 'import json,sys; print("%.2f" % json.load(sys.stdin)["mean_psnr"])')
  printf "%-6s %14.0f %12s %12s\n" "$crf" "$(python3 -c "print($bytes/$frames)")" "$p1" "$p2"
done
