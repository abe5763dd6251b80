//! The container's structural rules (format-spec §3.2, §3.3, §8.2) as an I/O-free core: both
//! readers ([`super::FileReader`] over `Read + Seek`, [`super::StreamReader`] over `Read`) hand
//! each chunk header they meet to these functions and only do the reading themselves, so a
//! rule is written once and both readers report the same error kind for the same fault. Every
//! decoder (3DGS and Scaffold-GS, random access and streaming) gets a GOP's chunks from one of
//! the two readers, so the GOP chunk rules of §3.3 (which types a GOP may hold, each at most
//! once, in which order) hold for all of them.

use crate::container::chunk::{ChunkInfo, ChunkType, SCENE_LEVEL};
use crate::container::chunk_type::is_known_chunk;
use crate::container::gop::{GopHeader, NO_REFERENCE};
use crate::container::header::{SceneHeader, Variant};
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

/// Where in the body a chunk stands: before the first `GOPH`, or inside GOP `g` (of this kind).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Section {
    Scene,
    Gop(u32, GopKind),
}

/// What decides which chunks a GOP may hold (§3.3): the file's variant, whether the scene has
/// dynamic Gaussians (anchors), whether the GOP has a reference GOP.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct GopKind {
    pub scaffold: bool,
    pub dynamic: bool,
    pub intra: bool,
}

impl GopKind {
    /// GOP of `scene` whose (checked) `GOPH` is `gh`.
    pub(crate) fn of(scene: &SceneHeader, gh: &GopHeader) -> Self {
        GopKind {
            scaffold: scene.variant == Variant::Scaffold,
            dynamic: scene.n_dynamic > 0,
            intra: gh.reference_gop == NO_REFERENCE,
        }
    }
}

/// Known chunk types that belong to the scene, not to a GOP (§3.4; `HEAD`, `GIDX`, `TAIL` are
/// structural and refused everywhere else on their own).
const SCENE_TYPES: [ChunkType; 2] = [ChunkType::META, ChunkType::LAED];

/// The place of a known, non-structural chunk type in a GOP of `kind` (§3.3): `Ok(Some(rank))`
/// for a chunk the GOP uses (ranks must not decrease along the GOP), `Ok(None)` for one its
/// readers ignore (the 3DGS chunks of a Scaffold-GS file and an `RNTC` in its intra GOPs, §6.9,
/// as since 1.16/1.17), `Err(why)` for one the GOP cannot hold (`Order`).
fn gop_place(kind: GopKind, ty: ChunkType) -> std::result::Result<Option<u8>, &'static str> {
    use ChunkType as T;
    if SCENE_TYPES.contains(&ty) {
        return Err("a scene-level chunk type inside a GOP");
    }
    if kind.scaffold {
        return match ty {
            T::ANCR | T::AHAC if kind.intra => Ok(Some(0)),
            T::ANCR | T::AHAC => Err("a residual Scaffold-GS GOP holds RNTC, not ANCR or AHAC"),
            T::RNTC if kind.intra => Ok(None),
            T::RNTC => Ok(Some(0)),
            T::AMLP => Ok(Some(1)),
            T::ADEF | T::TFEA if !kind.dynamic => {
                Err("ADEF and TFEA in a scene without dynamic anchors (HEAD.n_dynamic 0)")
            }
            T::ADEF => Ok(Some(2)),
            T::TFEA => Ok(Some(3)),
            T::LIFE => Err("LIFE in a Scaffold-GS file (it is defined for HEAD.variant 0)"),
            // CRAW, CSOG, MLPW, RDLT: no meaning in a variant-1 file; ignored.
            _ => Ok(None),
        };
    }
    match ty {
        T::CRAW | T::CSOG if kind.intra => Ok(Some(0)),
        T::CRAW | T::CSOG => Err("a canonical chunk in a GOP that has a reference GOP"),
        T::RNTC | T::RDLT if kind.intra => Err("a residual chunk in a GOP without a reference GOP"),
        T::RNTC | T::RDLT => Ok(Some(0)),
        T::TFEA | T::MLPW | T::LIFE if !kind.dynamic => {
            Err("TFEA, MLPW and LIFE in a scene without dynamic Gaussians (HEAD.n_dynamic 0)")
        }
        T::TFEA => Ok(Some(1)),
        T::MLPW => Ok(Some(2)),
        T::LIFE => Ok(Some(3)),
        // ANCR, AMLP, ADEF, AHAC.
        _ => Err("a Scaffold-GS chunk in a 3DGS file (HEAD.variant 0)"),
    }
}

/// Counts the chunks of one section against its limit (§8.2) and, in a GOP, checks each known
/// chunk's type, count and place (§3.3).
#[derive(Debug)]
pub(crate) struct SectionRules {
    section: Section,
    count: u32,
    /// The known chunk types this GOP uses so far, and the highest rank among them.
    used: Vec<ChunkType>,
    rank: u8,
}

