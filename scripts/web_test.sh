#!/usr/bin/env bash
# Browser tests of the web player (issue 67): Debian's chromium headless (SwiftShader WebGL2),
# driven by playwright-core (npm, installed into target/web-node), pages served on loopback by
# web/player/serve.py (python3 http.server + HTTP Range; a second instance without Range).
#
#   bash scripts/web_test.sh             build the bundle, run the tests (each fails the script):
#        1. the conformance vectors decoded in the page: GOP digests, error names, dynamic frames
#           bit for bit; HEVC vectors refused with the typed HevcFeatures error
#        2. screenshot of a real scene vs the CPU renderer (same camera, size, background): PSNR
#        3. playback at the file's fps for 4 s: frames shown / dropped
#        4. whole-file fallback when the server ignores Range; 5. typed HEVC error in the page;
#        6. language relevance view; 7. a Scaffold-GS file (the fixture run) against the CPU renderer
#   bash scripts/web_test.sh --measure   decode time per GOP and frames/s of an 80k-dynamic file in
#        the page, time to first frame at 20 Mbit/s + 40 ms (CDP throttling), bundle size, and the
#        native decoder's numbers for the same file
set -euo pipefail
MAIN=$(cd "$(dirname "$0")/.." && pwd)
DLGS=${DLGS:-$MAIN/target/release/dlgs}
DATA=${DLGS_DATA:-$MAIN/../shared/data}
OUT=$MAIN/target/web-test
WD=$MAIN/target/web-data
NODE_DIR=$MAIN/target/web-node
PORT=${PORT:-8771}
mkdir -p "$OUT" "$WD"

bash "$MAIN/scripts/web_build.sh"
if [ ! -d "$NODE_DIR/node_modules/playwright-core" ]; then
    mkdir -p "$NODE_DIR"
    [ -f "$NODE_DIR/package.json" ] || echo '{"private":true}' >"$NODE_DIR/package.json"
    (cd "$NODE_DIR" && npm install --no-audit --no-fund playwright-core >/dev/null)
fi
command -v chromium >/dev/null || { echo "web_test: chromium missing (bash web/toolchain.sh install)" >&2; exit 1; }
[ -x "$DLGS" ] || (cd "$MAIN" && cargo build --release -p dlgs-cli)

# Test scene: the MIT donut (real) with SYNTHETIC motion and language, time features quantised to
# 8 bits (TFEA codec 4: no HEVC); cameras.json of its orbit at 640x480 and the CPU renderer's
# image of view 0 at t = 0.5 s.
SCENE=$WD/demo-q8.dlgs
T=0.5
if [ ! -f "$SCENE" ]; then
    "$DLGS" synth "$DATA/ply/v3dg_donut_mipsplatting_45624_sh0.ply" -o "$SCENE" --quantised-features 8 --language --gops 3 >/dev/null
fi
"$DLGS" cameras "$SCENE" --orbit 8 --width 640 --height 480 -o "$WD/cams.json" >/dev/null
"$DLGS" render "$SCENE" --cameras "$WD/cams.json" --view 0 --t "$T" -o "$WD/ref.png" >/dev/null

# Scaffold-GS: the fitted fixture run (2,400 anchors from a real scene, tests/fixtures/scaffold_run)
# with its time features quantised to 8 bits; cameras of its orbit and the CPU renderer's image.
SCAFFOLD=$WD/scaffold-q8.dlgs
SCAFFOLD_T=0.5
if [ ! -f "$SCAFFOLD" ]; then
    "$DLGS" encode "$MAIN/tests/fixtures/scaffold_run" -o "$SCAFFOLD" --quantised-features 8 >/dev/null
fi
"$DLGS" cameras "$SCAFFOLD" --orbit 8 --width 640 --height 480 -o "$WD/scaffold-cams.json" >/dev/null
"$DLGS" render "$SCAFFOLD" --cameras "$WD/scaffold-cams.json" --view 0 --t "$SCAFFOLD_T" -o "$WD/scaffold-ref.png" >/dev/null

