//! `dlgs-decoder`: random-access decoding of `.dlgs` streams, including the dynamic
//! Gaussians at any time t (format-spec §6.4).
// Frames have the same bits on every platform: no libm transcendental (clippy.toml).
#![deny(clippy::disallowed_methods)]

mod build;
mod clock;
pub mod deform;
pub mod hevc;
mod hevc_headers;
pub mod interp;
mod lru;
pub mod panel;
mod panel_nofma;
pub mod pipeline;
pub mod planar;
mod prefix_keys;
mod read_ahead;
pub mod scaffold;
pub mod stream;

use std::fs::File;
use std::io::{BufReader, Read, Seek};
use std::path::Path;
use std::sync::Arc;

use dlgs::chunks::laed;
use dlgs::container::gop::NO_REFERENCE;
use dlgs::container::{ChunkType, FileReader, SceneHeader};
use dlgs::model::lang_decoder::LangDecoder;
use dlgs::model::ntc::NtcField;
use dlgs::model::{DynamicGop, Gaussians, TimePoint};
use dlgs::{Canonical, Error, FormatErrorKind, Limits, Result};

pub use deform::{Deformer, FrameOptions, FrameSlices};
pub use hevc::{KeyPictureDecoder, SharedKeyPictureDecoder};
use lru::GopLru;
use read_ahead::ReadAhead;

/// One decoded GOP: canonical Gaussians and, if the scene has dynamics, its deformation field.
pub struct DecodedGop {
    pub index: u32,
    pub canonical: Arc<Canonical>,
    pub deformer: Option<Deformer>,
    /// The chunk the canonical state came from (`CRAW`/`CSOG`, or `RNTC`/`RDLT` for residual
    /// GOPs).
    pub source: ChunkType,
    /// The GOP's binary voxel residual field, when `source` is `RNTC` (for re-encoding).
    pub ntc: Option<Arc<NtcField>>,
}

/// A decoded canonical state and where it came from.
#[derive(Clone)]
pub(crate) struct State {
    pub(crate) canonical: Arc<Canonical>,
    pub(crate) source: ChunkType,
    pub(crate) ntc: Option<Arc<NtcField>>,
}

impl DecodedGop {
    /// The Gaussians of this GOP at `time` (located in this GOP), written into the buffers
    /// of `reuse`. Fails only where intra-only time features decode a key for the first time
    /// and its picture is damaged.
    pub fn frame(
        gop: &Arc<DecodedGop>,
        time: TimePoint,
        opts: &FrameOptions,
        mut reuse: Gaussians,
    ) -> Result<Frame> {
        let canon = &gop.canonical.dynamics;
        match &gop.deformer {
            Some(d) => {
                d.frame_into(canon, time.key, time.delta, opts, &mut reuse)?;
                d.hide_outside_life(
                    time.local_frame,
                    &mut reuse.opacity,
                    &mut reuse.lang_opacity,
                );
            }
            None => reuse.clone_from(canon),
        }
        Ok(Frame {
            time,
            gop: gop.clone(),
            dynamics: reuse,
        })
    }

    /// Prepare the time-feature keys of `keys` (decoded, and their geometry computed) before
    /// the frames that need them: see [`Deformer::prepare_keys`]. Nothing for a static scene.
    pub fn prepare_keys(&self, keys: std::ops::Range<usize>) -> Result<()> {
        match &self.deformer {
            Some(d) => d.prepare_keys(&self.canonical.dynamics, keys),
            None => Ok(()),
        }
    }

    /// The GOP's time features and decoders, if the scene has dynamic Gaussians (rebuilt from
    /// the deformer's layout; for re-encoding and inspection, not per frame).
    pub fn dynamic(&self) -> Result<Option<DynamicGop>> {
        self.deformer
            .as_ref()
            .map(Deformer::dynamic_gop)
            .transpose()
    }
}

/// The Gaussians of one instant: the GOP's static set (shared, untouched) and the deformed
/// dynamic set.
pub struct Frame {
    pub time: TimePoint,
    pub gop: Arc<DecodedGop>,
    pub dynamics: Gaussians,
}

impl Frame {
    pub fn statics(&self) -> &Gaussians {
        &self.gop.canonical.statics
    }
    /// Static then dynamic Gaussians in one set, for renderers and exporters.
    pub fn merged(&self) -> Gaussians {
        let mut g = self.statics().clone();
        g.extend(&self.dynamics);
        g
    }
}

