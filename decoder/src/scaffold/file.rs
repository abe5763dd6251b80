//! Random-access decoding of Scaffold-GS files (`HEAD.variant = 1`; format-spec §6.9-§6.12):
//! a GOP's anchors (`ANCR` or HAC-coded `AHAC`, or in a sequential scene from GOP 1 on an
//! `RNTC` residual against the previous GOP's decoded anchors), view MLPs (`AMLP`, inherited
//! along the chain when a residual GOP omits it) and, with dynamic anchors, their time features
//! (`TFEA`) and deformation (`ADEF`); a frame is the neural Gaussians one camera sees at a time.

use std::io::{Read, Seek};
use std::sync::Arc;

use dlgs::container::header::Variant;
use dlgs::container::{ChunkInfo, ChunkType, FileReader, SceneHeader};
use dlgs::model::scaffold::{AnchorDeformation, Anchors, ScaffoldCanonical, ScaffoldMlps};
use dlgs::model::TimeFeatures;
use dlgs::{Error, FormatErrorKind, Limits, Result};

use super::gop_decode::{decode_dynamic, decode_state, GopChunks, GopState};
use super::{deform_anchors, neural_gaussians, NeuralGaussians, ViewRequest};
use crate::hevc::{self, SharedKeyPictureDecoder};

/// One decoded Scaffold-GS GOP.
#[derive(Debug, Clone)]
pub struct ScaffoldGop {
    pub index: u32,
    pub canonical: ScaffoldCanonical,
    pub mlps: ScaffoldMlps,
    /// With dynamic anchors: their deformation and key time features.
    pub dynamic: Option<(AnchorDeformation, TimeFeatures)>,
    /// What does not change with the time, computed once per GOP: every anchor's canonical
    /// position (static, then dynamic) and the static anchors' reach.
    positions: Vec<[f32; 3]>,
    static_reach: Vec<f32>,
}

impl ScaffoldGop {
    /// A GOP from its parts (the per-GOP caches are computed here).
    pub fn new(
        index: u32,
        canonical: ScaffoldCanonical,
        mlps: ScaffoldMlps,
        dynamic: Option<(AnchorDeformation, TimeFeatures)>,
    ) -> Self {
        let mut positions = canonical.statics.positions.clone();
        positions.extend_from_slice(&canonical.dynamics.positions);
        let static_reach = super::anchor_reach(&canonical.statics);
        ScaffoldGop {
            index,
            canonical,
            mlps,
            dynamic,
            positions,
            static_reach,
        }
    }

    /// Every anchor at key pair (`key`, `key + 1`), fraction `delta`: static anchors as stored,
    /// dynamic ones deformed (§6.12). Returns (pre-deformation positions, state).
    pub fn anchors_at(&self, key: usize, delta: f32) -> (&[[f32; 3]], Anchors) {
        let c = &self.canonical;
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
        // One allocation per attribute, sized for both sets.
        let join = |a: &[f32], b: &[f32]| {
            let mut v = Vec::with_capacity(a.len() + b.len());
            v.extend_from_slice(a);
            v.extend_from_slice(b);
            v
        };
        let mut positions = Vec::with_capacity(self.positions.len());
        positions.extend_from_slice(&c.statics.positions);
        positions.extend_from_slice(&dynamics.positions);
        let state = Anchors {
            positions,
            features: join(&c.statics.features, &dynamics.features),
            offsets: join(&c.statics.offsets, &dynamics.offsets),
            log_scalings: join(&c.statics.log_scalings, &dynamics.log_scalings),
        };
        (&self.positions, state)
    }

    /// How far each anchor of `state` (from [`Self::anchors_at`]) can reach
    /// ([`super::anchor_reach`]); the static anchors' is computed once per GOP.
    pub fn reach(&self, state: &Anchors) -> Vec<f32> {
        let ns = self.static_reach.len();
        let mut r = Vec::with_capacity(state.len());
        r.extend_from_slice(&self.static_reach);
        r.extend(super::neural::anchor_reach_range(state, ns..state.len()));
        r
    }

