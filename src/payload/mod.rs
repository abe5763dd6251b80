//! Payload codecs of the chunk types the container carries (format-spec §6 onwards).

pub mod grid_coder;
pub mod mlp_weights;
pub mod raw_canonical;
pub mod sorted_grid;
pub mod time_features;

use crate::container::{ChunkType, SceneHeader};
use crate::{Canonical, Limits, Result};

/// Chunk types that carry a GOP's canonical Gaussians, in the order a reader prefers them when
/// a GOP (wrongly) holds both (§6.5).
pub const CANONICAL_CHUNKS: [ChunkType; 2] = [ChunkType::CSOG, ChunkType::CRAW];

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
        ChunkType::CRAW => Some(raw_canonical::decode(p, offset, scene, limits)),
        ChunkType::CSOG => Some(sorted_grid::decode(p, offset, scene, limits)),
        _ => None,
    }
}
