#!/usr/bin/env bash
# Run every test of the workspace (optimised: the reference-renderer comparisons are heavy).
# Real scenes are read from ../shared/data (override with DLGS_DATA=/path/to/data).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cargo test --workspace --release "$@"
# Python bindings: wheel built with maturin, installed in a fresh venv, pytest (docs/python.md).
bash scripts/python_test.sh
