//! `dlgs-decoder`: random-access decoding of `.dlgs` streams, including the dynamic
//! Gaussians at any time t (format-spec §6.4).

pub mod deform;
pub mod interp;
pub mod panel;
pub mod planar;

use std::fs::File;
use std::io::{BufReader, Read, Seek};
use std::path::Path;
use std::sync::Arc;

use dlgs::container::{ChunkInfo, ChunkType, FileReader, SceneHeader};
use dlgs::model::{DynamicGop, Gaussians, TimePoint};
use dlgs::payload::time_features::{self, TfeaBody};
use dlgs::payload::{decode_canonical, mlp_weights, CANONICAL_CHUNKS};
use dlgs::{Canonical, Error, ErrorKind, Limits, Result};

pub use deform::{Deformer, FrameOptions};

/// One decoded GOP: canonical Gaussians and, if the scene has dynamics, its deformation field.
pub struct DecodedGop {
    pub index: u32,
    pub canonical: Arc<Canonical>,
    pub deformer: Option<Deformer>,
}

impl DecodedGop {
    /// The GOP's time features and decoders, if the scene has dynamic Gaussians (rebuilt from
    /// the deformer's layout; for re-encoding and inspection, not per frame).
    pub fn dynamic(&self) -> Option<DynamicGop> {
        self.deformer.as_ref().map(Deformer::dynamic_gop)
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
    /// The last decoded GOP, reused while playback stays in it.
    cached: Option<Arc<DecodedGop>>,
}

impl Decoder<BufReader<File>> {
    pub fn open_path(path: impl AsRef<Path>) -> Result<Self> {
        let f = File::open(path.as_ref()).map_err(|e| {
            Error::new(
                ErrorKind::Io(format!("{}: {e}", path.as_ref().display())),
                0,
            )
        })?;
        Self::new(BufReader::new(f), Limits::default())
    }
}

fn video_error(e: dlgs_video::VideoError, at: u64) -> Error {
    Error::new(
        ErrorKind::Payload {
            chunk: ChunkType::TFEA,
            reason: e.to_string(),
        },
        at,
    )
}

impl<R: Read + Seek> Decoder<R> {
    pub fn new(src: R, limits: Limits) -> Result<Self> {
        Ok(Decoder {
            reader: FileReader::open_with_limits(src, limits)?,
            cached: None,
        })
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

    fn find(chunks: &[ChunkInfo], ty: ChunkType) -> Option<ChunkInfo> {
        chunks.iter().find(|c| c.ty == ty).copied()
    }

    /// Decode GOP `g`: canonical Gaussians, time features and decoders (cached).
    pub fn gop(&mut self, g: u32) -> Result<Arc<DecodedGop>> {
        if let Some(c) = &self.cached {
            if c.index == g {
                return Ok(c.clone());
            }
        }
        let chunks = self.reader.gop_chunks(g)?;
        let gop_at = self.reader.gop_entry(g)?.offset;
        let scene = self.reader.scene().clone();
        let limits = *self.reader.limits();
        let canon_chunk = CANONICAL_CHUNKS
            .iter()
            .find_map(|&ty| Self::find(&chunks, ty))
            .ok_or_else(|| Error::new(ErrorKind::MissingChunk(ChunkType::CRAW), gop_at))?;
        let p = self.reader.payload(&canon_chunk)?;
        let canonical = Arc::new(
            decode_canonical(
                canon_chunk.ty,
                &p,
                canon_chunk.payload_offset(),
                &scene,
                &limits,
            )
            .expect("a canonical chunk type")?,
        );
        let mut dynamic = None;
        if scene.n_dynamic > 0 {
            let tfea = Self::find(&chunks, ChunkType::TFEA)
                .ok_or_else(|| Error::new(ErrorKind::MissingChunk(ChunkType::TFEA), gop_at))?;
            let mlpw = Self::find(&chunks, ChunkType::MLPW)
                .ok_or_else(|| Error::new(ErrorKind::MissingChunk(ChunkType::MLPW), gop_at))?;
            let p = self.reader.payload(&tfea)?;
            let at = tfea.payload_offset();
            let features = match time_features::decode(&p, at, &scene, &limits)? {
                TfeaBody::Exact(f) => f,
                TfeaBody::Hevc {
                    tiling,
                    ranges,
                    packets,
                } => {
                    let refs: Vec<&[u8]> = packets.iter().map(|p| p.as_slice()).collect();
                    let video = dlgs_video::decode_gray12(
                        &refs,
                        tiling.width() as u32,
                        tiling.height() as u32,
                        tiling.keys,
                    )
                    .map_err(|e| video_error(e, at))?;
                    time_features::untile(&video.frames, &tiling, &ranges)
                }
            };
            let p = self.reader.payload(&mlpw)?;
            let mlps = mlp_weights::decode(&p, mlpw.payload_offset(), &scene, &limits)?;
            dynamic = Some(DynamicGop { features, mlps });
        }
        let deformer = dynamic.map(|d| Deformer::new(&canonical.dynamics, d, scene.deform_model));
        let gop = Arc::new(DecodedGop {
            index: g,
            canonical,
            deformer,
        });
        self.cached = Some(gop.clone());
        Ok(gop)
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
        mut reuse: Gaussians,
    ) -> Result<Frame> {
        let time = self.scene().locate(t)?;
        let gop = self.gop(time.gop)?;
        let canon = &gop.canonical.dynamics;
        match &gop.deformer {
            Some(d) => d.frame_into(canon, time.key, time.delta, opts, &mut reuse),
            None => reuse.clone_from(canon),
        }
        Ok(Frame {
            time,
            gop,
            dynamics: reuse,
        })
    }
}
