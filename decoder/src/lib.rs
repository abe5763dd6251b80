//! `dlgs-decoder`: random-access decoding of `.dlgs` streams.

use std::fs::File;
use std::io::{BufReader, Read, Seek};
use std::path::Path;
use std::sync::Arc;

use dlgs::container::{ChunkType, FileReader, SceneHeader};
use dlgs::payload::raw_canonical;
use dlgs::{Canonical, Error, ErrorKind, Limits, Result};

/// Decodes GOPs and frames from a seekable `.dlgs` source.
pub struct Decoder<R: Read + Seek> {
    reader: FileReader<R>,
    /// The last decoded GOP's canonical state, reused while playback stays in that GOP.
    cached: Option<(u32, Arc<Canonical>)>,
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
        let s = self.scene();
        if !t.is_finite() || t < 0.0 || t > s.duration_seconds() {
            return Err(Error::new(
                ErrorKind::Request(format!(
                    "time {t} s outside the stream [0, {:.4}] s",
                    s.duration_seconds()
                )),
                0,
            ));
        }
        Ok(((t * s.fps()).floor() as u64).min(s.frame_count as u64 - 1) as u32)
    }

    /// Decode the canonical Gaussians of GOP `g`.
    pub fn gop_canonical(&mut self, g: u32) -> Result<Arc<Canonical>> {
        if let Some((cg, c)) = &self.cached {
            if *cg == g {
                return Ok(c.clone());
            }
        }
        let chunks = self.reader.gop_chunks(g)?;
        let craw = chunks.iter().find(|c| c.ty == ChunkType::CRAW).copied();
        let Some(craw) = craw else {
            let at = self.reader.gop_entry(g)?.offset;
            return Err(Error::new(ErrorKind::MissingChunk(ChunkType::CRAW), at));
        };
        let p = self.reader.payload(&craw)?;
        let limits = *self.reader.limits();
        let c = Arc::new(raw_canonical::decode(
            &p,
            craw.payload_offset(),
            self.reader.scene(),
            &limits,
        )?);
        self.cached = Some((g, c.clone()));
        Ok(c)
    }

    /// The Gaussians to render at time `t` seconds.
    pub fn frame_at(&mut self, t: f64) -> Result<Arc<Canonical>> {
        let f = self.frame_index_at(t)?;
        let g = f / self.scene().gop_length;
        self.gop_canonical(g)
    }
}
