#!/usr/bin/env bash
# wasm32 toolchain for the web player (issue 67): Debian's rustc-web 1.96 rebuilds std for
# wasm32-unknown-unknown (-Zbuild-std from rust-web-src), lld-22 links, wasm-bindgen-cli 0.2.130
# post-processes. Everything goes to target/wasm (never the main target/). See FEASIBILITY.md.
#
#   web/toolchain.sh install        apt packages + wasm-bindgen-cli (cargo install --debug, ~1.5 min)
#   web/toolchain.sh build [REPO]   build the feasibility probes experiments/web/probe and
#                                   experiments/web/bindgen-smoke of REPO (default: this checkout)
#                                   and run their tests
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
MAIN=$(cd "$HERE/.." && pwd)
export CARGO_TARGET_DIR=${CARGO_TARGET_DIR:-$MAIN/target/wasm}
TOOLS=$CARGO_TARGET_DIR/tools

install() {
    local sudo_cmd=""
    [ "$(id -u)" -ne 0 ] && sudo_cmd="sudo"
    $sudo_cmd apt-get update -qq
    # rustc-web/cargo-web 1.96 come from bookworm-security (bookworm itself has 1.85 < 1.87).
    # No Debian package has a prebuilt wasm32 std for rustc-web, hence rust-web-src.
    DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq --no-install-recommends \
        rustc-web cargo-web rust-web-src lld-22 clang chromium
    # The CLI must be the wasm-bindgen crate's exact version. Not --locked: its lock pins
    # webpki-roots 1.0.11, which the crates.io index here does not offer. --debug: 86 s to build
    # instead of about 5.5 min, and the same output (diff -r of its --target web output on
    # dlgs_web.wasm: identical, 2026-12-02) in under a second.
    if [ ! -x "$TOOLS/bin/wasm-bindgen" ]; then
        time "${CARGO_HOME:-$HOME/.cargo}/bin/cargo" install wasm-bindgen-cli --version 0.2.130 --debug -j2 \
            --root "$TOOLS" --target-dir "$CARGO_TARGET_DIR/cli-build"
    fi
}

build() {
    local repo=${1:-$MAIN}
    # shellcheck source=env.sh
    . "$HERE/env.sh"
    export CARGO_TARGET_DIR=${CARGO_TARGET_DIR:-$MAIN/target/wasm}
    local out=$CARGO_TARGET_DIR/wasm32-unknown-unknown/release
    local probes=$repo/experiments/web
    (cd "$probes/probe" && time cargo build --release $WASM_BUILD_STD_ARGS)
    node "$probes/probe/run_vectors.mjs" "$out/dlgs_wasm_probe.wasm" "$MAIN/format-spec/vectors"
    (cd "$probes/bindgen-smoke" && time cargo build --release $WASM_BUILD_STD_ARGS)
    "$TOOLS/bin/wasm-bindgen" --target nodejs --out-dir "$CARGO_TARGET_DIR/pkg-node" "$out/dlgs_bindgen_smoke.wasm"
    "$TOOLS/bin/wasm-bindgen" --target web --out-dir "$CARGO_TARGET_DIR/pkg-web" "$out/dlgs_bindgen_smoke.wasm"
    node "$probes/bindgen-smoke/smoke.mjs" "$CARGO_TARGET_DIR/pkg-node"
    # Headless chromium: serve the checkout (index.html imports /target/wasm/pkg-web/...).
    if command -v chromium >/dev/null && [ "$CARGO_TARGET_DIR" = "$MAIN/target/wasm" ]; then
        (cd "$MAIN" && exec python3 -m http.server 8767 --bind 127.0.0.1 >/dev/null 2>&1) &
        local srv=$!
        sleep 1
        timeout 60 chromium --headless --no-sandbox --disable-gpu --virtual-time-budget=10000 \
            --dump-dom http://127.0.0.1:8767/experiments/web/bindgen-smoke/index.html 2>/dev/null |
            grep -o '<pre id="out">[^<]*' || true
        kill "$srv"
    fi
}

case "${1:-}" in
    install) install ;;
    build) build "${2:-}" ;;
    *) sed -n '2,12p' "$0"; exit 2 ;;
esac
