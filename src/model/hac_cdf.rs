//! The integer Gaussian CDF of `AHAC` (format-spec §6.13.6): every symbol of a coded anchor
//! attribute has a categorical model at precision 24 computed on the fly from its context's
//! mean, scale and step, with a fixed table of the normal CDF and integer interpolation, so the
//! model is the same on every machine. A `constriction` model drives the range coder
//! (Appendix A) with it; the decoder searches the symbol from the mean without building a table.

use std::borrow::Borrow;
use std::num::NonZeroU32;

use constriction::stream::model::{DecoderModel, EncoderModel, EntropyModel};

use super::phi_table::PHI_TABLE;

/// Probability precision of the symbol models.
pub const PRECISION: usize = 24;
/// Largest alphabet `hi - lo + 1` of one stream (format limit).
pub const MAX_ALPHABET: u32 = 1 << 16;
/// Largest `|lo|`, `|hi|`: half-integers `x - 0.5` are then exact in f32.
pub const MAX_SYMBOL_MAGNITUDE: i32 = (1 << 23) - 1;
/// Smallest scale: `σ = max(scale, 1e-9)`.
pub const SIGMA_MIN: f32 = 1e-9;
/// `|adj|` is clamped to this before `tanh`.
pub const TANH_CLAMP: f32 = 20.0;

/// `Φfix(t)`: the table interpolated in integers, `0 ..= 2^32` (§6.13.6).
#[inline]
pub fn phi_fix(t: f32) -> u64 {
    let t = if t.is_nan() { -8.0 } else { t.clamp(-8.0, 8.0) };
    let v = (t + 8.0) * 256.0;
    // v in [0, 4096]: truncation is floor.
    let k = (v as u32).min(4095);
    let fr = ((v - k as f32) * 65536.0) as u64;
    let (a, b) = (PHI_TABLE[k as usize], PHI_TABLE[k as usize + 1]);
    a + (((b - a) * fr) >> 16)
}

/// The step `Q = base (1 + tanh(adj))` with §6.13.5's deterministic `tanh`.
#[inline]
pub fn step(base: f32, adj: f32) -> f32 {
    base * (1.0 + tanh_f32(adj))
}

/// `tanh` for the step (§6.13.5): `v` clamped to `[-20, 20]` (NaN -> 0), then in binary64 with
/// Appendix B's `exp`: `sign(v) (1 - 2 / (exp(2|v|) + 1))`, rounded to f32.
pub fn tanh_f32(v: f32) -> f32 {
    let v = if v.is_nan() {
        0.0
    } else {
        v.clamp(-TANH_CLAMP, TANH_CLAMP)
    };
    let a = (v as f64).abs();
    let m = 1.0 - 2.0 / (crate::elementary::exp(2.0 * a) + 1.0);
    (if v < 0.0 { -m } else { m }) as f32
}

/// One symbol's model: alphabet `lo ..= lo + len - 1`, mean `mu`, scale `sigma` (clamped
/// here), step `q`.
#[derive(Debug, Clone, Copy)]
pub struct GaussModel {
    pub lo: i32,
    pub len: u32,
    pub mu: f32,
    pub sigma: f32,
    pub q: f32,
}

impl GaussModel {
    /// `sigma` is clamped to [`SIGMA_MIN`] (NaN too); `len` in `2 ..= MAX_ALPHABET`.
    #[inline]
    pub fn new(lo: i32, len: u32, mu: f32, sigma: f32, q: f32) -> Self {
        let sigma = if sigma > SIGMA_MIN { sigma } else { SIGMA_MIN };
        GaussModel {
            lo,
            len,
            mu,
            sigma,
            q,
        }
    }

    /// `C(j)` for `j` in `0 ..= len` (§6.13.6): strictly increasing, `C(0) = 0`,
    /// `C(len) = 2^24`.
    #[inline]
    pub fn cdf(&self, j: u32) -> u32 {
        if j == 0 {
            return 0;
        }
        if j >= self.len {
            return 1 << PRECISION;
        }
        let e = ((self.lo + j as i32) as f32 - 0.5) * self.q;
        let t = (e - self.mu) / self.sigma;
        let span = (1u64 << PRECISION) - self.len as u64;
        (((phi_fix(t) * span) >> 32) + j as u64) as u32
    }

    /// Where the search for `quantile` starts (any start gives the same symbol): the inverse
    /// of the table at `quantile / 2^24`, mapped back through `μ`, `σ`, `Q`.
    #[inline]
    fn hint(&self, quantile: u32) -> u32 {
        let target = (quantile as u64) << (32 - PRECISION);
        let k = inverse_start(target);
        // The middle of the table interval (1/512 of σ at most from the interpolated inverse).
        let t = (k as f32 + 0.5) * (1.0 / 256.0) - 8.0;
        let h = (self.mu + t * self.sigma) / self.q + 0.5 - self.lo as f32;
        // floor without a libm call; NaN and negatives start at 0.
        if h.is_nan() || h < 1.0 {
            0
        } else if h >= self.len as f32 {
            self.len - 1
        } else {
            h as u32
        }
    }

