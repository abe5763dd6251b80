//! Payload codecs of the chunk types the container carries (format-spec §6 onwards).

pub mod adaptive_coder;
pub mod binary_bits;
pub mod binary_range_decoder;
pub mod bit_mixer;
pub mod colour_lattice;
pub mod delta_residual;
pub mod grid_coder;
pub mod grid_shaping;
pub mod half_range;
pub mod kd_layout;
pub mod lang_decoder;
pub mod mlp_weights;
pub mod ntc_residual;
pub mod octree_positions;
pub mod raw_canonical;
pub mod sorted_grid;
pub mod task_queue;
pub mod time_features;

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
        ChunkType::CRAW => Some(raw_canonical::decode(p, offset, scene, limits)),
        ChunkType::CSOG => Some(sorted_grid::decode(p, offset, scene, limits)),
        _ => None,
    }
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
            let field = ntc_residual::decode(p, offset, scene, limits)?;
            let next = field
                .apply(base)
                .map_err(|e| crate::Error::new(e.kind, offset))?;
            Ok((next, Some(field)))
        })()),
        ChunkType::RDLT => {
            Some(delta_residual::decode(p, offset, scene, limits).map(|d| (d.apply(base), None)))
        }
        _ => None,
    }
}
