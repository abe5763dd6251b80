//! Gaussian-coded anchor attributes (`feat_{s}_0.b`, `scaling_{s}_0.b`, `offsets_{s}_0.b`):
//! symbols `round(x/Q) - min` with a per-symbol CDF from the context model's mean and scale
//! (the CUDA `calculate_cdf_kernel` rule, in float32), decoded with torchac's range coder.

use crate::latents::torchac_decode_with;
use crate::IngestError;

use super::bitstream::{parse, CHUNK};

/// Largest symbol alphabet accepted (the symbols are int16).
const MAX_LP: usize = 1 << 16;

/// The complementary error function as torch's CPU float32 `erfc` computes it, as closely as
/// we can without its library: torch calls MKL's `vsErfc` (checked: same bits on 600,000
/// samples), which is faithful (always one of the two floats around the exact value) and for
/// z < 0 returns `f32(2 - erfc(|z|))` (checked: all samples). Here `erfc(|z|)` is fdlibm's
/// f64 `erfc` (the `libm` crate) rounded to f32, the correctly rounded value; MKL's differs
/// from it by one ulp for 1-7 % of arguments (more for larger |z|), where a CDF entry can
/// then round to another integer (measured in `tests/tests/hac_ingest.rs`).
pub fn erfc_f32(z: f32) -> f32 {
    let e = libm::erfc(z.abs() as f64) as f32;
    if z < 0.0 {
        2.0 - e
    } else {
        e
    }
}

/// Integer CDF entry `j` of a symbol with step `q`, mean `mu`, scale `sigma`, for a file with
/// minimum `mn` and `lp` entries: `rint(float32(cdf * (65536 - (lp-1)))) + j` (mod 2^16).
pub fn cdf_entry(mn: i32, j: usize, q: f32, mu: f32, sigma: f32, lp: usize) -> u16 {
    let x = (((mn as f64 + j as f64) - 0.5) * q as f64) as f32;
    let s = sigma.max(1e-9f32);
    let z = -(x - mu) / (s * std::f32::consts::SQRT_2);
    let cdf = 0.5 * erfc_f32(z);
    let v = (cdf * (65536.0f32 - (lp as f32 - 1.0))).round_ties_even();
    ((v as i64 + j as i64) & 0xFFFF) as u16
}

/// Decode one Gaussian `.b` file of `anchors` anchors × `channels` symbols, anchor-major,
/// with per-anchor `q` and per-symbol `mean`, `scale`; returns `(sym + min) * Q`.
pub fn decode_gaussian(
    bytes: &[u8],
    channels: usize,
    mean: &[f32],
    scale: &[f32],
    q: &[f32],
    what: &str,
) -> Result<Vec<f32>, IngestError> {
    let n = mean.len();
    if scale.len() != n || q.len().checked_mul(channels) != Some(n) {
        return Err(IngestError::shape(
            what,
            "context does not match the symbols",
        ));
    }
    let c = parse(bytes, true, n, what)?;
    let (mn, mx) = c.header;
    let ok = |v: f32| v.is_finite() && v.fract() == 0.0 && v.abs() <= 1e9;
    if !ok(mn) || !ok(mx) || mx < mn || (mx - mn) as usize + 2 > MAX_LP {
        return Err(IngestError::format(
            what,
            format!("symbol range [{mn}, {mx}] is not a valid int16 alphabet"),
        ));
    }
    if let Some(i) = (0..n).find(|&i| !(mean[i].is_finite() && scale[i].is_finite())) {
        return Err(IngestError::NonFinite {
            what: format!("{what}: context mean/scale"),
            index: i,
            value: if mean[i].is_finite() {
                scale[i]
            } else {
                mean[i]
            },
        });
    }
    let (mni, lp) = (mn as i32, (mx - mn) as usize + 2);
    let mut out = Vec::with_capacity(n);
    for (k, chunk) in c.chunks.iter().enumerate() {
        let base = k * CHUNK;
        let m = CHUNK.min(n - base);
        let syms = torchac_decode_with(chunk, m, lp, |i, j| {
            let g = base + i;
            cdf_entry(mni, j, q[g / channels], mean[g], scale[g], lp)
        });
        for (i, s) in syms.into_iter().enumerate() {
            let g = base + i;
            out.push((s as f32 + mn) * q[g / channels]);
        }
    }
    Ok(out)
}
