//! `dlgs`: the `.dlgs` container format and scene model for streaming language-embedded
//! dynamic Gaussian splatting video (DLGStream).
//!
//! The byte-level specification is `format-spec/dlgs.md`; every reader here enforces it.
//! This crate has no FFI and no `unsafe`.
#![forbid(unsafe_code)]
// Decoding gives the same floats on every platform: no libm transcendental (clippy.toml), only
// `elementary`; encoder-side uses are allowed where they stand.
#![deny(clippy::disallowed_methods)]

pub mod bytes;
pub mod chunks;
pub mod container;
pub mod elementary;
pub mod entropy;
pub mod error;
pub mod interop;
pub mod limits;
pub mod model;
mod task_queue;

pub use container::{ChunkType, FileReader, SceneHeader, StreamReader, Writer};
pub use error::{
    Error, FormatError, FormatErrorKind, InputError, IoError, LimitError, RequestError, Result,
};
pub use limits::Limits;
pub use model::{Canonical, Gaussians};
