#!/usr/bin/env bash
# Web player bundle (issue 67): the GPL-free decoder (dlgs-decoder without FFmpeg) compiled to
# wasm32 with Debian's rustc-web (web/env.sh, -Zbuild-std), wasm-bindgen, wasm-opt, plus the
# page and its ES modules, into target/web/. Prints the bundle size (raw and gzip).
#
#   bash scripts/web_build.sh            build target/web/
#   bash scripts/web_build.sh --serve    build, make a demo file if missing, serve on 127.0.0.1
#                                        (PORT=8768) and print the page's URL
# Toolchain (once): bash web/toolchain.sh install (apt rustc-web, lld-22, chromium; wasm-bindgen-cli).
set -euo pipefail
MAIN=$(cd "$(dirname "$0")/.." && pwd)
OUT=$MAIN/target/web
WASM_TARGET=$MAIN/target/wasm
TOOLS=$WASM_TARGET/tools/bin
PORT=${PORT:-8768}

if ! [ -x /usr/bin/rustc ] || ! [ -x "$TOOLS/wasm-bindgen" ] || ! [ -x /usr/lib/llvm-22/bin/wasm-ld ]; then
    echo "web_build: the wasm toolchain is missing; installing it (web/toolchain.sh install)" >&2
    bash "$MAIN/web/toolchain.sh" install
fi
(
    # shellcheck source=../web/env.sh
    . "$MAIN/web/env.sh"
    export CARGO_TARGET_DIR=$WASM_TARGET
    cd "$MAIN/web/player"
    # shellcheck disable=SC2086
    cargo build --release $WASM_BUILD_STD_ARGS
)
mkdir -p "$OUT/pkg"
"$TOOLS/wasm-bindgen" --target web --out-dir "$OUT/pkg" "$WASM_TARGET/wasm32-unknown-unknown/release/dlgs_web.wasm"
# npm binaryen (Debian's binaryen 108 breaks wasm-bindgen output, web/FEASIBILITY.md).
OPT=$WASM_TARGET/npm/node_modules/.bin/wasm-opt
if [ ! -x "$OPT" ]; then
    mkdir -p "$WASM_TARGET/npm"
    (cd "$WASM_TARGET/npm" && npm install --no-audit --no-fund binaryen@132.0.0 >/dev/null)
fi
"$OPT" -O3 --enable-simd --enable-bulk-memory --enable-nontrapping-float-to-int --enable-sign-ext --enable-mutable-globals \
    "$OUT/pkg/dlgs_web_bg.wasm" -o "$OUT/pkg/dlgs_web_bg.opt.wasm"
mv "$OUT/pkg/dlgs_web_bg.opt.wasm" "$OUT/pkg/dlgs_web_bg.wasm"
cp "$MAIN/web/player/index.html" "$MAIN"/web/player/js/*.js \
    "$MAIN/web/player/serve.py" "$MAIN/web/player/package.json" "$OUT/"
[ -f "$MAIN/web/player/README.md" ] && cp "$MAIN/web/player/README.md" "$OUT/"
size() { stat -c %s "$1"; }
gz() { gzip -9 -c "$1" | wc -c; }
raw=0; zipped=0
for f in index.html player.js renderer.js camera.js stream.js decoder_worker.js pkg/dlgs_web.js pkg/dlgs_web_bg.wasm; do
    raw=$((raw + $(size "$OUT/$f"))); zipped=$((zipped + $(gz "$OUT/$f")))
done
echo "web bundle: $OUT (wasm $(size "$OUT/pkg/dlgs_web_bg.wasm") B, gzip $(gz "$OUT/pkg/dlgs_web_bg.wasm") B; page + JS + wasm $raw B, gzip $zipped B)"

if [ "${1:-}" = "--serve" ]; then
    DEMO=$MAIN/target/web-data/demo-q8.dlgs
    if [ ! -f "$DEMO" ]; then
        DLGS=$MAIN/target/release/dlgs
        [ -x "$DLGS" ] || (cd "$MAIN" && cargo build --release -p dlgs-cli)
        mkdir -p "$(dirname "$DEMO")"
        # A real scene (MIT donut) with SYNTHETIC motion and language, time features quantised to
        # 8 bits (TFEA codec 4, no HEVC).
        "$DLGS" synth "${DLGS_DATA:-$MAIN/../shared/data}/ply/v3dg_donut_mipsplatting_45624_sh0.ply" \
            -o "$DEMO" --quantised-features 8 --language --gops 3 >/dev/null
    fi
    echo "demo: http://127.0.0.1:$PORT/target/web/index.html?file=/target/web-data/demo-q8.dlgs  (Ctrl-C stops)"
    exec python3 "$MAIN/web/player/serve.py" --dir "$MAIN" --port "$PORT"
fi
