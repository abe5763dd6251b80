#!/bin/bash
# usage: spz_decode.sh INDIR OUTDIR  -- decodes every .spz to PLY with splat-transform
set -e
IN=$1; OUT=$2; mkdir -p $OUT
for f in $IN/*.spz; do b=$(basename $f .spz)
  /tmp/peers/node_modules/.bin/splat-transform -q -w $f $OUT/$b.ply >/dev/null 2>&1
done
