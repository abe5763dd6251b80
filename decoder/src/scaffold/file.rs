//! Random-access decoding of Scaffold-GS files (`HEAD.variant = 1`; format-spec §6.9-§6.12):
//! a GOP's anchors (`ANCR`, or HAC-coded `AHAC`), view MLPs (`AMLP`) and, with dynamic anchors, their time features
//! (`TFEA`) and deformation (`ADEF`); a frame is the neural Gaussians one camera sees at a time.

use std::io::{Read, Seek};
use std::sync::Arc;

use dlgs::chunks::{adef, ahac, amlp, ancr};
use dlgs::container::header::Variant;
use dlgs::container::{ChunkInfo, ChunkType, FileReader, SceneHeader};
use dlgs::model::scaffold::{AnchorDeformation, Anchors, ScaffoldCanonical, ScaffoldMlps};
use dlgs::model::TimeFeatures;
use dlgs::{Error, FormatErrorKind, Limits, Result};

use super::{deform_anchors, neural_gaussians, NeuralGaussians, ViewRequest};
use crate::build::decode_time_features;
use crate::hevc::{self, SharedKeyPictureDecoder};

/// One decoded Scaffold-GS GOP.
#[derive(Debug, Clone)]
pub struct ScaffoldGop {
    pub index: u32,
    pub canonical: ScaffoldCanonical,
    pub mlps: ScaffoldMlps,
    /// With dynamic anchors: their deformation and key time features.
    pub dynamic: Option<(AnchorDeformation, TimeFeatures)>,
}

impl ScaffoldGop {
    /// Every anchor at key pair (`key`, `key + 1`), fraction `delta`: static anchors as stored,
    /// dynamic ones deformed (§6.12). Returns (pre-deformation positions, state).
    pub fn anchors_at(&self, key: usize, delta: f32) -> (Vec<[f32; 3]>, Anchors) {
        let c = &self.canonical;
        let mut view = c.statics.positions.clone();
        view.extend_from_slice(&c.dynamics.positions);
        let mut state = c.statics.clone();
        let moved;
        let dynamics = match &self.dynamic {
            Some((d, f)) => {
                moved = deform_anchors(
                    &c.dynamics,
                    f,
                    key,
                    delta,
                    &d.mlps,
                    (d.bound_min, d.bound_max),
                );
                &moved
            }
            None => &c.dynamics,
        };
        state.positions.extend_from_slice(&dynamics.positions);
        state.features.extend_from_slice(&dynamics.features);
        state.offsets.extend_from_slice(&dynamics.offsets);
        state.log_scalings.extend_from_slice(&dynamics.log_scalings);
        (view, state)
    }
}

/// A view test: given every anchor's position and reach, which anchors to decode.
pub type InView<'a> = dyn Fn(&[[f32; 3]], &[f32]) -> Vec<bool> + 'a;

/// Decodes GOPs and camera-dependent frames from a seekable Scaffold-GS `.dlgs` source.
pub struct ScaffoldDecoder<R: Read + Seek> {
    reader: FileReader<R>,
    last: Option<Arc<ScaffoldGop>>,
    hevc: Option<SharedKeyPictureDecoder>,
}

fn find(chunks: &[ChunkInfo], ty: ChunkType) -> Option<ChunkInfo> {
    chunks.iter().find(|c| c.ty == ty).copied()
}

impl<R: Read + Seek> ScaffoldDecoder<R> {
    pub fn new(src: R, limits: Limits) -> Result<Self> {
        let reader = FileReader::open_with_limits(src, limits)?;
        if reader.scene().variant != Variant::Scaffold {
            return Err(Error::request(
                "not a Scaffold-GS file (HEAD.variant is 0): decode it with dlgs_decoder::Decoder",
            ));
        }
        dlgs::model::scaffold::check_scene(reader.scene())
            .map_err(|r| Error::payload(ChunkType::HEAD, r, 0))?;
        Ok(ScaffoldDecoder {
            reader,
            last: None,
            hevc: hevc::default_decoder(),
        })
    }

    /// Decode HEVC time features with `decoder` instead of the default.
    pub fn set_key_picture_decoder(&mut self, decoder: SharedKeyPictureDecoder) {
        self.hevc = Some(decoder);
        self.last = None;
    }

