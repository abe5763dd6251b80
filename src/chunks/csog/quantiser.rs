//! Quantisation ranges and levels (§6.5.2): which range each channel gets, and the uniform
//! quantiser both directions share.

use super::channels::Kind;
use super::{colour_lattice, half_range};

/// Log-scales more than this below the channel's largest are raised to it before
/// quantisation: an axis under e^-14 (~1e-6) of the largest Gaussian's is far below a pixel at
/// any practical resolution, while trained scenes hold collapsed axes near e^-23 that would
/// otherwise take half the range (format-spec §6.5.2; measured in BENCHMARKS.md).
pub const LOG_SCALE_SPAN: f32 = 14.0;

/// Log-scales are also raised to `ln(R) - LOG_SCALE_BELOW_RADIUS`, `R` the set's robust
/// radius ([`robust_radius`]): with the whole scene 4,000 pixels across, a pixel is about
/// e^-7.6 R, so the floor is a twentieth of a pixel there, while the quantisation step shrinks
/// by the span it no longer covers (on the real lod2 tile at `medium`: 48.8 dB instead of 46.9
/// for 0.3 % fewer bytes; docs/benchmarks/canonical.md "Earlier changes").
pub const LOG_SCALE_BELOW_RADIUS: f32 = 10.0;

/// 80th percentile of the distances of the finite positions from their per-axis median
/// (what the renderer's orbit cameras frame); `None` for an empty or degenerate set.
pub fn robust_radius(positions: &[[f32; 3]]) -> Option<f32> {
    let pts: Vec<[f32; 3]> = positions
        .iter()
        .copied()
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .collect();
    if pts.is_empty() {
        return None;
    }
    let mut c = [0f32; 3];
    for (a, ca) in c.iter_mut().enumerate() {
        let mut v: Vec<f32> = pts.iter().map(|p| p[a]).collect();
        let mid = v.len() / 2;
        *ca = *v.select_nth_unstable_by(mid, f32::total_cmp).1;
    }
    let mut d: Vec<f32> = pts
        .iter()
        .map(|p| {
            let (x, y, z) = (p[0] - c[0], p[1] - c[1], p[2] - c[2]);
            (x * x + y * y + z * z).sqrt()
        })
        .collect();
    let k = (d.len() * 8 / 10).min(d.len() - 1);
    let r = *d.select_nth_unstable_by(k, f32::total_cmp).1;
    (r > 0.0 && r.is_finite()).then_some(r)
}

/// Quantisation range at `bits`: fixed for opacities, rotation components and the index; the
/// data's min/max otherwise (log-scales: raised to `max - LOG_SCALE_SPAN` and to
/// `ln(radius) - LOG_SCALE_BELOW_RADIUS`, never above the max; SH bands 1-3: widened to put a
/// level at zero where that is cheaper, [`zero_on_level`]). Every range but a position, rotation
/// or zero-on-level one is then widened to binary16 ends where that coarsens its step by at most
/// a 256th and moves each end by under half a step ([`half_range::snap`]): layout 4 stores such
/// a range in half the bytes (§6.5.7).
#[allow(clippy::disallowed_methods)] // encoder-side range choice
pub(super) fn range(k: Kind, v: &[f32], radius: Option<f32>, bits: u8) -> (f32, f32) {
    let min_max = || {
        v.iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &x| {
                (lo.min(x), hi.max(x))
            })
    };
    let (lo, hi) = match k {
        Kind::Opacity | Kind::LangOpacity => (0.0, 1.0),
        Kind::Rotation(_) => (
            -std::f32::consts::FRAC_1_SQRT_2,
            std::f32::consts::FRAC_1_SQRT_2,
        ),
        Kind::RotIndex => (0.0, 3.0),
        _ if v.is_empty() => (0.0, 0.0),
        Kind::LogScale(_) => {
            let (lo, hi) = min_max();
            let floor = radius.map_or(f32::NEG_INFINITY, |r| r.ln() - LOG_SCALE_BELOW_RADIUS);
            (lo.max(hi - LOG_SCALE_SPAN).max(floor.min(hi)), hi)
        }
        Kind::Sh(j) if j >= 3 => {
            let (lo, hi) = min_max();
            let plain = half_range::snap(lo, hi, bits);
            return cheaper_range(v, plain, zero_on_level(lo, hi, bits), bits);
        }
        // SH DC from 8-bit colours: levels on the colours, not snapped to binary16 ends
        // (that would move them off the colours again).
        Kind::Sh(_) => match colour_lattice::range(v, bits) {
            Some(r) => return r,
            None => min_max(),
        },
        _ => min_max(),
    };
    match k {
        // Positions keep the data's ends: moving a position lattice by up to half a step
        // measurably moves the image (gsplat at 11 bits: -0.17 dB) for 12 bytes per part.
        // Rotation components keep their fixed range (-0.06 dB there for 4 bytes).
        Kind::Position(_) | Kind::Rotation(_) => (lo, hi),
        _ => half_range::snap(lo, hi, bits),
    }
}

