#!/bin/bash
# usage: spz_encode.sh VERSION OUTDIR   -- encodes all 200 source SOG frames with splat-transform
set -e
V=$1; OUT=$2; S=/work/shared/data/sequence/playcanvas_wave_200f
mkdir -p $OUT
for i in $(seq -f %04g 1 200); do
  /tmp/peers/node_modules/.bin/splat-transform -q -w --spz-version $V $S/wave_$i.sog $OUT/wave_$i.spz
done