/// Decodes GOPs and frames from a seekable `.dlgs` source.
pub struct Decoder<R: Read + Seek> {
    reader: FileReader<R>,
    /// Recently decoded GOPs with their time features and decoders (by default only the
    /// last one, reused while playback stays in it).
    gops: GopLru<Arc<DecodedGop>>,
    /// Decoded canonical states of recent GOPs (GOP 0 is kept while the cache holds anything:
    /// it is every parallel-mode GOP's reference).
    states: GopLru<State>,
    /// Decodes HEVC time features; `None` without the `hevc` feature until a player sets one.
    hevc: Option<SharedKeyPictureDecoder>,
    /// The next GOP, decoded ahead while frames are asked for in time order.
    ahead: ReadAhead,
}

impl Decoder<BufReader<File>> {
    pub fn open_path(path: impl AsRef<Path>) -> Result<Self> {
        let f = File::open(path.as_ref())
            .map_err(|e| Error::io(format!("opening {}", path.as_ref().display()), e, 0))?;
        Self::new(BufReader::new(f), Limits::default())
    }
}

impl<R: Read + Seek> Decoder<R> {
    pub fn new(src: R, limits: Limits) -> Result<Self> {
        let reader = FileReader::open_with_limits(src, limits)?;
        if reader.scene().variant == dlgs::container::header::Variant::Scaffold {
            return Err(Error::request(
                "a Scaffold-GS file: its frames depend on the camera; decode it with \
                 dlgs_decoder::scaffold::ScaffoldDecoder",
            ));
        }
        Ok(Decoder {
            reader,
            gops: GopLru::new(1, None),
            states: GopLru::new(4, Some(0)),
            hevc: hevc::default_decoder(),
            ahead: ReadAhead::new(true),
        })
    }

    /// Decode HEVC time features with `decoder` instead of the default (FFmpeg with the `hevc`
    /// feature; none without it, so files with HEVC features fail with `NoHevcDecoder`).
    /// GOPs already decoded are dropped from the cache.
    pub fn set_key_picture_decoder(&mut self, decoder: SharedKeyPictureDecoder) {
        self.hevc = Some(decoder);
        self.gops.clear();
        self.set_read_ahead(self.read_ahead());
    }

    pub fn scene(&self) -> &SceneHeader {
        self.reader.scene()
    }
    pub fn reader(&mut self) -> &mut FileReader<R> {
        &mut self.reader
    }

    /// The frame index shown at time `t` seconds (frame f covers [f/fps, (f+1)/fps)).
    pub fn frame_index_at(&self, t: f64) -> Result<u32> {
        Ok(self.scene().locate(t)?.frame)
    }

    /// The scene's language autoencoder decoder and canonical negatives (`LAED`, §6.8), if
    /// the file carries one. Read on demand: only queries need it.
    pub fn lang_decoder(&mut self) -> Result<Option<LangDecoder>> {
        read_lang_decoder(&mut self.reader)
    }

    /// Decode GOP `g`: canonical Gaussians, time features and decoders (cached). HEVC time
    /// features decode the keys a frame needs when it first needs them: intra-only features
    /// (`TFEA` codec 3) those keys alone, one-stream features whose output order can be read
    /// the packets up to them (format-spec §6.2, "Decoding a prefix"); other streams whole.
    pub fn gop(&mut self, g: u32) -> Result<Arc<DecodedGop>> {
        self.gop_for_keys(g, 0..0)
    }

