//! Building decoded GOPs from a GOP's chunks, shared by the random-access [`crate::Decoder`]
//! and the in-order [`crate::stream::StreamDecoder`]: payloads come from a caller's closure.

use std::sync::Arc;

use dlgs::chunks::tfea::{self, TfeaBody, Tiling};
use dlgs::chunks::{
    decode_canonical, decode_residual, life, mlpw, CANONICAL_CHUNKS, RESIDUAL_CHUNKS,
};
use dlgs::container::{ChunkInfo, ChunkType, SceneHeader};
use dlgs::model::{DeformMlps, Lifetimes};
use dlgs::{Error, FormatErrorKind, Limits, Result};

use crate::hevc::SharedKeyPictureDecoder;
use crate::planar::{KeySource, PlanarFeatures};
use crate::prefix_keys::{Dequantise, PrefixKeys};
use crate::{DecodedGop, Deformer, State};

fn find(chunks: &[ChunkInfo], ty: ChunkType) -> Option<ChunkInfo> {
    chunks.iter().find(|c| c.ty == ty).copied()
}

/// Decode key pictures with `hevc`, or fail with `NoHevcDecoder` when there is none. A
/// decoder's failure is a fault of the `TFEA` payload at `at`. `beside`: the decode runs beside
/// other work (see [`crate::hevc::KeyPictureDecoder::decode_beside`]).
pub(crate) fn key_pictures(
    hevc: Option<&SharedKeyPictureDecoder>,
    packets: &[&[u8]],
    tiling: &Tiling,
    expect: usize,
    at: u64,
    beside: bool,
) -> Result<Vec<Vec<u16>>> {
    let hevc = hevc.ok_or(Error::NoHevcDecoder)?;
    let bad = |reason: String| Error::payload(ChunkType::TFEA, reason, at);
    let (w, h) = (tiling.width() as u32, tiling.height() as u32);
    let pictures = if beside {
        hevc.decode_beside(packets, w, h, expect)
    } else {
        hevc.decode(packets, w, h, expect)
    }
    .map_err(bad)?;
    if pictures.len() != expect {
        return Err(bad(format!(
            "the HEVC decoder gave {} pictures, {expect} expected",
            pictures.len()
        )));
    }
    check_pictures(&pictures, tiling, at)?;
    Ok(pictures)
}

/// A plugged-in decoder is not trusted: its pictures are checked before they are untiled.
pub(crate) fn check_pictures(pictures: &[Vec<u16>], tiling: &Tiling, at: u64) -> Result<()> {
    let bad = |reason: String| Error::payload(ChunkType::TFEA, reason, at);
    let side = tiling.width() * tiling.height();
    if let Some(p) = pictures.iter().find(|p| p.len() != side) {
        return Err(bad(format!(
            "the HEVC decoder gave a picture of {} samples, {side} expected",
            p.len()
        )));
    }
    if let Some(v) = pictures.iter().flatten().find(|&&v| v > 4095) {
        return Err(bad(format!(
            "the HEVC decoder gave sample {v}, above 12 bits"
        )));
    }
    Ok(())
}

/// Decode a GOP's canonical chunk, or apply its residual chunk to `base` (the reference GOP's
/// state; `None` for GOPs without a reference). `chunks` come from a container reader, which
/// has checked §3.3's GOP rules: each type at most once, one residual chunk at most, a
/// canonical chunk only without a reference GOP and a residual one only with one.
pub(crate) fn state(
    scene: &SceneHeader,
    limits: &Limits,
    chunks: &[ChunkInfo],
    gop_at: u64,
    base: Option<&State>,
    mut payload: impl FnMut(&ChunkInfo) -> Result<Vec<u8>>,
) -> Result<State> {
    // CSOG before CRAW: a GOP holding both (which writers must not write) decodes its CSOG.
    let find_any = |set: &[ChunkType]| set.iter().find_map(|&ty| find(chunks, ty));
    let (canon, residual) = (find_any(&CANONICAL_CHUNKS), find_any(&RESIDUAL_CHUNKS));
    let Some(base) = base else {
        let c = canon
            .ok_or_else(|| Error::format(FormatErrorKind::MissingChunk(ChunkType::CRAW), gop_at))?;
        let p = payload(&c)?;
        let canonical = decode_canonical(c.ty, &p, c.payload_offset(), scene, limits)
            .expect("a canonical chunk type")?;
        return Ok(State {
            canonical: Arc::new(canonical),
            source: c.ty,
            ntc: None,
        });
    };
    let c = residual
        .ok_or_else(|| Error::format(FormatErrorKind::MissingChunk(ChunkType::RDLT), gop_at))?;
    let p = payload(&c)?;
    let (canonical, ntc) =
        decode_residual(c.ty, &p, c.payload_offset(), scene, limits, &base.canonical)
            .expect("a residual chunk type")?;
    Ok(State {
        canonical: Arc::new(canonical),
        source: c.ty,
        ntc: ntc.map(Arc::new),
    })
}

/// The raw payloads of a GOP's time features (`TFEA`) and decoders (`MLPW`), with their offsets.
pub(crate) struct DynamicPayloads {
    tfea: (Vec<u8>, u64),
    mlpw: (Vec<u8>, u64),
    /// `LIFE` (§6.14), when some Gaussians are shown for only part of the GOP.
    life: Option<(Vec<u8>, u64)>,
}

/// A GOP's decoded time features, decoders and lifetimes.
pub(crate) type DynamicParts = (PlanarFeatures, DeformMlps, Option<Lifetimes>);

