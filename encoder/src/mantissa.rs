//! Weights rounded to fewer mantissa bits: the format stores MLP weights as f32 in a zstd
//! frame, and a weight whose low mantissa bits are zero costs zstd far less.

/// `v` rounded to `bits` mantissa bits (nearest, ties away from zero); 23 or more keeps it, and
/// a value that would round to infinity is kept.
pub fn round_mantissa(v: f32, bits: u32) -> f32 {
    if bits >= 23 || !v.is_finite() {
        return v;
    }
    let drop = 23 - bits;
    let half = 1u32 << (drop - 1);
    let r = f32::from_bits((v.to_bits() + half) & !((1u32 << drop) - 1));
    if r.is_finite() {
        r
    } else {
        v
    }
}

#[cfg(test)]
mod tests {
    use super::round_mantissa;

    #[test]
    fn rounding_keeps_the_leading_bits_and_rounds_to_nearest() {
        assert_eq!(round_mantissa(1.0, 8), 1.0);
        assert_eq!(round_mantissa(-3.5, 4), -3.5);
        let v = 1.0 + 1.0 / 512.0 + 1.0 / 1024.0; // above the midpoint of two 8-bit values
        assert_eq!(round_mantissa(v, 8), 1.0 + 1.0 / 256.0);
        assert_eq!(round_mantissa(-v, 8), -(1.0 + 1.0 / 256.0));
        assert_eq!(round_mantissa(0.1, 23), 0.1);
        assert_eq!(round_mantissa(1.75, 0), 2.0);
        assert_eq!(round_mantissa(f32::MAX, 4), f32::MAX);
        assert!(round_mantissa(f32::NAN, 4).is_nan());
        assert_eq!(round_mantissa(0.0, 2), 0.0);
    }
}
