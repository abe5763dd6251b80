//! Deterministic elementary functions (format-spec Appendix B).
//!
//! The decoder must give the same floats on every machine, but `f32::ln`, `f64::exp`,
//! `f32::sin` and `f32::acos` call the platform's C library, whose results differ in the last
//! bit between glibc, musl, macOS and Windows. These functions use only IEEE 754 binary64
//! addition, subtraction, multiplication, division, comparisons and exact bit manipulation,
//! in the order written here (Rust never fuses `a * b + c`), so every conforming platform
//! computes the same bits. The spec writes out the same algorithms step by step.
//!
//! Accuracy: `ln` and `exp` are within about one binary64 ulp; the binary32 results the
//! decoder uses are correctly rounded on every input the format produces where that is
//! checkable (every opacity level of every bit width: the test in `chunks/csog/quantiser.rs`). `sin` and `acos` are
//! within a few binary64 ulps on the ranges the deformation uses.

use multiversion::multiversion;

/// `ln 2` split so that `k * LN2_HI` is exact for `|k| < 2^20` (32 significant bits).
const LN2_HI: f64 = f64::from_bits(0x3fe6_2e42_fee0_0000);
const LN2_LO: f64 = f64::from_bits(0x3dea_39ef_3579_3c76);
/// `π/2` split so that `k * PIO2_HI` is exact for `|k| < 2^20` (33 significant bits).
const PIO2_HI: f64 = f64::from_bits(0x3ff9_21fb_5440_0000);
const PIO2_LO: f64 = f64::from_bits(0x3dd0_b461_1a62_6331);
const SQRT2: f64 = std::f64::consts::SQRT_2;

/// Terms of the `ln` series: `R(z) = sum_{k=1..=12} 2/(2k+1) z^k`.
const LN_TERMS: usize = 12;
/// Degree of the `exp` Taylor polynomial.
const EXP_DEGREE: usize = 13;
/// `asin` series terms (`z <= 1/4`).
const ASIN_TERMS: usize = 27;

// The coefficients, evaluated once at compile time with the same binary64 operations the
// spec writes (Rust's constant evaluation is IEEE 754 binary64 with round to nearest even, so
// these are the bits a run-time evaluation gives).

/// `LN_C[k] = 2 / (2k + 1)`.
const LN_C: [f64; LN_TERMS + 1] = {
    let mut c = [0.0; LN_TERMS + 1];
    let mut k = 1;
    while k <= LN_TERMS {
        c[k] = 2.0 / (2 * k + 1) as f64;
        k += 1;
    }
    c
};

/// `n!` as a binary64: products from 1.0, left to right (exact for `n <= 18`).
const fn factorial(n: usize) -> f64 {
    let mut a = 1.0;
    let mut i = 1;
    while i <= n {
        a *= i as f64;
        i += 1;
    }
    a
}

/// `EXP_C[j] = 1 / j!`.
const EXP_C: [f64; EXP_DEGREE + 1] = {
    let mut c = [0.0; EXP_DEGREE + 1];
    let mut j = 1;
    while j <= EXP_DEGREE {
        c[j] = 1.0 / factorial(j);
        j += 1;
    }
    c
};

/// `SIN_C[j] = (-1)^j / (2j + 1)!`, `COS_C[j] = (-1)^j / (2j)!`, for `j` in 1..=8.
const SIN_C: [f64; 9] = {
    let mut c = [0.0; 9];
    let mut j = 1;
    while j <= 8 {
        let sign = if j % 2 == 1 { -1.0 } else { 1.0 };
        c[j] = sign / factorial(2 * j + 1);
        j += 1;
    }
    c
};
const COS_C: [f64; 9] = {
    let mut c = [0.0; 9];
    let mut j = 1;
    while j <= 8 {
        let sign = if j % 2 == 1 { -1.0 } else { 1.0 };
        c[j] = sign / factorial(2 * j);
        j += 1;
    }
    c
};

/// `ASIN_C[n] = (2n)! / (4^n (n!)^2 (2n + 1))`, the product `(2n-1)!!/(2n)!!` built term by
/// term: `t = (t * (2n - 1)) / (2n)`, `ASIN_C[n] = t / (2n + 1)`.
const ASIN_C: [f64; ASIN_TERMS] = {
    let mut c = [0.0; ASIN_TERMS];
    let mut t = 1.0;
    let mut n = 1;
    while n < ASIN_TERMS {
        t = t * (2 * n - 1) as f64 / (2 * n) as f64;
        c[n] = t / (2 * n + 1) as f64;
        n += 1;
    }
    c
};

