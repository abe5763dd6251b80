//! One error type for every parser in the crate: what is wrong, and at which byte.

use std::fmt;

use crate::container::chunk_type::ChunkType;

/// What went wrong while reading or writing `.dlgs` (or a foreign splat file).
///
/// Every variant names the spec section it enforces (format-spec/dlgs.md).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ErrorKind {
    /// §2: the file does not start with the 8-byte `.dlgs` magic.
    #[error("not a .dlgs file (bad magic)")]
    BadMagic,
    /// §2: major version this reader does not implement.
    #[error("unsupported version {major}.{minor}")]
    UnsupportedVersion { major: u16, minor: u16 },
    /// Fewer bytes are present than a structure declares.
    #[error("truncated: {what} needs {needed} bytes, {available} available")]
    Truncated {
        what: &'static str,
        needed: u64,
        available: u64,
    },
    /// §3: the CRC-32C of a chunk header does not match.
    #[error("chunk header CRC mismatch (stored {stored:#010x}, computed {computed:#010x})")]
    HeaderCrc { stored: u32, computed: u32 },
    /// §3: the CRC-32C of a chunk payload does not match.
    #[error(
        "payload CRC mismatch in chunk {chunk} (stored {stored:#010x}, computed {computed:#010x})"
    )]
    PayloadCrc {
        chunk: ChunkType,
        stored: u32,
        computed: u32,
    },
    /// §3: chunk type bytes are not in the allowed alphabet.
    #[error("invalid chunk type bytes {0:02x?}")]
    InvalidChunkType([u8; 4]),
    /// §3.2: a chunk marked must-understand that this reader does not know.
    #[error("unknown must-understand chunk {0}")]
    UnknownCriticalChunk(ChunkType),
    /// §3.3: chunks are not in the order the spec requires.
    #[error("chunk order: {0}")]
    Order(&'static str),
    /// A required chunk is absent.
    #[error("missing chunk {0}")]
    MissingChunk(ChunkType),
    /// A field holds a value outside its allowed range.
    #[error("field {field} = {value}: {reason}")]
    InvalidField {
        field: &'static str,
        value: u64,
        reason: &'static str,
    },
    /// A float field is NaN or infinite where the spec requires a finite value.
    #[error("field {field} is not finite")]
    NonFinite { field: &'static str },
    /// A declared size exceeds a configured limit (see [`crate::Limits`]).
    #[error("limit exceeded: {what} = {value} > {limit}")]
    LimitExceeded {
        what: &'static str,
        value: u64,
        limit: u64,
    },
    /// §5: the GOP index disagrees with the chunks it points to.
    #[error("GOP index: {0}")]
    Index(&'static str),
    /// A payload is malformed in a way specific to its chunk type.
    #[error("invalid {chunk} payload: {reason}")]
    Payload { chunk: ChunkType, reason: String },
    /// A compressed stream failed to decompress or had the wrong size.
    #[error("decompression failed: {0}")]
    Decompress(String),
    /// A foreign splat file (PLY, .splat, SPZ, SOG) is malformed.
    #[error("{format}: {reason}")]
    Foreign {
        format: &'static str,
        reason: String,
    },
    /// An I/O error from the underlying reader or writer: what was being done, and the
    /// operating system's error itself (`std::error::Error::source` of [`Error`]).
    #[error("I/O: {what}: {source}")]
    Io { what: String, source: IoSource },
    /// The caller asked for something the file does not have (e.g. GOP 9 of 5).
    #[error("request: {0}")]
    Request(String),
    /// The encoder was given input it refuses to write (e.g. NaN).
    #[error("invalid input: {0}")]
    InvalidInput(String),
    /// The file's time features are HEVC (§6.2, `TFEA` codecs 1-3) and the decoder was built
    /// without one (`dlgs-decoder` without its `hevc` feature) and given none.
    #[error(
        "the time features are HEVC and this decoder has no HEVC decoder (build dlgs-decoder \
         with its `hevc` feature, or set a key-picture decoder)"
    )]
    NoHevcDecoder,
}

