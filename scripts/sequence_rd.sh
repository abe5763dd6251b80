#!/usr/bin/env bash
# Real motion (issue 52): encode the 200-frame PlayCanvas SOG sequence at several settings and
# check every frame against its source (8 orbit cameras per frame): one CSV row per setting.
# Usage: scripts/sequence_rd.sh [OUT_DIR]   (~75 s per setting on 2 cores)
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-target/sequence_rd}
DATA=${DLGS_DATA:-../shared/data}/sequence/playcanvas_wave_200f
mkdir -p "$OUT"
cargo build --release -q -p dlgs-cli
B=target/release/dlgs
echo "setting,bytes,bytes_per_frame,mean_psnr_db,worst_psnr_db,encode_s" > "$OUT/rd.csv"
run() {
  local name=$1; shift
  local log
  log=$(RUST_BACKTRACE=0 $B encode "$DATA" -o "$OUT/$name.dlgs" "$@" --check \
    --check-csv "$OUT/$name.frames.csv" 2>&1)
  local bytes; bytes=$(stat -c %s "$OUT/$name.dlgs")
  local mean worst fit coded
  mean=$(echo "$log" | sed -n 's/.*mean \([0-9.]*\) dB.*/\1/p')
  worst=$(echo "$log" | sed -n 's/.*worst \([0-9.]*\) dB.*/\1/p')
  fit=$(echo "$log" | sed -n 's/.*fitted in \([0-9.]*\) s.*/\1/p')
  coded=$(echo "$log" | sed -n 's/.*coded in \([0-9.]*\) s.*/\1/p')
  echo "$name,$bytes,$((bytes / 200)),$mean,$worst,$(echo "$fit + $coded" | bc)" | tee -a "$OUT/rd.csv"
}
# The default: sequential GOPs with fitted binary voxel residual fields (RNTC).
run "crf6_k10"
run "crf4_k10" --crf 4
run "crf2_k10" --crf 2
run "crf6_k10_field_it150" --field-iterations 150
run "crf6_k10_field_it2000" --field-iterations 2000
# Intra GOPs (every GOP's canonical Gaussians in full).
run "crf6_k10_intra" --residual-mode intra
run "crf2_k10_intra" --crf 2 --residual-mode intra
run "crf4_k10_intra" --crf 4 --residual-mode intra
run "crf10_k10_intra" --crf 10 --residual-mode intra
run "crf6_k5_intra" --key-interval 5 --residual-mode intra
run "crf6_k20_intra" --key-interval 20 --residual-mode intra
run "crf6_k10_gop30_intra" --gop-length 30 --residual-mode intra
run "lossless_features_intra" --lossless-features --residual-mode intra
# Sequential GOPs with explicit residuals (RDLT).
run "crf6_k10_sequential_rdlt" --residual-mode sequential --explicit-residuals

# Per-frame CSOG (our still coding of each frame) at each quality of PERFRAME_QUALITIES (default
# "high low": `high` is the still default, `low` lands nearer the sequence's PSNR): bytes of
# every STEP-th frame's file (PERFRAME_STEP, default 1: every frame) and its PSNR against the
# source frame on the same 8 orbit cameras (`dlgs compare`). PERFRAME=0 skips it (~4-10 min per
# quality at step 1).
if [ "${PERFRAME:-1}" = 1 ]; then
  for q in ${PERFRAME_QUALITIES:-high low}; do
    mkdir -p "$OUT/perframe_$q"
    echo "frame,bytes,psnr_db" > "$OUT/perframe_$q.csv"
    i=0
    for f in "$DATA"/wave_*.sog; do
      i=$((i + 1))
      [ $(((i - 1) % ${PERFRAME_STEP:-1})) = 0 ] || continue
      n=$(basename "$f" .sog)
      RUST_BACKTRACE=0 $B encode "$f" -o "$OUT/perframe_$q/$n.dlgs" --quality "$q" > /dev/null
      psnr=$(RUST_BACKTRACE=0 $B compare "$f" "$OUT/perframe_$q/$n.dlgs" --json \
        | python3 -c 'import json,sys; v=json.load(sys.stdin); print(sum(100 if x["psnr"] is None else min(x["psnr"], 100) for x in v["views"])/len(v["views"]))')
      echo "$n,$(stat -c %s "$OUT/perframe_$q/$n.dlgs"),$psnr" >> "$OUT/perframe_$q.csv"
    done
    python3 - "$OUT/perframe_$q.csv" "$q" <<'PY' | tee -a "$OUT/rd.csv"
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
b = sum(int(r["bytes"]) for r in rows)
p = [float(r["psnr_db"]) for r in rows]
print(f"perframe_csog_{sys.argv[2]},{b},{b // len(rows)},{sum(p)/len(p):.2f},{min(p):.2f},")
PY
  done
fi
