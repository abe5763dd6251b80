#!/usr/bin/env bash
# Install the system packages dlgs builds against (Debian/Ubuntu). Safe to run repeatedly.
set -euo pipefail
# FFmpeg (libavcodec with libx265) for the 12-bit HEVC time features; clang for bindgen;
# DejaVu Sans for the text of `dlgs rd` plots; musl-dev for the check that decoding owes nothing
# to the C library's math (scripts/libm_independence.sh).
pkgs=(pkg-config libzstd-dev clang libclang-dev libavcodec-dev libavformat-dev libavutil-dev libswscale-dev libswresample-dev libavfilter-dev libavdevice-dev libx265-dev fonts-dejavu-core musl-dev python3 binutils)
missing=()
for p in "${pkgs[@]}"; do dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p"); done
if [ ${#missing[@]} -gt 0 ]; then
  sudo_cmd=""
  [ "$(id -u)" -ne 0 ] && sudo_cmd="sudo"
  $sudo_cmd apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
command -v cargo >/dev/null || { echo "cargo not found: install Rust (rustup) first" >&2; exit 1; }
