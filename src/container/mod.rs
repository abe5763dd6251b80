//! The `.dlgs` container layer: signature, chunk framing, scene header, GOP index.
//! Byte-level description: format-spec/dlgs.md §2-§5.

pub mod chunk;
pub(crate) mod chunk_type;
pub mod gop;
pub mod header;
pub mod reader;
mod rules;
pub mod stream;
pub mod writer;

pub use chunk::{ChunkInfo, FLAG_MUST_UNDERSTAND, SCENE_LEVEL};
pub use chunk_type::{is_known_chunk, ChunkType, KNOWN_CHUNKS};
pub use gop::{GopHeader, GopIndex, IndexEntry, NO_REFERENCE};
pub use header::{DeformModel, ResidualMode, SceneHeader, Variant};
pub use reader::FileReader;
pub use stream::{StreamEvent, StreamReader};
pub use writer::Writer;
