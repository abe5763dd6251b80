//! `LAED`: the language autoencoder decoder and canonical negatives (format-spec §6.8).

use crate::bytes::{zstd_exact, ByteReader, PutLe};
use crate::chunks::mlpw::{WeightType, MAX_LAYERS, MAX_WIDTH};
use crate::container::{ChunkType, SceneHeader};
use crate::error::{Error, FormatErrorKind, Result};
use crate::model::lang_decoder::{DenseLayer, LangDecoder, NamedEmbedding};
use crate::Limits;

/// Most negatives a reader accepts.
pub const MAX_NEGATIVES: usize = 64;

/// Serialise a decoder. Rejects invalid shapes, NaN/Inf and f16 overflow.
pub fn encode(d: &LangDecoder, ty: WeightType, zstd_level: i32) -> Result<Vec<u8>> {
    d.validate()?;
    let widths = d.widths();
    if d.layers.len() > MAX_LAYERS
        || widths.iter().any(|&w| w > MAX_WIDTH)
        || d.negatives.len() > MAX_NEGATIVES
    {
        return Err(Error::input(format!(
                "language decoder outside the format's limits ({} layers <= {MAX_LAYERS}, widths <= {MAX_WIDTH}, {} negatives <= {MAX_NEGATIVES})",
                d.layers.len(),
                d.negatives.len()
            )));
    }
    let mut b = Vec::new();
    b.put_u8(ty as u8);
    b.put_u8(d.layers.len() as u8);
    b.put_u8(d.negatives.len() as u8);
    b.put_u8(0);
    for &w in &widths {
        b.put_u16(w as u16);
    }
    for n in &d.negatives {
        b.put_u8(n.name.len() as u8);
        b.extend_from_slice(n.name.as_bytes());
    }
    let mut raw = Vec::new();
    for l in &d.layers {
        for &v in l.weight.iter().chain(&l.bias) {
            ty.put(&mut raw, v, "language decoder value")?;
        }
    }
    for n in &d.negatives {
        for &v in &n.values {
            ty.put(&mut raw, v, "negative embedding value")?;
        }
    }
    let z = crate::bytes::zstd_compress(&raw, zstd_level)?;
    b.put_u32(raw.len() as u32);
    b.extend_from_slice(&z);
    Ok(b)
}

/// Parse a `LAED` payload at absolute `offset` and check it against the scene.
pub fn decode(p: &[u8], offset: u64, scene: &SceneHeader, limits: &Limits) -> Result<LangDecoder> {
    let mut r = ByteReader::new(p, offset);
    let at = r.offset();
    let ty = match r.u8("LAED weight type")? {
        0 => WeightType::F32,
        1 => WeightType::F16,
        v => {
            return Err(Error::payload(
                ChunkType::LAED,
                format!("unknown weight type {v}"),
                at,
            ))
        }
    };
    let layers = r.u8("LAED layer count")? as usize;
    if layers == 0 || layers > MAX_LAYERS {
        return Err(Error::payload(
            ChunkType::LAED,
            format!("{layers} layers (1..={MAX_LAYERS})"),
            at + 1,
        ));
    }
    let negatives = r.u8("LAED negative count")? as usize;
    if negatives > MAX_NEGATIVES {
        return Err(Error::payload(
            ChunkType::LAED,
            format!("{negatives} negatives (0..={MAX_NEGATIVES})"),
            at + 2,
        ));
    }
    r.u8("LAED reserved")?;
    let mut widths = Vec::with_capacity(layers + 1);
    for _ in 0..=layers {
        let w = r.u16("LAED width")? as usize;
        if w == 0 || w > MAX_WIDTH {
            return Err(Error::payload(
                ChunkType::LAED,
                format!("layer width {w} (1..={MAX_WIDTH})"),
                r.offset() - 2,
            ));
        }
        widths.push(w);
    }
    if scene.lang_levels == 0 {
        return Err(Error::payload(
            ChunkType::LAED,
            "the scene has no language features",
            at,
        ));
    }
    if widths[0] != scene.lang_dims as usize {
        return Err(Error::payload(
            ChunkType::LAED,
            format!(
                "decoder input width {} but the scene has {} dims per language level",
                widths[0], scene.lang_dims
            ),
            at + 4,
        ));
    }
    let mut names = Vec::with_capacity(negatives);
    for _ in 0..negatives {
        let len = r.u8("LAED negative name length")? as usize;
        let name_at = r.offset();
        let bytes = r.take(len, "LAED negative name")?;
        let name = std::str::from_utf8(bytes)
            .map_err(|_| Error::payload(ChunkType::LAED, "negative name is not UTF-8", name_at))?;
        names.push(name.to_string());
    }
    let embed = *widths.last().unwrap_or(&0) as u64;
    let values: u64 = widths
        .windows(2)
        .map(|w| (w[0] * w[1] + w[1]) as u64)
        .sum::<u64>()
        + negatives as u64 * embed;
    let size = ty.size() as u64;
    let raw_at = r.offset();
    let raw_len = r.u32("LAED value bytes")? as u64;
    if raw_len != values * size {
        return Err(Error::payload(
            ChunkType::LAED,
            format!(
                "{raw_len} value bytes declared, shapes need {}",
                values * size
            ),
            raw_at,
        ));
    }
    limits.check_alloc("LAED values", raw_len, raw_at)?;
    let body_at = r.offset();
    let raw = zstd_exact(r.rest(), raw_len, body_at)?;
    let mut it = ty.values(&raw);
    let mut take = |n: usize| -> Result<Vec<f32>> {
        let v: Vec<f32> = it.by_ref().take(n).collect();
        if v.iter().all(|x| x.is_finite()) {
            Ok(v)
        } else {
            Err(Error::format(
                FormatErrorKind::NonFinite {
                    field: "LAED value",
                },
                body_at,
            ))
        }
    };
    let mut out_layers = Vec::with_capacity(layers);
    for w in widths.windows(2) {
        let weight = take(w[0] * w[1])?;
        let bias = take(w[1])?;
        out_layers.push(DenseLayer {
            inputs: w[0],
            outputs: w[1],
            weight,
            bias,
        });
    }
    let mut negs = Vec::with_capacity(negatives);
    for name in names {
        let values = take(embed as usize)?;
        if values.iter().all(|&v| v == 0.0) {
            return Err(Error::payload(
                ChunkType::LAED,
                format!("negative '{name}' is the zero vector"),
                body_at,
            ));
        }
        negs.push(NamedEmbedding { name, values });
    }
    Ok(LangDecoder {
        layers: out_layers,
        negatives: negs,
    })
}
