//! The range decoder of codec 5 and of octree positions (format-spec §6.5.3, §6.5.5),
//! specialised for the two models those streams use: a binary split at a 16-bit probability
//! and `2^k` equally likely values. It reads exactly the streams `constriction`'s
//! `DefaultRangeEncoder` writes (32-bit words, 64-bit state) and returns exactly what
//! `constriction`'s `DefaultRangeDecoder` returns for them, symbol by symbol and error by error
//! (test `agrees_with_constriction_on_any_words`); it is only faster.
//!
//! Why: those streams code every value bit by bit, tens of millions of binary decisions for a
//! large scene, and the generic decoder divides by the range's scale at each one. For a binary
//! split the quotient is only compared with the probability, and `floor(d / s) < p` is
//! `d < p * s`: a multiplication in place of a 64-bit division.

/// Probability precision of both models (`constriction`'s `PRECISION`).
const PRECISION: u32 = 16;
/// Renormalise when the range falls below this: one 32-bit word of the 64-bit state.
const RENORMALISE_BELOW: u64 = 1 << 32;

/// The data is not a stream this decoder can continue: `constriction` would report
/// `InvalidData` at the same symbol.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InvalidData;

pub struct BinaryRangeDecoder {
    words: Vec<u32>,
    /// The next word to read.
    next: usize,
    lower: u64,
    /// Never zero: the models give every symbol a non-zero width.
    range: u64,
    /// Invariant: `point - lower < range` (wrapping).
    point: u64,
    /// Whether a step of [`Self::binary_deferred`] met an invalid state.
    invalid: bool,
}

impl BinaryRangeDecoder {
    /// A decoder over `words`, the whole stream. The state starts as the first two words, the
    /// first in the high half; a shorter stream is padded with zero bits.
    pub fn new(words: Vec<u32>) -> BinaryRangeDecoder {
        let mut point = 0u64;
        let first = words.len().min(2);
        for &w in &words[..first] {
            point = (point << 32) | w as u64;
        }
        if first == 1 {
            point <<= 32;
        }
        BinaryRangeDecoder {
            words,
            next: first,
            lower: 0,
            range: u64::MAX,
            point,
            invalid: false,
        }
    }

    /// The next bit, `false` with probability `p0 / 2^16`; `p0` must be in `[1, 2^16 - 1]`.
    #[inline]
    pub fn binary(&mut self, p0: u32) -> Result<bool, InvalidData> {
        debug_assert!(p0 > 0 && p0 < 1 << PRECISION);
        let scale = self.range >> PRECISION;
        let offset = self.point.wrapping_sub(self.lower);
        // `constriction` rejects a quantile `offset / scale` of 2^16 or more.
        if offset >= scale << PRECISION {
            return Err(InvalidData);
        }
        Ok(self.split::<PRECISION>(scale, offset, p0))
    }

    /// The step shared by the binary models at precision `P`, after the caller's check of
    /// `offset` against `scale << P`: the bit, and the range narrowed to its side.
    #[inline(always)]
    fn split<const P: u32>(&mut self, scale: u64, offset: u64, p0: u32) -> bool {
        let split = scale * p0 as u64;
        let bit = offset >= split;
        // Branch-free: the bit is as unpredictable as the data is compressed, and a
        // mispredicted branch costs more than computing both sides.
        let ones = (bit as u64).wrapping_neg();
        self.lower = self.lower.wrapping_add(split & ones);
        let range_if_one = (scale << P) - split;
        self.range = split ^ ((split ^ range_if_one) & ones);
        self.renormalise();
        bit
    }

    /// [`Self::binary`] for a loop that checks for errors once, at its end ([`Self::failed`]):
    /// where `binary` returns an error, this marks the stream failed and goes on with some
    /// bit (the range stays non-zero, so nothing can panic or loop), saving a branch and an
    /// error path in every step of a hot loop. The bits up to the first failure are those of
    /// `binary`.
    #[inline(always)]
    pub fn binary_deferred(&mut self, p0: u32) -> bool {
        debug_assert!(p0 > 0 && p0 < 1 << PRECISION);
        let scale = self.range >> PRECISION;
        let offset = self.point.wrapping_sub(self.lower);
        self.invalid |= offset >= scale << PRECISION;
        self.split::<PRECISION>(scale, offset, p0)
    }

