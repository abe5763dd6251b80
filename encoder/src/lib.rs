//! `dlgs-encoder`: turns scene models into `.dlgs` streams.
//!
//! Today it writes intra GOPs with raw canonical Gaussians (`CRAW`); compressed canonical,
//! time-feature and residual stages plug in here as their issues land.

use std::io::Write;

use dlgs::container::{ChunkType, SceneHeader, Writer, FLAG_MUST_UNDERSTAND};
use dlgs::payload::raw_canonical::{self, RawCodec};
use dlgs::{Canonical, Error, ErrorKind, Result};

/// Encoder settings.
#[derive(Debug, Clone)]
pub struct EncoderConfig {
    /// How `CRAW` bodies are stored.
    pub raw_codec: RawCodec,
    /// zstd level for `CRAW` when `raw_codec` is zstd (1..=22).
    pub zstd_level: i32,
    /// Free-form JSON written as the scene-level `META` chunk (provenance, credits).
    pub meta: Option<serde_json::Value>,
}

impl Default for EncoderConfig {
    fn default() -> Self {
        EncoderConfig {
            raw_codec: RawCodec::Zstd,
            zstd_level: 9,
            meta: None,
        }
    }
}

/// Writes one GOP at a time, in order.
pub struct StreamEncoder<W: Write> {
    writer: Writer<W>,
    cfg: EncoderConfig,
}

impl<W: Write> StreamEncoder<W> {
    pub fn new(out: W, scene: SceneHeader, cfg: EncoderConfig) -> Result<Self> {
        let mut writer = Writer::new(out, scene)?;
        if let Some(meta) = &cfg.meta {
            let bytes = serde_json::to_vec(meta)
                .map_err(|e| Error::new(ErrorKind::InvalidInput(e.to_string()), 0))?;
            writer.scene_chunk(ChunkType::META, 0, &bytes)?;
        }
        Ok(StreamEncoder { writer, cfg })
    }

    /// Append the next GOP, coded intra from its canonical Gaussians.
    pub fn push_intra_gop(&mut self, canon: &Canonical) -> Result<()> {
        let s = self.writer.scene();
        if canon.statics.len() != s.n_static as usize
            || canon.dynamics.len() != s.n_dynamic as usize
        {
            return Err(Error::new(
                ErrorKind::InvalidInput(format!(
                    "GOP has {}/{} static/dynamic Gaussians, header declares {}/{}",
                    canon.statics.len(),
                    canon.dynamics.len(),
                    s.n_static,
                    s.n_dynamic
                )),
                0,
            ));
        }
        if canon.statics.sh_degree != s.sh_degree || canon.statics.lang_width != s.lang_width() {
            return Err(Error::new(
                ErrorKind::InvalidInput(
                    "GOP layout differs from the header (SH degree or language width)".into(),
                ),
                0,
            ));
        }
        let payload = raw_canonical::encode(canon, self.cfg.raw_codec, self.cfg.zstd_level)?;
        self.writer.begin_gop()?;
        self.writer
            .gop_chunk(ChunkType::CRAW, FLAG_MUST_UNDERSTAND, &payload)
    }

    pub fn finish(self) -> Result<W> {
        self.writer.finish()
    }
}

/// Encode a single still frame (one GOP, one frame) from static Gaussians.
pub fn encode_still<W: Write>(g: &dlgs::Gaussians, cfg: EncoderConfig, out: W) -> Result<W> {
    let mut scene = SceneHeader::still(g.len() as u32, g.sh_degree);
    if g.has_language() {
        // DLGStream's 9-dim feature is 3 levels x 3 dims; other widths are one level.
        let (levels, dims) = if g.lang_width == 9 {
            (3, 3)
        } else {
            (1, g.lang_width as u8)
        };
        scene.lang_levels = levels;
        scene.lang_dims = dims;
    }
    let mut enc = StreamEncoder::new(out, scene, cfg)?;
    enc.push_intra_gop(&Canonical::from_static(g.clone()))?;
    enc.finish()
}