/// Read the dynamic payloads of a GOP (`None` when the scene has no dynamic Gaussians).
pub(crate) fn dynamic_payloads(
    scene: &SceneHeader,
    chunks: &[ChunkInfo],
    gop_at: u64,
    mut payload: impl FnMut(&ChunkInfo) -> Result<Vec<u8>>,
) -> Result<Option<DynamicPayloads>> {
    if scene.n_dynamic == 0 {
        return Ok(None);
    }
    let mut read = |ty: ChunkType| -> Result<(Vec<u8>, u64)> {
        let c = find(chunks, ty)
            .ok_or_else(|| Error::format(FormatErrorKind::MissingChunk(ty), gop_at))?;
        Ok((payload(&c)?, c.payload_offset()))
    };
    let tfea = read(ChunkType::TFEA)?;
    let mlpw = read(ChunkType::MLPW)?;
    let life = match find(chunks, ChunkType::LIFE) {
        Some(c) => Some((payload(&c)?, c.payload_offset())),
        None => None,
    };
    Ok(Some(DynamicPayloads { tfea, mlpw, life }))
}

/// Decode the time features (HEVC included) straight into the deformer's key- and
/// channel-major layout, and the decoders. Needs nothing of the canonical state, so the random
/// access decoder runs it alongside the residual.
pub(crate) fn decode_dynamic(
    scene: &SceneHeader,
    limits: &Limits,
    hevc: Option<&SharedKeyPictureDecoder>,
    p: &DynamicPayloads,
) -> Result<DynamicParts> {
    let features = decode_time_features(scene, limits, hevc, &p.tfea.0, p.tfea.1)?;
    let mlps = mlpw::decode(&p.mlpw.0, p.mlpw.1, scene, limits)?;
    let life = p
        .life
        .as_ref()
        .map(|(b, at)| life::decode(b, *at, scene, limits))
        .transpose()?;
    Ok((features, mlps, life))
}

/// Decode a `TFEA` payload (at file offset `at`) into the key- and channel-major layout; HEVC
/// through `hevc`. Both variants' dynamic sets use it.
pub(crate) fn decode_time_features(
    scene: &SceneHeader,
    limits: &Limits,
    hevc: Option<&SharedKeyPictureDecoder>,
    bytes: &[u8],
    at: u64,
) -> Result<PlanarFeatures> {
    Ok(match tfea::decode(bytes, at, scene, limits)? {
        TfeaBody::Exact(f) => PlanarFeatures::new(&f),
        TfeaBody::Quantised(q) => {
            PlanarFeatures::from_columns(q.n, q.keys, q.channels, q.columns())
        }
        TfeaBody::Hevc {
            tiling,
            ranges,
            reference: None,
            packets,
            intra: true,
        } => PlanarFeatures::per_key(
            tiling.n,
            tiling.keys,
            tiling.channels,
            Arc::new(IntraKeys {
                tiling,
                dequantise: Dequantise::Ranges(ranges),
                packets,
                at,
                hevc: hevc.cloned(),
            }),
        ),
        TfeaBody::Hevc {
            tiling,
            ranges,
            reference,
            packets,
            ..
        } => {
            // Streams whose output order can be read decode the keys a frame needs, when first
            // needed, from a prefix.
            let dequantise = match reference {
                Some(range) => Dequantise::Reference(range),
                None => Dequantise::Ranges(ranges.clone()),
            };
            let packets = match PrefixKeys::new(tiling, dequantise, packets, at, hevc.cloned()) {
                Ok(keys) => {
                    return Ok(PlanarFeatures::per_key(
                        tiling.n,
                        tiling.keys,
                        tiling.channels,
                        Arc::new(keys),
                    ))
                }
                Err(packets) => packets,
            };
            let refs: Vec<&[u8]> = packets.iter().map(|p| p.as_slice()).collect();
            let frames = key_pictures(hevc, &refs, &tiling, tiling.keys, at, false)?;
            let data = match reference {
                Some(range) => {
                    tfea::untile_columns(&frames, &tiling, tfea::reference_sample_value(range))
                }
                None => tfea::untile_columns(&frames, &tiling, tfea::sample_value(&ranges)),
            };
            PlanarFeatures::from_columns(tiling.n, tiling.keys, tiling.channels, data)
        }
    })
}

/// Intra-only HEVC time features (`TFEA` codec 3): packet `k` is key `k`'s picture alone.
struct IntraKeys {
    tiling: Tiling,
    dequantise: Dequantise,
    packets: Vec<Vec<u8>>,
    /// Offset of the `TFEA` payload, for errors.
    at: u64,
    hevc: Option<SharedKeyPictureDecoder>,
}

impl KeySource for IntraKeys {
    fn key(&self, k: usize) -> Result<Vec<f32>> {
        // Keys decode two at a time (a frame's pair), each on one thread.
        let frames = key_pictures(
            self.hevc.as_ref(),
            &[self.packets[k].as_slice()],
            &self.tiling,
            1,
            self.at,
            true,
        )?;
        Ok(self.dequantise.untile_key(&frames[0], &self.tiling))
    }
}

/// GOP `g` from its decoded canonical `state` and its decoded time features and decoders.
pub(crate) fn assemble(
    scene: &SceneHeader,
    g: u32,
    state: State,
    dynamic: Option<DynamicParts>,
) -> DecodedGop {
    let canonical = state.canonical;
    let deformer = dynamic.map(|(features, mlps, life)| {
        Deformer::from_planar(features, mlps, scene.deform_model).with_life(life)
    });
    DecodedGop {
        index: g,
        canonical,
        deformer,
        source: state.source,
        ntc: state.ntc,
    }
}