    /// Whether a step of [`Self::binary_deferred`] failed: `binary` would have returned an
    /// error at that step or before.
    pub fn failed(&self) -> bool {
        self.invalid
    }

    /// The next bit of a two-symbol categorical model at precision 24 (`RNTC` segments,
    /// `AHAC` grids: §6.6.3), `false` with probability `p0 / 2^24`, `p0` in `[1, 2^24 - 1]`:
    /// what `constriction`'s generic decoder returns for that model, without its division.
    #[inline]
    pub fn binary24(&mut self, p0: u32) -> Result<bool, InvalidData> {
        const P: u32 = 24;
        debug_assert!(p0 > 0 && p0 < 1 << P);
        let scale = self.range >> P;
        let offset = self.point.wrapping_sub(self.lower);
        if offset >= scale << P {
            return Err(InvalidData);
        }
        Ok(self.split::<P>(scale, offset, p0))
    }

    /// A value of `k` bits, `1 <= k <= 16`, each of the `2^k` equally likely.
    #[inline]
    pub fn uniform(&mut self, k: u32) -> Result<u32, InvalidData> {
        debug_assert!((1..=PRECISION).contains(&k));
        let scale = self.range >> PRECISION;
        let quantile = self.point.wrapping_sub(self.lower) / scale;
        if quantile >= 1 << PRECISION {
            return Err(InvalidData);
        }
        let shift = PRECISION - k;
        let v = (quantile >> shift) as u32;
        self.lower = self.lower.wrapping_add(scale * ((v as u64) << shift));
        self.range = scale << shift;
        self.renormalise();
        Ok(v)
    }

