//! `RDLT`: explicit residual, quantised per-attribute deltas against the reference GOP
//! (format-spec §6.7). Each channel's integer deltas are offset by their minimum and coded with
//! the sorted-grid channel coder (§6.5.3) when they fit 16 bits, else as byte-planed zstd.

use crate::bytes::{ByteReader, PutLe};
use crate::chunks::csog::grid_coder::{self, GridCodec};
use crate::chunks::csog::grid_width;
use crate::container::{ChunkType, SceneHeader};
use crate::error::{Error, FormatErrorKind, Result};
use crate::limits::Limits;
use crate::model::residual::{AttrGroup, DeltaGroup, DeltaMode, DeltaResidual};

/// Channel codec id for deltas wider than 16 bits.
const WIDE: u8 = 3;
const GROUP_HEADER_LEN: usize = 12;

fn bits_for(span: u64) -> u8 {
    (64 - span.leading_zeros()).max(1) as u8
}

/// Code one channel (`n` deltas).
fn encode_channel(out: &mut Vec<u8>, k: &[i32], zstd_level: i32) {
    let kmin = k.iter().copied().min().unwrap_or(0);
    let kmax = k.iter().copied().max().unwrap_or(0);
    let span = (kmax as i64 - kmin as i64) as u64;
    let u = |v: i32| (v as i64 - kmin as i64) as u32;
    out.put_u32(kmin as u32);
    let (codec, bits, data) = if span < 1 << 16 {
        let bits = bits_for(span);
        let q: Vec<u16> = k.iter().map(|&v| u(v) as u16).collect();
        let (c, d) = grid_coder::encode_classic(&q, grid_width(k.len()), bits, zstd_level);
        (c as u8, bits, d)
    } else {
        // Byte planes: all low bytes, then the next, ... so zstd sees runs.
        let mut planes = Vec::with_capacity(k.len() * 4);
        for b in 0..4 {
            planes.extend(k.iter().map(|&v| (u(v) >> (8 * b)) as u8));
        }
        let z = zstd::bulk::compress(&planes, zstd_level).expect("zstd of a memory buffer");
        (WIDE, 32, z)
    };
    out.put_u8(codec);
    out.put_u8(bits);
    out.put_u16(0);
    out.put_u32(data.len() as u32);
    out.extend_from_slice(&data);
}

/// Encode a residual for a scene with this layout.
pub fn encode(d: &DeltaResidual, scene: &SceneHeader, zstd_level: i32) -> Result<Vec<u8>> {
    let lw = scene.lang_width();
    let counts = [scene.n_static as usize, scene.n_dynamic as usize];
    let mut out = Vec::new();
    out.put_u8(d.groups.len() as u8);
    out.extend_from_slice(&[0, 0, 0]);
    for g in &d.groups {
        let w = g.group.width(scene.sh_degree, lw);
        if w == 0
            || g.statics.len() != counts[0] * w
            || g.dynamics.len() != counts[1] * w
            || d.groups.iter().filter(|h| h.group == g.group).count() > 1
        {
            return Err(Error::input(format!(
                "RDLT group {} does not match the scene",
                g.group.name()
            )));
        }
        out.put_u8(g.group as u8);
        let (mode, step, bound) = match g.mode {
            DeltaMode::Exact => (0u8, 0.0, 0.0),
            DeltaMode::Quantised { step, bound } => (1, step, bound),
        };
        out.put_u8(mode);
        out.put_u16(0);
        out.put_f32(step);
        out.put_f32(bound);
    }
    for g in &d.groups {
        let w = g.group.width(scene.sh_degree, lw);
        for (k, n) in [(&g.statics, counts[0]), (&g.dynamics, counts[1])] {
            let mut col = vec![0i32; n];
            for c in 0..w {
                for (i, v) in col.iter_mut().enumerate() {
                    *v = k[i * w + c];
                }
                encode_channel(&mut out, &col, zstd_level);
            }
        }
    }
    Ok(out)
}

