//! Payload codecs of the chunk types the container carries (format-spec §6 onwards).

pub mod raw_canonical;
