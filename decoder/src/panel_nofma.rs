//! The decoders' layers on CPUs without a fused multiply-add instruction (wasm32), still
//! exactly `fma` (format-spec §6.4), in SIMD lanes instead of one soft-float call per product.
//!
//! Each step `acc = fma(w, x, acc)` is computed as `s = w·x + acc` in binary64, then `s` rounded
//! to binary32:
//! * `w·x` is exact in binary64 (two binary32 significands make at most 48 bits);
//! * `s` is the exact sum `v` rounded once (binary64); rounding `s` to binary32 gives fma's
//!   `RN32(v)` **unless `s` is exactly halfway between two binary32 values**: the binary32
//!   midpoints around `v` are binary64 numbers and rounding is monotone, so a non-midpoint `s`
//!   lies strictly between the same two midpoints as `v` and rounds to the same binary32;
//! * for `2^-126 <= |s| < 2^127` a midpoint is a binary64 whose low 29 significand bits are
//!   `1 << 28`, and the rounding to binary32 is done in binary64 (`round32`) with no conversion
//!   (LLVM scalarises wasm's `f32x4.demote`/`f64x2.promote` pair);
//! * lanes that meet a midpoint or a non-zero `|s|` outside that range (binary32 subnormals,
//!   overflow; never seen in trained decoders) are recomputed with `f32::mul_add`;
//! * `s = 0` is exact (`v` is a multiple of `2^-298`, far above binary64's smallest subnormal)
//!   and is `+0`, as fma's: the chain starts at `+0` and an exact zero sum rounds to `+0`.
//!
//! The same bits as [`f32::mul_add`] on every input (tests below, and the conformance vectors in
//! the browser): the portable version of the sweep, which is what the tests run natively, does
//! the same arithmetic as the wasm SIMD one.

use crate::panel::{Lane, PANEL};

/// A panel column widened to binary64.
pub type Lane64 = [f64; PANEL];

const LOW: u64 = (1 << 29) - 1;
const HALF: u64 = 1 << 28;
const EXP: u64 = 0x7ff0_0000_0000_0000;
/// Added to a binary64's exponent bits: `1.5 · 2^(e + 29)` for `s` in `[2^e, 2^(e+1))`.
const MAGIC: u64 = (29 << 52) | (1 << 51);
/// High words of `2^-126` and `2^127` (binary64): the range `round32` serves.
const HI_MIN: u32 = 0x3810_0000;
const HI_MAX: u32 = 0x47e0_0000;

/// `s` rounded to binary32's precision (nearest, ties to even), as a binary64, for
/// `2^-126 <= |s| < 2^127` and `s = 0`: adding `c = 1.5 · 2^(e + 29)` rounds to a multiple of
/// `2^(e - 23)`, binary32's last place in `s`'s binade, and subtracting it is exact.
#[cfg(not(all(target_arch = "wasm32", target_feature = "simd128")))]
#[inline(always)]
fn round32(s: f64) -> f64 {
    let c = f64::from_bits((s.to_bits() & EXP) + MAGIC);
    (s + c) - c
}

/// Whether a lane's sum needs the exact path: a binary32 midpoint, or non-zero and outside
/// `[2^-126, 2^127)`.
#[cfg(not(all(target_arch = "wasm32", target_feature = "simd128")))]
#[inline(always)]
fn needs_exact(s: f64) -> bool {
    let bits = s.to_bits();
    let hi = ((bits >> 32) as u32) & 0x7fff_ffff;
    (bits & LOW) == HALF || (s != 0.0 && !(HI_MIN..HI_MAX).contains(&hi))
}

/// `y[o] = fma(w[o, n-1], x[n-1], ... fma(w[o, 0], x[0], +0))` per row, as
/// [`crate::panel`]'s `layer`, with the weights widened to binary64 (exactly). `wide` is
/// scratch.
pub fn layer(x: &[Lane], weights: &[f64], y: &mut [Lane], wide: &mut Vec<Lane64>) {
    let inputs = x.len();
    wide.clear();
    wide.extend(x.iter().map(|l| l.map(f64::from)));
    let mut pairs = y.chunks_exact_mut(2);
    let mut wp = weights.chunks_exact(2 * inputs);
    for (yq, w) in (&mut pairs).zip(&mut wp) {
        block::<2>(wide, x, w, yq);
    }
    let rest = pairs.into_remainder();
    for (yo, wo) in rest.chunks_mut(1).zip(wp.remainder().chunks_exact(inputs)) {
        block::<1>(wide, x, wo, yo);
    }
}