    /// The neural Gaussians `view` sees at key pair (`key`, `key + 1`), fraction `delta`.
    pub fn frame(&self, key: usize, delta: f32, view: &ViewRequest) -> NeuralGaussians {
        let (positions, state) = self.anchors_at(key, delta);
        neural_gaussians(positions, &state, &self.mlps, view)
    }

    /// As [`Self::frame`], decoding only the anchors `in_view(positions, reach)` keeps.
    /// Returns the frame and the anchors kept.
    pub fn frame_in_view(
        &self,
        key: usize,
        delta: f32,
        camera_center: [f32; 3],
        language: bool,
        in_view: &InView,
    ) -> Result<(NeuralGaussians, usize)> {
        let (positions, state) = self.anchors_at(key, delta);
        let visible = in_view(&state.positions, &self.reach(&state));
        if visible.len() != state.len() {
            return Err(Error::request("the view test must answer once per anchor"));
        }
        let kept = visible.iter().filter(|&&v| v).count();
        let view = ViewRequest {
            camera_center,
            language,
            visible: Some(&visible),
        };
        Ok((neural_gaussians(positions, &state, &self.mlps, &view), kept))
    }

    /// The anchors at key pair (`key`, `key + 1`), fraction `delta`, as stand-in Gaussians
    /// (position, the larger three log-scalings, unit rotation, zero colour and opacity; with
    /// `language`, zero language): what stands for a Scaffold-GS scene where only its extent
    /// matters (bounds, orbit cameras).
    pub fn stand_ins(&self, key: usize, delta: f32, language: bool) -> dlgs::model::Gaussians {
        let (_, a) = self.anchors_at(key, delta);
        let lang = if language { 9 } else { 0 };
        let mut g = dlgs::model::Gaussians::new(0, lang);
        for i in 0..a.len() {
            g.positions.push(a.positions[i]);
            let s = a.log_scaling(i);
            g.log_scales.push([s[3], s[4], s[5]]);
            g.rotations.push([1.0, 0.0, 0.0, 0.0]);
            g.opacity.push(0.0);
            g.sh.extend_from_slice(&[0.0; 3]);
            if language {
                g.lang_opacity.push(0.0);
                g.lang.extend_from_slice(&[0.0; 9]);
            }
        }
        g
    }
}

/// A view test: given every anchor's position and reach, which anchors to decode.
pub type InView<'a> = dyn Fn(&[[f32; 3]], &[f32]) -> Vec<bool> + 'a;

/// Decoded GOP states kept for residual chains (GOP 0's preferentially), so sequential
/// playback decodes each GOP's residual once and a seek walks the chain from the nearest state
/// held (bounded memory: at most this many states).
const STATE_CACHE: usize = 3;

