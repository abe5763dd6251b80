//! The payload of each chunk type (format-spec §6), one module per chunk code: `craw` (§6.1),
//! `tfea` (§6.2), `mlpw` (§6.3), `csog` (§6.5, with everything it is made of), `rntc` (§6.6),
//! `rdlt` (§6.7), `laed` (§6.8), `life` (§6.14); the Scaffold-GS variant's `ancr` (§6.9), `amlp` (§6.10) and
//! `adef` (§6.11), whose MLPs share `scaffold_layers`. The entropy coders they share are in
//! [`crate::entropy`].

pub mod adef;
pub mod ahac;
pub mod amlp;
pub mod ancr;
pub mod craw;
pub mod csog;
pub mod laed;
pub mod life;
pub mod mlpw;
pub mod rdlt;
pub mod rntc;
pub mod scaffold_layers;
pub mod tfea;
pub mod tfea_quantised;

use crate::container::{ChunkType, SceneHeader};
use crate::{Canonical, Limits, Result};

/// Chunk types that carry a GOP's canonical Gaussians, in the order a reader prefers them when
/// a GOP (wrongly) holds both (§6.5).
pub const CANONICAL_CHUNKS: [ChunkType; 2] = [ChunkType::CSOG, ChunkType::CRAW];

/// Chunk types that carry a GOP's canonical state as a residual against its reference GOP
/// (§6.6, §6.7).
pub const RESIDUAL_CHUNKS: [ChunkType; 2] = [ChunkType::RNTC, ChunkType::RDLT];

/// Decode a canonical chunk (`CRAW` §6.1 or `CSOG` §6.5) whose payload starts at `offset`;
/// `None` for any other chunk type.
pub fn decode_canonical(
    ty: ChunkType,
    p: &[u8],
    offset: u64,
    scene: &SceneHeader,
    limits: &Limits,
) -> Option<Result<Canonical>> {
    match ty {
        ChunkType::CRAW => Some(craw::decode(p, offset, scene, limits)),
        ChunkType::CSOG => Some(csog::decode(p, offset, scene, limits)),
        _ => None,
    }
    .map(|r| r.map_err(|e| e.in_chunk(ty)))
}

/// Decode a residual chunk (`RNTC` §6.6 or `RDLT` §6.7) whose payload starts at `offset` and
/// apply it to the reference GOP's state `base`; also returns the binary voxel field for `RNTC`.
/// `None` for any other chunk type.
pub fn decode_residual(
    ty: ChunkType,
    p: &[u8],
    offset: u64,
    scene: &SceneHeader,
    limits: &Limits,
    base: &Canonical,
) -> Option<Result<(Canonical, Option<crate::model::ntc::NtcField>)>> {
    match ty {
        ChunkType::RNTC => Some((|| {
            let field = rntc::decode(p, offset, scene, limits)?;
            let next = field.apply(base).map_err(|e| match e {
                // The residual names groups or sets the scene lacks: the file is at fault.
                crate::Error::Input(i) => crate::Error::payload(ty, i.message, offset),
                e => e,
            })?;
            Ok((next, Some(field)))
        })()),
        ChunkType::RDLT => {
            Some(rdlt::decode(p, offset, scene, limits).map(|d| (d.apply(base), None)))
        }
        _ => None,
    }
    .map(|r| r.map_err(|e| e.in_chunk(ty)))
}
