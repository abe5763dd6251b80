//! The in-memory scene model.

pub mod dynamic;
pub mod gaussians;
pub mod hac_cdf;
pub mod hac_context;
pub mod lang_decoder;
pub mod lifetimes;
pub mod ntc;
mod ntc_config;
mod ntc_lanes;
mod phi_table;
pub mod residual;
pub mod scaffold;

pub use dynamic::{DeformMlps, DynamicGop, Layer, Mlp, MlpRole, TimeFeatures, TimePoint};
pub use gaussians::{sh_coeffs, sigmoid, Canonical, Gaussians};
pub use lifetimes::{Life, Lifetimes};
