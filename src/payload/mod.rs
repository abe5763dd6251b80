//! Payload codecs of the chunk types the container carries (format-spec §6 onwards).

pub mod grid_coder;
pub mod mlp_weights;
pub mod raw_canonical;
pub mod sorted_grid;
pub mod time_features;
