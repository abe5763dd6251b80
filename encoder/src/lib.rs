//! `dlgs-encoder`: turns scene models into `.dlgs` streams.
//!
//! It writes intra GOPs: canonical Gaussians (raw `CRAW`, or sorted quantised grids `CSOG`)
//! and, for dynamic scenes, the key time features (`TFEA`, 12-bit HEVC or exact) and the
//! deformation decoders (`MLPW`). Residual stages plug in here as their issues land.

pub mod grid_sort;
pub mod synth;

use std::io::Write;

use dlgs::container::{ChunkType, SceneHeader, Writer, FLAG_MUST_UNDERSTAND};
use dlgs::model::DynamicGop;
use dlgs::payload::mlp_weights::{self, WeightType};
use dlgs::payload::raw_canonical::{self, RawCodec};
use dlgs::payload::sorted_grid::{self, QuantBits};
use dlgs::payload::time_features::{self, TfeaBody, Tiling};
use dlgs::{Canonical, Error, ErrorKind, Result};
pub use dlgs_video::HevcSettings;

/// How key time features are stored.
#[derive(Debug, Clone, PartialEq)]
pub enum FeatureCodec {
    /// Exact f32 (zstd): the lossless interchange form.
    Exact,
    /// Tiled 12-bit images coded with libx265 (the reference's feature video).
    Hevc(HevcSettings),
}

/// How canonical Gaussians are stored.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CanonicalCodec {
    /// `CRAW`: f32, lossless (zstd or not, see `raw_codec`).
    Raw,
    /// `CSOG`: the static set sorted into a grid, every attribute quantised to `bits` and coded
    /// losslessly. The dynamic set keeps its order (its time features are tied to it).
    Sorted { bits: QuantBits, sort: SortSpec },
}

pub use grid_sort::SortSpec;

/// Encoder settings.
#[derive(Debug, Clone)]
pub struct EncoderConfig {
    /// Canonical Gaussians: raw or sorted quantised grids.
    pub canonical: CanonicalCodec,
    /// How `CRAW` bodies are stored.
    pub raw_codec: RawCodec,
    /// zstd level for `CRAW` when `raw_codec` is zstd (1..=22).
    pub zstd_level: i32,
    /// Free-form JSON written as the scene-level `META` chunk (provenance, credits).
    pub meta: Option<serde_json::Value>,
    /// Time-feature coding.
    pub features: FeatureCodec,
    /// One quantisation range for all channels (the reference) instead of one per channel.
    pub per_gop_range: bool,
    /// Storage type of the MLP weights.
    pub mlp_weights: WeightType,
}

impl Default for EncoderConfig {
    fn default() -> Self {
        EncoderConfig {
            canonical: CanonicalCodec::Raw,
            raw_codec: RawCodec::Zstd,
            zstd_level: 9,
            meta: None,
            features: FeatureCodec::Hevc(HevcSettings::default()),
            per_gop_range: false,
            mlp_weights: WeightType::F32,
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

    /// Append the next GOP, coded intra from its canonical Gaussians (static scenes).
    pub fn push_intra_gop(&mut self, canon: &Canonical) -> Result<()> {
        self.push_gop(canon, None)
    }

    /// Append the next GOP: canonical Gaussians plus, when the scene has dynamic Gaussians,
    /// its deformation field.
    pub fn push_gop(&mut self, canon: &Canonical, dynamic: Option<&DynamicGop>) -> Result<()> {
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
        let dyn_chunks = match (s.n_dynamic > 0, dynamic) {
            (false, None) => None,
            (true, Some(d)) => Some(self.dynamic_payloads(d)?),
            (true, None) => {
                return Err(invalid(
                    "the scene has dynamic Gaussians but the GOP has no deformation field".into(),
                ))
            }
            (false, Some(_)) => {
                return Err(invalid(
                    "a deformation field for a scene without dynamic Gaussians".into(),
                ))
            }
        };
        let (ty, payload) = match self.cfg.canonical {
            CanonicalCodec::Raw => (
                ChunkType::CRAW,
                raw_canonical::encode(canon, self.cfg.raw_codec, self.cfg.zstd_level)?,
            ),
            CanonicalCodec::Sorted { bits, sort } => {
                let order = grid_sort::grid_order(&canon.statics, sort);
                let sorted = Canonical {
                    statics: grid_sort::permute(&canon.statics, &order),
                    dynamics: canon.dynamics.clone(),
                };
                (
                    ChunkType::CSOG,
                    sorted_grid::encode(&sorted, &bits, self.cfg.zstd_level)?,
                )
            }
        };
        self.writer.begin_gop()?;
        self.writer.gop_chunk(ty, FLAG_MUST_UNDERSTAND, &payload)?;
        if let Some((tfea, mlpw)) = dyn_chunks {
            self.writer
                .gop_chunk(ChunkType::TFEA, FLAG_MUST_UNDERSTAND, &tfea)?;
            self.writer
                .gop_chunk(ChunkType::MLPW, FLAG_MUST_UNDERSTAND, &mlpw)?;
        }
        Ok(())
    }

    fn dynamic_payloads(&self, d: &DynamicGop) -> Result<(Vec<u8>, Vec<u8>)> {
        let s = self.writer.scene();
        let f = &d.features;
        if f.n != s.n_dynamic as usize
            || f.keys != s.keys_per_gop() as usize
            || f.channels != s.time_channels as usize
            || f.data.len() != f.n * f.keys * f.channels
        {
            return Err(invalid(format!(
                "time features ({}, {}, {}) do not match the scene ({}, {}, {})",
                f.n,
                f.keys,
                f.channels,
                s.n_dynamic,
                s.keys_per_gop(),
                s.time_channels
            )));
        }
        dlgs::model::dynamic::check_finite("time features", &f.data)?;
        d.mlps.validate(s, 0).map_err(|e| invalid(e.to_string()))?;
        let body = match &self.cfg.features {
            FeatureCodec::Exact => TfeaBody::Exact(f.clone()),
            FeatureCodec::Hevc(settings) => {
                let tiling = Tiling::for_count(f.n, f.keys, f.channels);
                let ranges = time_features::ranges(f, self.cfg.per_gop_range);
                let video = dlgs_video::Gray12 {
                    width: tiling.width() as u32,
                    height: tiling.height() as u32,
                    frames: time_features::tile(f, &tiling, &ranges),
                };
                let packets = dlgs_video::encode_gray12(&video, settings)
                    .map_err(|e| invalid(format!("time-feature video: {e}")))?;
                TfeaBody::Hevc {
                    tiling,
                    ranges,
                    packets,
                }
            }
        };
        let tfea = time_features::encode(&body, self.cfg.zstd_level)?;
        let mlpw = mlp_weights::encode(&d.mlps, self.cfg.mlp_weights, self.cfg.zstd_level)?;
        Ok((tfea, mlpw))
    }

    pub fn scene(&self) -> &SceneHeader {
        self.writer.scene()
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

fn invalid(msg: String) -> Error {
    Error::new(ErrorKind::InvalidInput(msg), 0)
}
