#!/usr/bin/env bash
# The GPL-free decoder seam (README "Licences"): dlgs-decoder and the C library built without
# FFmpeg (cargo feature `hevc` off) link no libavcodec/libx265, decode exact-feature and still
# files to the same floats as the full build, and report HEVC time features as a typed error.
set -euo pipefail
cd "$(dirname "$0")/.."
# The library without FFmpeg, built in the shared target directory (its dependencies are those of
# the tests: only dlgs-decoder and dlgs-capi compile again; a target directory of its own took
# 89 s on 2 cores) and copied aside, since the cdylib's file name does not change with its
# features; then the full library (with FFmpeg) to compare with: target/release/libdlgs_capi.so.
T=target/gpl-free
cargo build --release -p dlgs-capi --no-default-features
mkdir -p "$T/release"
cp target/release/libdlgs_capi.so "$T/release/libdlgs_capi.so"
cargo build --release -p dlgs-capi
lib="$T/release/libdlgs_capi.so"
if ldd "$lib" | grep -E "libavcodec|libavformat|libavutil|libx265|libswscale"; then
  echo "gpl_free: $lib links FFmpeg/x265" >&2
  exit 1
fi
echo "gpl_free: ldd $lib shows no FFmpeg/x265"
# The decoder's own tests without the feature (the HEVC vector gives NoHevcDecoder), and its
# lints in that configuration.
cargo test --release -p dlgs-decoder --no-default-features --lib
cargo clippy --release -p dlgs-decoder --no-default-features --lib -- -D warnings
# The C example player against both libraries: identical output on files needing no HEVC.
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
build_player() {
  cc -O2 -Wall -Wextra -Werror -std=c11 capi/examples/player.c -Icapi/include \
    -L"$1" -ldlgs_capi -Wl,-rpath,"$(cd "$1" && pwd)" -o "$2"
}
build_player "$T/release" "$out/player-gpl-free"
build_player target/release "$out/player-full"
# Still files have one frame (t = 0 only); the dynamic ones are sampled between frames too.
for v in lod3-dynamic:0,0.5,1.2345,2.0,3.95 lod3-residuals:0,0.5,1.2345,2.0,5.5 \
  lod3-csog-compact:0 tiny-language:0; do
  f="format-spec/vectors/valid/${v%%:*}.dlgs"
  IFS=, read -r -a times <<<"${v#*:}"
  "$out/player-gpl-free" "$f" "${times[@]}" >"$out/a.txt" 2>/dev/null
  "$out/player-full" "$f" "${times[@]}" >"$out/b.txt" 2>/dev/null
  cmp "$out/a.txt" "$out/b.txt"
  echo "gpl_free: ${v%%:*}: $(grep -c fnv= "$out/a.txt") frames, same checksums as the full build"
done
if "$out/player-gpl-free" format-spec/vectors/valid/lod3-dynamic-intra.dlgs 0.5 >/dev/null 2>"$out/err.txt"; then
  echo "gpl_free: an HEVC file decoded without an HEVC decoder" >&2
  exit 1
fi
grep -q DLGS_STATUS_NO_HEVC_DECODER "$out/err.txt"
echo "gpl_free: HEVC time features -> $(grep -o 'DLGS_STATUS_NO_HEVC_DECODER' "$out/err.txt" | head -1)"
echo "gpl_free: passed"
