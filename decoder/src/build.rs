//! Building decoded GOPs from a GOP's chunks, shared by the random-access [`crate::Decoder`]
//! and the in-order [`crate::stream::StreamDecoder`]: payloads come from a caller's closure.

use std::sync::Arc;

use dlgs::container::{ChunkInfo, ChunkType, SceneHeader};
use dlgs::model::DynamicGop;
use dlgs::payload::time_features::{self, TfeaBody};
use dlgs::payload::{
    decode_canonical, decode_residual, mlp_weights, CANONICAL_CHUNKS, RESIDUAL_CHUNKS,
};
use dlgs::{Error, ErrorKind, Limits, Result};

use crate::{DecodedGop, Deformer, State};

fn find(chunks: &[ChunkInfo], ty: ChunkType) -> Option<ChunkInfo> {
    chunks.iter().find(|c| c.ty == ty).copied()
}

fn video_error(e: dlgs_video::VideoError, at: u64) -> Error {
    Error::new(
        ErrorKind::Payload {
            chunk: ChunkType::TFEA,
            reason: e.to_string(),
        },
        at,
    )
}

/// Decode a GOP's canonical chunk, or apply its residual chunk to `base` (the reference GOP's
/// state; `None` for GOPs without a reference).
pub(crate) fn state(
    scene: &SceneHeader,
    limits: &Limits,
    chunks: &[ChunkInfo],
    gop_at: u64,
    base: Option<&State>,
    mut payload: impl FnMut(&ChunkInfo) -> Result<Vec<u8>>,
) -> Result<State> {
    let find_any = |set: &[ChunkType]| set.iter().find_map(|&ty| find(chunks, ty));
    let (canon, residual) = (find_any(&CANONICAL_CHUNKS), find_any(&RESIDUAL_CHUNKS));
    let Some(base) = base else {
        if let Some(c) = residual {
            return Err(Error::new(
                ErrorKind::Order("a residual chunk in a GOP without a reference GOP"),
                c.offset,
            ));
        }
        let c =
            canon.ok_or_else(|| Error::new(ErrorKind::MissingChunk(ChunkType::CRAW), gop_at))?;
        let p = payload(&c)?;
        let canonical = decode_canonical(c.ty, &p, c.payload_offset(), scene, limits)
            .expect("a canonical chunk type")?;
        return Ok(State {
            canonical: Arc::new(canonical),
            source: c.ty,
            ntc: None,
        });
    };
    if let Some(c) = canon {
        return Err(Error::new(
            ErrorKind::Order("a canonical chunk in a GOP that has a reference GOP"),
            c.offset,
        ));
    }
    let c = residual.ok_or_else(|| Error::new(ErrorKind::MissingChunk(ChunkType::RDLT), gop_at))?;
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

/// GOP `g` from its decoded canonical `state` and its time features and decoders.
pub(crate) fn gop(
    scene: &SceneHeader,
    limits: &Limits,
    g: u32,
    chunks: &[ChunkInfo],
    gop_at: u64,
    state: State,
    mut payload: impl FnMut(&ChunkInfo) -> Result<Vec<u8>>,
) -> Result<DecodedGop> {
    let mut dynamic = None;
    if scene.n_dynamic > 0 {
        let tfea = find(chunks, ChunkType::TFEA)
            .ok_or_else(|| Error::new(ErrorKind::MissingChunk(ChunkType::TFEA), gop_at))?;
        let mlpw = find(chunks, ChunkType::MLPW)
            .ok_or_else(|| Error::new(ErrorKind::MissingChunk(ChunkType::MLPW), gop_at))?;
        let p = payload(&tfea)?;
        let at = tfea.payload_offset();
        let features = match time_features::decode(&p, at, scene, limits)? {
            TfeaBody::Exact(f) => f,
            TfeaBody::Hevc {
                tiling,
                ranges,
                reference,
                packets,
            } => {
                let refs: Vec<&[u8]> = packets.iter().map(|p| p.as_slice()).collect();
                let video = dlgs_video::decode_gray12(
                    &refs,
                    tiling.width() as u32,
                    tiling.height() as u32,
                    tiling.keys,
                )
                .map_err(|e| video_error(e, at))?;
                match reference {
                    Some(range) => time_features::untile_reference(&video.frames, &tiling, range),
                    None => time_features::untile(&video.frames, &tiling, &ranges),
                }
            }
        };
        let p = payload(&mlpw)?;
        let mlps = mlp_weights::decode(&p, mlpw.payload_offset(), scene, limits)?;
        dynamic = Some(DynamicGop { features, mlps });
    }
    let canonical = state.canonical;
    let deformer = dynamic.map(|d| Deformer::new(&canonical.dynamics, d, scene.deform_model));
    Ok(DecodedGop {
        index: g,
        canonical,
        deformer,
        source: state.source,
        ntc: state.ntc,
    })
}
