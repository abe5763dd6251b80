#!/usr/bin/env bash
# Decoding does not depend on the platform's C math library (format-spec Appendix B): with a
# libm whose log/exp/sin/cos/acos/tanh/pow are all off by a relative 1e-6 preloaded, the
# conformance test still decodes every vector to its listed checksums and frames bit for bit;
# as a control, a test that compares with the C library's `ln` fails under the same libm.
# Then the same with musl's own libm (its math objects from Debian's musl-dev, linked into a
# shared object and preloaded), which really differs from glibc's on sinf/acosf/log: what a
# decoder built for musl would call. (The Rust musl target itself cannot be fetched here.)
set -euo pipefail
cd "$(dirname "$0")/.."
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
cc -O2 -shared -fPIC tests/libm/perturbed_libm.c -o "$out/libperturbed.so" -ldl
test_binary() { # package, test target (or --lib): the test executable cargo builds
  cargo test --release -p "$1" $2 --no-run --message-format=json 2>/dev/null |
    python3 -c 'import json,sys
for l in sys.stdin:
    m=json.loads(l)
    if m.get("reason")=="compiler-artifact" and m.get("executable") and m["profile"]["test"]:
        print(m["executable"])' | tail -n 1
}
conf=$(test_binary dlgs-tests "--test conformance")
lib=$(test_binary dlgs --lib)
ldd "$conf" | grep 'libm\.so' >/dev/null || { echo "libm_independence: $conf does not link libm" >&2; exit 1; }
if LD_PRELOAD="$out/libperturbed.so" "$lib" --exact elementary::tests::ln_matches_the_platform_within_an_ulp \
  >"$out/control.txt" 2>&1; then
  echo "libm_independence: control failed: the preloaded libm did not change the C library's ln" >&2
  exit 1
fi
echo "libm_independence: control: the C library's ln differs under the preloaded libm (as intended)"
# The generator test is skipped: building vectors (synthetic language, encoder) may use libm.
LD_PRELOAD="$out/libperturbed.so" "$conf" --skip committed_vectors_equal_what_the_generator_builds \
  2>&1 | tail -n 3
echo "libm_independence: every vector decodes to its checksums and frames with the perturbed libm"
# musl's libm: the math functions of musl-dev's libc.a and what they need, as a shared object.
musl_a=/usr/lib/$(uname -m)-linux-musl/libc.a
if [ ! -f "$musl_a" ]; then
  echo "libm_independence: $musl_a missing (apt-get install musl-dev)" >&2
  exit 1
fi
mkdir "$out/musl"
(
  cd "$out/musl"
  for f in log logf log2 log2f exp expf exp2 exp2f sin sinf cos cosf acos acosf tanh tanhf pow powf expm1 expm1f; do
    ar x "$musl_a" "$f.lo"
  done
  for _ in 1 2 3 4 5 6 7 8 9 10; do
    missing=$(cc -shared -o libmuslm.so ./*.lo -Wl,--no-undefined 2>&1 |
      grep -o "undefined reference to \`[^']*'" | sed "s/undefined reference to \`//; s/'//" | sort -u || true)
    [ -z "$missing" ] && break
    for s in $missing; do
      o=$(nm -A "$musl_a" 2>/dev/null | grep -E " [TDRB] $s\$" | head -n 1 | cut -d: -f2 || true)
      [ -n "$o" ] && ar x "$musl_a" "$o"
    done
  done
  cc -shared -o libmuslm.so ./*.lo -Wl,--no-undefined
)
cc -O2 tests/libm/compare_libm.c -o "$out/compare_libm" -lm -ldl
echo "libm_independence: $("$out/compare_libm" "$out/musl/libmuslm.so")"
LD_PRELOAD="$out/musl/libmuslm.so" "$conf" --skip committed_vectors_equal_what_the_generator_builds \
  2>&1 | tail -n 3
echo "libm_independence: every vector decodes to its checksums and frames with musl's libm"
