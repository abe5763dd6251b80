//! exp(x) for x <= 0 without a libm call, so the compositing loop stays cheap.
//! Cody-Waite range reduction and a degree-6 polynomial: relative error below 3e-7 on
//! [-87, 0] (tested against `f32::exp`); returns 0 below -87.

#[inline(always)]
pub fn exp_neg(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    const LN2_HI: f32 = 0.693_145_75;
    const LN2_LO: f32 = 1.428_606_8e-6;
    let x = x.max(-87.0);
    // Round to nearest with the 1.5 * 2^23 trick: `f32::round` is a libm call on baseline
    // x86-64 and would stop this loop from vectorising.
    const MAGIC: f32 = 12_582_912.0;
    let shifted = x * LOG2E + MAGIC;
    let n = shifted - MAGIC;
    let r = x - n * LN2_HI - n * LN2_LO;
    // e^r on [-ln2/2, ln2/2]
    let p = 1.0
        + r * (1.0
            + r * (0.5
                + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0))))));
    // The low mantissa bits of `shifted` hold n; building 2^n from them avoids a saturating
    // float-to-int conversion (which blocks vectorisation).
    let bits = shifted.to_bits().wrapping_sub(0x4B40_0000 - 127) << 23;
    p * f32::from_bits(bits)
}

/// 2^x for x <= 0, cheaper and coarser than [`exp_neg`]: the fast render knob
/// ([`crate::Accuracy::Fast`]). Round to nearest, then a degree-3 polynomial for 2^f on
/// [-0.5, 0.5] (fitted for relative error, 7.6e-5 at worst); clamped below at -125 so 2^n stays
/// a normal float. Relative error below 1e-4 (tested against `f32::exp2`).
#[inline(always)]
pub fn exp2_neg_fast(x: f32) -> f32 {
    const MAGIC: f32 = 12_582_912.0;
    let x = x.max(-125.0);
    let shifted = x + MAGIC;
    let n = shifted - MAGIC;
    let f = x - n;
    let p = 0.999_928_24 + f * (0.693_261 + f * (0.242_608_52 + f * 0.055_170_5));
    let bits = shifted.to_bits().wrapping_sub(0x4B40_0000 - 127) << 23;
    p * f32::from_bits(bits)
}

#[cfg(test)]
mod tests {
    use super::{exp2_neg_fast, exp_neg};

    #[test]
    fn fast_exp2_within_1e_4_relative() {
        let mut worst = 0f32;
        let mut x = -125.0f32;
        while x <= 0.0 {
            let (a, b) = (exp2_neg_fast(x), x.exp2());
            worst = worst.max(((a - b) / b).abs());
            x += 0.000_37;
        }
        assert!(worst < 1e-4, "worst relative error {worst}");
        assert!(exp2_neg_fast(-1000.0) > 0.0 && exp2_neg_fast(-1000.0) < 1e-37);
    }

    #[test]
    fn matches_libm_within_3e_7_relative() {
        let mut worst = 0f32;
        let mut x = -87.0f32;
        while x <= 0.0 {
            let (a, b) = (exp_neg(x), x.exp());
            worst = worst.max(((a - b) / b).abs());
            x += 0.000_37;
        }
        assert!(worst < 3e-7, "worst relative error {worst}");
        assert_eq!(exp_neg(-1000.0), exp_neg(-87.0));
        assert!(exp_neg(-87.0) > 0.0);
    }
}