    pub fn scene(&self) -> &SceneHeader {
        self.reader.scene()
    }

    /// GOP `g`, decoded (the last one is kept for the next call).
    pub fn gop(&mut self, g: u32) -> Result<Arc<ScaffoldGop>> {
        if let Some(last) = self.last.as_ref().filter(|l| l.index == g) {
            return Ok(last.clone());
        }
        let scene = self.reader.scene().clone();
        let limits = self.reader.limits().fresh();
        let at = self.reader.gop_entry(g)?.offset;
        let chunks = self.reader.gop_chunks(g)?;
        let mut read = |ty: ChunkType| -> Result<(Vec<u8>, u64)> {
            let c = find(&chunks, ty)
                .ok_or_else(|| Error::format(FormatErrorKind::MissingChunk(ty), at))?;
            Ok((self.reader.payload(&c)?, c.payload_offset()))
        };
        // Exactly one of ANCR (§6.9) and AHAC (§6.13).
        let canonical = match (
            find(&chunks, ChunkType::ANCR),
            find(&chunks, ChunkType::AHAC),
        ) {
            (Some(_), Some(c)) => {
                return Err(Error::payload(
                    ChunkType::AHAC,
                    "a GOP holds both ANCR and AHAC",
                    c.payload_offset(),
                ))
            }
            (None, Some(_)) => {
                let (p, o) = read(ChunkType::AHAC)?;
                ahac::decode(&p, o, &scene, &limits).map_err(|e| e.in_chunk(ChunkType::AHAC))?
            }
            _ => {
                let (p, o) = read(ChunkType::ANCR)?;
                ancr::decode(&p, o, &scene, &limits).map_err(|e| e.in_chunk(ChunkType::ANCR))?
            }
        };
        let (p, o) = read(ChunkType::AMLP)?;
        let mlps = amlp::decode(&p, o, &scene, &limits).map_err(|e| e.in_chunk(ChunkType::AMLP))?;
        let dynamic = if scene.n_dynamic > 0 {
            let (p, o) = read(ChunkType::ADEF)?;
            let d = adef::decode(&p, o, &limits).map_err(|e| e.in_chunk(ChunkType::ADEF))?;
            let (p, o) = read(ChunkType::TFEA)?;
            let f = decode_time_features(&scene, &limits, self.hevc.as_ref(), &p, o)
                .and_then(|f| f.to_time_features())
                .map_err(|e| e.in_chunk(ChunkType::TFEA))?;
            Some((d, f))
        } else {
            None
        };
        let gop = Arc::new(ScaffoldGop {
            index: g,
            canonical,
            mlps,
            dynamic,
        });
        self.last = Some(gop.clone());
        Ok(gop)
    }

    /// The neural Gaussians `view` sees at time `t` seconds (between frames too).
    pub fn frame_at(&mut self, t: f64, view: &ViewRequest) -> Result<NeuralGaussians> {
        let tp = self.scene().locate(t)?;
        let gop = self.gop(tp.gop)?;
        let (positions, state) = gop.anchors_at(tp.key, tp.delta);
        Ok(neural_gaussians(&positions, &state, &gop.mlps, view))
    }

    /// As [`Self::frame_at`], decoding only the anchors `in_view(positions, reach)` keeps: it
    /// gets every anchor's position at `t` and how far its children can reach
    /// ([`super::anchor_reach`]), e.g. a frustum test. Returns the frame and the anchors kept.
    pub fn frame_in_view(
        &mut self,
        t: f64,
        camera_center: [f32; 3],
        language: bool,
        in_view: &InView,
    ) -> Result<(NeuralGaussians, usize)> {
        let tp = self.scene().locate(t)?;
        let gop = self.gop(tp.gop)?;
        let (positions, state) = gop.anchors_at(tp.key, tp.delta);
        let visible = in_view(&state.positions, &super::anchor_reach(&state));
        if visible.len() != state.len() {
            return Err(Error::request("the view test must answer once per anchor"));
        }
        let kept = visible.iter().filter(|&&v| v).count();
        let view = ViewRequest {
            camera_center,
            language,
            visible: Some(&visible),
        };
        Ok((neural_gaussians(&positions, &state, &gop.mlps, &view), kept))
    }
}
