//! `ANCR`: raw canonical anchors of a Scaffold-GS GOP (format-spec §6.9): every float exactly as
//! the encoder received it.

use crate::bytes::{zstd_compress, zstd_exact, ByteReader, PutLe};
use crate::container::{ChunkType, SceneHeader};
use crate::error::{Error, Result};
use crate::limits::Limits;
use crate::model::scaffold::{Anchors, ScaffoldCanonical, FEAT_DIM, N_OFFSETS, SCALING_DIM};

/// Floats per anchor: position, feature, offsets, log-scalings.
pub const FLOATS: usize = 3 + FEAT_DIM + 3 * N_OFFSETS + SCALING_DIM;

/// Serialise (codec 1, zstd). Rejects shapes that disagree with the scene and NaN/Inf.
pub fn encode(c: &ScaffoldCanonical, scene: &SceneHeader, zstd_level: i32) -> Result<Vec<u8>> {
    if c.statics.len() != scene.n_static as usize || c.dynamics.len() != scene.n_dynamic as usize {
        return Err(Error::input(format!(
            "{} static + {} dynamic anchors, the scene says {} + {}",
            c.statics.len(),
            c.dynamics.len(),
            scene.n_static,
            scene.n_dynamic
        )));
    }
    let mut body = Vec::with_capacity((c.statics.len() + c.dynamics.len()) * FLOATS * 4);
    for (set, name) in [(&c.statics, "static"), (&c.dynamics, "dynamic")] {
        set.check_shapes()
            .map_err(|e| Error::input(format!("{name} anchors: {e}")))?;
        let arrays: [(&str, Vec<f32>); 4] = [
            (
                "position",
                set.positions.iter().flatten().copied().collect(),
            ),
            ("feature", set.features.clone()),
            ("offsets", set.offsets.clone()),
            ("log-scaling", set.log_scalings.clone()),
        ];
        for (what, v) in &arrays {
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                return Err(Error::input(format!(
                    "{name} anchors: {what} value {i} is {} (anchors must be finite)",
                    v[i]
                )));
            }
            for &x in v {
                body.put_f32(x);
            }
        }
    }
    let mut p = Vec::new();
    p.put_u8(1);
    p.extend_from_slice(&[0, 0, 0]);
    p.put_u32(scene.n_static);
    p.put_u32(scene.n_dynamic);
    p.put_u64(body.len() as u64);
    p.extend_from_slice(&zstd_compress(&body, zstd_level)?);
    Ok(p)
}

fn read_set(r: &mut ByteReader, n: usize, at: u64) -> Result<Anchors> {
    let pos = r.f32_vec(3 * n, "positions")?;
    let a = Anchors {
        positions: pos.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect(),
        features: r.f32_vec(FEAT_DIM * n, "features")?,
        offsets: r.f32_vec(3 * N_OFFSETS * n, "offsets")?,
        log_scalings: r.f32_vec(SCALING_DIM * n, "log-scalings")?,
    };
    let finite = |v: &[f32]| v.iter().all(|x| x.is_finite());
    if !(finite(&pos) && finite(&a.features) && finite(&a.offsets) && finite(&a.log_scalings)) {
        return Err(Error::payload(
            ChunkType::ANCR,
            "anchors must be finite",
            at,
        ));
    }
    Ok(a)
}

/// Parse a payload at file offset `offset`.
pub fn decode(
    p: &[u8],
    offset: u64,
    scene: &SceneHeader,
    limits: &Limits,
) -> Result<ScaffoldCanonical> {
    let mut r = ByteReader::new(p, offset);
    let codec = r.u8("codec")?;
    r.take(3, "reserved")?;
    let ns_at = r.offset();
    let ns = r.u32("n_static")?;
    let nd = r.u32("n_dynamic")?;
    if ns != scene.n_static || nd != scene.n_dynamic {
        return Err(Error::payload(
            ChunkType::ANCR,
            format!(
                "{ns} + {nd} anchors, the scene header says {} + {}",
                scene.n_static, scene.n_dynamic
            ),
            ns_at,
        ));
    }
    let len_at = r.offset();
    let body_len = r.u64("body_len")?;
    let want = (ns as u64 + nd as u64) * FLOATS as u64 * 4;
    if body_len != want {
        return Err(Error::payload(
            ChunkType::ANCR,
            format!("body_len {body_len}, {want} for these counts"),
            len_at,
        ));
    }
    limits.check_alloc("anchors", body_len, len_at)?;
    let at = r.offset();
    let body = match codec {
        0 => {
            let b = r.rest();
            if b.len() as u64 != body_len {
                return Err(Error::payload(
                    ChunkType::ANCR,
                    format!("{} body bytes, body_len says {body_len}", b.len()),
                    at,
                ));
            }
            b.to_vec()
        }
        1 => zstd_exact(r.rest(), body_len, at)?,
        c => {
            return Err(Error::payload(
                ChunkType::ANCR,
                format!("codec {c} (0 or 1)"),
                offset,
            ))
        }
    };
    let mut b = ByteReader::new(&body, at);
    let statics = read_set(&mut b, ns as usize, at)?;
    let dynamics = read_set(&mut b, nd as usize, at)?;
    Ok(ScaffoldCanonical { statics, dynamics })
}
