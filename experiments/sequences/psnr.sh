#!/bin/bash
# usage: psnr.sh TESTDIR EXT STEP OUT.csv -- dlgs compare ply/wave_NNNN.ply TESTDIR/wave_NNNN.EXT for frames 1..200 step STEP
# writes frame,mean_psnr_capped100,min_view_psnr,mean_ssim
export RUST_BACKTRACE=0
T=$1; EXT=$2; STEP=$3; OUT=$4
echo "frame,psnr,min_view_psnr,ssim" > $OUT
for n in $(seq 1 $STEP 200); do i=$(printf %04d $n)
  /tmp/peers/dlgs compare /tmp/peers/ply/wave_$i.ply $T/wave_$i.$EXT --json > /tmp/peers/tmp/cmp.json 2>/tmp/peers/tmp/cmp.err || { echo "$n,ERR,$(head -c 200 /tmp/peers/tmp/cmp.err | tr '\n,' '  ')," >> $OUT; continue; }
  python3 - $n >> $OUT <<'PY'
import json,sys
d=json.load(open('/tmp/peers/tmp/cmp.json'))
p=[min(100.0, v['psnr'] if v['psnr'] is not None else 100.0) for v in d['views']]
s=[v['ssim'] for v in d['views']]
print("%s,%.4f,%.4f,%.6f"%(sys.argv[1], sum(p)/len(p), min(p), sum(s)/len(s)))
PY
done