    /// [`Self::gop`], decoding the time-feature keys of `keys` alongside the canonical state
    /// (all keys are decoded anyway when the features decode only whole).
    fn gop_for_keys(&mut self, g: u32, keys: std::ops::Range<usize>) -> Result<Arc<DecodedGop>> {
        if let Some(c) = self.gops.get(g) {
            return Ok(c);
        }
        if let Some(decoded) = self.take_ahead(g) {
            return decoded;
        }
        let chunks = self.reader.gop_chunks(g)?;
        let gop_at = self.reader.gop_entry(g)?.offset;
        let scene = self.reader.scene().clone();
        let limits = self.reader.limits().fresh();
        let hevc = self.hevc.clone();
        let reader = &mut self.reader;
        let payloads = build::dynamic_payloads(&scene, &chunks, gop_at, |c| reader.payload(c))?;
        // The time features (HEVC decode) need nothing of the canonical state: decode them on
        // a second thread while this one decodes the state (residual application). Chunks that
        // cannot be read fail first; decode errors are reported state first, as a sequential
        // decode would. Every value depends only on its inputs, so the overlap changes no bit.
        let decode_dynamic = || {
            let dynamic = payloads
                .as_ref()
                .map(|p| build::decode_dynamic(&scene, &limits, hevc.as_ref(), p))
                .transpose()?;
            if let Some((features, _, _)) = &dynamic {
                features.ensure_keys(keys)?;
            }
            Ok(dynamic)
        };
        // wasm32-unknown-unknown cannot start threads (std::thread panics): in turn there.
        let (state, dynamic) = if cfg!(target_arch = "wasm32") {
            let state = self.state(g);
            (state, decode_dynamic())
        } else {
            std::thread::scope(|s| {
                let worker = s.spawn(decode_dynamic);
                let state = self.state(g);
                let dynamic = worker
                    .join()
                    .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
                (state, dynamic)
            })
        };
        let gop = Arc::new(build::assemble(&scene, g, state?, dynamic?));
        self.gops.insert(g, gop.clone());
        Ok(gop)
    }

    /// How many decoded canonical states to keep (default 4; GOP 0 is kept preferentially).
    /// Sequential seeks walk the residual chain from the nearest cached GOP.
    pub fn set_state_cache(&mut self, capacity: usize) {
        self.states.reset(capacity);
    }

    /// How many decoded GOPs (canonical state, time features as far as decoded, decoders) to
    /// keep, least recently used dropped first; at least 1, the default. More makes a jump
    /// back into a kept GOP cost only the frame, at the memory of those GOPs: on the
    /// 273k-Gaussian benchmark stream (81,876 dynamic) about 45 MB per GOP
    /// (docs/benchmarks/residuals-seek.md "Keeping decoded GOPs").
    pub fn set_gop_cache(&mut self, capacity: usize) {
        self.gops.reset(capacity.max(1));
    }

    /// The GOPs the GOP cache holds, ascending.
    pub fn cached_gops(&self) -> Vec<u32> {
        self.gops.keys()
    }

    /// The decoded canonical state of GOP `g`: its own canonical chunk, or its residual
    /// applied to its reference GOP's state (§5.1, §6.6, §6.7), walking the chain from the
    /// nearest cached state.
    fn state(&mut self, g: u32) -> Result<State> {
        if let Some(s) = self.states.get(g) {
            return Ok(s);
        }
        let mut chain = vec![g];
        let mut base = None;
        loop {
            let cur = *chain.last().expect("non-empty");
            let r = self.reader.gop_entry(cur)?.header.reference_gop;
            if r == NO_REFERENCE {
                break;
            }
            if let Some(s) = self.states.get(r) {
                base = Some(s);
                break;
            }
            if chain.len() > self.scene().gop_count as usize {
                return Err(Error::format(
                    FormatErrorKind::Index("reference GOPs form a cycle"),
                    self.reader.gop_entry(g)?.offset,
                ));
            }
            chain.push(r);
        }
        while let Some(cur) = chain.pop() {
            let s = self.decode_state(cur, base.as_ref())?;
            self.states.insert(cur, s.clone());
            base = Some(s);
        }
        Ok(base.expect("the chain decoded at least GOP g"))
    }

    /// Decode GOP `g`'s canonical chunk, or apply its residual chunk to `base`.
    fn decode_state(&mut self, g: u32, base: Option<&State>) -> Result<State> {
        let chunks = self.reader.gop_chunks(g)?;
        let gop_at = self.reader.gop_entry(g)?.offset;
        let scene = self.reader.scene().clone();
        let limits = self.reader.limits().fresh();
        let reader = &mut self.reader;
        build::state(&scene, &limits, &chunks, gop_at, base, |c| {
            reader.payload(c)
        })
    }

    /// Prepare the GOP that holds time `t` and return the Gaussians at `t`: the same as
    /// [`Self::frame_at`], named for players that jump.
    pub fn seek(&mut self, t: f64, opts: &FrameOptions) -> Result<Frame> {
        self.frame_at(t, opts)
    }

