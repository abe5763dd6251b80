//! Ingest of the DLGStream reference implementation's trained outputs (its "fdsd" / 3DGS
//! variant): the per-GOP `jxl_quant` folders with JPEG XL attribute images, the 12-bit HEVC
//! time-feature video, `compression_info.csv`, the `mlp_*.pth` decoders and, from GOP 1 on,
//! `offset_compressed.pkl` (torchac-coded latent residuals); or, for GOP folders without them,
//! the `model.pth` / `model_offset.pth` checkpoints ([`checkpoint`]).
//! [`run::read_run`] turns them into the tensors the reference's decoder produces, and
//! [`convert`] into a `.dlgs` stream that decodes to the same model.

pub mod checkpoint;
pub mod convert;
pub mod csv;
pub mod hac;
pub mod hac_mlps;
pub mod jxl;
pub mod latents;
pub mod pickle;
pub mod ref_gop;
pub mod run;
pub mod torch;

use std::path::PathBuf;

/// What went wrong reading a reference run, naming the file (and what in it).
#[derive(Debug, thiserror::Error)]
pub enum IngestError {
    #[error("{path}: missing ({what})")]
    Missing { path: PathBuf, what: String },
    #[error("{what}: {reason}")]
    Format { what: String, reason: String },
    #[error("{what}: wrong shape: {reason}")]
    Shape { what: String, reason: String },
    #[error("{what}: value {index} is not finite ({value})")]
    NonFinite {
        what: String,
        index: usize,
        value: f32,
    },
    #[error("{what}: {source}")]
    Io {
        what: String,
        #[source]
        source: std::io::Error,
    },
    #[error(transparent)]
    Dlgs(#[from] dlgs::Error),
}

impl IngestError {
    pub fn format(what: &str, reason: impl Into<String>) -> Self {
        IngestError::Format {
            what: what.to_string(),
            reason: reason.into(),
        }
    }
    pub fn shape(what: &str, reason: impl Into<String>) -> Self {
        IngestError::Shape {
            what: what.to_string(),
            reason: reason.into(),
        }
    }
}

/// Refuse NaN/Inf with the first offending index (the encoder never writes them).
pub fn check_finite(what: &str, v: &[f32]) -> Result<(), IngestError> {
    match v.iter().position(|x| !x.is_finite()) {
        Some(index) => Err(IngestError::NonFinite {
            what: what.to_string(),
            index,
            value: v[index],
        }),
        None => Ok(()),
    }
}