fn decode_channel(r: &mut ByteReader, n: usize, limits: &Limits) -> Result<Vec<i32>> {
    let at = r.offset();
    let kmin = r.u32("RDLT channel minimum")? as i32;
    let codec = r.u8("RDLT channel codec")?;
    let bits = r.u8("RDLT channel bits")?;
    r.u16("RDLT reserved")?;
    let len = r.u32("RDLT channel length")? as usize;
    let data_at = r.offset();
    let data = r.take(len, "RDLT channel data")?;
    limits.check_alloc("RDLT channel", n as u64 * 4, at)?;
    // Modulo 2^32, as §6.7.2 states: a damaged minimum wraps instead of failing.
    let from = |u: u32| (kmin as i64 + u as i64) as i32;
    if codec == WIDE {
        if bits != 32 {
            return Err(Error::payload(
                ChunkType::RDLT,
                format!("wide channel with {bits} bits"),
                at,
            ));
        }
        let raw = crate::bytes::zstd_exact(data, n as u64 * 4, data_at)?;
        return Ok((0..n)
            .map(|i| {
                from(u32::from_le_bytes([
                    raw[i],
                    raw[n + i],
                    raw[2 * n + i],
                    raw[3 * n + i],
                ]))
            })
            .collect());
    }
    // RDLT channels use codecs 0-2 only (3 is its own wide codec, above).
    let codec = GridCodec::from_u8(codec)
        .filter(|c| (*c as u8) <= GridCodec::Predictive as u8)
        .ok_or_else(|| {
            Error::payload(
                ChunkType::RDLT,
                format!("unknown channel codec {codec}"),
                at,
            )
        })?;
    if !(1..=16).contains(&bits) {
        return Err(Error::payload(
            ChunkType::RDLT,
            format!("{bits}-bit channel (1..=16)"),
            at,
        ));
    }
    let q = grid_coder::decode(
        codec,
        ByteReader::new(data, data_at),
        n,
        grid_width(n),
        bits,
        None,
        None,
    )
    .map_err(|e| match e {
        // The shared grid coder names CSOG; here its stream is inside RDLT.
        Error::Format(crate::FormatError {
            kind: FormatErrorKind::Payload { reason, .. },
            offset,
            ..
        }) => Error::payload(ChunkType::RDLT, reason, offset),
        e => e,
    })?;
    Ok(q.into_iter().map(|v| from(v as u32)).collect())
}