/// Decodes GOPs and camera-dependent frames from a seekable Scaffold-GS `.dlgs` source.
pub struct ScaffoldDecoder<R: Read + Seek> {
    reader: FileReader<R>,
    last: Option<Arc<ScaffoldGop>>,
    /// Most recently used last.
    states: Vec<(u32, Arc<GopState>)>,
    hevc: Option<SharedKeyPictureDecoder>,
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
            states: Vec::new(),
            hevc: hevc::default_decoder(),
        })
    }

    /// Decode HEVC time features with `decoder` instead of the default.
    pub fn set_key_picture_decoder(&mut self, decoder: SharedKeyPictureDecoder) {
        self.hevc = Some(decoder);
        self.last = None;
    }

    /// The anchors at `t` as stand-in Gaussians (position, the larger three log-scalings, unit
    /// rotation, zero colour and opacity): what stands for a Scaffold-GS scene where only its
    /// extent matters (bounds, orbit cameras); the CLI and the Python reader use the same.
    pub fn anchor_stand_ins(&mut self, t: f64) -> Result<dlgs::model::Gaussians> {
        let tp = self.scene().locate(t)?;
        let language = self.scene().lang_levels > 0;
        Ok(self.gop(tp.gop)?.stand_ins(tp.key, tp.delta, language))
    }

    /// GOP `g`'s canonical anchors (after its residual chain) without its deformation.
    pub fn canonical(&mut self, g: u32) -> Result<ScaffoldCanonical> {
        Ok(self.state(g)?.canonical.clone())
    }

    pub fn scene(&self) -> &SceneHeader {
        self.reader.scene()
    }

    /// The container reader (scene-level chunks, GOP index).
    pub fn reader(&mut self) -> &mut FileReader<R> {
        &mut self.reader
    }

    /// GOP `g`, decoded (the last one is kept for the next call). In a sequential scene this
    /// decodes the residual chain from the nearest GOP state held (GOP 0 at worst).
    pub fn gop(&mut self, g: u32) -> Result<Arc<ScaffoldGop>> {
        if let Some(last) = self.last.as_ref().filter(|l| l.index == g) {
            return Ok(last.clone());
        }
        let state = self.state(g)?;
        let scene = self.reader.scene().clone();
        let limits = self.reader.limits().fresh();
        let at = self.reader.gop_entry(g)?.offset;
        let chunks = self.reader.gop_chunks(g)?;
        let reader = &mut self.reader;
        let mut read = |c: &ChunkInfo| reader.payload(c);
        let mut chunks = GopChunks {
            chunks: &chunks,
            at,
            read: &mut read,
        };
        let dynamic = decode_dynamic(&scene, &limits, self.hevc.as_ref(), &mut chunks)?;
        let gop = Arc::new(ScaffoldGop::new(
            g,
            state.canonical.clone(),
            state.mlps.clone(),
            dynamic,
        ));
        self.last = Some(gop.clone());
        Ok(gop)
    }

    /// The canonical anchors and view MLPs of GOP `g`: from the cache, or decoded from the
    /// nearest state held along `g`'s reference chain.
    fn state(&mut self, g: u32) -> Result<Arc<GopState>> {
        // Walk back to a GOP whose state is held or that has no reference GOP.
        let mut chain = Vec::new();
        let mut h = g;
        let mut base = loop {
            if let Some(i) = self.states.iter().position(|(k, _)| *k == h) {
                let hit = self.states.remove(i);
                let st = hit.1.clone();
                self.states.push(hit);
                break Some(st);
            }
            let r = self.reader.gop_entry(h)?.header.reference_gop;
            chain.push((h, r));
            if r == dlgs::container::gop::NO_REFERENCE {
                break None;
            }
            if r >= h {
                // GIDX/GOPH validation makes a reference earlier; never loop on a bad file.
                return Err(Error::format(
                    FormatErrorKind::Index("a GOP's reference GOP must come before it"),
                    self.reader.gop_entry(h)?.offset,
                ));
            }
            h = r;
        };
        for &(h, _) in chain.iter().rev() {
            let st = Arc::new(self.decode_state(h, base.as_deref())?);
            self.remember(h, st.clone());
            base = Some(st);
        }
        Ok(base.expect("the chain ends at a decoded state"))
    }

    fn remember(&mut self, g: u32, st: Arc<GopState>) {
        if self.states.len() >= STATE_CACHE {
            // Evict the least recently used state, GOP 0's last.
            let i = self.states.iter().position(|(k, _)| *k != 0).unwrap_or(0);
            self.states.remove(i);
        }
        self.states.push((g, st));
    }

    /// Decode GOP `g`'s canonical anchors and view MLPs; `reference` is its reference GOP's
    /// state (`None` for an intra GOP).
    fn decode_state(&mut self, g: u32, reference: Option<&GopState>) -> Result<GopState> {
        let scene = self.reader.scene().clone();
        let limits = self.reader.limits().fresh();
        let at = self.reader.gop_entry(g)?.offset;
        let chunks = self.reader.gop_chunks(g)?;
        let reader = &mut self.reader;
        let mut read = |c: &ChunkInfo| reader.payload(c);
        let mut gop = GopChunks {
            chunks: &chunks,
            at,
            read: &mut read,
        };
        decode_state(&scene, &limits, &mut gop, reference)
    }

    /// The neural Gaussians `view` sees at time `t` seconds (between frames too).
    pub fn frame_at(&mut self, t: f64, view: &ViewRequest) -> Result<NeuralGaussians> {
        let tp = self.scene().locate(t)?;
        Ok(self.gop(tp.gop)?.frame(tp.key, tp.delta, view))
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
        self.gop(tp.gop)?
            .frame_in_view(tp.key, tp.delta, camera_center, language, in_view)
    }
}
