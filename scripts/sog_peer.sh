#!/usr/bin/env bash
# Our SOG writer against the peer (by hand, not in CI: needs node/npx and the npm registry):
# `dlgs export --format sog` of a real scene, read by `@playcanvas/splat-transform@2.7.1` into
# a PLY; both decodes are written back to PLY by dlgs and compared byte for byte, i.e. the
# peer decodes our file to the floats our own reader gives.
#   bash scripts/sog_peer.sh [SCENE.ply]       (DLGS=path/to/dlgs to pick the binary)
set -euo pipefail
cd "$(dirname "$0")/.."
B=${DLGS:-${CARGO_TARGET_DIR:-target}/release/dlgs}
SCENE=${1:-../shared/data/ply/supersplat_fruit_drops_minimal_4721_sh3.ply}
W=$(mktemp -d)
trap 'rm -rf "$W"' EXIT
"$B" export "$SCENE" --format sog -o "$W/ours.sog" >/dev/null
npx -y @playcanvas/splat-transform@2.7.1 "$W/ours.sog" "$W/peer.ply" >"$W/peer.log" 2>&1 || { cat "$W/peer.log"; exit 1; }
"$B" export "$W/ours.sog" -o "$W/ours.ply" >/dev/null
"$B" export "$W/peer.ply" -o "$W/peer_again.ply" >/dev/null
cmp "$W/ours.ply" "$W/peer_again.ply"
echo "splat-transform 2.7.1 reads $(stat -c %s "$W/ours.sog") bytes of our SOG to the same floats as our reader"
