//! Niantic SPZ writer: version 3 (gzip, smallest-three rotations; read by Niantic's `spz`
//! library since 2.0, SuperSplat / PlayCanvas and `@playcanvas/splat-transform`) or version 2
//! (gzip, 3-byte rotations, for older players). Layout: see [`super::spz`]. Quantisation is
//! SPZ's own: positions 24-bit fixed point, log-scales `(s + 10) * 16`, alpha `sigmoid * 255`,
//! DC colour `v * 0.15 + 0.5` in 8 bits, SH rest 8 bits (`v * 128 + 128`; Niantic's writer
//! keeps only 5/4 of those bits, any 8-bit value reads the same way). Language features have
//! no place in SPZ and are dropped.

use std::io::Write;

use crate::error::{Error, Result};
use crate::model::{sh_coeffs, Gaussians};

const MAGIC: u32 = 0x5053_474e;
const COLOR_SCALE: f32 = 0.15;
/// Niantic's default fixed-point precision (1/4096 unit); fewer bits only if the scene is larger
/// than 24-bit fixed point at 12 fractional bits can hold (+-2048 units).
const MAX_FRACTIONAL_BITS: u8 = 12;

/// Sign flips per SH coefficient (index 1..16) for the RDF -> RUB change (180 deg about x).
const SH_FLIP: [f32; 16] = [
    1., -1., -1., 1., -1., 1., 1., -1., 1., -1., 1., -1., -1., 1., -1., 1.,
];

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SpzVersion {
    V2,
    V3,
}

fn u8_of(v: f32) -> u8 {
    // NaN maps to 0 (`as` saturates); inputs are checked finite first.
    v.round().clamp(0.0, 255.0) as u8
}

/// The fractional bits that keep every coordinate within 24-bit fixed point.
fn fractional_bits(g: &Gaussians) -> Result<u8> {
    let max = g
        .positions
        .iter()
        .flatten()
        .fold(0f32, |m, v| m.max(v.abs()));
    (0..=MAX_FRACTIONAL_BITS)
        .rev()
        .find(|&f| max * (1u32 << f) as f32 <= ((1 << 23) - 1) as f32)
        .ok_or_else(|| {
            Error::foreign(
                "SPZ",
                format!("a coordinate of {max} does not fit 24-bit fixed point"),
            )
        })
}

/// Smallest-three rotation (v3): the largest |component| is dropped (made positive by
/// negating the whole quaternion), the others are stored as 9-bit magnitudes in units of
/// 1/sqrt(2) with a sign bit, first component in the highest bits, index of the dropped one
/// in the top 2 bits.
fn smallest_three(xyzw: [f32; 4]) -> [u8; 4] {
    let largest = (0..4)
        .max_by(|&a, &b| xyzw[a].abs().total_cmp(&xyzw[b].abs()))
        .expect("four components");
    let sign = if xyzw[largest] < 0.0 { -1.0 } else { 1.0 };
    let mut comp = 0u32;
    for k in 0..4 {
        if k == largest {
            continue;
        }
        let v = xyzw[k] * sign;
        let mag = (v.abs() / std::f32::consts::FRAC_1_SQRT_2 * 511.0)
            .round()
            .min(511.0) as u32;
        comp = comp << 10 | u32::from(v < 0.0) << 9 | mag;
    }
    (comp | (largest as u32) << 30).to_le_bytes()
}

/// Normalised (x, y, z, w) in SPZ's RUB axes; a zero quaternion becomes the identity.
fn rub_quaternion(wxyz: [f32; 4]) -> [f32; 4] {
    let n = wxyz.iter().map(|v| v * v).sum::<f32>().sqrt();
    if !(n > 1e-12) {
        return [0.0, 0.0, 0.0, 1.0];
    }
    let [w, x, y, z] = wxyz.map(|v| v / n);
    [x, -y, -z, w]
}

