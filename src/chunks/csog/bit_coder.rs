//! The adaptive binary models of grid codec 5 (format-spec §6.5.3) and the octree positions,
//! and the two directions of their range coder: [`BitCoder`] codes a bit (or a uniform value)
//! with a model's probability, [`Encoder`] writes it, [`Decoder`] reads it back, so the walks
//! over cells and nodes are written once for both directions.

use crate::container::ChunkType;
use crate::Error;
use std::borrow::Borrow;
use std::num::NonZeroU32;

use constriction::stream::model::{EncoderModel, EntropyModel};
use constriction::stream::queue::DefaultRangeEncoder;
use constriction::stream::Encode;

use super::cells::read_words;
use crate::bytes::ByteReader;
use crate::entropy::binary_range_decoder::BinaryRangeDecoder;
use crate::error::Result;

/// Probability precision of the binary models.
const PRECISION: usize = 16;
pub(super) const ONE: u32 = 1 << PRECISION;
/// Probabilities stay in `[P_MIN, ONE - P_MIN]`.
pub(super) const P_MIN: u32 = 32;
/// Slowest adaptation: a model moves `1/2^MAX_SHIFT` of the way to each new bit.
const MAX_SHIFT: u32 = 6;

/// An adaptive binary model: `p` = probability of a 0 bit in units of `2^-16`, and how many
/// bits it has seen (its adaptation is fast at first, then settles at `1/64`).
#[derive(Clone, Copy)]
pub(crate) struct Adaptive {
    pub(super) p: u16,
    seen: u8,
}

impl Adaptive {
    pub(crate) const NEW: Adaptive = Adaptive {
        p: (ONE / 2) as u16,
        seen: 0,
    };

    /// The probability of a 0 bit, in units of `2^-16`.
    #[inline(always)]
    pub(super) fn p(self) -> u32 {
        self.p as u32
    }

    #[inline(always)]
    pub(super) fn update(&mut self, bit: bool) {
        let shift = (self.seen as u32 + 1).min(MAX_SHIFT);
        let p = self.p as u32;
        // Both sides, then a select: the bit is unpredictable, so a branch would often miss.
        let down = p - (p >> shift);
        let up = p + ((ONE - p) >> shift);
        let p = if bit { down } else { up };
        self.p = p.clamp(P_MIN, ONE - P_MIN) as u16;
        self.seen = self.seen.saturating_add(1);
    }
}

/// A two-symbol model for constriction's range encoder: `false` takes `[0, p0)`
/// ([`BinaryRangeDecoder::binary`] reads it back).
struct Binary {
    p0: u32,
}

impl EntropyModel<PRECISION> for Binary {
    type Symbol = bool;
    type Probability = u32;
}

impl EncoderModel<PRECISION> for Binary {
    fn left_cumulative_and_probability(
        &self,
        symbol: impl Borrow<bool>,
    ) -> Option<(u32, NonZeroU32)> {
        if *symbol.borrow() {
            Some((self.p0, NonZeroU32::new(ONE - self.p0)?))
        } else {
            Some((0, NonZeroU32::new(self.p0)?))
        }
    }
}

/// One direction of the coder: the encoder codes `bit` and returns it; the decoder ignores it
/// and returns the decoded bit.
pub(crate) trait BitCoder {
    /// Code `bit` with the probability `p0` (units of `2^-16`, in `[P_MIN, ONE - P_MIN]`) of
    /// a 0 bit; no model learns from it.
    fn code_p(&mut self, p0: u32, bit: bool) -> Result<bool>;
    /// Code `bit` with model `m`'s probability, then let `m` learn it.
    #[inline(always)]
    fn code(&mut self, m: &mut Adaptive, bit: bool) -> Result<bool> {
        let bit = self.code_p(m.p as u32, bit)?;
        m.update(bit);
        Ok(bit)
    }
    /// A bit with probability 1/2 and no model.
    fn raw(&mut self, bit: bool) -> Result<bool> {
        let mut fresh = Adaptive::NEW;
        self.code(&mut fresh, bit)
    }
    /// The `k <= 16` low bits of `value` as one symbol, each of the `2^k` equally likely
    /// (nothing for `k = 0`): what `k` raw bits carry, in one coder step.
    fn uniform(&mut self, value: u32, k: u8) -> Result<u32>;
}

/// `2^k` equally likely values at the binary models' precision: value `v` takes
/// `[v 2^(16-k), (v + 1) 2^(16-k))` of the range.
struct Uniform {
    k: u8,
}

impl EntropyModel<PRECISION> for Uniform {
    type Symbol = u32;
    type Probability = u32;
}

impl EncoderModel<PRECISION> for Uniform {
    fn left_cumulative_and_probability(
        &self,
        symbol: impl Borrow<u32>,
    ) -> Option<(u32, NonZeroU32)> {
        let v = *symbol.borrow();
        let shift = PRECISION as u32 - self.k as u32;
        (v >> self.k == 0).then(|| (v << shift, NonZeroU32::new(1 << shift).expect("k <= 16")))
    }
}

pub(crate) struct Encoder(pub(crate) DefaultRangeEncoder);

impl BitCoder for Encoder {
    fn code_p(&mut self, p0: u32, bit: bool) -> Result<bool> {
        self.0
            .encode_symbol(bit, Binary { p0 })
            .expect("a bool is inside a binary model");
        Ok(bit)
    }

    fn uniform(&mut self, value: u32, k: u8) -> Result<u32> {
        assert!(k <= PRECISION as u8, "at most 16 bits in one symbol");
        if k > 0 {
            let v = value & ((1u32 << k) - 1);
            self.0
                .encode_symbol(v, Uniform { k })
                .expect("the value fits its bits");
        }
        Ok(value & ((1u32 << k) - 1))
    }
}

pub(crate) struct Decoder<'a> {
    pub(crate) dec: BinaryRangeDecoder,
    pub(crate) r: &'a ByteReader<'a>,
}

impl BitCoder for Decoder<'_> {
    #[inline(always)]
    fn code_p(&mut self, p0: u32, _: bool) -> Result<bool> {
        match self.dec.binary(p0) {
            Ok(bit) => Ok(bit),
            Err(_) => Err(ended_early(self.r)),
        }
    }

    #[inline]
    fn uniform(&mut self, _: u32, k: u8) -> Result<u32> {
        if k == 0 {
            return Ok(0);
        }
        let k = k.min(PRECISION as u8);
        self.dec.uniform(k as u32).map_err(|_| ended_early(self.r))
    }
}

/// The error of a stream that the range decoder cannot continue (out of the hot loops).
#[cold]
#[inline(never)]
pub(super) fn ended_early(r: &ByteReader) -> Error {
    Error::payload(
        ChunkType::CSOG,
        "range coder stream ended early",
        r.offset(),
    )
}

/// The range decoder of a stream that fills the rest of `r`: a word count, the words, and
/// nothing after them (`what` names the stream in errors).
pub(crate) fn open_stream(r: &mut ByteReader, what: &str) -> Result<BinaryRangeDecoder> {
    let words = read_words(r)?;
    if r.remaining() != 0 {
        return Err(Error::payload(
            ChunkType::CSOG,
            format!("{} bytes after the {what} stream", r.remaining()),
            r.offset(),
        ));
    }
    Ok(BinaryRangeDecoder::new(words))
}