    /// Decode the canonical Gaussians of GOP `g`.
    pub fn gop_canonical(&mut self, g: u32) -> Result<Arc<Canonical>> {
        Ok(self.gop(g)?.canonical.clone())
    }

    /// The Gaussians at any time `t` seconds in `[0, duration]`, between frames included:
    /// key features are interpolated at the exact fraction (4D frame interpolation).
    pub fn frame_at(&mut self, t: f64, opts: &FrameOptions) -> Result<Frame> {
        self.frame_at_reusing(t, opts, Gaussians::default())
    }

    /// [`Self::frame_at`] writing into the buffers of `reuse` (e.g. the previous frame's
    /// `dynamics`), so a player allocates nothing per frame.
    pub fn frame_at_reusing(
        &mut self,
        t: f64,
        opts: &FrameOptions,
        reuse: Gaussians,
    ) -> Result<Frame> {
        let time = self.scene().locate(t)?;
        let gop = self.gop_for_keys(time.gop, time.key..time.key + 2)?;
        self.frame_requested(time.gop, t);
        DecodedGop::frame(&gop, time, opts, reuse)
    }

    /// The Gaussians at `t` as [`Frame::merged`] gives them (static then dynamic), built
    /// with one copy of the static set: the dynamic set is decoded straight into its rows of
    /// the merged buffers (new, exact-size allocations the caller owns).
    pub fn frame_at_merged(&mut self, t: f64, opts: &FrameOptions) -> Result<Gaussians> {
        let time = self.scene().locate(t)?;
        let gop = self.gop_for_keys(time.gop, time.key..time.key + 2)?;
        self.frame_requested(time.gop, t);
        let (statics, canon) = (&gop.canonical.statics, &gop.canonical.dynamics);
        let same_layout =
            statics.sh_degree == canon.sh_degree && statics.lang_width == canon.lang_width;
        match &gop.deformer {
            Some(d) if same_layout => {
                let mut out = with_room(statics, canon.len());
                d.frame_into_after(canon, time.key, time.delta, opts, &mut out, statics.len())?;
                let lo = usize::from(out.has_language());
                d.hide_outside_life(
                    time.local_frame,
                    &mut out.opacity[statics.len()..],
                    &mut out.lang_opacity[statics.len() * lo..],
                );
                Ok(out)
            }
            _ => Ok(DecodedGop::frame(&gop, time, opts, Gaussians::default())?.merged()),
        }
    }
}

impl<R: Read + Seek> Decoder<R> {
    /// [`Self::frame_at_merged`] written into caller-owned slices that hold exactly the merged
    /// frame (static then dynamic rows, the stream's layout; the language slices empty
    /// when the stream has none): the static rows are copied, the dynamic rows decoded in
    /// place. For bindings that decode into memory they hand out again.
    pub fn frame_at_merged_into(
        &mut self,
        t: f64,
        opts: &FrameOptions,
        out: FrameSlices<'_>,
    ) -> Result<()> {
        let time = self.scene().locate(t)?;
        let gop = self.gop_for_keys(time.gop, time.key..time.key + 2)?;
        self.frame_requested(time.gop, t);
        let (statics, canon) = (&gop.canonical.statics, &gop.canonical.dynamics);
        let fits = |g: &Gaussians, extra: &Gaussians| {
            let rows = g.len() + extra.len();
            out.positions.len() == rows
                && out.log_scales.len() == rows
                && out.rotations.len() == rows
                && out.opacity.len() == rows
                && out.lang_opacity.len() == g.lang_opacity.len() + extra.lang_opacity.len()
                && out.sh.len() == g.sh.len() + extra.sh.len()
                && out.lang.len() == g.lang.len() + extra.lang.len()
        };
        let same_layout =
            statics.sh_degree == canon.sh_degree && statics.lang_width == canon.lang_width;
        let Some(d) = gop.deformer.as_ref().filter(|_| same_layout) else {
            let g = DecodedGop::frame(&gop, time, opts, Gaussians::default())?.merged();
            if !fits(&g, &Gaussians::default()) {
                return Err(Error::request("the slices do not hold the merged frame"));
            }
            copy_rows(&g, out);
            return Ok(());
        };
        if !fits(statics, canon) {
            return Err(Error::request("the slices do not hold the merged frame"));
        }
        let ns = statics.len();
        let (lo, stride, lw) = (
            usize::from(statics.has_language()),
            statics.sh_stride(),
            statics.lang_width,
        );
        let (pos_s, pos_d) = out.positions.split_at_mut(ns);
        let (sc_s, sc_d) = out.log_scales.split_at_mut(ns);
        let (rot_s, rot_d) = out.rotations.split_at_mut(ns);
        let (op_s, op_d) = out.opacity.split_at_mut(ns);
        let (lop_s, lop_d) = out.lang_opacity.split_at_mut(ns * lo);
        let (sh_s, sh_d) = out.sh.split_at_mut(ns * stride);
        let (l_s, l_d) = out.lang.split_at_mut(ns * lw);
        copy_rows(
            statics,
            FrameSlices {
                positions: pos_s,
                log_scales: sc_s,
                rotations: rot_s,
                opacity: op_s,
                lang_opacity: lop_s,
                sh: sh_s,
                lang: l_s,
            },
        );
        let dynamic = FrameSlices {
            positions: pos_d,
            log_scales: sc_d,
            rotations: rot_d,
            opacity: &mut *op_d,
            lang_opacity: &mut *lop_d,
            sh: sh_d,
            lang: l_d,
        };
        d.frame_into_slices(canon, time.key, time.delta, opts, dynamic)?;
        d.hide_outside_life(time.local_frame, op_d, lop_d);
        Ok(())
    }
}

