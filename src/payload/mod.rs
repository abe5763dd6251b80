//! Payload codecs of the chunk types the container carries (format-spec §6 onwards).

pub mod mlp_weights;
pub mod raw_canonical;
pub mod time_features;
