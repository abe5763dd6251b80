//! Niantic SPZ versions 2, 3 (gzip) and 4 (plain header + TOC + zstd streams), read.
//! v4: 32-byte header {magic u32, version u32, numPoints u32, shDegree u8, fractionalBits u8,
//! flags u8, numStreams u8, tocByteOffset u32, reserved[12]}, optional extension records,
//! TOC of numStreams x {compressed u64, uncompressed u64}, then one zstd frame per stream in
//! the order positions, alphas, colours, scales, rotations (smallest-three), SH.
//! Extensions are skipped (the SH min/max quantisation extension is not applied).
//! v2/v3 layout after gunzip:
//! 16-byte header {magic "NGSP" u32, version u32, numPoints u32, shDegree u8, fractionalBits u8,
//! flags u8, reserved u8}, then planar: positions (24-bit fixed, 9 B), alphas (1 B),
//! colours (3 B), scales (3 B), rotations (v2: 3 B xyz, v3: 4 B smallest-three), SH (u8).
//! SPZ stores the RUB axis convention; INRIA PLY uses RDF, so y and z are flipped on read
//! (positions, quaternion vector part, SH odd in y or z), as the reference loader does.

use std::io::Read;

use crate::error::{Error, Result};
use crate::interop::splat::alpha_u8_to_logit;
use crate::limits::Limits;
use crate::model::{sh_coeffs, Gaussians};

const MAGIC: u32 = 0x5053_474e;
const COLOR_SCALE: f32 = 0.15;

/// Sign flips per SH coefficient (index 1..16) for the RUB -> RDF change (180 deg about x).
const SH_FLIP: [f32; 16] = [
    1., -1., -1., 1., -1., 1., 1., -1., 1., -1., 1., -1., -1., 1., -1., 1.,
];

pub fn read_spz(data: &[u8], limits: &Limits) -> Result<Gaussians> {
    if data.len() >= 4 && u32::from_le_bytes(data[0..4].try_into().expect("4 bytes")) == MAGIC {
        return read_v4(data, limits);
    }
    if data.len() < 2 || data[0..2] != [0x1f, 0x8b] {
        return Err(Error::foreign(
            "SPZ",
            "neither a gzip SPZ (v2/v3) nor an NGSP v4 header",
        ));
    }
    let mut raw = Vec::new();
    flate2::read::GzDecoder::new(data)
        .take(limits.max_alloc)
        .read_to_end(&mut raw)
        .map_err(|e| Error::foreign("SPZ", format!("gzip: {e}")))?;
    limits.check_alloc("SPZ decompressed", raw.len() as u64, 0)?;
    if raw.len() < 16 {
        return Err(Error::foreign("SPZ", "header truncated"));
    }
    let u32at = |i: usize| u32::from_le_bytes(raw[i..i + 4].try_into().expect("4 bytes"));
    if u32at(0) != MAGIC {
        return Err(Error::foreign("SPZ", "bad NGSP magic"));
    }
    let version = u32at(4);
    if !(2..=3).contains(&version) {
        return Err(Error::foreign(
            "SPZ",
            format!("gzip container with version {version}; 2 and 3 are supported"),
        ));
    }
    let (n, degree, frac) = (u32at(8) as usize, raw[12], raw[13]);
    check_header(degree, frac)?;
    let rot_bytes = if version >= 3 { 4 } else { 3 };
    let sizes = stream_sizes(n, degree, rot_bytes)?;
    let need = 16 + sizes.iter().sum::<usize>();
    if raw.len() != need {
        return Err(Error::foreign(
            "SPZ",
            format!("{n} points need {need} bytes, {} present", raw.len()),
        ));
    }
    let mut streams = Vec::with_capacity(6);
    let mut at = 16;
    for len in sizes {
        streams.push(&raw[at..at + len]);
        at += len;
    }
    Ok(unpack(n, degree, frac, version >= 3, &streams))
}

fn check_header(degree: u8, frac: u8) -> Result<()> {
    if degree > 3 {
        return Err(Error::foreign("SPZ", format!("SH degree {degree} > 3")));
    }
    if frac > 23 {
        return Err(Error::foreign(
            "SPZ",
            format!("fractional bits {frac} > 23"),
        ));
    }
    Ok(())
}

