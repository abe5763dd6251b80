//! Chunk type codes (format-spec §3.1) and the catalogue of those this version understands
//! (§3.4). Depends on nothing else in the crate, so errors can name a chunk.

use std::fmt;

/// A four-byte chunk type, e.g. `HEAD`. Bytes are ASCII letters, digits, or space.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ChunkType(pub [u8; 4]);

impl ChunkType {
    pub const HEAD: ChunkType = ChunkType(*b"HEAD");
    pub const META: ChunkType = ChunkType(*b"META");
    pub const GOPH: ChunkType = ChunkType(*b"GOPH");
    pub const GIDX: ChunkType = ChunkType(*b"GIDX");
    pub const TAIL: ChunkType = ChunkType(*b"TAIL");
    /// Raw (uncompressed-float) canonical Gaussians, §6.1.
    pub const CRAW: ChunkType = ChunkType(*b"CRAW");
    pub const TFEA: ChunkType = ChunkType(*b"TFEA");
    pub const MLPW: ChunkType = ChunkType(*b"MLPW");
    /// Canonical Gaussians as quantised, sorted attribute grids, §6.5.
    pub const CSOG: ChunkType = ChunkType(*b"CSOG");
    /// Binary-voxel residual field against the reference GOP, §6.6.
    pub const RNTC: ChunkType = ChunkType(*b"RNTC");
    /// Explicit quantised per-attribute residual against the reference GOP, §6.7.
    pub const RDLT: ChunkType = ChunkType(*b"RDLT");
    /// Language autoencoder decoder and canonical negatives, for queries, §6.8.
    pub const LAED: ChunkType = ChunkType(*b"LAED");
    /// Raw canonical anchors of a Scaffold-GS GOP, §6.9.
    pub const ANCR: ChunkType = ChunkType(*b"ANCR");
    /// View-dependent MLPs of a Scaffold-GS GOP, §6.10.
    pub const AMLP: ChunkType = ChunkType(*b"AMLP");
    /// Anchor deformation MLPs and box of a Scaffold-GS GOP, §6.11.
    pub const ADEF: ChunkType = ChunkType(*b"ADEF");
    /// Canonical anchors of a Scaffold-GS GOP, HAC-coded, §6.13.
    pub const AHAC: ChunkType = ChunkType(*b"AHAC");
    /// The frames at which each dynamic Gaussian of a GOP is shown, §6.14.
    pub const LIFE: ChunkType = ChunkType(*b"LIFE");

    pub fn is_valid(bytes: [u8; 4]) -> bool {
        bytes
            .iter()
            .all(|b| b.is_ascii_alphanumeric() || *b == b' ')
    }
    pub fn as_str(&self) -> &str {
        std::str::from_utf8(&self.0).unwrap_or("????")
    }
}

impl fmt::Display for ChunkType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl fmt::Debug for ChunkType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "ChunkType({})", self.as_str())
    }
}

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
    ChunkType::ANCR,
    ChunkType::AMLP,
    ChunkType::ADEF,
    ChunkType::AHAC,
    ChunkType::LIFE,
];

pub fn is_known_chunk(t: ChunkType) -> bool {
    KNOWN_CHUNKS.contains(&t)
}
