//! The bits of one `AHAC` symbol under a Gaussian model and their gradient, for fitting: the
//! integer `x` at step `Q` stands for the interval `[(x - 0.5) Q, (x + 0.5) Q)`, whose mass
//! under `N(μ, σ²)` is what the coder's CDF (format-spec §6.13.6) approximates. Binary64 with
//! the crate's own `exp` and `ln` (Appendix B), so a fit is the same on every machine.

use dlgs::elementary::{exp, ln};

/// Smallest probability the fit counts (the coder's floor is about 2^-24 per symbol).
const P_FLOOR: f64 = 1.0 / (1u64 << 24) as f64;
const FRAC_1_SQRT_2PI: f64 = 0.398_942_280_401_432_7;

/// `erfc(x)`, fractional error below 1.2e-7 everywhere (a Chebyshev fit, Numerical Recipes'
/// `erfcc`): enough for a gradient, and exact in the tails where differences of `Φ` vanish.
pub fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let poly = -z * z - 1.265_512_23
        + t * (1.000_023_68
            + t * (0.374_091_96
                + t * (0.096_784_18
                    + t * (-0.186_288_06
                        + t * (0.278_868_07
                            + t * (-1.135_203_98
                                + t * (1.488_515_87 + t * (-0.822_152_23 + t * 0.170_872_77))))))));
    let r = t * exp(poly);
    if x >= 0.0 {
        r
    } else {
        2.0 - r
    }
}

/// Upper tail `1 - Φ(t)`.
fn upper(t: f64) -> f64 {
    0.5 * erfc(t * std::f64::consts::FRAC_1_SQRT_2)
}

fn density(t: f64) -> f64 {
    FRAC_1_SQRT_2PI * exp(-0.5 * t * t)
}

/// Bits of `x` and their derivatives by `μ` and `σ`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SymbolRate {
    pub bits: f64,
    pub d_mu: f64,
    pub d_sigma: f64,
}

/// `-log2 P(x)` with `P = Φ(b) - Φ(a)`, `a = ((x - ½)Q - μ)/σ`, `b = ((x + ½)Q - μ)/σ`, floored at
/// 2^-24 (no gradient below the floor). `σ > 0`, `Q > 0`. The bits themselves (a logarithm)
/// only `with_bits`; otherwise `bits` is 0 (the gradient does not need them).
pub fn symbol_rate(x: i32, q: f64, mu: f64, sigma: f64, with_bits: bool) -> SymbolRate {
    let a = ((x as f64 - 0.5) * q - mu) / sigma;
    let b = ((x as f64 + 0.5) * q - mu) / sigma;
    // The difference of the tail on the side away from the mean: no cancellation.
    let p = if a >= 0.0 {
        upper(a) - upper(b)
    } else if b <= 0.0 {
        upper(-b) - upper(-a)
    } else {
        1.0 - upper(-a) - upper(b)
    };
    if !(p > P_FLOOR) {
        return SymbolRate {
            bits: -ln(P_FLOOR) * std::f64::consts::LOG2_E,
            d_mu: 0.0,
            d_sigma: 0.0,
        };
    }
    let (fa, fb) = (density(a), density(b));
    // dP/dμ = (φ(a) - φ(b)) / σ, dP/dσ = (a φ(a) - b φ(b)) / σ; d(-log2 P) = -dP / (P ln 2).
    let k = -std::f64::consts::LOG2_E / (p * sigma);
    SymbolRate {
        bits: if with_bits {
            -ln(p) * std::f64::consts::LOG2_E
        } else {
            0.0
        },
        d_mu: k * (fa - fb),
        d_sigma: k * (a * fa - b * fb),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn erfc_matches_known_values() {
        for (x, want) in [
            (0.0, 1.0),
            (0.5, 0.479_500_122_186_953_5),
            (1.0, 0.157_299_207_050_285_1),
            (-1.0, 1.842_700_792_949_715),
            (3.0, 2.209_049_699_858_544e-5),
        ] {
            let got = erfc(x);
            assert!(
                ((got - want) / want).abs() < 2e-7,
                "erfc({x}) = {got}, want {want}"
            );
        }
    }

    #[test]
    fn gradients_match_finite_differences() {
        for &(x, q, mu, sigma) in &[
            (0, 1.0, 0.2, 0.7),
            (3, 0.5, 0.1, 1.3),
            (-2, 0.01, -0.013, 0.004),
            (7, 1.0, -1.0, 2.5),
        ] {
            let r = symbol_rate(x, q, mu, sigma, true);
            let h = 1e-6 * sigma;
            let dm = (symbol_rate(x, q, mu + h, sigma, true).bits
                - symbol_rate(x, q, mu - h, sigma, true).bits)
                / (2.0 * h);
            let ds = (symbol_rate(x, q, mu, sigma + h, true).bits
                - symbol_rate(x, q, mu, sigma - h, true).bits)
                / (2.0 * h);
            assert!(
                (dm - r.d_mu).abs() < 1e-3 * (1.0 + dm.abs()),
                "{dm} vs {}",
                r.d_mu
            );
            assert!(
                (ds - r.d_sigma).abs() < 1e-3 * (1.0 + ds.abs()),
                "{ds} vs {}",
                r.d_sigma
            );
        }
    }

    #[test]
    fn a_centred_narrow_model_costs_almost_nothing_and_a_far_symbol_hits_the_floor() {
        assert!(symbol_rate(0, 1.0, 0.0, 0.05, true).bits < 1e-6);
        let far = symbol_rate(100, 1.0, 0.0, 0.5, true);
        assert!((far.bits - 24.0).abs() < 1e-9, "{}", far.bits);
        assert_eq!((far.d_mu, far.d_sigma), (0.0, 0.0));
        // Probabilities of all symbols sum to one.
        let total: f64 = (-40..=40)
            .map(|x| 2f64.powf(-symbol_rate(x, 0.5, 0.3, 2.0, true).bits))
            .sum();
        assert!((total - 1.0).abs() < 1e-5, "{total}");
    }
}