/// A range around zero widened (by at most one step in all) so that zero is one of its
/// levels: SH bands 1-3 of trained scenes gather at zero, and on a range that merely spans the
/// data's min and max zero falls between two levels, shifting every such coefficient by up to
/// half a step. The encoder keeps this range only where it is the cheaper one
/// ([`cheaper_range`]): real gsplat at `low`, 7 % fewer bytes at the same PSNR; fruit at its
/// presets, no change (docs/benchmarks/canonical-levers.md "SH bands"). Ranges not around zero,
/// and 1-bit channels,
/// are returned as they are.
fn zero_on_level(lo: f32, hi: f32, bits: u8) -> (f32, f32) {
    let l = levels(bits);
    if !(lo < 0.0 && hi > 0.0) || l < 2.0 {
        return (lo, hi);
    }
    let (lo64, hi64, l64) = (lo as f64, hi as f64, l as f64);
    // Zero's level: of the two around where zero falls, the one that widens the range least.
    let step_at = |m: f64| (-lo64 / m).max(hi64 / (l64 - m));
    let at = -lo64 / (hi64 - lo64) * l64;
    let (below, above) = (
        at.floor().clamp(1.0, l64 - 1.0),
        at.ceil().clamp(1.0, l64 - 1.0),
    );
    let m = if step_at(below) <= step_at(above) {
        below
    } else {
        above
    };
    let step = step_at(m);
    // f32 rounding must not narrow the range below the data.
    let widened = (
        ((-m * step) as f32).min(lo),
        (((l64 - m) * step) as f32).max(hi),
    );
    // Near f32::MAX the widened ends overflow: stored ranges must be finite (§6.5.2).
    if widened.0.is_finite() && widened.1.is_finite() {
        widened
    } else {
        (lo, hi)
    }
}

/// Of two ranges, the one with the lower estimated rate-distortion cost for `v` (ties: `a`):
/// squared error plus `λ` times the order-0 entropy of the levels, `λ = 2 ln 2 / 12 · step²`
/// (the slope of uniform quantisation at high rate: one bit more quarters the error `step²/12`).
#[allow(clippy::disallowed_methods)] // encoder-side cost estimate
fn cheaper_range(v: &[f32], a: (f32, f32), b: (f32, f32), bits: u8) -> (f32, f32) {
    if a == b {
        return a;
    }
    let cost = |(lo, hi): (f32, f32)| -> f64 {
        let mut counts = vec![0u32; 1 << bits];
        let mut sse = 0.0;
        for &x in v {
            let q = quantise(x, lo, hi, bits);
            counts[q as usize] += 1;
            let e = (x - dequantise(q, lo, hi, bits)) as f64;
            sse += e * e;
        }
        let n = v.len() as f64;
        let rate: f64 = counts
            .iter()
            .filter(|&&c| c > 0)
            .map(|&c| -(c as f64) * (c as f64 / n).log2())
            .sum();
        let step = (hi as f64 - lo as f64) / levels(bits) as f64;
        sse + 2.0 * std::f64::consts::LN_2 / 12.0 * step * step * rate
    };
    if cost(b) < cost(a) {
        b
    } else {
        a
    }
}

pub(super) fn levels(bits: u8) -> f32 {
    ((1u32 << bits) - 1) as f32
}

/// Scene distance of one quantisation step of each position channel (the first three).
pub(super) fn position_steps(chans: &[(u8, f32, f32, Vec<u16>)]) -> [f64; 3] {
    let step =
        |c: &(u8, f32, f32, Vec<u16>)| (c.2 as f64 - c.1 as f64).max(0.0) / (levels(c.0) as f64);
    [step(&chans[0]), step(&chans[1]), step(&chans[2])]
}

/// `q = round((v - min) / (max - min) * (2^bits - 1))`, clamped; 0 when the range is empty.
pub fn quantise(v: f32, min: f32, max: f32, bits: u8) -> u16 {
    if !(max > min) {
        return 0;
    }
    let t = ((v - min) / (max - min) * levels(bits)).round();
    t.clamp(0.0, levels(bits)) as u16
}

/// `v = min + q * ((max - min) / (2^bits - 1))` in f32 (§6.5.2).
pub fn dequantise(q: u16, min: f32, max: f32, bits: u8) -> f32 {
    min + q as f32 * ((max - min) / levels(bits))
}

/// Grid width for `n` cells: `ceil(sqrt(n))` (0 for an empty set).
pub fn grid_width(n: usize) -> usize {
    if n == 0 {
        return 0;
    }
    let mut w = (n as f64).sqrt() as usize;
    while w * w < n {
        w += 1;
    }
    w
}

