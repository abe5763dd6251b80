//! A read reference run to a `.dlgs` stream: GOP 0's canonical state as a canonical chunk,
//! later GOPs as residuals against the previous GOP's decoded state (sequential mode, as the
//! reference accumulates), the time-feature video's own HEVC access units passed through
//! (`TFEA` codec 2: the reference's dequantisation, so features decode bit for bit), the
//! decoders as `MLPW`.

use std::io::Write;

use dlgs::chunks::tfea::{TfeaBody, Tiling};
use dlgs::container::header::{DeformModel, ResidualMode, Variant};
use dlgs::model::DynamicGop;
use dlgs::{Canonical, SceneHeader};
use dlgs_encoder::{EncoderConfig, FeatureCodec, GopCanonical, StreamEncoder};

use crate::run::{FeatureSource, RefGop, CHANNELS, KEYS};
use crate::IngestError;

/// The reference's GOP: 60 frames with a key every 10 (`time_line`, `interval`).
pub const GOP_LENGTH: u32 = 60;
pub const KEY_INTERVAL: u32 = 10;

/// The scene header of a run (`fps`: the capture rate; the reference's N3DV videos are 30).
pub fn scene_header(gops: &[RefGop], fps: u32) -> Result<SceneHeader, IngestError> {
    let first = gops
        .first()
        .ok_or_else(|| IngestError::format("run", "no GOP folders"))?;
    let lang = first.statics.lang_width > 0;
    Ok(SceneHeader {
        variant: Variant::Gaussians3d,
        residual_mode: if gops.len() > 1 {
            ResidualMode::Sequential
        } else {
            ResidualMode::Intra
        },
        deform_model: DeformModel::Reference,
        sh_degree: first.statics.sh_degree,
        lang_levels: if lang { 3 } else { 0 },
        lang_dims: if lang { 3 } else { 0 },
        time_channels: CHANNELS as u8,
        fps_num: fps,
        fps_den: 1,
        gop_length: GOP_LENGTH,
        key_interval: KEY_INTERVAL,
        gop_count: gops.len() as u32,
        frame_count: gops.len() as u32 * GOP_LENGTH,
        n_static: first.statics.len() as u32,
        n_dynamic: first.dynamics.len() as u32,
        refresh_interval: 0,
    })
}

/// Encode the run. `cfg` chooses the canonical and residual coding (lossless `CRAW` and exact
/// residuals by default); the feature video is passed through unless `cfg.features` asks for
/// exact features (then features are stored as the f32 the reference decodes).
pub fn encode<W: Write>(
    gops: &[RefGop],
    fps: u32,
    cfg: EncoderConfig,
    out: W,
    mut progress: impl FnMut(usize),
) -> Result<W, IngestError> {
    let scene = scene_header(gops, fps)?;
    let pass_through = matches!(cfg.dynamic.features, FeatureCodec::Hevc(_));
    let mut enc = StreamEncoder::new(out, scene, cfg)?;
    for (g, gop) in gops.iter().enumerate() {
        if gop.statics.len() != gops[0].statics.len()
            || gop.dynamics.len() != gops[0].dynamics.len()
        {
            return Err(IngestError::shape(
                &gop.dir.display().to_string(),
                "Gaussian counts change between GOPs (the reference freezes them after GOP 0)",
            ));
        }
        let canonical = Canonical {
            statics: gop.statics.clone(),
            dynamics: gop.dynamics.clone(),
        };
        let dynamic = DynamicGop {
            features: gop.features.clone(),
            mlps: gop.mlps.clone(),
            life: None,
        };
        let coded = match (&gop.feature_source, pass_through) {
            (
                FeatureSource::Video {
                    packets,
                    side,
                    range,
                },
                true,
            ) => Some(TfeaBody::Hevc {
                tiling: Tiling {
                    n: gop.dynamics.len(),
                    keys: KEYS,
                    channels: CHANNELS,
                    side: *side,
                },
                ranges: vec![],
                reference: Some(*range),
                packets: packets.clone(),
                intra: false,
            }),
            _ => None,
        };
        enc.push_coded(
            GopCanonical::State(&canonical),
            Some(&dynamic),
            coded.as_ref(),
        )?;
        progress(g);
    }
    Ok(enc.finish()?)
}

/// Bytes per GOP: the reference's counted files, those plus what it forgets (`mlp_lang.pth`),
/// and the `.dlgs` GOP (its share of the scene-level chunks spread evenly over GOPs).
#[derive(Debug, Clone, PartialEq)]
pub struct GopBytes {
    pub reference_counted: u64,
    pub reference_with_lang_mlp: u64,
    pub dlgs: f64,
}

pub fn byte_report(gops: &[RefGop], file: &[u8]) -> Result<Vec<GopBytes>, IngestError> {
    let reader = dlgs::FileReader::open(std::io::Cursor::new(file))?;
    let entries = &reader.index().entries;
    let in_gops: u64 = entries.iter().map(|e| e.length).sum();
    let overhead = (file.len() as u64 - in_gops) as f64 / gops.len().max(1) as f64;
    Ok(gops
        .iter()
        .zip(entries)
        .map(|(g, e)| GopBytes {
            reference_counted: g.files.iter().filter(|f| f.counted).map(|f| f.bytes).sum(),
            reference_with_lang_mlp: g.files.iter().map(|f| f.bytes).sum(),
            dlgs: e.length as f64 + overhead,
        })
        .collect())
}
