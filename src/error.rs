//! Errors typed by who is at fault, each saying what is wrong and where.
//!
//! - [`FormatError`]: the bytes break the spec (a `.dlgs` or foreign splat file is at fault);
//!   its [`FormatErrorKind`] names the spec section it enforces, with the byte offset and, inside
//!   a chunk, the chunk's type.
//! - [`LimitError`]: a declared size passes the reader's [`crate::Limits`] budget (the file may
//!   be valid; the reader was told not to spend that much).
//! - [`IoError`]: the operating system failed a read or write; its source is kept.
//! - [`RequestError`]: the caller asked for something the file does not have or passed a bad
//!   parameter (GOP 9 of 5, a time outside the stream).
//! - [`InputError`]: the encoder was given data it refuses to write (NaN, mismatched lengths).
//! - [`Error::NoHevcDecoder`]: a capability this build lacks.

use std::fmt;
use std::sync::Arc;

use crate::container::chunk_type::ChunkType;

/// What is wrong with the bytes of a `.dlgs` (or foreign splat) file.
///
/// Every variant names the spec section it enforces (format-spec/dlgs.md).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum FormatErrorKind {
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
}

impl FormatErrorKind {
    /// A short stable name, used by conformance vectors (`expected-errors.txt`).
    pub fn name(&self) -> &'static str {
        match self {
            FormatErrorKind::BadMagic => "BadMagic",
            FormatErrorKind::UnsupportedVersion { .. } => "UnsupportedVersion",
            FormatErrorKind::Truncated { .. } => "Truncated",
            FormatErrorKind::HeaderCrc { .. } => "HeaderCrc",
            FormatErrorKind::PayloadCrc { .. } => "PayloadCrc",
            FormatErrorKind::InvalidChunkType(_) => "InvalidChunkType",
            FormatErrorKind::UnknownCriticalChunk(_) => "UnknownCriticalChunk",
            FormatErrorKind::Order(_) => "Order",
            FormatErrorKind::MissingChunk(_) => "MissingChunk",
            FormatErrorKind::InvalidField { .. } => "InvalidField",
            FormatErrorKind::NonFinite { .. } => "NonFinite",
            FormatErrorKind::Index(_) => "Index",
            FormatErrorKind::Payload { .. } => "Payload",
            FormatErrorKind::Decompress(_) => "Decompress",
            FormatErrorKind::Foreign { .. } => "Foreign",
        }
    }
}

/// The file is at fault: what is wrong, at which absolute byte, and in which chunk.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FormatError {
    pub kind: FormatErrorKind,
    /// Absolute byte offset in the file (or stream) where the problem was detected.
    pub offset: u64,
    /// The chunk being decoded, when the fault is inside one.
    pub chunk: Option<ChunkType>,
}

impl fmt::Display for FormatError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (&self.kind, self.chunk) {
            // These already name their chunk.
            (FormatErrorKind::Payload { .. } | FormatErrorKind::PayloadCrc { .. }, _)
            | (_, None) => {
                write!(f, "{} (at byte {})", self.kind, self.offset)
            }
            (kind, Some(chunk)) => write!(f, "{chunk}: {kind} (at byte {})", self.offset),
        }
    }
}

/// A declared size passes the reader's budget ([`crate::Limits`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LimitError {
    pub what: &'static str,
    pub value: u64,
    pub limit: u64,
    /// Where the size was declared.
    pub offset: u64,
}

impl fmt::Display for LimitError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "limit exceeded: {} = {} > {} (at byte {})",
            self.what, self.value, self.limit, self.offset
        )
    }
}

/// The operating system failed a read or write: what was being done, and its error (the
/// [`std::error::Error::source`]); shared so errors stay `Clone`. Two are equal when their
/// `what`, offset, kind and message are.
#[derive(Debug, Clone)]
pub struct IoError {
    pub what: String,
    pub source: Arc<std::io::Error>,
    pub offset: u64,
}

impl PartialEq for IoError {
    fn eq(&self, o: &Self) -> bool {
        self.what == o.what
            && self.offset == o.offset
            && self.source.kind() == o.source.kind()
            && self.source.to_string() == o.source.to_string()
    }
}

impl Eq for IoError {}

impl fmt::Display for IoError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "I/O: {}: {}", self.what, self.source)
    }
}

/// The caller asked for something the file does not have, or passed a bad parameter.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RequestError {
    pub message: String,
}

/// The encoder was given data it refuses to write.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InputError {
    pub message: String,
}

/// Every error of the crate, by who is at fault.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The bytes break the spec.
    #[error("{0}")]
    Format(FormatError),
    /// A declared size passes the reader's [`crate::Limits`].
    #[error("{0}")]
    Limit(LimitError),
    /// The operating system failed a read or write.
    #[error("{0}")]
    Io(#[source] IoError),
    /// A bad request or parameter from the caller.
    #[error("request: {}", .0.message)]
    Request(RequestError),
    /// Data the encoder refuses to write.
    #[error("invalid input: {}", .0.message)]
    Input(InputError),
    /// The time features are HEVC (§6.2, `TFEA` codecs 1-3) and the decoder was built without
    /// one (`dlgs-decoder` without its `hevc` feature) and given none.
    #[error(
        "the time features are HEVC and this decoder has no HEVC decoder (build dlgs-decoder \
         with its `hevc` feature, or set a key-picture decoder)"
    )]
    NoHevcDecoder,
}