/// An [`ErrorKind`] plus the absolute byte offset where it was found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Error {
    pub kind: ErrorKind,
    /// Absolute byte offset in the file (or stream) where the problem was detected.
    pub offset: u64,
}

impl Error {
    pub fn new(kind: ErrorKind, offset: u64) -> Self {
        Error { kind, offset }
    }
    pub fn kind(&self) -> &ErrorKind {
        &self.kind
    }
    /// A short stable name for the error kind, used by conformance vectors.
    pub fn name(&self) -> &'static str {
        match &self.kind {
            ErrorKind::BadMagic => "BadMagic",
            ErrorKind::UnsupportedVersion { .. } => "UnsupportedVersion",
            ErrorKind::Truncated { .. } => "Truncated",
            ErrorKind::HeaderCrc { .. } => "HeaderCrc",
            ErrorKind::PayloadCrc { .. } => "PayloadCrc",
            ErrorKind::InvalidChunkType(_) => "InvalidChunkType",
            ErrorKind::UnknownCriticalChunk(_) => "UnknownCriticalChunk",
            ErrorKind::Order(_) => "Order",
            ErrorKind::MissingChunk(_) => "MissingChunk",
            ErrorKind::InvalidField { .. } => "InvalidField",
            ErrorKind::NonFinite { .. } => "NonFinite",
            ErrorKind::LimitExceeded { .. } => "LimitExceeded",
            ErrorKind::Index(_) => "Index",
            ErrorKind::Payload { .. } => "Payload",
            ErrorKind::Decompress(_) => "Decompress",
            ErrorKind::Foreign { .. } => "Foreign",
            ErrorKind::Io { .. } => "Io",
            ErrorKind::Request(_) => "Request",
            ErrorKind::InvalidInput(_) => "InvalidInput",
            ErrorKind::NoHevcDecoder => "NoHevcDecoder",
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} (at byte {})", self.kind, self.offset)
    }
}

impl std::error::Error for Error {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match &self.kind {
            ErrorKind::Io { source, .. } => Some(source.0.as_ref()),
            _ => None,
        }
    }
}

/// The `std::io::Error` behind [`ErrorKind::Io`], shared so errors stay `Clone`; two are equal
/// when their kind and message are.
#[derive(Debug, Clone)]
pub struct IoSource(pub std::sync::Arc<std::io::Error>);

impl PartialEq for IoSource {
    fn eq(&self, other: &Self) -> bool {
        self.0.kind() == other.0.kind() && self.0.to_string() == other.0.to_string()
    }
}

impl Eq for IoSource {}

impl std::error::Error for IoSource {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        Some(self.0.as_ref())
    }
}

impl fmt::Display for IoSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.0.fmt(f)
    }
}

impl Error {
    /// An I/O failure while doing `what` (e.g. "reading scene.ply"), keeping its source.
    pub fn io(what: impl Into<String>, source: std::io::Error, offset: u64) -> Error {
        Error::new(
            ErrorKind::Io {
                what: what.into(),
                source: IoSource(std::sync::Arc::new(source)),
            },
            offset,
        )
    }
}

pub type Result<T> = std::result::Result<T, Error>;

/// Turn an `io::Error` at `offset` into our error; an unexpected EOF is a truncation.
pub(crate) fn io_err(e: std::io::Error, offset: u64, what: &'static str) -> Error {
    if e.kind() == std::io::ErrorKind::UnexpectedEof {
        Error::new(
            ErrorKind::Truncated {
                what,
                needed: 0,
                available: 0,
            },
            offset,
        )
    } else {
        Error::io(what, e, offset)
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn io_errors_keep_their_source_and_say_what_failed() {
        let missing = std::path::Path::new("/nonexistent/dlgs-scene.ply");
        let e = crate::interop::read_splat_file(missing).unwrap_err();
        assert_eq!(e.name(), "Io");
        assert!(e.to_string().contains("dlgs-scene.ply"), "{e}");
        let source = std::error::Error::source(&e).expect("the io::Error");
        let io = source
            .downcast_ref::<std::io::Error>()
            .expect("an io::Error");
        assert_eq!(io.kind(), std::io::ErrorKind::NotFound);
        assert_eq!(e.clone(), e, "errors stay comparable");
    }
}