/// `Q` outputs (weights `w`, `Q` rows of the layer), four rows of the panel at a time.
#[inline(always)]
fn block<const Q: usize>(wide: &[Lane64], x: &[Lane], w: &[f64], y: &mut [Lane]) {
    let inputs = wide.len();
    for k in (0..PANEL).step_by(4) {
        let (acc, exact) = sweep::<Q>(wide, w, k);
        for q in 0..Q {
            let wo = &w[q * inputs..(q + 1) * inputs];
            for h in 0..4 {
                y[q][k + h] = if exact[q][h] {
                    x.iter()
                        .zip(wo)
                        .fold(0f32, |a, (xi, &wj)| xi[k + h].mul_add(wj as f32, a))
                } else {
                    acc[q][h] as f32
                };
            }
        }
    }
}

/// Rows `k..k + 4` of `Q` outputs: the binary64 sums rounded to binary32 after every step,
/// and whether a lane needs the exact path.
#[cfg(not(all(target_arch = "wasm32", target_feature = "simd128")))]
#[inline(always)]
fn sweep<const Q: usize>(wide: &[Lane64], w: &[f64], k: usize) -> ([[f64; 4]; Q], [[bool; 4]; Q]) {
    let inputs = wide.len();
    let mut acc = [[0f64; 4]; Q];
    let mut exact = [[false; 4]; Q];
    for (j, xj) in wide.iter().enumerate() {
        for q in 0..Q {
            let wj = w[q * inputs + j];
            for h in 0..4 {
                let s = xj[k + h] * wj + acc[q][h];
                exact[q][h] |= needs_exact(s);
                acc[q][h] = round32(s);
            }
        }
    }
    (acc, exact)
}