/// Natural logarithm, binary64. `ln(0) = -inf`, `ln(+inf) = +inf`, negative or NaN: NaN.
pub fn ln(x: f64) -> f64 {
    if x.is_nan() || x < 0.0 {
        return f64::NAN;
    }
    if x == 0.0 {
        return f64::NEG_INFINITY;
    }
    if x == f64::INFINITY {
        return x;
    }
    let (mut x, mut e) = (x, 0i64);
    if x < f64::MIN_POSITIVE {
        // Subnormal: scale into the normal range (exact).
        x *= f64::from_bits(0x4350_0000_0000_0000); // 2^54
        e = -54;
    }
    let bits = x.to_bits();
    e += ((bits >> 52) & 0x7ff) as i64 - 1023;
    // m in [1, 2), exactly x's significand.
    let mut m = f64::from_bits((bits & 0x000f_ffff_ffff_ffff) | 0x3ff0_0000_0000_0000);
    if m > SQRT2 {
        m *= 0.5;
        e += 1;
    }
    // m in [1/√2, √2]: f = m - 1 is exact (Sterbenz).
    let f = m - 1.0;
    let s = f / (2.0 + f);
    let z = s * s;
    let mut r = 0.0;
    for k in (1..=LN_TERMS).rev() {
        r = (r + LN_C[k]) * z;
    }
    let hfsq = 0.5 * f * f;
    let dk = e as f64;
    dk * LN2_HI - ((hfsq - (s * (hfsq + r) + dk * LN2_LO)) - f)
}

/// `e^x`, binary64. Above 709.0: +inf; below -708.0: 0 (no subnormal results); NaN: NaN.
pub fn exp(x: f64) -> f64 {
    if x.is_nan() {
        return x;
    }
    if x > 709.0 {
        return f64::INFINITY;
    }
    if x < -708.0 {
        return 0.0;
    }
    // k = round(x / ln 2), ties away from zero; r = x - k ln 2 in [-0.35, 0.35].
    let k = (x * std::f64::consts::LOG2_E).round();
    let r = (x - k * LN2_HI) - k * LN2_LO;
    let mut p = 0.0;
    for j in (1..=EXP_DEGREE).rev() {
        p = (p + EXP_C[j]) * r;
    }
    let p = p + 1.0;
    // k in [-1022, 1023]: 2^k is a normal binary64.
    p * f64::from_bits(((k as i64 + 1023) as u64) << 52)
}

/// `sin x`, binary64, for finite `x` (accurate for `|x| < 2^20 π/2`); non-finite: NaN.
pub fn sin(x: f64) -> f64 {
    sin_core(x)
}

/// [`sin`] of every value in place: the same bits, in SIMD lanes where the CPU has them (the
/// steps are [`sin`]'s, without a branch or a conversion to an integer).
#[multiversion(targets("x86_64+avx512f+avx512vl+avx2+fma", "x86_64+avx2+fma", "aarch64+neon"))]
pub fn sin_lanes(values: &mut [f64]) {
    for x in values.iter_mut() {
        *x = sin_core(*x);
    }
}

/// `round(t)`, halves away from zero, from `trunc` (exact) and the exact fraction `t - trunc t`:
/// the same value as `f64::round` (up to the sign of a zero), vectorisable.
#[inline(always)]
fn round_half_away(t: f64) -> f64 {
    let whole = t.trunc();
    let step: f64 = if (t - whole).abs() >= 0.5 { 1.0 } else { 0.0 };
    whole + step.copysign(t)
}

/// `k mod 4` of an integer-valued `k` as an integer, non-negative, exactly: `k/4` and its
/// floor are exact, and so is `k - 4 floor(k/4)`, in `0..=3`, also for `k` beyond `2^63`.
#[inline(always)]
fn quadrant(k: f64) -> f64 {
    k - 4.0 * (k * 0.25).floor()
}

/// Appendix B's `sin`, branch-free so that it vectorises.
#[inline(always)]
fn sin_core(x: f64) -> f64 {
    let k = round_half_away(x * std::f64::consts::FRAC_2_PI);
    let r = (x - k * PIO2_HI) - k * PIO2_LO;
    let z = r * r;
    // sin r = r (1 - z/3! + z^2/5! - ...), cos r = 1 - z/2! + z^2/4! - ...; |r| <= π/4.
    let mut ps = 0.0;
    let mut pc = 0.0;
    for j in (1..9).rev() {
        ps = (ps + SIN_C[j]) * z;
        pc = (pc + COS_C[j]) * z;
    }
    let (s, c) = (r + r * ps, 1.0 + pc);
    // By k mod 4: s, c, -s, -c (selects, so that the loop vectorises).
    let q = quadrant(k);
    let odd = (q == 1.0) | (q == 3.0);
    let v = if odd { c } else { s };
    let v = if q >= 2.0 { -v } else { v };
    if x.is_finite() {
        v
    } else {
        f64::NAN
    }
}

