#!/usr/bin/env bash
# Large motion and changing counts (issue 65): hard per-frame sequences made from a REAL scene
# (the Mip-Splatting donut, SH 0, every 2nd Gaussian: 22,812) with SYNTHETIC motion by
# `dlgs synth-frames`, encoded by us at several settings and by the peers, every 10th frame
# compared with `dlgs compare` (8 orbit views around that source frame, PSNR capped at 100 dB).
# Usage: scripts/hard_sequences_rd.sh [OUT_DIR]   (about 30 min on 2 cores)
# Needs python3 -m venv; installs fourdgs (the .4dgs reference) into OUT_DIR/venv.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-target/hard_sequences}
DATA=${DLGS_DATA:-../shared/data}
SCENE=$DATA/ply/v3dg_donut_mipsplatting_45624_sh0.ply
FRAMES=${FRAMES:-120}
mkdir -p "$OUT"
cargo build --release -q -p dlgs-cli
B=$(pwd)/target/release/dlgs
[ -x "$OUT/venv/bin/python" ] || python3 -m venv "$OUT/venv"
"$OUT/venv/bin/pip" install -q fourdgs numpy
export RUST_BACKTRACE=0
CSV=$OUT/rd.csv
echo "sequence,coding,bytes_per_frame,psnr_every10_db,check_mean_db,check_worst_db,encode_s" > "$CSV"
# Mean PSNR of every 10th frame: compare SRC_DIR/frame_NNNN.ply against TARGET (a .dlgs at the
# frame's time, or a folder of decoded PLYs).
psnr10() {
  local src=$1 target=$2 sum=0 n=0 t p
  for ((t = 0; t < FRAMES; t += 10)); do
    local f; f=$(printf "frame_%04d.ply" "$t")
    if [ -d "$target" ]; then
      p=$($B compare "$src/$f" "$target/$f" --json)
    else
      p=$($B compare "$src/$f" "$target" --t "$(python3 -c "print($t/30)")" --json)
    fi
    p=$(echo "$p" | python3 -c 'import json,sys; v=json.load(sys.stdin)["views"]; print(sum(100 if x["psnr"] is None else min(x["psnr"], 100) for x in v)/len(v))')
    sum=$(python3 -c "print($sum + $p)"); n=$((n + 1))
  done
  python3 -c "print(f'{$sum / $n:.2f}')"
}
ours() {
  local seq=$1 name=$2; shift 2
  local start log; start=$(date +%s.%N)
  log=$($B encode "$OUT/$seq" -o "$OUT/$seq.$name.dlgs" --check "$@" 2>&1)
  local secs; secs=$(python3 -c "print(f'{$(date +%s.%N) - $start:.1f}')")
  echo "$log" | grep -v '^  GOP' > "$OUT/$seq.$name.log"
  local mean worst bytes
  mean=$(echo "$log" | sed -n 's/.*mean \([0-9.]*\) dB.*/\1/p')
  worst=$(echo "$log" | sed -n 's/.*worst \([0-9.]*\) dB (frame.*/\1/p')
  bytes=$(stat -c %s "$OUT/$seq.$name.dlgs")
  echo "$seq,ours $name,$((bytes / FRAMES)),$(psnr10 "$OUT/$seq" "$OUT/$seq.$name.dlgs"),$mean,$worst,$secs" | tee -a "$CSV"
}
for spec in "articulated:--motion articulated" "rigid:--motion rigid" "rigid_births:--motion rigid --births 0.1"; do
  seq=${spec%%:*}
  # shellcheck disable=SC2086
  $B synth-frames "$SCENE" -o "$OUT/$seq" --frames "$FRAMES" --speed 10 --every 2 --ids ${spec#*:} | tee "$OUT/$seq.txt"
  ours "$seq" default
  ours "$seq" intra --residual-mode intra
  ours "$seq" lossy-features --features lossy
  # Per-frame CSOG high (our still default) on every 10th frame.
  sum=0; n=0
  for ((t = 0; t < FRAMES; t += 10)); do
    f=$(printf "frame_%04d" "$t")
    $B encode "$OUT/$seq/$f.ply" -o "$OUT/$seq.csog.dlgs" > /dev/null
    sum=$((sum + $(stat -c %s "$OUT/$seq.csog.dlgs"))); n=$((n + 1))
  done
  echo "$seq,per-frame CSOG high (every 10th frame),$((sum / n)),,,," | tee -a "$CSV"
  # .4dgs keyframe-delta with the true identities (its best case).
  for prof in default fine; do
    j=$("$OUT/venv/bin/python" scripts/fdgs_sequence.py "$OUT/$seq" "$OUT/$seq.4dgs_$prof" "$prof")
    bpf=$(echo "$j" | python3 -c 'import json,sys; print(int(json.load(sys.stdin)["bytes_per_frame"]))')
    enc=$(echo "$j" | python3 -c 'import json,sys; print("%.1f" % json.load(sys.stdin)["encode_s"])')
    echo "$seq,.4dgs $prof (true ids),$bpf,$(psnr10 "$OUT/$seq" "$OUT/$seq.4dgs_$prof"),,,$enc" | tee -a "$CSV"
  done
done