/// Byte sizes of the six planar streams.
fn stream_sizes(n: usize, degree: u8, rot_bytes: usize) -> Result<[usize; 6]> {
    let rest = sh_coeffs(degree) - 1;
    let m = |k: usize| {
        n.checked_mul(k)
            .ok_or_else(|| Error::foreign("SPZ", "size overflow"))
    };
    Ok([m(9)?, m(1)?, m(3)?, m(3)?, m(rot_bytes)?, m(rest * 3)?])
}

fn read_v4(data: &[u8], limits: &Limits) -> Result<Gaussians> {
    if data.len() < 32 {
        return Err(Error::foreign("SPZ", "v4 header truncated"));
    }
    let u32at = |i: usize| u32::from_le_bytes(data[i..i + 4].try_into().expect("4 bytes"));
    let version = u32at(4);
    if version != 4 {
        return Err(Error::foreign(
            "SPZ",
            format!("uncompressed NGSP header with version {version}; only 4 is defined"),
        ));
    }
    let (n, degree, frac, streams_n, toc) = (
        u32at(8) as usize,
        data[12],
        data[13],
        data[15] as usize,
        u32at(16) as usize,
    );
    check_header(degree, frac)?;
    // Six streams; writers may leave out the SH stream when there is no SH beyond DC
    // (`@playcanvas/splat-transform` does for degree 0).
    if !(streams_n == 6 || (streams_n == 5 && degree == 0)) {
        return Err(Error::foreign(
            "SPZ",
            format!("{streams_n} streams; v4 defines 6 (5 without SH bands)"),
        ));
    }
    if toc < 32
        || toc
            .checked_add(streams_n * 16)
            .is_none_or(|e| e > data.len())
    {
        return Err(Error::foreign("SPZ", "TOC outside the file"));
    }
    let sizes = stream_sizes(n, degree, 4)?;
    limits.check_alloc("SPZ streams", sizes.iter().sum::<usize>() as u64, 0)?;
    let u64at = |i: usize| u64::from_le_bytes(data[i..i + 8].try_into().expect("8 bytes"));
    let mut at = toc + streams_n * 16;
    let mut owned = Vec::with_capacity(6);
    for (k, want) in sizes.iter().enumerate().take(streams_n) {
        let (comp, uncomp) = (u64at(toc + k * 16), u64at(toc + k * 16 + 8));
        if uncomp != *want as u64 {
            return Err(Error::foreign(
                "SPZ",
                format!("stream {k}: {uncomp} bytes declared, {want} expected for {n} points"),
            ));
        }
        let end = (at as u64)
            .checked_add(comp)
            .filter(|e| *e <= data.len() as u64)
            .ok_or_else(|| Error::foreign("SPZ", format!("stream {k} runs past the end")))?
            as usize;
        let out = zstd::bulk::decompress(&data[at..end], *want)
            .map_err(|e| Error::foreign("SPZ", format!("stream {k}: zstd: {e}")))?;
        if out.len() != *want {
            return Err(Error::foreign(
                "SPZ",
                format!(
                    "stream {k}: {} bytes decompressed, {want} expected",
                    out.len()
                ),
            ));
        }
        owned.push(out);
        at = end;
    }
    // A left-out SH stream holds nothing (degree 0).
    owned.resize(6, Vec::new());
    let streams: Vec<&[u8]> = owned.iter().map(Vec::as_slice).collect();
    Ok(unpack(n, degree, frac, true, &streams))
}

/// Decode the six planar streams (sizes already checked).
fn unpack(n: usize, degree: u8, frac: u8, smallest_three: bool, streams: &[&[u8]]) -> Gaussians {
    let [pos, alpha, col, scl, rot, sh] = [
        streams[0], streams[1], streams[2], streams[3], streams[4], streams[5],
    ];
    let rest = sh_coeffs(degree) - 1;
    let version = if smallest_three { 3 } else { 2 };
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
    g
}
