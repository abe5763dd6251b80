//! The in-memory scene model.

pub mod gaussians;

pub use gaussians::{sh_coeffs, Canonical, Gaussians};
