#!/usr/bin/env bash
# Run every test of the workspace (optimised: the reference-renderer comparisons are heavy).
# Real scenes are read from ../shared/data (override with DLGS_DATA=/path/to/data).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cargo test --workspace --release "$@"
# Python bindings: wheel built with maturin, installed in a fresh venv, pytest (docs/python.md).
bash scripts/python_test.sh
# Web player (issue 67): the wasm bundle, then headless chromium tests (conformance vectors bit for
# bit in the page, screenshot PSNR against the CPU renderer, playback, Range fallback, HEVC error,
# language view). The toolchain (rustc-web, lld-22, chromium, wasm-bindgen-cli) is installed on
# first use (docs/web-player.md).
bash scripts/web_test.sh