impl std::error::Error for IoError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        Some(self.source.as_ref())
    }
}

impl Error {
    /// A file fault of `kind` found at byte `offset`.
    pub fn format(kind: FormatErrorKind, offset: u64) -> Error {
        Error::Format(FormatError {
            kind,
            offset,
            chunk: None,
        })
    }
    /// §3-§6: a payload of `chunk` is malformed (`reason`), found at byte `offset`.
    pub fn payload(chunk: ChunkType, reason: impl Into<String>, offset: u64) -> Error {
        Error::format(
            FormatErrorKind::Payload {
                chunk,
                reason: reason.into(),
            },
            offset,
        )
    }
    /// A foreign splat file of `format` (PLY, SPZ, ...) is malformed.
    pub fn foreign(format: &'static str, reason: impl Into<String>) -> Error {
        Error::format(
            FormatErrorKind::Foreign {
                format,
                reason: reason.into(),
            },
            0,
        )
    }
    /// `what` at byte `offset` declares `value`, more than the budget's `limit`.
    pub fn limit(what: &'static str, value: u64, limit: u64, offset: u64) -> Error {
        Error::Limit(LimitError {
            what,
            value,
            limit,
            offset,
        })
    }
    /// An I/O failure while doing `what` (e.g. "reading scene.ply"), keeping its source.
    pub fn io(what: impl Into<String>, source: std::io::Error, offset: u64) -> Error {
        Error::Io(IoError {
            what: what.into(),
            source: Arc::new(source),
            offset,
        })
    }
    /// The caller asked for something the file does not have.
    pub fn request(message: impl Into<String>) -> Error {
        Error::Request(RequestError {
            message: message.into(),
        })
    }
    /// The encoder refuses its input.
    pub fn input(message: impl Into<String>) -> Error {
        Error::Input(InputError {
            message: message.into(),
        })
    }

    /// The file fault, if the file is at fault.
    pub fn format_kind(&self) -> Option<&FormatErrorKind> {
        match self {
            Error::Format(f) => Some(&f.kind),
            _ => None,
        }
    }
    /// The byte where the problem was found, for faults tied to a place in the input.
    pub fn offset(&self) -> Option<u64> {
        match self {
            Error::Format(f) => Some(f.offset),
            Error::Limit(l) => Some(l.offset),
            Error::Io(i) => Some(i.offset),
            _ => None,
        }
    }
    /// The same error found inside `chunk` (kept if one is already named); others unchanged.
    pub fn in_chunk(self, chunk: ChunkType) -> Error {
        match self {
            Error::Format(mut f) => {
                f.chunk.get_or_insert(chunk);
                Error::Format(f)
            }
            e => e,
        }
    }
    /// A short stable name for the error, used by conformance vectors: the file fault's kind
    /// (`Truncated`, `Payload`, ...) or `LimitExceeded`, `Io`, `Request`, `InvalidInput`,
    /// `NoHevcDecoder`.
    pub fn name(&self) -> &'static str {
        match self {
            Error::Format(f) => f.kind.name(),
            Error::Limit(_) => "LimitExceeded",
            Error::Io(_) => "Io",
            Error::Request(_) => "Request",
            Error::Input(_) => "InvalidInput",
            Error::NoHevcDecoder => "NoHevcDecoder",
        }
    }
}

pub type Result<T> = std::result::Result<T, Error>;

/// Turn an `io::Error` at `offset` into our error; an unexpected EOF is a truncation.
pub(crate) fn io_err(e: std::io::Error, offset: u64, what: &'static str) -> Error {
    if e.kind() == std::io::ErrorKind::UnexpectedEof {
        Error::format(
            FormatErrorKind::Truncated {
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
    use super::*;

    #[test]
    fn io_errors_keep_their_source_and_say_what_failed() {
        let missing = std::path::Path::new("/nonexistent/dlgs-scene.ply");
        let e = crate::interop::read_splat_file(missing).unwrap_err();
        assert_eq!(e.name(), "Io");
        assert!(e.to_string().contains("dlgs-scene.ply"), "{e}");
        let source = std::error::Error::source(&e).expect("the IoError");
        let io = std::error::Error::source(source)
            .and_then(|s| s.downcast_ref::<std::io::Error>())
            .expect("an io::Error behind it");
        assert_eq!(io.kind(), std::io::ErrorKind::NotFound);
        assert_eq!(e.clone(), e, "errors stay comparable");
    }

    #[test]
    fn a_fault_inside_a_chunk_names_the_chunk_and_the_byte() {
        let e = Error::format(FormatErrorKind::Index("x"), 77).in_chunk(ChunkType::TFEA);
        assert_eq!(e.to_string(), "TFEA: GOP index: x (at byte 77)");
        assert_eq!(e.offset(), Some(77));
        assert_eq!(e.name(), "Index");
        let p = Error::payload(ChunkType::MLPW, "bad", 5).in_chunk(ChunkType::TFEA);
        assert_eq!(p.to_string(), "invalid MLPW payload: bad (at byte 5)");
        assert_eq!(Error::request("GOP 9 of 5").offset(), None);
        assert_eq!(Error::limit("n", 3, 2, 9).name(), "LimitExceeded");
    }
}
