//! SH DC channels of scenes stored with 8-bit colours (a `.splat` capture, or a PLY written
//! from one) hold `(c / 255 - 0.5) / C0` for whole numbers `c`. On the data's min/max range the
//! quantiser's levels fall between those colours and every value moves by up to half a step;
//! on a range whose levels are the colours themselves (or every `m`-th of them, at fewer bits
//! than the colours' spread needs) the values keep their colour, for the same number of levels.
//! The plant's goal row: 0.9 % fewer bytes and +0.16 dB
//! (docs/benchmarks/canonical-levers.md "Colour lattice").

use crate::interop::splat::{colour_to_dc as dc, SH_C0};

/// Largest distance, in 8-bit colour steps, of a value from a whole colour for it to count as
/// one: f32 rounding of `(c / 255 - 0.5) / C0` and back stays under 1e-4 steps.
const TOLERANCE: f32 = 1e-3;

/// The colour step `c` of an SH DC value.
fn colour(dc: f32) -> f32 {
    (dc * SH_C0 + 0.5) * 255.0
}

/// If every value of `v` is a whole 8-bit colour step, the range for `bits`-bit levels that
/// starts at the lowest colour present and steps by the fewest colours (`m >= 1`) that reach
/// the highest in `2^bits - 1` steps; else `None` (also for no values or `bits = 0`).
pub fn range(v: &[f32], bits: u8) -> Option<(f32, f32)> {
    if v.is_empty() || bits == 0 || bits > 16 {
        return None;
    }
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for &x in v {
        let c = colour(x);
        // `!(<=)` also refuses NaN.
        if !((c - c.round()).abs() <= TOLERANCE) {
            return None;
        }
        lo = lo.min(c.round());
        hi = hi.max(c.round());
    }
    let levels = ((1u32 << bits) - 1) as f32;
    let m = ((hi - lo) / levels).ceil().max(1.0);
    let (min, max) = (dc(lo), dc(lo + m * levels));
    (min.is_finite() && max.is_finite() && min < max).then_some((min, max))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::chunks::csog::{dequantise, quantise};

    #[test]
    fn colours_keep_their_value_when_bits_cover_their_spread() {
        let v: Vec<f32> = [3u8, 7, 200, 131, 3, 250]
            .iter()
            .map(|&c| dc(c as f32))
            .collect();
        for bits in [8, 9, 12] {
            let (min, max) = range(&v, bits).unwrap();
            assert_eq!(min, dc(3.0));
            for &x in &v {
                let back = dequantise(quantise(x, min, max, bits), min, max, bits);
                assert!(
                    (colour(back) - colour(x)).abs() < 1e-3,
                    "{bits} bits: {x} -> {back}"
                );
            }
        }
        // 7 bits for a spread of 247 colours: every second colour is a level, so no value
        // moves by more than one colour.
        let (min, max) = range(&v, 7).unwrap();
        assert_eq!(max, dc(3.0 + 2.0 * 127.0));
        for &x in &v {
            let back = dequantise(quantise(x, min, max, 7), min, max, 7);
            assert!((colour(back) - colour(x)).abs() <= 1.0 + 1e-3);
        }
    }

    #[test]
    fn other_values_and_degenerate_input_take_no_lattice() {
        assert_eq!(range(&[dc(10.0), dc(10.0) + 0.01], 8), None);
        assert_eq!(range(&[dc(10.0), f32::NAN], 8), None);
        assert_eq!(range(&[f32::INFINITY], 8), None);
        assert_eq!(range(&[], 8), None);
        assert_eq!(range(&[dc(10.0)], 0), None);
        // One colour: a range of one colour per level, starting at it.
        let (min, max) = range(&[dc(10.0); 4], 8).unwrap();
        assert_eq!((min, max), (dc(10.0), dc(265.0)));
        assert_eq!(quantise(dc(10.0), min, max, 8), 0);
    }
}
