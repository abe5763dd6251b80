#!/usr/bin/env bash
# Decode time side by side: PlayCanvas SOG and SPZ with @playcanvas/splat-transform 2.7.1's own
# readers (Node; SPZ through the official SPZ WebAssembly library), and dlgs files with
# `decode_timing`, each from bytes in memory to Gaussians in memory, median of RUNS after a
# warm-up (docs/benchmarks/decode.md "Decode time against SOG and SPZ").
# Usage: bash scripts/peer_decode.sh PEER_DIR... -- DLGS_FILE...
#   PEER_DIR: folders made by scripts/peers.sh (their .sog and .spz files are timed).
#   Env: RUNS (default 9). Needs node/npm (installs splat-transform into target/peer-node once).
set -euo pipefail
cd "$(dirname "$0")/.."
RUNS=${RUNS:-9}
peers=()
files=()
seen_sep=0
for a in "$@"; do
  if [ "$a" = -- ]; then seen_sep=1; continue; fi
  if [ $seen_sep = 0 ]; then peers+=("$a"); else files+=("$a"); fi
done
MODULES=target/peer-node/node_modules
if [ ! -d "$MODULES/@playcanvas/splat-transform" ]; then
  mkdir -p target/peer-node
  npm install --silent --no-audit --no-fund --prefix target/peer-node @playcanvas/splat-transform@2.7.1
fi
cargo build --release -q -p dlgs-decoder --example decode_timing
printf 'file\tGaussians\tthreads\tmedian_ms\n'
for d in "${peers[@]}"; do
  for f in "$d"/*.sog "$d"/*.spz; do
    [ -e "$f" ] || continue
    # name, Gaussians, median, min, max
    node scripts/peer_decode_timing.mjs "$MODULES" "$f" "$RUNS" |
      awk -F'\t' '{printf "%s\t%s\t1\t%s\n", $1, $2, $3}'
  done
done
for f in "${files[@]}"; do
  for t in 1 2; do
    ms=$(RAYON_NUM_THREADS=$t ./target/release/examples/decode_timing "$f" "$RUNS" |
      sed -E 's/.*median ([0-9.]+) ms.*/\1/')
    printf '%s\t-\t%s\t%s\n' "$f" "$t" "$ms"
  done
done