    #[inline(always)]
    fn renormalise(&mut self) {
        if self.range < RENORMALISE_BELOW {
            self.lower <<= 32;
            self.range <<= 32;
            self.point <<= 32;
            if let Some(&w) = self.words.get(self.next) {
                self.point |= w as u64;
                self.next += 1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use constriction::stream::model::{DecoderModel, EntropyModel};
    use constriction::stream::queue::{DefaultRangeDecoder, DefaultRangeEncoder};
    use constriction::stream::{Decode, Encode};
    use std::num::NonZeroU32;

    /// The reference: `constriction`'s generic coder with the two models spelled out, both
    /// directions.
    struct Split(u32);
    impl EntropyModel<16> for Split {
        type Symbol = bool;
        type Probability = u32;
    }
    impl DecoderModel<16> for Split {
        fn quantile_function(&self, q: u32) -> (bool, u32, NonZeroU32) {
            if q < self.0 {
                (false, 0, NonZeroU32::new(self.0).unwrap())
            } else {
                (true, self.0, NonZeroU32::new((1 << 16) - self.0).unwrap())
            }
        }
    }
    impl constriction::stream::model::EncoderModel<16> for Split {
        fn left_cumulative_and_probability(
            &self,
            s: impl std::borrow::Borrow<bool>,
        ) -> Option<(u32, NonZeroU32)> {
            if *s.borrow() {
                Some((self.0, NonZeroU32::new((1 << 16) - self.0)?))
            } else {
                Some((0, NonZeroU32::new(self.0)?))
            }
        }
    }
    struct Flat(u32);
    impl EntropyModel<16> for Flat {
        type Symbol = u32;
        type Probability = u32;
    }
    impl DecoderModel<16> for Flat {
        fn quantile_function(&self, q: u32) -> (u32, u32, NonZeroU32) {
            let shift = 16 - self.0;
            let v = q >> shift;
            (v, v << shift, NonZeroU32::new(1 << shift).unwrap())
        }
    }
    impl constriction::stream::model::EncoderModel<16> for Flat {
        fn left_cumulative_and_probability(
            &self,
            s: impl std::borrow::Borrow<u32>,
        ) -> Option<(u32, NonZeroU32)> {
            let shift = 16 - self.0;
            Some((*s.borrow() << shift, NonZeroU32::new(1 << shift)?))
        }
    }

    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            self.0
        }
    }

    /// One random step: a binary split (mostly skewed, as adaptive models are) or a uniform
    /// value.
    enum Step {
        Binary(u32),
        Uniform(u32),
    }
    fn step(rng: &mut Rng) -> Step {
        match rng.next() % 8 {
            0 => Step::Uniform(1 + (rng.next() % 16) as u32),
            1 => Step::Binary(1 + (rng.next() % 65535) as u32),
            2 => Step::Binary(if rng.next().is_multiple_of(2) {
                1
            } else {
                65535
            }),
            _ => Step::Binary(32 + (rng.next() % 65472) as u32),
        }
    }

    /// Both decoders over the same words and steps: the same symbols, and an error at the same
    /// step if any; whether they stopped at an error.
    fn agree(words: Vec<u32>, seed: u64, steps: usize) -> bool {
        let mut ours = BinaryRangeDecoder::new(words.clone());
        let mut theirs = DefaultRangeDecoder::from_compressed(words).unwrap();
        let mut rng = Rng(seed);
        for i in 0..steps {
            let (a, b) = match step(&mut rng) {
                Step::Binary(p0) => (
                    ours.binary(p0).map(|b| b as u32),
                    theirs.decode_symbol(Split(p0)).map(|b| b as u32),
                ),
                Step::Uniform(k) => (ours.uniform(k), theirs.decode_symbol(Flat(k))),
            };
            match (a, b) {
                (Ok(x), Ok(y)) => assert_eq!(x, y, "step {i}"),
                (Err(_), Err(_)) => return true,
                (a, b) => panic!("step {i}: ours {a:?}, constriction's {b:?}"),
            }
        }
        false
    }

    #[test]
    fn agrees_with_constriction_on_any_words() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let mut stopped = 0;
        for case in 0..3000u64 {
            let len = (rng.next() % 12) as usize;
            let words: Vec<u32> = (0..len)
                .map(|_| match rng.next() % 4 {
                    0 => 0,
                    1 => u32::MAX,
                    _ => rng.next() as u32,
                })
                .collect();
            stopped += agree(words, case + 1, 400) as usize;
        }
        // Garbage words end in an error now and then (both decoders at the same symbol), and
        // most decode all 400 symbols.
        assert!(
            (30..1500).contains(&stopped),
            "{stopped} of 3000 stopped at an error"
        );
    }

    #[test]
    fn decodes_what_constriction_encodes() {
        let mut rng = Rng(7);
        for case in 0..200u64 {
            // Encode a random sequence of steps with random symbols, decode it with ours.
            let mut enc = DefaultRangeEncoder::new();
            let mut plan = Vec::new();
            let mut steps = Rng(case + 11);
            for _ in 0..(rng.next() % 3000) {
                match step(&mut steps) {
                    Step::Binary(p0) => {
                        let bit = (rng.next() % 65536) as u32 >= p0;
                        enc.encode_symbol(bit, Split(p0)).unwrap();
                        plan.push((Step::Binary(p0), bit as u32));
                    }
                    Step::Uniform(k) => {
                        let v = (rng.next() % (1 << k)) as u32;
                        enc.encode_symbol(v, Flat(k)).unwrap();
                        plan.push((Step::Uniform(k), v));
                    }
                }
            }
            let mut dec = BinaryRangeDecoder::new(enc.into_compressed().unwrap());
            for (i, (s, want)) in plan.into_iter().enumerate() {
                let got = match s {
                    Step::Binary(p0) => dec.binary(p0).map(|b| b as u32),
                    Step::Uniform(k) => dec.uniform(k),
                };
                assert_eq!(got, Ok(want), "case {case} symbol {i}");
            }
        }
    }
}