/// `asin y` for `|y| <= 1/2` by its Taylor series in `z = y^2`.
#[inline(always)]
fn asin_small(y: f64) -> f64 {
    let z = y * y;
    let mut p = 0.0;
    for n in (1..ASIN_TERMS).rev() {
        p = (p + ASIN_C[n]) * z;
    }
    y + y * p
}

/// `acos x` in `[0, π]`, binary64; outside `[-1, 1]` or NaN: NaN.
pub fn acos(x: f64) -> f64 {
    acos_core(x)
}

/// [`acos`] of every value in place: the same bits, in SIMD lanes where the CPU has them.
#[multiversion(targets("x86_64+avx512f+avx512vl+avx2+fma", "x86_64+avx2+fma", "aarch64+neon"))]
pub fn acos_lanes(values: &mut [f64]) {
    for x in values.iter_mut() {
        *x = acos_core(*x);
    }
}

/// Appendix B's `acos`, branch-free so that it vectorises: the series' argument and the
/// result's form are chosen by selects. Beyond `1/2`, `1 - |x|` is the spec's `1 - x` for
/// `x > 0` and its `1 + x` for `x < 0` (the same binary64 operation).
#[inline(always)]
fn acos_core(x: f64) -> f64 {
    use std::f64::consts::{FRAC_PI_2, PI};
    let a = x.abs();
    let middle = a <= 0.5;
    // 1 - |x| is exact for |x| in [1/2, 1] (Sterbenz); halving is exact.
    let y = if middle { x } else { ((1.0 - a) * 0.5).sqrt() };
    let p = asin_small(y);
    let ends = if x > 0.0 { 2.0 * p } else { PI - 2.0 * p };
    let v = if middle { FRAC_PI_2 - p } else { ends };
    if a <= 1.0 {
        v
    } else {
        // Outside [-1, 1], and NaN (which fails every comparison).
        f64::NAN
    }
}

/// [`ln`] of a binary32, rounded to binary32.
pub fn ln_f32(x: f32) -> f32 {
    ln(x as f64) as f32
}

/// [`sin`] of a binary32, rounded to binary32.
pub fn sin_f32(x: f32) -> f32 {
    sin(x as f64) as f32
}

/// [`acos`] of a binary32, rounded to binary32.
pub fn acos_f32(x: f32) -> f32 {
    acos(x as f64) as f32
}

/// The logistic function `1 / (1 + e^-v)` in binary64 with [`exp`], rounded to binary32.
pub fn sigmoid_f32(v: f32) -> f32 {
    (1.0 / (1.0 + exp(-(v as f64)))) as f32
}

#[cfg(test)]
#[allow(clippy::disallowed_methods)] // the platform's functions are the accuracy reference
mod tests {
    use super::*;

    fn ulps(a: f64, b: f64) -> u64 {
        (a.to_bits() as i64 - b.to_bits() as i64).unsigned_abs()
    }

    #[test]
    fn ln_matches_the_platform_within_an_ulp() {
        let mut rng = fastrand::Rng::with_seed(7);
        for _ in 0..200_000 {
            let x = f64::from_bits(rng.u64(1..0x7fef_ffff_ffff_ffff));
            assert!(ulps(ln(x), x.ln()) <= 1, "ln({x:e}) = {:e}", ln(x));
        }
        for x in [1.0, 2.0, 0.5, SQRT2, 1e-310, f64::MIN_POSITIVE, f64::MAX] {
            assert!(ulps(ln(x), x.ln()) <= 1, "ln({x:e})");
        }
        assert_eq!(ln(1.0), 0.0);
        assert_eq!(ln(0.0), f64::NEG_INFINITY);
        assert!(ln(-1.0).is_nan() && ln(f64::NAN).is_nan());
        assert_eq!(ln(f64::INFINITY), f64::INFINITY);
    }

    #[test]
    fn exp_matches_the_platform_within_two_ulps() {
        let mut rng = fastrand::Rng::with_seed(8);
        for _ in 0..200_000 {
            let x = rng.f64() * 1416.0 - 708.0;
            assert!(ulps(exp(x), x.exp()) <= 2, "exp({x}) = {:e}", exp(x));
        }
        assert_eq!(exp(0.0), 1.0);
        assert_eq!(exp(710.0), f64::INFINITY);
        assert_eq!(exp(-709.0), 0.0);
        assert!(exp(f64::NAN).is_nan());
    }

