//! `MLPW`: the deformation decoders of one GOP (format-spec §6.3): shapes, then every weight
//! in one zstd frame as f32 or f16.

use crate::bytes::{zstd_exact, ByteReader, PutLe};
use crate::container::{ChunkType, SceneHeader};
use crate::error::{Error, FormatErrorKind, Result};
use crate::model::dynamic::check_finite;
use crate::model::{DeformMlps, Layer, Mlp, MlpRole};
use crate::Limits;

/// Most layers per MLP and widest layer a reader accepts (format limits, §6.3).
pub const MAX_LAYERS: usize = 8;
pub const MAX_WIDTH: usize = 4096;

/// Storage type of the weights.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WeightType {
    F32 = 0,
    F16 = 1,
}

impl WeightType {
    /// Bytes per stored value.
    pub fn size(self) -> usize {
        match self {
            WeightType::F32 => 4,
            WeightType::F16 => 2,
        }
    }

    /// Append `v` little-endian; `InvalidInput` naming `what` when it overflows f16.
    pub fn put(self, out: &mut Vec<u8>, v: f32, what: &str) -> Result<()> {
        match self {
            WeightType::F32 => out.put_f32(v),
            WeightType::F16 => {
                let h = half::f16::from_f32(v);
                if !h.is_finite() {
                    return Err(Error::input(format!("{what} {v} overflows f16")));
                }
                out.put_u16(h.to_bits());
            }
        }
        Ok(())
    }

    /// The values of `raw` (a multiple of `size()` bytes), as f32.
    pub fn values(self, raw: &[u8]) -> impl Iterator<Item = f32> + '_ {
        raw.chunks_exact(self.size()).map(move |b| match self {
            WeightType::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            WeightType::F16 => half::f16::from_bits(u16::from_le_bytes([b[0], b[1]])).to_f32(),
        })
    }
}

const FLAG_SCALE_OFFSETS: u8 = 1;

/// Serialise the decoders. Rejects NaN/Inf and f16 overflow.
pub fn encode(m: &DeformMlps, ty: WeightType, zstd_level: i32) -> Result<Vec<u8>> {
    let mlps: Vec<&Mlp> = m.iter().collect();
    let mut b = Vec::new();
    b.put_u8(ty as u8);
    b.put_u8(if m.scale_offsets {
        FLAG_SCALE_OFFSETS
    } else {
        0
    });
    b.put_u8(mlps.len() as u8);
    b.put_u8(0);
    let mut raw = Vec::new();
    for mlp in &mlps {
        b.put_u8(mlp.role as u8);
        b.put_u8(mlp.layers.len() as u8);
        b.put_u16(mlp.inputs() as u16);
        for l in &mlp.layers {
            b.put_u16(l.outputs as u16);
        }
        for l in &mlp.layers {
            check_finite(&format!("{} MLP weights", mlp.role.name()), &l.weights)?;
            let what = format!("{} MLP weight", mlp.role.name());
            for &w in &l.weights {
                ty.put(&mut raw, w, &what)?;
            }
        }
    }
    let z = crate::bytes::zstd_compress(&raw, zstd_level)?;
    b.put_u32(raw.len() as u32);
    b.extend_from_slice(&z);
    Ok(b)
}

/// Parse an `MLPW` payload at absolute `offset` and check it against the scene (§6.3).
pub fn decode(p: &[u8], offset: u64, scene: &SceneHeader, limits: &Limits) -> Result<DeformMlps> {
    let mut r = ByteReader::new(p, offset);
    let at = r.offset();
    let ty = match r.u8("MLPW weight type")? {
        0 => WeightType::F32,
        1 => WeightType::F16,
        v => {
            return Err(Error::payload(
                ChunkType::MLPW,
                format!("unknown weight type {v}"),
                at,
            ))
        }
    };
    let flags = r.u8("MLPW flags")?;
    let at_count = r.offset();
    let count = r.u8("MLPW count")? as usize;
    r.u8("MLPW reserved")?;
    if count == 0 || count > MlpRole::ALL.len() {
        return Err(Error::payload(
            ChunkType::MLPW,
            format!("{count} MLPs (1..=5 allowed)"),
            at_count,
        ));
    }
    let mut shapes: Vec<(MlpRole, Vec<usize>, u64)> = Vec::with_capacity(count);
    let mut total: u64 = 0;
    for _ in 0..count {
        let at = r.offset();
        let role = r.u8("MLPW role")?;
        let role = MlpRole::from_u8(role)
            .ok_or_else(|| Error::payload(ChunkType::MLPW, format!("unknown role {role}"), at))?;
        if shapes.iter().any(|s| s.0 == role) {
            return Err(Error::payload(
                ChunkType::MLPW,
                format!("{} MLP given twice", role.name()),
                at,
            ));
        }
        let layers = r.u8("MLPW layer count")? as usize;
        if layers == 0 || layers > MAX_LAYERS {
            return Err(Error::payload(
                ChunkType::MLPW,
                format!("{layers} layers (1..={MAX_LAYERS})"),
                at + 1,
            ));
        }
        let mut widths = Vec::with_capacity(layers + 1);
        for _ in 0..=layers {
            let w = r.u16("MLPW width")? as usize;
            if w == 0 || w > MAX_WIDTH {
                return Err(Error::payload(
                    ChunkType::MLPW,
                    format!("layer width {w} (1..={MAX_WIDTH})"),
                    r.offset() - 2,
                ));
            }
            widths.push(w);
        }
        total += widths.windows(2).map(|w| (w[0] * w[1]) as u64).sum::<u64>();
        shapes.push((role, widths, at));
    }
    let raw_at = r.offset();
    let raw_len = r.u32("MLPW weight bytes")? as u64;
    if raw_len != total * ty.size() as u64 {
        return Err(Error::payload(
            ChunkType::MLPW,
            format!(
                "{raw_len} weight bytes declared, shapes need {}",
                total * ty.size() as u64
            ),
            raw_at,
        ));
    }
    limits.check_alloc("MLPW weights", raw_len, raw_at)?;
    let body_at = r.offset();
    let raw = zstd_exact(r.rest(), raw_len, body_at)?;
    let mut values = ty.values(&raw);
    let mut slots: [Option<Mlp>; 5] = Default::default();
    for (role, widths, at) in shapes {
        let mut layers = Vec::with_capacity(widths.len() - 1);
        for w in widths.windows(2) {
            let weights: Vec<f32> = values.by_ref().take(w[0] * w[1]).collect();
            if weights.iter().any(|x| !x.is_finite()) {
                return Err(Error::format(
                    FormatErrorKind::NonFinite {
                        field: "MLPW weight",
                    },
                    at,
                ));
            }
            layers.push(Layer {
                inputs: w[0],
                outputs: w[1],
                weights,
            });
        }
        slots[role as usize] = Some(Mlp { role, layers });
    }
    let [deform, cov, opacity, color, lang] = slots;
    let missing = |r: MlpRole| {
        Error::payload(
            ChunkType::MLPW,
            format!("{} MLP missing", r.name()),
            at_count,
        )
    };
    let m = DeformMlps {
        deform: deform.ok_or_else(|| missing(MlpRole::Deform))?,
        cov: cov.ok_or_else(|| missing(MlpRole::Cov))?,
        opacity: opacity.ok_or_else(|| missing(MlpRole::Opacity))?,
        color: color.ok_or_else(|| missing(MlpRole::Color))?,
        lang,
        scale_offsets: flags & FLAG_SCALE_OFFSETS != 0,
    };
    m.validate(scene, offset)?;
    Ok(m)
}
