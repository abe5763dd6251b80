//! Entropy coders shared by several chunk types: bits with their +1 frequency (`RNTC`, octree
//! flags), the binary range decoder's fast path, and the context mixer of `CSOG` codec 5
//! (format-spec §6.5.3, §6.6.3, Appendix A).

pub mod binary_bits;
pub(crate) mod binary_range_decoder;
pub(crate) mod bit_mixer;
