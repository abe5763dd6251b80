//! The container's structural rules (format-spec §3.2, §3.3, §8.2) as an I/O-free core: both
//! readers ([`super::FileReader`] over `Read + Seek`, [`super::StreamReader`] over `Read`) hand
//! each chunk header they meet to these functions and only do the reading themselves, so a
//! rule is written once and both readers report the same error kind for the same fault.

use crate::container::chunk::{ChunkInfo, ChunkType, SCENE_LEVEL};
use crate::container::chunk_type::is_known_chunk;
use crate::error::{Error, FormatErrorKind, Result};
use crate::limits::Limits;

/// A chunk header's declared payload length against `max_chunk_len` (§8.2), checked before
/// anything is read or reserved.
pub(crate) fn check_len(info: &ChunkInfo, limits: &Limits) -> Result<()> {
    if info.len > limits.max_chunk_len {
        return Err(Error::limit(
            "chunk length",
            info.len,
            limits.max_chunk_len,
            info.offset + 12,
        ));
    }
    Ok(())
}

/// §3.3: the first chunk after the signature is the scene-level `HEAD`.
pub(crate) fn check_head(c: &ChunkInfo) -> Result<()> {
    if c.ty != ChunkType::HEAD || c.gop != SCENE_LEVEL {
        return Err(Error::format(
            FormatErrorKind::Order("the first chunk must be a scene-level HEAD"),
            c.offset,
        ));
    }
    Ok(())
}

/// Where in the body a chunk stands: before the first `GOPH`, or inside GOP `g`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Section {
    Scene,
    Gop(u32),
}

/// Counts the chunks of one section against its limit (§8.2).
#[derive(Debug)]
pub(crate) struct SectionRules {
    section: Section,
    count: u32,
}

impl SectionRules {
    pub(crate) fn new(section: Section) -> Self {
        SectionRules { section, count: 0 }
    }

    /// Admit a chunk of this section that is not a section boundary (`GOPH` of the next GOP,
    /// `GIDX`): its GOP number and type fit its place (§3.3), a must-understand chunk is known
    /// (§3.2), the section's chunk count stays within its limit (§8.2). Returns whether the
    /// chunk is known (unknown ancillary chunks are skipped by the caller).
    pub(crate) fn admit(&mut self, c: &ChunkInfo, limits: &Limits) -> Result<bool> {
        let structural = matches!(
            c.ty,
            ChunkType::HEAD | ChunkType::GOPH | ChunkType::GIDX | ChunkType::TAIL
        );
        let (gop, what, limit, order) = match self.section {
            Section::Scene => (
                SCENE_LEVEL,
                "scene-level chunks",
                limits.max_scene_chunks,
                "only scene-level chunks may precede the first GOPH",
            ),
            Section::Gop(g) => (
                g,
                "chunks per GOP",
                limits.max_chunks_per_gop,
                "a GOP may hold only payload chunks of its own GOP number",
            ),
        };
        if c.gop != gop || structural {
            return Err(Error::format(FormatErrorKind::Order(order), c.offset));
        }
        if c.must_understand() && !is_known_chunk(c.ty) {
            return Err(Error::format(
                FormatErrorKind::UnknownCriticalChunk(c.ty),
                c.offset,
            ));
        }
        self.count += 1;
        if self.count > limit {
            return Err(Error::limit(
                what,
                self.count as u64,
                limit as u64,
                c.offset,
            ));
        }
        Ok(is_known_chunk(c.ty))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::container::chunk::FLAG_MUST_UNDERSTAND;

    fn chunk(ty: &[u8; 4], flags: u16, gop: u32) -> ChunkInfo {
        ChunkInfo {
            ty: ChunkType(*ty),
            flags,
            gop,
            len: 0,
            offset: 100,
        }
    }

    #[test]
    fn sections_admit_their_own_chunks_and_count_them() {
        let limits = Limits {
            max_chunks_per_gop: 2,
            ..Limits::default()
        };
        let mut g = SectionRules::new(Section::Gop(3));
        assert!(g.admit(&chunk(b"CRAW", 1, 3), &limits).unwrap());
        assert!(
            !g.admit(&chunk(b"XTRA", 0, 3), &limits).unwrap(),
            "unknown ancillary"
        );
        let e = g.admit(&chunk(b"CRAW", 1, 3), &limits).unwrap_err();
        assert!(
            matches!(e, Error::Limit(crate::LimitError { value: 3, .. })),
            "{e}"
        );
        let mut g = SectionRules::new(Section::Gop(3));
        for bad in [
            chunk(b"CRAW", 1, 4),
            chunk(b"GOPH", 1, 3),
            chunk(b"TAIL", 1, 3),
        ] {
            assert!(matches!(
                g.admit(&bad, &limits).unwrap_err().format_kind(),
                Some(FormatErrorKind::Order(_))
            ));
        }
        let e = g
            .admit(&chunk(b"ZZZZ", FLAG_MUST_UNDERSTAND, 3), &limits)
            .unwrap_err();
        assert!(matches!(
            e.format_kind(),
            Some(FormatErrorKind::UnknownCriticalChunk(_))
        ));
        let mut s = SectionRules::new(Section::Scene);
        assert!(s.admit(&chunk(b"META", 0, SCENE_LEVEL), &limits).unwrap());
        assert!(s.admit(&chunk(b"META", 0, 0), &limits).is_err());
    }
}
