//! `CRAW`: canonical Gaussians as planar little-endian f32 arrays, optionally zstd-compressed
//! (format-spec §6.1). Lossless; the baseline every compressed canonical codec is measured against.

use crate::bytes::{ByteReader, PutLe};
use crate::container::{ChunkType, SceneHeader};
use crate::error::{Error, Result};
use crate::limits::Limits;
use crate::model::{sh_coeffs, Canonical, Gaussians};

/// Fixed part of a `CRAW` payload before the body.
pub const CRAW_PREFIX_LEN: usize = 20;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RawCodec {
    None = 0,
    Zstd = 1,
}

/// Floats per Gaussian in the body for this layout.
pub fn floats_per_gaussian(sh_degree: u8, lang_width: usize) -> usize {
    3 + 3 + 4 + 1 + sh_coeffs(sh_degree) * 3 + if lang_width > 0 { 1 + lang_width } else { 0 }
}

fn put_set(body: &mut Vec<u8>, g: &Gaussians) {
    body.put_f32s(g.positions.as_flattened());
    body.put_f32s(g.log_scales.as_flattened());
    body.put_f32s(g.rotations.as_flattened());
    body.put_f32s(&g.opacity);
    body.put_f32s(&g.sh);
    if g.has_language() {
        body.put_f32s(&g.lang_opacity);
        body.put_f32s(&g.lang);
    }
}

/// The uncompressed body: static set then dynamic set, attribute-planar.
pub fn canonical_body(c: &Canonical) -> Vec<u8> {
    let fpg = floats_per_gaussian(c.statics.sh_degree, c.statics.lang_width);
    let mut body = Vec::with_capacity(c.len() * fpg * 4);
    put_set(&mut body, &c.statics);
    put_set(&mut body, &c.dynamics);
    body
}

/// SHA-256 of [`canonical_body`], hex: the checksum conformance vectors list.
pub fn canonical_digest(c: &Canonical) -> String {
    use sha2::{Digest, Sha256};
    let d = Sha256::digest(canonical_body(c));
    d.iter().map(|b| format!("{b:02x}")).collect()
}

pub fn encode(c: &Canonical, codec: RawCodec, zstd_level: i32) -> Result<Vec<u8>> {
    c.statics.check_shapes()?;
    c.dynamics.check_shapes()?;
    if c.statics.sh_degree != c.dynamics.sh_degree || c.statics.lang_width != c.dynamics.lang_width
    {
        return Err(Error::input(
            "static and dynamic sets must share SH degree and language width",
        ));
    }
    c.statics.check_finite()?;
    c.dynamics.check_finite()?;
    let body = canonical_body(c);
    let mut p = Vec::with_capacity(CRAW_PREFIX_LEN + body.len());
    p.put_u8(c.statics.sh_degree);
    p.put_u8(c.statics.lang_width as u8);
    p.put_u8(codec as u8);
    p.put_u8(0);
    p.put_u32(c.statics.len() as u32);
    p.put_u32(c.dynamics.len() as u32);
    p.put_u64(body.len() as u64);
    match codec {
        RawCodec::None => p.extend_from_slice(&body),
        RawCodec::Zstd => {
            let z = crate::bytes::zstd_compress(&body, zstd_level)?;
            p.extend_from_slice(&z);
        }
    }
    Ok(p)
}

fn read_set(r: &mut ByteReader, n: usize, sh_degree: u8, lw: usize) -> Result<Gaussians> {
    let mut g = Gaussians::new(sh_degree, lw);
    let to3 = |v: Vec<f32>| {
        v.chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect::<Vec<_>>()
    };
    g.positions = to3(r.f32_vec(n * 3, "positions")?);
    g.log_scales = to3(r.f32_vec(n * 3, "log-scales")?);
    g.rotations = r
        .f32_vec(n * 4, "rotations")?
        .chunks_exact(4)
        .map(|c| [c[0], c[1], c[2], c[3]])
        .collect();
    g.opacity = r.f32_vec(n, "opacity")?;
    g.sh = r.f32_vec(n * g.sh_stride(), "SH")?;
    if lw > 0 {
        g.lang_opacity = r.f32_vec(n, "language opacity")?;
        g.lang = r.f32_vec(n * lw, "language features")?;
    }
    Ok(g)
}

/// Decode a `CRAW` payload that starts at absolute `offset`, checking it against the scene.
pub fn decode(p: &[u8], offset: u64, scene: &SceneHeader, limits: &Limits) -> Result<Canonical> {
    let mut r = ByteReader::new(p, offset);
    let bad = |reason: String, at: u64| Error::payload(ChunkType::CRAW, reason, at);
    let at = r.offset();
    let sh_degree = r.u8("CRAW sh_degree")?;
    let lw = r.u8("CRAW lang_width")? as usize;
    if sh_degree != scene.sh_degree || lw != scene.lang_width() {
        return Err(bad(
            format!("layout (SH {sh_degree}, language {lw}) differs from HEAD"),
            at,
        ));
    }
    let at = r.offset();
    let codec = match r.u8("CRAW codec")? {
        0 => RawCodec::None,
        1 => RawCodec::Zstd,
        v => return Err(bad(format!("unknown codec {v}"), at)),
    };
    r.u8("CRAW reserved")?;
    let at = r.offset();
    let ns = r.u32("CRAW n_static")? as usize;
    let nd = r.u32("CRAW n_dynamic")? as usize;
    if ns != scene.n_static as usize || nd != scene.n_dynamic as usize {
        return Err(bad(
            format!(
                "counts {ns}/{nd} differ from HEAD {}/{}",
                scene.n_static, scene.n_dynamic
            ),
            at,
        ));
    }
    let at = r.offset();
    let body_len = r.u64("CRAW body length")?;
    // Counts are bounded by HEAD (already checked against limits), so this cannot overflow u64.
    let want = (ns + nd) as u64 * floats_per_gaussian(sh_degree, lw) as u64 * 4;
    if body_len != want {
        return Err(bad(
            format!("body length {body_len}, layout needs {want}"),
            at,
        ));
    }
    limits.check_alloc("CRAW body", body_len, at)?;
    let body_at = r.offset();
    let rest = r.rest();
    let owned;
    let body: &[u8] = match codec {
        RawCodec::None => {
            if rest.len() as u64 != body_len {
                return Err(bad(
                    format!("{} body bytes present, {body_len} declared", rest.len()),
                    body_at,
                ));
            }
            rest
        }
        RawCodec::Zstd => {
            owned = crate::bytes::zstd_exact(rest, body_len, body_at)?;
            &owned
        }
    };
    let mut br = ByteReader::new(body, body_at);
    let statics = read_set(&mut br, ns, sh_degree, lw)?;
    let dynamics = read_set(&mut br, nd, sh_degree, lw)?;
    Ok(Canonical { statics, dynamics })
}