/// The same in wasm SIMD: two `f64x2` sums per output; both checks on four lanes at once from
/// the sums' low words (the bits below binary32's last place) and high words (sign, exponent).
#[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
#[inline(always)]
fn sweep<const Q: usize>(wide: &[Lane64], w: &[f64], k: usize) -> ([[f64; 4]; Q], [[bool; 4]; Q]) {
    use core::arch::wasm32::*;
    let inputs = wide.len();
    let (low, half) = (u32x4_splat(LOW as u32), u32x4_splat(HALF as u32));
    let abs = u32x4_splat(0x7fff_ffff);
    // hi - 1 (a zero sum wraps to -1): below HI_MIN - 1 unsigned, or above HI_MAX - 2 signed.
    let (one, tiny, huge) = (
        u32x4_splat(1),
        u32x4_splat(HI_MIN - 1),
        u32x4_splat(HI_MAX - 2),
    );
    let (exp, magic) = (u64x2_splat(EXP), u64x2_splat(MAGIC));
    let round32 = |s: v128| {
        let c = i64x2_add(v128_and(s, exp), magic);
        f64x2_sub(f64x2_add(s, c), c)
    };
    let zero = f64x2_splat(0.0);
    let mut acc = [[zero; 2]; Q];
    let mut flag = [u32x4_splat(0); Q];
    for (j, xj) in wide.iter().enumerate() {
        let x0 = f64x2(xj[k], xj[k + 1]);
        let x1 = f64x2(xj[k + 2], xj[k + 3]);
        for q in 0..Q {
            let wj = f64x2_splat(w[q * inputs + j]);
            let s0 = f64x2_add(f64x2_mul(x0, wj), acc[q][0]);
            let s1 = f64x2_add(f64x2_mul(x1, wj), acc[q][1]);
            let lo = i32x4_shuffle::<0, 2, 4, 6>(s0, s1);
            let hi = i32x4_sub(v128_and(i32x4_shuffle::<1, 3, 5, 7>(s0, s1), abs), one);
            let range = v128_or(u32x4_lt(hi, tiny), i32x4_gt(hi, huge));
            let f = v128_or(i32x4_eq(v128_and(lo, low), half), range);
            flag[q] = v128_or(flag[q], f);
            acc[q] = [round32(s0), round32(s1)];
        }
    }
    let lanes = |a: [v128; 2]| {
        [
            f64x2_extract_lane::<0>(a[0]),
            f64x2_extract_lane::<1>(a[0]),
            f64x2_extract_lane::<0>(a[1]),
            f64x2_extract_lane::<1>(a[1]),
        ]
    };
    let flags = |f: v128| {
        [
            u32x4_extract_lane::<0>(f) != 0,
            u32x4_extract_lane::<1>(f) != 0,
            u32x4_extract_lane::<2>(f) != 0,
            u32x4_extract_lane::<3>(f) != 0,
        ]
    };
    (acc.map(lanes), flag.map(flags))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `2^e` for binary32 exponents, exactly (no `powi`).
    fn pow2(e: i32) -> f32 {
        f32::from_bits(((e + 127) as u32) << 23)
    }

    fn reference(x: &[Lane], weights: &[f32], outputs: usize) -> Vec<Lane> {
        let inputs = x.len();
        (0..outputs)
            .map(|o| {
                std::array::from_fn(|l| {
                    (0..inputs).fold(0f32, |a, i| x[i][l].mul_add(weights[o * inputs + i], a))
                })
            })
            .collect()
    }

    fn check(x: &[Lane], weights: &[f32], outputs: usize) -> usize {
        let want = reference(x, weights, outputs);
        let mut got = vec![[0f32; PANEL]; outputs];
        let w64: Vec<f64> = weights.iter().map(|&w| f64::from(w)).collect();
        layer(x, &w64, &mut got, &mut Vec::new());
        assert_bits(&got, &want);
        outputs * PANEL
    }

    fn assert_bits(got: &[Lane], want: &[Lane]) {
        for o in 0..got.len() {
            for l in 0..PANEL {
                assert_eq!(
                    got[o][l].to_bits(),
                    want[o][l].to_bits(),
                    "output {o} row {l}: {} vs {}",
                    got[o][l],
                    want[o][l]
                );
            }
        }
    }

    fn f16_exact(bits: u16) -> f32 {
        // binary16 -> binary32 by hand (no `half` in this crate's dependencies).
        let sign = if bits >> 15 == 1 { -1.0 } else { 1.0 };
        let e = i32::from((bits >> 10) & 0x1f);
        let m = f32::from(bits & 0x3ff);
        match e {
            0 => sign * m * pow2(-24),
            31 => sign * 65504.0,
            _ => sign * (1.0 + m / 1024.0) * pow2(e - 15),
        }
    }

    #[test]
    fn same_bits_as_mul_add_on_random_binary16_weights() {
        let mut rng = fastrand::Rng::with_seed(11);
        let mut n = 0;
        for (inputs, outputs) in [(16, 64), (64, 3), (64, 7), (12, 9), (1, 5)] {
            for scale in [1e-3f32, 1.0, 1e3, 1e-38, 1e30] {
                let weights: Vec<f32> = (0..inputs * outputs)
                    .map(|_| f16_exact(rng.u16(..)))
                    .map(|w| if w.is_finite() { w } else { 1.0 })
                    .collect();
                let x: Vec<Lane> = (0..inputs)
                    .map(|_| std::array::from_fn(|_| (rng.f32() - 0.5) * scale))
                    .collect();
                n += check(&x, &weights, outputs);
            }
        }
        assert_eq!(n, 88 * PANEL * 5);
    }

    /// Sums whose binary64 rounding lands exactly halfway between two binary32 values, the case
    /// where plain double rounding differs from fma: must still give fma's bits.
    #[test]
    fn halfway_sums_take_the_exact_path() {
        // w·x = 2^-24 + k·2^-58 (0 < k < 32) with w a binary16 in [1, 2) and x a binary32: after
        // acc = 1, the exact sum 1 + 2^-24 + k·2^-58 rounds (binary64) to 1 + 2^-24, a binary32
        // midpoint. fma rounds up to 1 + 2^-23; rounding the binary64 again gives 1 (to even).
        let (w, x) = (1025u64..2048)
            .step_by(2)
            .find_map(|w| {
                let x = (1u64 << 34).div_ceil(w);
                let k = w * x - (1 << 34);
                (k > 0 && k < 32 && x < 1 << 24).then_some((w, x))
            })
            .expect("a factorisation near 2^34");
        let w = w as f32 / 1024.0;
        let x = x as f32 * pow2(-48);
        let one = [1.0f32; PANEL];
        let xs: Lane = std::array::from_fn(|l| if l % 2 == 0 { x } else { 1.0 });
        let weights = vec![1.0, w];
        let mut got = vec![[0f32; PANEL]; 1];
        layer(&[one, xs], &[1.0, f64::from(w)], &mut got, &mut Vec::new());
        let want = reference(&[one, xs], &weights, 1);
        assert_eq!(got, want);
        assert_eq!(want[0][0], 1.0 + pow2(-23));
        let double_rounded = (f64::from(x) * f64::from(w) + 1.0) as f32;
        assert_eq!(double_rounded, 1.0, "the case this test is about");
    }

    #[test]
    fn subnormal_and_signed_zero_sums() {
        let mut rng = fastrand::Rng::with_seed(5);
        let weights: Vec<f32> = (0..8 * 6).map(|_| f16_exact(rng.u16(..0x7c00))).collect();
        let x: Vec<Lane> = (0..8)
            .map(|i| {
                std::array::from_fn(|l| match (i + l) % 4 {
                    0 => f32::from_bits(rng.u32(1..0x0080_0000)), // subnormal
                    1 => -0.0,
                    2 => 0.0,
                    _ => (rng.f32() - 0.5) * 1e-36,
                })
            })
            .collect();
        check(&x, &weights, 6);
    }

    #[test]
    fn same_bits_as_mul_add_on_binary32_weights_and_subnormal_sums() {
        let mut rng = fastrand::Rng::with_seed(3);
        let mut n = 0;
        for scale in [1.0f32, 1e-20, 1e-30] {
            let weights: Vec<f32> = (0..32 * 7).map(|_| (rng.f32() - 0.5) * scale).collect();
            let x: Vec<Lane> = (0..32)
                .map(|_| std::array::from_fn(|_| (rng.f32() - 0.5) * 1e-10))
                .collect();
            n += check(&x, &weights, 7);
        }
        assert_eq!(n, 3 * 7 * PANEL);
    }

    #[test]
    fn overflow_and_random_exponents() {
        let mut rng = fastrand::Rng::with_seed(9);
        let mut n = 0;
        for scale in [1e38f32, 3e19, 1.0] {
            let weights: Vec<f32> = (0..24 * 5)
                .map(|_| f32::from_bits(rng.u32(..0x7f80_0000) | (rng.u32(..2) << 31)))
                .map(|w| w.clamp(-4.0, 4.0))
                .collect();
            let x: Vec<Lane> = (0..24)
                .map(|_| std::array::from_fn(|_| (rng.f32() - 0.5) * scale))
                .collect();
            n += check(&x, &weights, 5);
        }
        assert_eq!(n, 3 * 5 * PANEL);
    }

    /// The fast path is the common one: on ordinary values almost no lane needs the exact path
    /// (a version that always fell back would pass the bit tests above).
    #[test]
    fn ordinary_sums_stay_on_the_fast_path() {
        let mut rng = fastrand::Rng::with_seed(1);
        let inputs = 64;
        let w: Vec<f64> = (0..2 * inputs)
            .map(|_| f64::from(rng.f32() - 0.5))
            .collect();
        let wide: Vec<Lane64> = (0..inputs)
            .map(|_| std::array::from_fn(|_| f64::from(rng.f32() * 2.0)))
            .collect();
        let mut exact = 0;
        for k in (0..PANEL).step_by(4) {
            let (_, e) = sweep::<2>(&wide, &w, k);
            exact += e.iter().flatten().filter(|&&b| b).count();
        }
        assert_eq!(exact, 0);
    }
}
