# Source this: puts Debian's rustc-web 1.96 (not rustup) in front and configures wasm32 builds.
# Debian ships no prebuilt wasm32 std for rustc-web, so std is rebuilt from rust-web-src (-Zbuild-std).
export PATH=/usr/bin:$PATH
export RUSTC=/usr/bin/rustc RUSTDOC=/usr/bin/rustdoc CARGO=/usr/bin/cargo
export RUSTC_BOOTSTRAP=1                       # allow -Zbuild-std on a stable compiler
export CARGO_TARGET_WASM32_UNKNOWN_UNKNOWN_LINKER=/usr/lib/llvm-22/bin/wasm-ld   # no rust-lld in Debian; lld-22 matches rustc-web's LLVM 22
export CARGO_TARGET_DIR=${CARGO_TARGET_DIR:-$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)/target/wasm}
export CARGO_BUILD_JOBS=${CARGO_BUILD_JOBS:-2}
WASM_BUILD_STD_ARGS="--target wasm32-unknown-unknown -Zbuild-std=std,panic_abort"
# wasm SIMD (every browser with WebGL2 since 2021-2023): the decoders' exact fused multiply-adds
# run in f64x2 lanes (decoder/src/panel_nofma.rs) instead of one soft-float call each.
export RUSTFLAGS="-C target-feature=+simd128"
