//! Niantic SPZ, legacy gzip versions 2 and 3 (read). Layout after gunzip:
//! 16-byte header {magic "NGSP" u32, version u32, numPoints u32, shDegree u8, fractionalBits u8,
//! flags u8, reserved u8}, then planar: positions (24-bit fixed, 9 B), alphas (1 B),
//! colours (3 B), scales (3 B), rotations (v2: 3 B xyz, v3: 4 B smallest-three), SH (u8).
//! SPZ stores the RUB axis convention; INRIA PLY uses RDF, so y and z are flipped on read
//! (positions, quaternion vector part, SH odd in y or z), as the reference loader does.

use std::io::Read;

use crate::error::{Error, ErrorKind, Result};
use crate::interop::splat::alpha_u8_to_logit;
use crate::limits::Limits;
use crate::model::{sh_coeffs, Gaussians};

const MAGIC: u32 = 0x5053_474e;
const COLOR_SCALE: f32 = 0.15;

fn err(reason: impl Into<String>) -> Error {
    Error::new(
        ErrorKind::Foreign {
            format: "SPZ",
            reason: reason.into(),
        },
        0,
    )
}

/// Sign flips per SH coefficient (index 1..16) for the RUB -> RDF change (180 deg about x).
const SH_FLIP: [f32; 16] = [
    1., -1., -1., 1., -1., 1., 1., -1., 1., -1., 1., -1., -1., 1., -1., 1.,
];

pub fn read_spz(data: &[u8], limits: &Limits) -> Result<Gaussians> {
    if data.len() < 2 || data[0..2] != [0x1f, 0x8b] {
        return Err(err(
            "not a gzip SPZ (v2/v3); SPZ v4 (NGSP + zstd) is not supported yet",
        ));
    }
    let mut raw = Vec::new();
    flate2::read::GzDecoder::new(data)
        .take(limits.max_alloc)
        .read_to_end(&mut raw)
        .map_err(|e| err(format!("gzip: {e}")))?;
    if raw.len() < 16 {
        return Err(err("header truncated"));
    }
    let u32at = |i: usize| u32::from_le_bytes(raw[i..i + 4].try_into().expect("4 bytes"));
    if u32at(0) != MAGIC {
        return Err(err("bad NGSP magic"));
    }
    let version = u32at(4);
    if !(2..=3).contains(&version) {
        return Err(err(format!(
            "version {version} not supported (2 and 3 are)"
        )));
    }
    let n = u32at(8) as usize;
    let degree = raw[12];
    let frac = raw[13];
    if degree > 3 {
        return Err(err(format!("SH degree {degree} > 3")));
    }
    if frac > 23 {
        return Err(err(format!("fractional bits {frac} > 23")));
    }
    let rot_bytes = if version >= 3 { 4 } else { 3 };
    let rest = sh_coeffs(degree) - 1;
    let per = 9 + 1 + 3 + 3 + rot_bytes + rest * 3;
    let need = 16 + n.checked_mul(per).ok_or_else(|| err("size overflow"))?;
    if raw.len() != need {
        return Err(err(format!(
            "{} points need {need} bytes, {} present",
            n,
            raw.len()
        )));
    }
    let pos = &raw[16..16 + 9 * n];
    let alpha = &raw[16 + 9 * n..16 + 10 * n];
    let col = &raw[16 + 10 * n..16 + 13 * n];
    let scl = &raw[16 + 13 * n..16 + 16 * n];
    let rot = &raw[16 + 16 * n..16 + (16 + rot_bytes) * n];
    let sh = &raw[16 + (16 + rot_bytes) * n..];
    let mut g = Gaussians::new(degree, 0);
    let scale = 1.0 / (1u32 << frac) as f32;
    let flip = [1.0f32, -1.0, -1.0];
    for i in 0..n {
        let p = |a: usize| {
            let b = &pos[(i * 3 + a) * 3..];
            let v = (b[0] as i32 | (b[1] as i32) << 8 | (b[2] as i32) << 16) << 8 >> 8;
            v as f32 * scale * flip[a]
        };
        g.positions.push([p(0), p(1), p(2)]);
        g.log_scales
            .push([0, 1, 2].map(|a| scl[i * 3 + a] as f32 / 16.0 - 10.0));
        g.opacity.push(alpha_u8_to_logit(alpha[i]));
        let mut xyzw = [0f32; 4];
        if version >= 3 {
            let r = &rot[i * 4..i * 4 + 4];
            let mut comp = u32::from_le_bytes(r.try_into().expect("4 bytes"));
            let largest = (comp >> 30) as usize;
            let mut ss = 0.0;
            for k in (0..4).rev() {
                if k != largest {
                    let mag = (comp & 511) as f32 / 511.0 * std::f32::consts::FRAC_1_SQRT_2;
                    xyzw[k] = if (comp >> 9) & 1 == 1 { -mag } else { mag };
                    ss += xyzw[k] * xyzw[k];
                    comp >>= 10;
                }
            }
            xyzw[largest] = (1.0f32 - ss).max(0.0).sqrt();
        } else {
            let r = &rot[i * 3..i * 3 + 3];
            for k in 0..3 {
                xyzw[k] = r[k] as f32 / 127.5 - 1.0;
            }
            xyzw[3] = (1.0 - xyzw[..3].iter().map(|v| v * v).sum::<f32>())
                .max(0.0)
                .sqrt();
        }
        g.rotations.push([
            xyzw[3],
            xyzw[0] * flip[0],
            xyzw[1] * flip[1],
            xyzw[2] * flip[2],
        ]);
        for c in 0..3 {
            g.sh.push((col[i * 3 + c] as f32 / 255.0 - 0.5) / COLOR_SCALE);
        }
        for k in 0..rest {
            for c in 0..3 {
                g.sh.push((sh[(i * rest + k) * 3 + c] as f32 - 128.0) / 128.0 * SH_FLIP[k + 1]);
            }
        }
    }
    Ok(g)
}