/// Back to pre-sigmoid opacity; alpha is kept half a step away from 0 and 1 so the logit is
/// finite (§6.5.2). `a / (1 - a)` in binary32, its logarithm correctly rounded to binary32 by
/// the crate's own [`crate::elementary::ln`] (Appendix B): the same bits on every platform.
pub(super) fn logit(alpha: Vec<f32>, bits: u8) -> Vec<f32> {
    let eps = 0.5 / levels(bits);
    alpha
        .into_iter()
        .map(|a| {
            let a = a.clamp(eps, 1.0 - eps);
            crate::elementary::ln_f32(a / (1.0 - a))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every opacity level of every bit width decodes to the correctly rounded binary32 of
    /// `ln(a / (1 - a))` (of the binary32 quotient), so any implementation that rounds
    /// correctly, or follows Appendix B, gives the same bits: the binary64 logarithm is
    /// farther than 16 of its ulps from every binary32 rounding boundary, and the
    /// platform's binary64 `ln` agrees with ours within one ulp on the same inputs.
    #[test]
    #[allow(clippy::disallowed_methods)] // the platform's `ln` as an independent reference
    fn opacity_levels_are_correctly_rounded_at_every_bit_width() {
        let mut checked = 0;
        for bits in 1..=16u8 {
            let q: Vec<u16> = (0..=levels(bits) as u32).map(|q| q as u16).collect();
            let alpha: Vec<f32> = q.iter().map(|&q| dequantise(q, 0.0, 1.0, bits)).collect();
            let ours = logit(alpha.clone(), bits);
            let eps = 0.5 / levels(bits);
            for (a, v) in alpha.into_iter().zip(ours) {
                let a = a.clamp(eps, 1.0 - eps);
                let x = (a / (1.0 - a)) as f64;
                let y = crate::elementary::ln(x);
                assert!(y.to_bits().abs_diff(x.ln().to_bits()) <= 1, "ln({x})");
                assert_eq!(v, y as f32);
                if v == 0.0 {
                    continue; // ln(1) = 0 exactly
                }
                // The neighbours of v towards y and the rounding boundary between them.
                let up = if (y > v as f64) == (v > 0.0) {
                    f32::from_bits(v.to_bits() + 1)
                } else {
                    f32::from_bits(v.to_bits() - 1)
                };
                let boundary = (v as f64 + up as f64) / 2.0;
                let ulp = f64::from_bits(y.abs().to_bits() + 1) - y.abs();
                assert!(
                    (y - boundary).abs() > 16.0 * ulp,
                    "{bits}-bit level of alpha {a}: ln too close to a rounding boundary"
                );
                checked += 1;
            }
        }
        assert!(checked > 130_000);
    }

    #[test]
    fn robust_radius_of_degenerate_sets() {
        assert_eq!(robust_radius(&[]), None);
        assert_eq!(
            robust_radius(&[[1.0, 2.0, 3.0]; 5]),
            None,
            "all at one point"
        );
        assert_eq!(robust_radius(&[[f32::NAN, 0.0, 0.0]]), None);
        // Non-finite positions are ignored; the 80th percentile distance from the median.
        let mut p: Vec<[f32; 3]> = (0..10).map(|i| [i as f32, 0.0, 0.0]).collect();
        p.push([f32::INFINITY, 0.0, 0.0]);
        assert_eq!(robust_radius(&p), Some(4.0));
    }

    #[test]
    fn quantisation_hits_ends_and_constant_ranges() {
        assert_eq!(quantise(-1.0, -1.0, 3.0, 8), 0);
        assert_eq!(quantise(3.0, -1.0, 3.0, 8), 255);
        assert_eq!(dequantise(255, -1.0, 3.0, 8), 3.0);
        assert_eq!(quantise(5.0, 2.0, 2.0, 8), 0);
        assert_eq!(dequantise(0, 2.0, 2.0, 8), 2.0);
        assert_eq!(quantise(1e30, 0.0, 1.0, 16), 65535);
    }

    #[test]
    fn zero_on_level_covers_the_range_and_codes_zero_exactly() {
        for (lo, hi) in [(-0.3f32, 0.7f32), (-5.0, 0.001), (-1e-6, 40.0), (-0.5, 0.5)] {
            for bits in 2..=16u8 {
                let (a, b) = zero_on_level(lo, hi, bits);
                assert!(a <= lo && b >= hi, "{lo}..{hi} at {bits} bits -> {a}..{b}");
                // Widened by at most one step of the new range in all (f32 rounding aside).
                let step = (b - a) / levels(bits);
                assert!(
                    (lo - a) + (b - hi) <= step * 1.01,
                    "{lo}..{hi} at {bits} bits -> {a}..{b}"
                );
                let back = dequantise(quantise(0.0, a, b, bits), a, b, bits);
                assert!(
                    back.abs() <= 1e-6 * (hi - lo),
                    "zero -> {back} at {bits} bits"
                );
            }
        }
        // Ranges not around zero, empty ranges and 1-bit channels are left as they are.
        assert_eq!(zero_on_level(0.2, 0.9, 8), (0.2, 0.9));
        assert_eq!(zero_on_level(-0.9, -0.2, 8), (-0.9, -0.2));
        assert_eq!(zero_on_level(0.0, 0.0, 8), (0.0, 0.0));
        assert_eq!(zero_on_level(-1.0, 1.0, 1), (-1.0, 1.0));
        // Ends that would overflow f32 keep the data's range.
        assert_eq!(zero_on_level(-f32::MAX, f32::MAX, 8), (-f32::MAX, f32::MAX));
    }
}
