//! The encoder facade of `CSOG`: what a writer, a conformance-vector generator or a bench
//! needs beyond [`encode`](super::encode) and [`decode`](super::decode), and nothing more.
//!
//! - The lossless grid codecs of §6.5.3-§6.5.5, one channel at a time: [`encode_best`] tries
//!   every codec and keeps the smallest (within [`MIXED_MARGIN`] of the best dependent choice),
//!   [`decode`] reverses any of them; the single codecs ([`encode_zstd`], [`encode_histogram`],
//!   [`adaptive_encode`]) exist so that vectors can pin each path.
//! - [`delta`] / [`undo_delta`]: the modular difference to a previous channel (§6.5.3).
//! - The kd layout of §6.5.7 that the encoder's grid sort follows ([`valid_in`], [`halves`],
//!   [`first_valid`]), and how far grid shaping may move a level ([`MAX_MOVE`]).
//! - [`colour_lattice_range`]: the range that puts 8-bit colours on exact levels (§6.5.2).
//!
//! The coders' internals (contexts, models, the octree, the mixer) are private to the crate.

pub use super::adaptive_coder::{
    decode as adaptive_decode, encode as adaptive_encode, Mode as AdaptiveMode, Previous,
};
pub use super::colour_lattice::range as colour_lattice_range;
pub use super::grid_coder::{
    decode, delta, encode_best, encode_best_tabled, encode_histogram, encode_zstd, undo_delta,
    GridCodec, MIXED_MARGIN,
};
pub use super::grid_shaping::MAX_MOVE;
pub use super::kd_layout::{first_valid, halves, valid_in};