/// `g`'s rows into slices of exactly its size, the attributes in parallel.
fn copy_rows(g: &Gaussians, out: FrameSlices<'_>) {
    let FrameSlices {
        positions,
        log_scales,
        rotations,
        opacity,
        lang_opacity,
        sh,
        lang,
    } = out;
    rayon::join(
        || {
            rayon::join(
                || positions.copy_from_slice(&g.positions),
                || log_scales.copy_from_slice(&g.log_scales),
            );
            rayon::join(
                || rotations.copy_from_slice(&g.rotations),
                || opacity.copy_from_slice(&g.opacity),
            );
        },
        || {
            rayon::join(
                || sh.copy_from_slice(&g.sh),
                || lang.copy_from_slice(&g.lang),
            );
            lang_opacity.copy_from_slice(&g.lang_opacity);
        },
    );
}

/// `g`'s rows in new buffers with room for `more` rows of the same layout. The attributes are
/// copied in parallel (the copy and the first touch of the new pages are what the merged
/// frame costs over the dynamic set alone).
fn with_room(g: &Gaussians, more: usize) -> Gaussians {
    fn copy<T: Copy + Send + Sync>(v: &[T], extra: usize) -> Vec<T> {
        let mut out = Vec::with_capacity(v.len() + extra);
        out.extend_from_slice(v);
        out
    }
    let lo = usize::from(g.has_language());
    let ((positions, log_scales), (rotations, opacity)) = rayon::join(
        || rayon::join(|| copy(&g.positions, more), || copy(&g.log_scales, more)),
        || rayon::join(|| copy(&g.rotations, more), || copy(&g.opacity, more)),
    );
    let ((sh, lang), lang_opacity) = rayon::join(
        || {
            rayon::join(
                || copy(&g.sh, more * g.sh_stride()),
                || copy(&g.lang, more * g.lang_width),
            )
        },
        || copy(&g.lang_opacity, more * lo),
    );
    Gaussians {
        sh_degree: g.sh_degree,
        lang_width: g.lang_width,
        positions,
        log_scales,
        rotations,
        opacity,
        lang_opacity,
        sh,
        lang,
    }
}

/// The scene's language decoder and canonical negatives (`LAED`, §6.8) from a file of either
/// variant, if it carries one.
pub fn read_lang_decoder<R: Read + Seek>(
    reader: &mut FileReader<R>,
) -> Result<Option<LangDecoder>> {
    let Some(c) = reader
        .scene_chunks()
        .iter()
        .find(|c| c.ty == ChunkType::LAED)
        .copied()
    else {
        return Ok(None);
    };
    let p = reader.payload(&c)?;
    let scene = reader.scene().clone();
    let limits = reader.limits().fresh();
    laed::decode(&p, c.payload_offset(), &scene, &limits).map(Some)
}
