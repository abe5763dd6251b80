//! The `.dlgs` container layer: signature, chunk framing, scene header, GOP index.
//! Byte-level description: format-spec/dlgs.md §2-§5.

pub mod chunk;
pub mod gop;
pub mod header;
pub mod reader;
pub mod stream;
pub mod writer;

pub use chunk::{ChunkInfo, ChunkType, FLAG_MUST_UNDERSTAND, SCENE_LEVEL};
pub use gop::{GopHeader, GopIndex, IndexEntry, NO_REFERENCE};
pub use header::{DeformModel, ResidualMode, SceneHeader, Variant};
pub use reader::FileReader;
pub use stream::{StreamEvent, StreamReader};
pub use writer::Writer;

/// Chunk types this version of the library understands (§3.4, chunk catalogue).
pub const KNOWN_CHUNKS: &[ChunkType] = &[
    ChunkType::HEAD,
    ChunkType::META,
    ChunkType::GOPH,
    ChunkType::GIDX,
    ChunkType::TAIL,
    ChunkType::CRAW,
    ChunkType::TFEA,
    ChunkType::MLPW,
    ChunkType::CSOG,
    ChunkType::RNTC,
    ChunkType::RDLT,
    ChunkType::LAED,
];

pub fn is_known_chunk(t: ChunkType) -> bool {
    KNOWN_CHUNKS.contains(&t)
}
