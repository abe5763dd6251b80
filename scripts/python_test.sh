#!/usr/bin/env bash
# Python bindings (python/, docs/python.md): build the abi3 wheel with maturin, install it in
# a fresh venv (not `maturin develop`), run the pytest suite against the real data and the CLI.
# Called by scripts/test.sh after the Rust tests (the CLI and the workspace's dependencies are
# then built: the wheel reuses them from the shared target directory).
set -euo pipefail
cd "$(dirname "$0")/.."
if ! python3 -c 'import ensurepip, venv' 2>/dev/null; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO=sudo
  $SUDO apt-get install -y -q python3-venv python3-pip >/dev/null
fi
cargo build --release -q -p dlgs-cli
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
# Build tools in their own venv; the tests in another, fresh one with only the wheel + pytest.
python3 -m venv "$WORK/build"
"$WORK/build/bin/pip" install -q "maturin>=1.5,<2"
"$WORK/build/bin/maturin" build --release -q -m python/Cargo.toml -o "$WORK/wheels"
WHEEL=$(ls "$WORK"/wheels/dlgs-*.whl)
echo "wheel: $(basename "$WHEEL"), $(stat -c %s "$WHEEL") bytes"
python3 -m venv "$WORK/test"
"$WORK/test/bin/pip" install -q "$WHEEL" pytest
(cd python/tests && "$WORK/test/bin/python" -m pytest -q -rs -p no:cacheprovider .)
