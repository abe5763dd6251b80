//! `dlgs-query`: open-vocabulary queries on `.dlgs` scenes.
//!
//! A query renders the language feature image (dual opacity), decodes every language level
//! to the text-embedding space with the scene's autoencoder decoder (`LAED`, format-spec
//! §6.8), scores each pixel against the positive text embedding and the canonical negatives,
//! and turns the scores into a mask exactly as the reference evaluation does (29x29 mean
//! filter, min-max normalisation, `2o-1` clamp, threshold 0.4, 7x7 smoothing, level chosen by
//! the mean filtered relevance inside the mask). The same scores per Gaussian give a 3D
//! selection. Nothing here runs unless a query asks for it.

pub mod batch_decode;
pub mod decoder_io;
pub mod embeddings;
pub mod error;
pub mod images;
pub mod mask;
pub mod relevance;
pub mod select;

pub use embeddings::{read_embeddings, Embeddings};
pub use error::QueryError;
pub use mask::{query_levels, ImageQuery, MaskParams};
pub use relevance::{Precision, RelevanceField};
pub use select::{select_gaussians, Selection};
