//! Channel ranges that binary16 holds exactly. Layout 4's channel records (format-spec §6.5.7)
//! store a range in 4 bytes instead of 8 when both ends are binary16 values; the encoder widens
//! a range outwards to the nearest such ends when that coarsens the channel's step by at most
//! [`MAX_WIDENING`] of it, far below what a rendered image shows, and moves each end by less
//! than half a step, so the values at the data's ends still take the end levels: decoding and
//! quantising again gives the same range and levels.

use half::f16;

/// Largest widening, as a fraction of the range, that [`snap`] accepts: the step grows by the
/// same fraction, the channel's squared error by twice it (at most 0.034 dB were that channel
/// all the error; measured on real scenes in docs/benchmarks/canonical-levers.md
/// "Compact records").
pub const MAX_WIDENING: f64 = 1.0 / 256.0;

/// Whether `v` is exactly a finite binary16 value.
pub fn is_f16(v: f32) -> bool {
    let h = f16::from_f32(v);
    h.is_finite() && h.to_f32() == v
}

/// The next binary16 value towards minus (`down`) or plus infinity.
fn next(h: f16, down: bool) -> f16 {
    let v = h.to_f32();
    let b = h.to_bits();
    f16::from_bits(match (v == 0.0, v > 0.0, down) {
        (true, _, true) => 0x8001,
        (true, _, false) => 0x0001,
        (false, true, true) | (false, false, false) => b - 1,
        (false, true, false) | (false, false, true) => b + 1,
    })
}

/// `(lo, hi)` widened to the nearest binary16 ends outside it, when both are finite, the
/// widening is at most [`MAX_WIDENING`] of the range and each end moves by under 0.49 of the
/// widened range's step at `bits`; else `(lo, hi)` unchanged. An empty range (`lo >= hi`) is
/// kept as it is.
pub fn snap(lo: f32, hi: f32, bits: u8) -> (f32, f32) {
    if !(lo < hi) || !lo.is_finite() || !hi.is_finite() {
        return (lo, hi);
    }
    let mut l = f16::from_f32(lo);
    if l.to_f32() > lo {
        l = next(l, true);
    }
    let mut h = f16::from_f32(hi);
    if h.to_f32() < hi {
        h = next(h, false);
    }
    let (l, h) = (l.to_f32(), h.to_f32());
    let span = hi as f64 - lo as f64;
    let widening = (h as f64 - l as f64) - span;
    let half_step = 0.49 * (h as f64 - l as f64) / ((1u64 << bits) - 1) as f64;
    let ends_move = (lo as f64 - l as f64).max(h as f64 - hi as f64);
    if l.is_finite() && h.is_finite() && widening <= MAX_WIDENING * span && ends_move < half_step {
        (l, h)
    } else {
        (lo, hi)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn snapped_ranges_hold_the_data_and_are_binary16() {
        for (lo, hi) in [
            (-0.70710677f32, 0.70710677),
            (0.0, 1.0),
            (-12.3456, -2.5312),
            (-37.5, 41.25),
            (-1e-3, 2e-3),
        ] {
            let (l, h) = snap(lo, hi, 6);
            assert!(l <= lo && h >= hi, "{lo} {hi} -> {l} {h}");
            assert!(is_f16(l) && is_f16(h), "{lo} {hi} -> {l} {h}");
            assert!((h - l) as f64 <= (hi - lo) as f64 * (1.0 + MAX_WIDENING));
        }
    }

    #[test]
    fn ranges_binary16_cannot_hold_closely_are_kept() {
        // Past binary16's largest finite value, and a span narrow for its magnitude.
        for (lo, hi) in [
            (0.0f32, 70_000.0),
            (1000.0, 1000.5),
            (1e-7, 3e-7),
            (5.0, 5.0),
            (3.0, 1.0),
        ] {
            assert_eq!(snap(lo, hi, 6), (lo, hi));
        }
        // Each end may move by under half a step: at 14 bits this range's ends cannot.
        assert_eq!(snap(-37.3, 41.2, 14), (-37.3, 41.2));
        assert!(!is_f16(f32::NAN) && !is_f16(1e6) && !is_f16(0.1) && is_f16(0.5));
    }
}
