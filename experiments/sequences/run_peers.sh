#!/bin/bash
# Reproduces every measurement in /tmp/peers/RESULTS.md. Run heavy steps one at a time (2 shared cores).
set -e
export RUST_BACKTRACE=0
R=/tmp/peers; S=/work/shared/data/sequence/playcanvas_wave_200f
cd $R
now() { date +%s.%N; }

# ---- 0. tools
cp /tmp/dlgs_bin $R/dlgs
[ -d node_modules/@playcanvas/splat-transform ] || { npm init -y >/dev/null; npm install @playcanvas/splat-transform; }
[ -x venv/bin/python ] || python3 -m venv venv
venv/bin/pip install -q fourdgs scipy
mkdir -p ply res tmp fdgs
{ echo "splat-transform $(node_modules/.bin/splat-transform --version 2>&1 | tail -1)"; echo "node $(node --version)";
  echo "fourdgs $(venv/bin/python -c 'import fourdgs;print(fourdgs.__version__)')"; venv/bin/pip list 2>/dev/null | grep -Ei '^(numpy|scipy) ';
  echo "python $(venv/bin/python --version)"; echo "dlgs $(./dlgs --version)"; } > res/versions.txt

# ---- 1. SOG -> PLY (exact) with dlgs
for i in $(seq -f %04g 1 200); do
  ./dlgs encode $S/wave_$i.sog --quality lossless -o tmp/t.dlgs >/dev/null
  ./dlgs decode tmp/t.dlgs -o ply/wave_$i.ply >/dev/null
done

# ---- 2. SPZ with splat-transform (v4 = its default, and v3), encode from the source SOG, decode back to PLY
: > res/spz_times.txt
for v in 4 3; do
  s=$(now); ./spz_encode.sh $v spz_v$v; e=$(now); echo "encode_v$v $(echo "$e - $s" | bc)" >> res/spz_times.txt
  s=$(now); ./spz_decode.sh spz_v$v spzdec_v$v; e=$(now); echo "decode_v$v $(echo "$e - $s" | bc)" >> res/spz_times.txt
  echo "bytes_v$v $(cat spz_v$v/*.spz | wc -c)" >> res/spz_times.txt
done
# splat-transform's own in-process time per frame ("done in"), v4, includes reading the SOG
for i in $(seq -f %04g 1 200); do node_modules/.bin/splat-transform -w $S/wave_$i.sog tmp/x.spz 2>&1 | grep -o 'done in [0-9.]*s'; done \
  | awk '{gsub("s","",$3); t+=$3} END {print "inproc_encode_v4_sum", t}' >> res/spz_times.txt
s=$(now); for i in $(seq 1 200); do node -e 1; done; e=$(now); echo "node_startup_x200 $(echo "$e - $s" | bc)" >> res/spz_times.txt
# can dlgs read splat-transform's SPZ?  (v4: no -> error recorded; v3: yes)
( ./dlgs compare ply/wave_0001.ply spz_v4/wave_0001.spz --json > res/dlgs_reads_spz_v4.txt 2>&1; echo "exit $?" >> res/dlgs_reads_spz_v4.txt ) || true
# v3 and v4 decode (splat-transform) to identical Gaussians?
venv/bin/python same_sets.py spzdec_v3 spzdec_v4 > res/spz_v3_vs_v4.txt
# PSNR every frame: dlgs reads the v3 files directly
./psnr.sh $R/spz_v3 spz 1 res/psnr_spz_v3.csv

# ---- 3. .4dgs keyframe-delta (fourdgs reference library), 3 profiles x 2 id assignments
for prof in default fine coarse; do for order in row nn; do
  venv/bin/python fdgs_run.py $prof $order fdgs/${prof}_$order > fdgs/${prof}_$order.log
done; done
for prof in default fine coarse; do venv/bin/python same_sets.py fdgs/${prof}_row fdgs/${prof}_nn; done > res/fdgs_row_vs_nn.txt
# PSNR: every 10th frame (1, 11, ..., 191) for all six; then all 200 frames for the row-order runs
for prof in default fine coarse; do for order in row nn; do
  ./psnr.sh $R/fdgs/${prof}_$order ply 10 res/psnr10_fdgs_${prof}_$order.csv
done; done
for prof in default fine coarse; do ./psnr.sh $R/fdgs/${prof}_row ply 1 res/psnr_fdgs_${prof}_row.csv; done

# timing: repeat encode and decode 5 times each (no PLY rewrite), report the median
for prof in default fine coarse; do for order in row nn; do
  venv/bin/python fdgs_run.py $prof $order fdgs/${prof}_$order --repeat 5 --no-ply > fdgs/${prof}_${order}_timing.log
done; done

# ---- 3b. extra: the package's own CLI converter for a PLY directory (gaussian-birth model, not keyframe-delta)
mkdir -p fdgs/birth_default
s=$(now); venv/bin/fourdgs convert ply -o fdgs/birth_default/wave.4dgs; e=$(now); echo "encode_s $(echo "$e - $s" | bc)" > fdgs/birth_default/encode_time.txt
venv/bin/python fdgs_birth.py fdgs/birth_default
./psnr.sh $R/fdgs/birth_default ply 10 res/psnr10_fdgs_birth_default.csv

# ---- 4. table
venv/bin/python summarize.py > res/table.md
cat res/table.md