MEASURE=${1:-}
MFILE=$WD/plant80k-q8.dlgs
if [ "$MEASURE" = "--measure" ] && [ ! -f "$MFILE" ]; then
    # The plant (real) with 80,000 SYNTHETIC dynamic Gaussians and language: the native
    # benchmarks' 80k configuration (docs/benchmarks/dynamic.md), time features quantised to 8 bits.
    "$DLGS" synth "$DATA/splat/marcelpadilla_plant.splat" -o "$MFILE" --dynamic-fraction 0.75 \
        --max-dynamic 80000 --language --gops 3 --quantised-features 8 >/dev/null
fi

python3 "$MAIN/web/player/serve.py" --dir "$MAIN" --port "$PORT" >/dev/null 2>&1 &
SRV=$!
python3 "$MAIN/web/player/serve.py" --dir "$MAIN" --port $((PORT + 1)) --no-range >/dev/null 2>&1 &
SRV2=$!
trap 'kill $SRV $SRV2 2>/dev/null || true' EXIT
for _ in $(seq 50); do
    curl -s -o /dev/null "http://127.0.0.1:$PORT/" && curl -s -o /dev/null "http://127.0.0.1:$((PORT + 1))/" && break
    sleep 0.1
done

rel() { echo "/${1#"$MAIN"/}"; }
SCENE_URL=$(rel "$SCENE")
export NODE_MODULES_DIR=$NODE_DIR/node_modules SCENE=$SCENE_URL CAMS=$(rel "$WD/cams.json") REF=$WD/ref.png T
export PSNR_FLOOR=${PSNR_FLOOR:-50} PLAY_FILE=$SCENE_URL MEASURE_FILE=$(rel "$MFILE")
export SCAFFOLD=$(rel "$SCAFFOLD") SCAFFOLD_CAMS=$(rel "$WD/scaffold-cams.json") SCAFFOLD_REF=$WD/scaffold-ref.png SCAFFOLD_T
export TTFF_FILES=${TTFF_FILES:-$SCENE_URL,$(rel "$MFILE")}
node "$MAIN/web/player/test/browser_test.mjs" "http://127.0.0.1:$PORT" "http://127.0.0.1:$((PORT + 1))" "$OUT" $MEASURE

if [ "$MEASURE" = "--measure" ]; then
    W=$MAIN/target/web
    echo "MEASURE bundle: wasm $(stat -c %s "$W/pkg/dlgs_web_bg.wasm") B (gzip $(gzip -9 -c "$W/pkg/dlgs_web_bg.wasm" | wc -c) B); page + JS + wasm $(cat "$W"/index.html "$W"/*.js "$W"/pkg/dlgs_web.js "$W"/pkg/dlgs_web_bg.wasm | wc -c) B (gzip $(for f in index.html player.js renderer.js camera.js stream.js decoder_worker.js pkg/dlgs_web.js pkg/dlgs_web_bg.wasm; do gzip -9 -c "$W/$f"; done | wc -c) B)"
    TIMING=$MAIN/target/release/examples/decode_timing
    if [ -x "$TIMING" ]; then
        echo "MEASURE native (2 threads): $("$TIMING" "$MFILE" 9)"
        echo "MEASURE native (1 thread):  $(RAYON_NUM_THREADS=1 "$TIMING" "$MFILE" 9)"
    else
        echo "MEASURE native decode_timing not built (cargo build --release -p dlgs-decoder --example decode_timing)"
    fi
    echo "MEASURE native dlgs play --max-speed (2 threads):"; "$DLGS" play "$MFILE" --max-speed 2>&1 | tail -4
    echo "MEASURE native dlgs play --max-speed --gop-threads 1 (RAYON_NUM_THREADS=1):"; RAYON_NUM_THREADS=1 "$DLGS" play "$MFILE" --max-speed --gop-threads 1 2>&1 | tail -4
fi