    #[test]
    fn sin_and_acos_are_accurate_where_slerp_uses_them() {
        for i in -40_000..=40_000 {
            let x = i as f64 * 1e-4;
            assert!((sin(x) - x.sin()).abs() <= 4e-16, "sin({x})");
        }
        for i in -100_000..=100_000 {
            let x = i as f64 * 1e-5;
            assert!((acos(x) - x.acos()).abs() <= 8e-16, "acos({x})");
        }
        assert_eq!(acos(1.0), 0.0);
        assert_eq!(acos(-1.0), std::f64::consts::PI);
        assert!(acos(1.5).is_nan() && sin(f64::INFINITY).is_nan());
        assert_eq!(sin(0.0), 0.0);
    }

    /// The lanes give [`sin`]'s bits; both take `k mod 4` of `k` as an integer (Appendix B),
    /// also where `k` is beyond every machine integer.
    #[test]
    fn sin_lanes_give_the_same_bits_as_sin() {
        let mut rng = fastrand::Rng::with_seed(9);
        let mut xs: Vec<f64> = (0..100_000)
            .map(|i| match i % 4 {
                0 => rng.f64() * 8.0 - 4.0,
                1 => rng.f64() * std::f64::consts::PI,
                2 => (rng.f64() - 0.5) * 1e7,
                _ => f64::from_bits(rng.u64(..)),
            })
            .collect();
        // Halves of the quadrant: `x · 2/π` within an ulp of `n + 1/2`.
        for n in -50..50 {
            let t = n as f64 + 0.5;
            let x = t / std::f64::consts::FRAC_2_PI;
            xs.extend([
                x,
                f64::from_bits(x.to_bits() + 1),
                f64::from_bits(x.to_bits() - 1),
            ]);
        }
        xs.extend([
            0.0,
            -0.0,
            1e-300,
            f64::MIN_POSITIVE,
            1e19,
            -1e19,
            4e19,
            1e300,
            f64::MAX,
            -f64::MAX,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ]);
        let mut lanes = xs.clone();
        sin_lanes(&mut lanes);
        for (x, got) in xs.iter().zip(&lanes) {
            let want = sin(*x);
            assert!(
                got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
                "sin({x:e}): lanes {got:e}, scalar {want:e}"
            );
        }
        let two = 2f64;
        for (k, q) in [
            (0.0, 0.0),
            (5.0, 1.0),
            (-1.0, 3.0),
            (-6.0, 2.0),
            (two.powi(53) + 2.0, 2.0),
            (two.powi(64), 0.0),
            (-two.powi(70), 0.0),
        ] {
            assert_eq!(quadrant(k), q, "{k:e} mod 4");
        }
    }

    /// The lanes give [`acos`]'s bits on `[-1, 1]`, at its branch points and outside.
    #[test]
    fn acos_lanes_give_the_same_bits_as_acos() {
        let mut rng = fastrand::Rng::with_seed(10);
        let mut xs: Vec<f64> = (0..100_000)
            .map(|i| match i % 3 {
                0 => rng.f64() * 2.0 - 1.0,
                1 => 1.0 - rng.f64() * 1e-3,
                _ => f64::from_bits(rng.u64(..)),
            })
            .collect();
        for b in [0.5f64, -0.5, 1.0, -1.0, 0.0, -0.0, 1.0 - 1e-4, -1.0 + 1e-4] {
            xs.extend([
                b,
                f64::from_bits(b.to_bits() + 1),
                f64::from_bits(b.to_bits().wrapping_sub(1)),
            ]);
        }
        xs.extend([1.5, -1.5, f64::INFINITY, f64::NEG_INFINITY, f64::NAN]);
        let mut lanes = xs.clone();
        acos_lanes(&mut lanes);
        for (x, got) in xs.iter().zip(&lanes) {
            let want = acos(*x);
            assert!(
                got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
                "acos({x:e}): lanes {got:e}, scalar {want:e}"
            );
        }
    }

    #[test]
    fn sigmoid_is_within_an_f32_ulp_and_saturates() {
        for i in -20_000..=20_000 {
            let v = i as f32 * 1e-3;
            let want = (1.0 / (1.0 + (-(v as f64)).exp())) as f32;
            let got = sigmoid_f32(v);
            assert!(got.to_bits().abs_diff(want.to_bits()) <= 1, "sigmoid({v})");
        }
        assert_eq!(sigmoid_f32(-1e30), 0.0);
        assert_eq!(sigmoid_f32(1e30), 1.0);
    }
}
