//! antimatter15 `.splat`: 32 bytes per Gaussian, SH degree 0, no header.
//! position f32x3 | linear scale f32x3 | RGBA u8x4 | quaternion u8x4 (w, x, y, z; q*128+128).
#![allow(clippy::disallowed_methods)] // a foreign format: see the module doc of `interop`

use crate::error::{Error, Result};
use crate::limits::Limits;
use crate::model::Gaussians;

pub const SH_C0: f32 = 0.282_094_8;

/// The SH DC coefficient of 8-bit colour value `c` (`c` may lie outside 0..=255: an encoder
/// extends the colour lattice past the data, `chunks::csog::colour_lattice`).
pub fn colour_to_dc(c: f32) -> f32 {
    (c / 255.0 - 0.5) / SH_C0
}
const STRIDE: usize = 32;

/// Inverse sigmoid of an 8-bit alpha. 0 and 255 would give +-inf, so alpha is taken as
/// `clamp(a / 255, 0.5/255, 254.5/255)`: the logit stays within +-6.2.
pub fn alpha_u8_to_logit(a: u8) -> f32 {
    let p = (a as f32 / 255.0).clamp(0.5 / 255.0, 254.5 / 255.0);
    (p / (1.0 - p)).ln()
}

/// Read an antimatter15 `.splat` (32 bytes per Gaussian); at most `limits.max_gaussians`.
pub fn read_splat(data: &[u8], limits: &Limits) -> Result<Gaussians> {
    if !data.len().is_multiple_of(STRIDE) {
        return Err(Error::foreign(
            ".splat",
            format!("{} bytes is not a multiple of 32", data.len()),
        ));
    }
    let n = data.len() / STRIDE;
    limits.check_gaussians(".splat Gaussians", n as u64, 0)?;
    let mut g = Gaussians::new(0, 0);
    g.positions.reserve(n);
    let f =
        |b: &[u8], i: usize| f32::from_le_bytes(b[i * 4..i * 4 + 4].try_into().expect("4 bytes"));
    for r in data.chunks_exact(STRIDE) {
        g.positions.push([f(r, 0), f(r, 1), f(r, 2)]);
        // A zero linear scale maps to -inf log-scale; floor at 1e-12 so it stays finite.
        g.log_scales
            .push([3, 4, 5].map(|i| f(r, i).abs().max(1e-12).ln()));
        let c = &r[24..28];
        for ch in 0..3 {
            g.sh.push(colour_to_dc(c[ch] as f32));
        }
        g.opacity.push(alpha_u8_to_logit(c[3]));
        let q = &r[28..32];
        g.rotations
            .push([0, 1, 2, 3].map(|i| (q[i] as f32 - 128.0) / 128.0));
    }
    Ok(g)
}