    /// The symbol `s` with `C(s) <= quantile < C(s + 1)`, and `C(s)`, `C(s + 1)`.
    pub fn find(&self, quantile: u32) -> (u32, u32, u32) {
        let s = self.hint(quantile);
        // Both edges at once (independent: they overlap in the pipeline).
        let (cs, cn) = (self.cdf(s), self.cdf(s + 1));
        if cs <= quantile && quantile < cn {
            return (s, cs, cn);
        }
        // Invariant: C(lo) = c_lo <= quantile < C(hi) = c_hi.
        let (mut lo, mut c_lo, mut hi, mut c_hi);
        if cn <= quantile {
            lo = s + 1;
            c_lo = cn;
            let mut step = 1u32;
            loop {
                let n = lo.saturating_add(step).min(self.len);
                let c = self.cdf(n);
                if c > quantile {
                    hi = n;
                    c_hi = c;
                    break;
                }
                lo = n;
                c_lo = c;
                step = step.saturating_mul(2);
            }
        } else {
            hi = s;
            c_hi = cs;
            let mut step = 1u32;
            loop {
                let n = hi.saturating_sub(step);
                let c = self.cdf(n);
                if c <= quantile {
                    lo = n;
                    c_lo = c;
                    break;
                }
                hi = n;
                c_hi = c;
                step = step.saturating_mul(2);
            }
        }
        while hi - lo > 1 {
            let mid = lo + (hi - lo) / 2;
            let c = self.cdf(mid);
            if c <= quantile {
                lo = mid;
                c_lo = c;
            } else {
                hi = mid;
                c_hi = c;
            }
        }
        (lo, c_lo, c_hi)
    }
}

/// About the `k` with `T[k] <= target < T[k+1]`: a 4096-bucket index of the table by the
/// target's top 12 bits (the largest `k` with `T[k]` at most the bucket's start). Only a hint.
#[inline]
fn inverse_start(target: u64) -> usize {
    static INDEX: std::sync::OnceLock<Vec<u16>> = std::sync::OnceLock::new();
    let idx = INDEX.get_or_init(|| {
        (0..4096u64)
            .map(|b| {
                let v = b << 20;
                PHI_TABLE[..4096]
                    .partition_point(|&t| t <= v)
                    .saturating_sub(1) as u16
            })
            .collect()
    });
    idx[((target >> 20) as usize).min(4095)] as usize
}

impl EntropyModel<PRECISION> for GaussModel {
    type Symbol = u32;
    type Probability = u32;
}

impl EncoderModel<PRECISION> for GaussModel {
    #[inline]
    fn left_cumulative_and_probability(
        &self,
        symbol: impl Borrow<u32>,
    ) -> Option<(u32, NonZeroU32)> {
        let s = *symbol.borrow();
        if s >= self.len {
            return None;
        }
        let (a, b) = (self.cdf(s), self.cdf(s + 1));
        Some((a, NonZeroU32::new(b - a)?))
    }
}

impl DecoderModel<PRECISION> for GaussModel {
    #[inline]
    fn quantile_function(&self, quantile: u32) -> (u32, u32, NonZeroU32) {
        let (s, a, b) = self.find(quantile);
        (
            s,
            a,
            NonZeroU32::new(b - a).expect("C is strictly increasing"),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[allow(clippy::disallowed_methods)]
    fn phi_table_matches_erfc() {
        let text = include_str!("../../format-spec/vectors/phi_table.txt");
        let file: Vec<u64> = text.lines().map(|l| l.parse().unwrap()).collect();
        assert_eq!(file.len(), 4097);
        for k in 0..=4096usize {
            let x = -8.0 + k as f64 / 256.0;
            let v = 0.5 * libm::erfc(-x / std::f64::consts::SQRT_2) * 4294967296.0;
            let t = v.round() as u64;
            assert_eq!(PHI_TABLE[k], t, "k {k}");
            assert_eq!(file[k], t, "k {k} (phi_table.txt)");
        }
        assert!(PHI_TABLE.windows(2).all(|w| w[0] <= w[1]));
        assert_eq!(PHI_TABLE[4096], 1 << 32);
    }

    #[test]
    fn cdf_is_strictly_increasing_and_find_inverts_it() {
        let mut rng = fastrand::Rng::with_seed(3);
        let odd = [
            0.0,
            -0.0,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            1e30,
            -1e30,
        ];
        for case in 0..3000 {
            let len = if case % 7 == 0 { 2 } else { rng.u32(2..600) };
            let lo = rng.i32(-300..300);
            let pick = |r: &mut fastrand::Rng, scale: f32| {
                if r.u8(..) < 20 {
                    odd[r.usize(..odd.len())]
                } else {
                    (r.f32() - 0.5) * scale
                }
            };
            let m = GaussModel::new(
                lo,
                len,
                pick(&mut rng, 400.0),
                pick(&mut rng, 30.0).abs(),
                if case % 11 == 0 {
                    0.0
                } else {
                    pick(&mut rng, 2.0).abs()
                },
            );
            let mut prev = 0;
            for j in 1..=len {
                let c = m.cdf(j);
                assert!(c > prev, "case {case} j {j}: {c} after {prev}");
                prev = c;
            }
            assert_eq!(prev, 1 << PRECISION);
            for _ in 0..20 {
                let q = rng.u32(0..1 << PRECISION);
                let (s, a, b) = m.find(q);
                assert!(a <= q && q < b && a == m.cdf(s) && b == m.cdf(s + 1));
            }
        }
    }

    #[test]
    fn tanh_is_close_and_odd() {
        for i in -4000..=4000 {
            let v = i as f32 * 0.01;
            let t = tanh_f32(v);
            #[allow(clippy::disallowed_methods)]
            let r = (v as f64).tanh();
            assert!((t as f64 - r).abs() <= 2e-7, "{v}: {t} vs {r}");
            assert_eq!(tanh_f32(-v), -t);
        }
        assert_eq!(tanh_f32(-50.0), -1.0);
        assert_eq!(step(0.2, -50.0), 0.0);
        assert_eq!(tanh_f32(f32::NAN), 0.0);
    }
}
