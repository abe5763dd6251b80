//! `dlgs-encoder`: turns scene models into `.dlgs` streams.
//!
//! Every GOP carries its canonical state, either in full (raw `CRAW`, or sorted quantised grids
//! `CSOG`) or, in sequential and parallel scenes from GOP 1 on, as a residual against the
//! reference GOP (binary voxel field `RNTC`, or explicit deltas `RDLT` computed closed-loop
//! against what the decoder will reconstruct); and, for dynamic scenes, the key time features
//! (`TFEA`, 12-bit HEVC or exact) and the deformation decoders (`MLPW`).

mod adam;
pub mod bit_allocation;
pub mod colour_refit;
pub mod config;
pub mod grid_sort;
pub mod importance;
pub mod invisible;
pub mod judge_views;
mod mantissa;
pub mod orientation;
pub mod quality_search;
mod refit_stage;
pub mod scaffold;
pub mod scaffold_fit;
pub mod scaffold_prior;
pub mod scaffold_recode;
pub mod sequence;
mod still;
mod stream;
pub mod zero_bands;

pub use config::{
    bounds_like_quantisation, CanonicalCodec, CanonicalSettings, ContainerSettings,
    DynamicSettings, EncoderConfig, FeatureCodec, GopCanonical, LanguageSettings, RefitSettings,
    ResidualConfig, SortSpec, StillTools,
};
pub use dlgs_video::{FastStart, HevcSettings};
pub use refit_stage::RefitReport;
pub use still::{encode_still, encode_still_reporting, prepare_still, StillReport};
pub use stream::StreamEncoder;
