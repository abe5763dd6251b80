//! One Scaffold-GS GOP from its chunks, whoever read them (the random-access
//! [`super::ScaffoldDecoder`] or the in-order [`super::ScaffoldStreamDecoder`]): its canonical
//! anchors and view MLPs (`ANCR` or `AHAC` and `AMLP`, or in a residual GOP `RNTC` over the
//! reference GOP's state, `AMLP` inherited or language-only) and its dynamic part (`ADEF`,
//! `TFEA`).

use dlgs::chunks::{adef, ahac, amlp, ancr, rntc};
use dlgs::container::{ChunkInfo, ChunkType, SceneHeader};
use dlgs::model::scaffold::{AnchorDeformation, ScaffoldCanonical, ScaffoldMlps};
use dlgs::model::TimeFeatures;
use dlgs::{Error, FormatErrorKind, Limits, Result};

use crate::build::decode_time_features;
use crate::hevc::SharedKeyPictureDecoder;

/// What a residual GOP needs of its reference GOP: the decoded canonical anchors and the view
/// MLPs in force (format-spec §6.10, §6.12).
#[derive(Debug)]
pub(super) struct GopState {
    pub canonical: ScaffoldCanonical,
    pub mlps: ScaffoldMlps,
}

/// A GOP's chunk headers and a way to read a chunk's payload. The headers come from a
/// container reader, which has checked §3.3's GOP rules (each type at most once, in order, and
/// only the chunks this GOP can use), so a type found is the GOP's one chunk of that type.
pub(super) struct GopChunks<'a> {
    pub chunks: &'a [ChunkInfo],
    /// Offset of the GOP (for errors about missing chunks).
    pub at: u64,
    pub read: &'a mut dyn FnMut(&ChunkInfo) -> Result<Vec<u8>>,
}

impl GopChunks<'_> {
    fn find(&self, ty: ChunkType) -> Option<ChunkInfo> {
        self.chunks.iter().find(|c| c.ty == ty).copied()
    }

    /// The payload of the GOP's chunk of type `ty` and its file offset.
    fn read(&mut self, ty: ChunkType) -> Result<(Vec<u8>, u64)> {
        let c = self
            .find(ty)
            .ok_or_else(|| Error::format(FormatErrorKind::MissingChunk(ty), self.at))?;
        Ok(((self.read)(&c)?, c.payload_offset()))
    }
}

/// The GOP's canonical anchors and view MLPs; `reference` is its reference GOP's state
/// (`None` for an intra GOP).
pub(super) fn decode_state(
    scene: &SceneHeader,
    limits: &Limits,
    gop: &mut GopChunks,
    reference: Option<&GopState>,
) -> Result<GopState> {
    let Some(reference) = reference else {
        // Exactly one of ANCR (§6.9) and AHAC (§6.13).
        let canonical = match (gop.find(ChunkType::ANCR), gop.find(ChunkType::AHAC)) {
            (Some(_), Some(c)) => {
                return Err(Error::payload(
                    ChunkType::AHAC,
                    "a GOP holds both ANCR and AHAC",
                    c.payload_offset(),
                ))
            }
            (None, Some(_)) => {
                let (p, o) = gop.read(ChunkType::AHAC)?;
                ahac::decode(&p, o, scene, limits).map_err(|e| e.in_chunk(ChunkType::AHAC))?
            }
            _ => {
                let (p, o) = gop.read(ChunkType::ANCR)?;
                ancr::decode(&p, o, scene, limits).map_err(|e| e.in_chunk(ChunkType::ANCR))?
            }
        };
        let (p, o) = gop.read(ChunkType::AMLP)?;
        let mlps = amlp::decode(&p, o, scene, limits).map_err(|e| e.in_chunk(ChunkType::AMLP))?;
        return Ok(GopState { canonical, mlps });
    };
    // A residual GOP (§6.12): an RNTC over anchor groups (the container reader has refused
    // ANCR and AHAC here, §3.3).
    let (p, o) = gop.read(ChunkType::RNTC)?;
    let canonical = rntc::decode(&p, o, scene, limits)
        .and_then(|field| {
            reference
                .canonical
                .with_residual(&field)
                .map_err(|e| Error::payload(ChunkType::RNTC, e, o))
        })
        .map_err(|e| e.in_chunk(ChunkType::RNTC))?;
    let mlps = match gop.find(ChunkType::AMLP) {
        None => reference.mlps.clone(),
        Some(_) => {
            let (p, o) = gop.read(ChunkType::AMLP)?;
            amlp::decode_any(&p, o, scene, limits)
                .map_err(|e| e.in_chunk(ChunkType::AMLP))?
                .resolve(Some(&reference.mlps))
                .expect("a reference is given")
        }
    };
    Ok(GopState { canonical, mlps })
}

/// With dynamic anchors: the GOP's deformation (`ADEF`) and key time features (`TFEA`).
pub(super) fn decode_dynamic(
    scene: &SceneHeader,
    limits: &Limits,
    hevc: Option<&SharedKeyPictureDecoder>,
    gop: &mut GopChunks,
) -> Result<Option<(AnchorDeformation, TimeFeatures)>> {
    if scene.n_dynamic == 0 {
        return Ok(None);
    }
    let (p, o) = gop.read(ChunkType::ADEF)?;
    let d = adef::decode(&p, o, limits).map_err(|e| e.in_chunk(ChunkType::ADEF))?;
    let (p, o) = gop.read(ChunkType::TFEA)?;
    let f = decode_time_features(scene, limits, hevc, &p, o)
        .and_then(|f| f.to_time_features())
        .map_err(|e| e.in_chunk(ChunkType::TFEA))?;
    Ok(Some((d, f)))
}