#[allow(clippy::disallowed_methods)] // writing SPZ (encoder side)
pub fn write_spz(g: &Gaussians, version: SpzVersion) -> Result<Vec<u8>> {
    g.check_shapes()?;
    g.check_finite()?;
    if g.sh_degree > 3 {
        return Err(Error::foreign(
            "SPZ",
            format!("SH degree {} > 3", g.sh_degree),
        ));
    }
    let n = g.len();
    let n32 = u32::try_from(n).map_err(|_| Error::foreign("SPZ", "more than 2^32 Gaussians"))?;
    let frac = fractional_bits(g)?;
    let rest = sh_coeffs(g.sh_degree) - 1;
    let stride = g.sh_stride();
    let rot_bytes = if version == SpzVersion::V3 { 4 } else { 3 };
    let mut raw = Vec::with_capacity(16 + n * (9 + 1 + 3 + 3 + rot_bytes + rest * 3));
    raw.extend_from_slice(&MAGIC.to_le_bytes());
    raw.extend_from_slice(&(if version == SpzVersion::V3 { 3u32 } else { 2 }).to_le_bytes());
    raw.extend_from_slice(&n32.to_le_bytes());
    raw.extend_from_slice(&[g.sh_degree, frac, 0, 0]);
    let fixed = (1u32 << frac) as f32;
    let flip = [1.0f32, -1.0, -1.0];
    for p in &g.positions {
        for a in 0..3 {
            let v = (p[a] * flip[a] * fixed).round() as i32;
            raw.extend_from_slice(&v.to_le_bytes()[..3]);
        }
    }
    for &o in &g.opacity {
        raw.push(u8_of(255.0 / (1.0 + (-o).exp())));
    }
    for i in 0..n {
        for c in 0..3 {
            raw.push(u8_of((g.sh[i * stride + c] * COLOR_SCALE + 0.5) * 255.0));
        }
    }
    for s in &g.log_scales {
        for a in 0..3 {
            raw.push(u8_of((s[a] + 10.0) * 16.0));
        }
    }
    for q in &g.rotations {
        let xyzw = rub_quaternion(*q);
        match version {
            SpzVersion::V3 => raw.extend_from_slice(&smallest_three(xyzw)),
            SpzVersion::V2 => {
                // w is implied non-negative.
                let s = if xyzw[3] < 0.0 { -1.0 } else { 1.0 };
                for k in 0..3 {
                    raw.push(u8_of((xyzw[k] * s + 1.0) * 127.5));
                }
            }
        }
    }
    for i in 0..n {
        for k in 0..rest {
            for c in 0..3 {
                let v = g.sh[i * stride + (k + 1) * 3 + c] * SH_FLIP[k + 1];
                raw.push(u8_of(v * 128.0 + 128.0));
            }
        }
    }
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    gz.write_all(&raw)
        .and_then(|_| gz.finish())
        .map_err(|e| Error::foreign("SPZ", format!("gzip: {e}")))
}

#[cfg(test)]
#[allow(clippy::disallowed_methods)] // the platform libm as a reference or test data
mod tests {
    use super::*;
    use crate::interop::spz::read_spz;
    use crate::limits::Limits;

    fn scene() -> Gaussians {
        let mut g = Gaussians::new(1, 0);
        let quats = [
            [1.0, 0.0, 0.0, 0.0],
            [0.2, -0.9, 0.3, 0.1],
            [-0.5, 0.5, -0.5, 0.5],
            [0.0, 0.0, 0.0, 0.0],
        ];
        for (i, q) in quats.iter().enumerate() {
            let f = i as f32;
            g.positions.push([f * 0.37 - 1.0, 2.5 - f, f * f * 0.1]);
            g.log_scales.push([-4.0 + f, -3.0, -9.9]);
            g.rotations.push(*q);
            g.opacity.push(f - 1.5);
            for k in 0..12 {
                g.sh.push(((i * 12 + k) as f32 * 0.37).sin() * 0.8);
            }
        }
        g
    }

    #[test]
    fn round_trip_within_spz_quantisation() {
        let g = scene();
        for v in [SpzVersion::V2, SpzVersion::V3] {
            let back = read_spz(&write_spz(&g, v).unwrap(), &Limits::default()).unwrap();
            assert_eq!(back.len(), g.len());
            for i in 0..g.len() {
                for a in 0..3 {
                    assert!((back.positions[i][a] - g.positions[i][a]).abs() <= 0.5 / 4096.0);
                    assert!((back.log_scales[i][a] - g.log_scales[i][a]).abs() <= 1.0 / 32.0);
                }
                let s = |o: f32| 1.0 / (1.0 + (-o).exp());
                assert!((s(back.opacity[i]) - s(g.opacity[i])).abs() <= 0.5 / 255.0 + 1e-6);
                for k in 0..12 {
                    let step = if k < 3 {
                        1.0 / (255.0 * COLOR_SCALE)
                    } else {
                        1.0 / 128.0
                    };
                    let d = (back.sh[i * 12 + k] - g.sh[i * 12 + k]).abs();
                    assert!(d <= step * 0.5 + 1e-5, "{v:?} sh {i} {k}: {d}");
                }
                // Same rotation up to sign; the zero quaternion reads back as identity.
                let q = rub_quaternion(g.rotations[i]);
                let want = [q[3], q[0], -q[1], -q[2]];
                let r = back.rotations[i];
                let dot: f32 = (0..4).map(|k| r[k] * want[k]).sum();
                let tol = if v == SpzVersion::V3 { 0.003 } else { 0.02 };
                assert!(1.0 - dot.abs() < tol, "{v:?} rotation {i}: dot {dot}");
            }
        }
    }

    #[test]
    fn refuses_non_finite_and_shrinks_precision_for_large_scenes() {
        let mut g = scene();
        g.positions[1][0] = f32::NAN;
        assert!(write_spz(&g, SpzVersion::V3).is_err());
        let mut g = scene();
        g.positions[2][1] = 5000.0;
        let back = read_spz(&write_spz(&g, SpzVersion::V3).unwrap(), &Limits::default()).unwrap();
        assert!((back.positions[2][1] - 5000.0).abs() <= 0.5 / 1024.0);
    }
}