impl SectionRules {
    pub(crate) fn new(section: Section) -> Self {
        SectionRules {
            section,
            count: 0,
            used: Vec::new(),
            rank: 0,
        }
    }

    /// §3.3 for a known chunk `c` of this section: a GOP-level type before the first `GOPH`,
    /// or in GOP of `kind` a type it cannot hold, a second chunk of a type, a second residual
    /// chunk, or a chunk after one that must follow it: `Order`, naming the chunk.
    fn place(&mut self, c: &ChunkInfo) -> Result<()> {
        let order = |why: &'static str| {
            Err(Error::format(FormatErrorKind::Order(why), c.offset).in_chunk(c.ty))
        };
        let kind = match self.section {
            Section::Scene if SCENE_TYPES.contains(&c.ty) => return Ok(()),
            Section::Scene => return order("a GOP chunk type among the scene-level chunks"),
            Section::Gop(_, kind) => kind,
        };
        let rank = match gop_place(kind, c.ty) {
            Err(why) => return order(why),
            Ok(None) => return Ok(()),
            Ok(Some(rank)) => rank,
        };
        if self.used.contains(&c.ty) {
            return order("a second chunk of a type a GOP holds at most once");
        }
        let residual = [ChunkType::RNTC, ChunkType::RDLT];
        if residual.contains(&c.ty) && self.used.iter().any(|t| residual.contains(t)) {
            return order("a second residual chunk (a GOP holds one RNTC or one RDLT)");
        }
        if rank < self.rank {
            return order(if kind.scaffold {
                "after a chunk it must precede (a Scaffold-GS GOP holds ANCR, AHAC or RNTC, then \
                 AMLP, ADEF, TFEA)"
            } else {
                "after a chunk it must precede (a GOP holds its canonical or residual chunk, then \
                 TFEA, MLPW, LIFE)"
            });
        }
        self.used.push(c.ty);
        self.rank = rank;
        Ok(())
    }

    /// Admit a chunk of this section that is not a section boundary (`GOPH` of the next GOP,
    /// `GIDX`): its GOP number and type fit its place (§3.3), a must-understand chunk is known
    /// (§3.2), the section's chunk count stays within its limit (§8.2), a known chunk's type,
    /// count and order fit the section (§3.3, [`Self::place`]). Returns whether the chunk is
    /// known (unknown ancillary chunks are skipped by the caller and take no part in §3.3's
    /// GOP rules).
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
            Section::Gop(g, _) => (
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
        if !is_known_chunk(c.ty) {
            return Ok(false);
        }
        self.place(c)?;
        Ok(true)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::container::chunk::FLAG_MUST_UNDERSTAND;

    /// An intra GOP of a 3DGS scene with dynamic Gaussians.
    const INTRA: GopKind = GopKind {
        scaffold: false,
        dynamic: true,
        intra: true,
    };

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
        let mut g = SectionRules::new(Section::Gop(3, INTRA));
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
        let mut g = SectionRules::new(Section::Gop(3, INTRA));
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

    /// Admit `types` (GOP 0; known ones must-understand, unknown ones ancillary) into one GOP
    /// of `kind`: `Ok` or the first error's chunk type and message.
    fn gop(kind: GopKind, types: &[&[u8; 4]]) -> std::result::Result<(), (ChunkType, String)> {
        let mut rules = SectionRules::new(Section::Gop(0, kind));
        for (k, ty) in types.iter().enumerate() {
            let flags = is_known_chunk(ChunkType(**ty)) as u16 * FLAG_MUST_UNDERSTAND;
            let mut c = chunk(ty, flags, 0);
            c.offset = 1000 + k as u64;
            if let Err(e) = rules.admit(&c, &Limits::default()) {
                let Error::Format(f) = &e else { panic!("{e}") };
                assert!(matches!(f.kind, FormatErrorKind::Order(_)), "{e}");
                assert_eq!((f.chunk, f.offset), (Some(c.ty), c.offset), "{e}");
                return Err((c.ty, e.to_string()));
            }
        }
        Ok(())
    }

    #[test]
    fn a_gop_holds_each_chunk_once_in_order_and_only_what_its_scene_uses() {
        let residual = GopKind {
            intra: false,
            ..INTRA
        };
        let still = GopKind {
            dynamic: false,
            ..INTRA
        };
        let scaffold = GopKind {
            scaffold: true,
            ..INTRA
        };
        let scaffold_residual = GopKind {
            intra: false,
            ..scaffold
        };
        let scaffold_still = GopKind {
            dynamic: false,
            ..scaffold
        };
        // What the writers write, with unknown ancillary chunks anywhere.
        gop(INTRA, &[b"CRAW", b"XTRA", b"TFEA", b"MLPW", b"LIFE"]).unwrap();
        gop(residual, &[b"RDLT", b"TFEA", b"MLPW"]).unwrap();
        gop(still, &[b"CSOG"]).unwrap();
        gop(scaffold, &[b"AHAC", b"AMLP", b"ADEF", b"TFEA"]).unwrap();
        gop(scaffold_residual, &[b"RNTC", b"ADEF", b"TFEA"]).unwrap();
        gop(scaffold_still, &[b"ANCR", b"AMLP"]).unwrap();
        // Kept (§6.5, §6.9): CSOG beside CRAW; ANCR beside AHAC (the decoder's Payload); the
        // 3DGS chunks of a Scaffold-GS file and an RNTC in its intra GOP are ignored.
        gop(INTRA, &[b"CSOG", b"CRAW", b"TFEA"]).unwrap();
        gop(scaffold, &[b"ANCR", b"AHAC", b"AMLP"]).unwrap();
        gop(
            scaffold,
            &[
                b"ANCR", b"MLPW", b"AMLP", b"CRAW", b"RNTC", b"RDLT", b"CSOG",
            ],
        )
        .unwrap();
        // Each fault: the chunk that makes it.
        let fails = |kind, types: &[&[u8; 4]], at: &[u8; 4], says: &str| {
            let (ty, msg) = gop(kind, types).unwrap_err();
            assert_eq!(ty, ChunkType(*at), "{msg}");
            assert!(msg.contains(says) && msg.contains(ty.as_str()), "{msg}");
        };
        fails(INTRA, &[b"CRAW", b"CRAW"], b"CRAW", "at most once");
        fails(INTRA, &[b"CSOG", b"TFEA", b"TFEA"], b"TFEA", "at most once");
        fails(
            INTRA,
            &[b"CRAW", b"TFEA", b"MLPW", b"MLPW"],
            b"MLPW",
            "at most once",
        );
        fails(
            INTRA,
            &[b"CRAW", b"TFEA", b"MLPW", b"LIFE", b"LIFE"],
            b"LIFE",
            "at most once",
        );
        fails(residual, &[b"RNTC", b"RDLT"], b"RDLT", "second residual");
        fails(residual, &[b"RNTC", b"RNTC"], b"RNTC", "at most once");
        fails(INTRA, &[b"CRAW", b"MLPW", b"TFEA"], b"TFEA", "must precede");
        fails(INTRA, &[b"TFEA", b"CRAW"], b"CRAW", "must precede");
        fails(
            INTRA,
            &[b"CRAW", b"TFEA", b"LIFE", b"MLPW"],
            b"MLPW",
            "must precede",
        );
        fails(
            INTRA,
            &[b"CRAW", b"RNTC"],
            b"RNTC",
            "without a reference GOP",
        );
        fails(residual, &[b"CSOG"], b"CSOG", "has a reference GOP");
        fails(
            still,
            &[b"CRAW", b"TFEA"],
            b"TFEA",
            "without dynamic Gaussians",
        );
        fails(
            still,
            &[b"CRAW", b"MLPW"],
            b"MLPW",
            "without dynamic Gaussians",
        );
        fails(
            still,
            &[b"CRAW", b"LIFE"],
            b"LIFE",
            "without dynamic Gaussians",
        );
        fails(INTRA, &[b"CRAW", b"ADEF"], b"ADEF", "Scaffold-GS chunk");
        fails(INTRA, &[b"CRAW", b"META"], b"META", "scene-level");
        fails(scaffold, &[b"ANCR", b"ANCR"], b"ANCR", "at most once");
        fails(
            scaffold,
            &[b"AHAC", b"AMLP", b"AMLP"],
            b"AMLP",
            "at most once",
        );
        fails(
            scaffold_residual,
            &[b"RNTC", b"RNTC"],
            b"RNTC",
            "at most once",
        );
        fails(
            scaffold_residual,
            &[b"RNTC", b"ANCR"],
            b"ANCR",
            "not ANCR or AHAC",
        );
        fails(
            scaffold,
            &[b"ANCR", b"ADEF", b"AMLP"],
            b"AMLP",
            "must precede",
        );
        fails(
            scaffold,
            &[b"ANCR", b"AMLP", b"TFEA", b"ADEF"],
            b"ADEF",
            "must precede",
        );
        fails(
            scaffold_still,
            &[b"ANCR", b"AMLP", b"ADEF"],
            b"ADEF",
            "without dynamic anchors",
        );
        fails(
            scaffold_still,
            &[b"ANCR", b"AMLP", b"TFEA"],
            b"TFEA",
            "without dynamic anchors",
        );
        fails(scaffold, &[b"ANCR", b"LIFE"], b"LIFE", "Scaffold-GS file");
        // Scene level: scene types only.
        let mut s = SectionRules::new(Section::Scene);
        let limits = Limits::default();
        assert!(s.admit(&chunk(b"LAED", 0, SCENE_LEVEL), &limits).unwrap());
        let e = s
            .admit(&chunk(b"CRAW", FLAG_MUST_UNDERSTAND, SCENE_LEVEL), &limits)
            .unwrap_err();
        assert!(
            matches!(e.format_kind(), Some(FormatErrorKind::Order(_))),
            "{e}"
        );
    }
}