/// Decode an `RDLT` payload starting at file offset `offset`.
pub fn decode(
    p: &[u8],
    offset: u64,
    scene: &SceneHeader,
    limits: &Limits,
) -> Result<DeltaResidual> {
    let mut r = ByteReader::new(p, offset);
    let count = r.u8("RDLT group count")? as usize;
    if count > AttrGroup::ALL.len() {
        return Err(Error::payload(
            ChunkType::RDLT,
            format!(
                "{count} groups (0..={}: each group at most once)",
                AttrGroup::ALL.len()
            ),
            offset,
        ));
    }
    r.take(3, "RDLT reserved")?;
    let lw = scene.lang_width();
    let mut heads = Vec::with_capacity(count);
    for _ in 0..count {
        let at = r.offset();
        let head = r.take(GROUP_HEADER_LEN, "RDLT group header")?;
        let group = AttrGroup::from_u8(head[0]).ok_or_else(|| {
            Error::payload(
                ChunkType::RDLT,
                format!("unknown attribute group {}", head[0]),
                at,
            )
        })?;
        if group.width(scene.sh_degree, lw) == 0 {
            return Err(Error::payload(
                ChunkType::RDLT,
                format!("group {} does not exist in this scene", group.name()),
                at,
            ));
        }
        if heads.iter().any(|&(g, _)| g == group) {
            return Err(Error::payload(
                ChunkType::RDLT,
                format!("group {} given twice", group.name()),
                at,
            ));
        }
        let f = |o: usize| f32::from_le_bytes(head[o..o + 4].try_into().expect("4 bytes"));
        let mode = match head[1] {
            0 => DeltaMode::Exact,
            1 => {
                let (step, bound) = (f(4), f(8));
                if !(step.is_finite() && step > 0.0 && bound.is_finite() && bound >= 0.0) {
                    return Err(Error::payload(
                        ChunkType::RDLT,
                        format!("step {step} / bound {bound} for {}", group.name()),
                        at + 4,
                    ));
                }
                DeltaMode::Quantised { step, bound }
            }
            m => {
                return Err(Error::payload(
                    ChunkType::RDLT,
                    format!("unknown delta mode {m}"),
                    at + 1,
                ))
            }
        };
        heads.push((group, mode));
    }
    let counts = [scene.n_static as usize, scene.n_dynamic as usize];
    let mut groups = Vec::with_capacity(count);
    for (group, mode) in heads {
        let w = group.width(scene.sh_degree, lw);
        let mut sets = [Vec::new(), Vec::new()];
        for (set, &n) in sets.iter_mut().zip(&counts) {
            limits.check_alloc("RDLT group", (n * w) as u64 * 4, r.offset())?;
            let mut k = vec![0i32; n * w];
            for c in 0..w {
                let col = decode_channel(&mut r, n, limits)?;
                for (i, v) in col.into_iter().enumerate() {
                    k[i * w + c] = v;
                }
            }
            *set = k;
        }
        let [statics, dynamics] = sets;
        groups.push(DeltaGroup {
            group,
            mode,
            statics,
            dynamics,
        });
    }
    Ok(DeltaResidual { groups })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scene of 5 static and 2 dynamic Gaussians at SH degree 0, no language.
    fn scene() -> SceneHeader {
        let mut s = SceneHeader::still(5, 0);
        s.n_dynamic = 2;
        s
    }

    /// Position (exact) and opacity (quantised) deltas for every Gaussian; one opacity channel
    /// of the static set wide (a delta span above 2^16).
    fn residual() -> DeltaResidual {
        DeltaResidual {
            groups: vec![
                DeltaGroup {
                    group: AttrGroup::Position,
                    mode: DeltaMode::Exact,
                    statics: (0..15).map(|i| i - 7).collect(),
                    dynamics: vec![1, 2, 3, 4, 5, 6],
                },
                DeltaGroup {
                    group: AttrGroup::Opacity,
                    mode: DeltaMode::Quantised {
                        step: 0.5,
                        bound: 0.25,
                    },
                    statics: vec![0, 1 << 20, -3, 4, 5],
                    dynamics: vec![-1, 1],
                },
            ],
        }
    }

    /// The error of decoding `p` (at offset 1000) as a `Payload` of `RDLT`: its offset.
    fn payload_error(p: &[u8]) -> u64 {
        let e = decode(p, 1000, &scene(), &Limits::default()).unwrap_err();
        assert_eq!(e.name(), "Payload", "{e}");
        assert!(e.to_string().contains("RDLT"), "{e}");
        e.offset().unwrap()
    }

    #[test]
    fn every_group_header_field_is_checked_where_it_stands() {
        let d = residual();
        let p = encode(&d, &scene(), 3).unwrap();
        assert_eq!(decode(&p, 1000, &scene(), &Limits::default()).unwrap(), d);
        let edit = |f: &dyn Fn(&mut Vec<u8>)| {
            let mut q = p.clone();
            f(&mut q);
            q
        };
        // G above 8 (each group at most once): refused before any group header is read.
        assert_eq!(payload_error(&edit(&|q| q[0] = 9)), 1000);
        // Group id: unknown, absent from the scene (no language), given twice.
        assert_eq!(payload_error(&edit(&|q| q[4] = 8)), 1004);
        assert_eq!(payload_error(&edit(&|q| q[4] = 7)), 1004);
        assert_eq!(payload_error(&edit(&|q| q[16] = 0)), 1016);
        // Mode: 2 is unknown; mode 1 needs a finite step > 0 and a finite bound >= 0.
        assert_eq!(payload_error(&edit(&|q| q[17] = 2)), 1017);
        for (at, v) in [
            (20, 0.0f32),
            (20, -1.0),
            (20, f32::NAN),
            (24, -0.5),
            (24, f32::INFINITY),
        ] {
            let q = edit(&|q| q[at..at + 4].copy_from_slice(&v.to_le_bytes()));
            assert_eq!(payload_error(&q), 1020, "byte {at} = {v}");
        }
        // Mode 0 ignores step and bound.
        let q = edit(&|q| q[8..16].copy_from_slice(&[0xff; 8]));
        assert_eq!(decode(&q, 1000, &scene(), &Limits::default()).unwrap(), d);
        // Channel codec and bits: the first channel (position x of the static set).
        let ch = 4 + 12 * 2;
        assert_eq!(payload_error(&edit(&|q| q[ch + 4] = 4)), 1000 + ch as u64);
        assert_eq!(payload_error(&edit(&|q| q[ch + 5] = 0)), 1000 + ch as u64);
        assert_eq!(payload_error(&edit(&|q| q[ch + 5] = 17)), 1000 + ch as u64);
        // A channel longer than the payload: Truncated; above the budget: LimitExceeded.
        let e = decode(&p[..p.len() - 1], 0, &scene(), &Limits::default()).unwrap_err();
        assert_eq!(e.name(), "Truncated", "{e}");
        let tight = Limits {
            max_alloc: 16,
            ..Limits::default()
        };
        let e = decode(&p, 0, &scene(), &tight).unwrap_err();
        assert_eq!(e.name(), "LimitExceeded", "{e}");
    }

    #[test]
    fn no_byte_change_panics_and_empty_sets_decode() {
        let p = encode(&residual(), &scene(), 3).unwrap();
        for i in 0..p.len() {
            for v in [0, 1, 3, 0x7f, 0x80, 0xff, p[i] ^ 0x10] {
                let mut q = p.clone();
                q[i] = v;
                let _ = decode(&q, 0, &scene(), &Limits::default());
            }
        }
        // A scene without dynamic Gaussians: every dynamic channel holds no delta.
        let mut still = scene();
        still.n_dynamic = 0;
        let mut d = residual();
        for g in &mut d.groups {
            g.dynamics.clear();
        }
        let p = encode(&d, &still, 3).unwrap();
        assert_eq!(decode(&p, 0, &still, &Limits::default()).unwrap(), d);
    }
}
