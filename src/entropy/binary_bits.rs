//! Entropy coding of binary grids with the stored frequency of +1 (format-spec §6.6.2).
//!
//! A segment (one plane level, or the gate grid) is coded on its own, so segments decode in
//! parallel. The probability of a 1 bit comes from a stored count of ones: the segment's own
//! count, or the sum over its whole grid, whichever the encoder measured smaller. A segment whose
//! bits are all equal codes to zero bytes. The coder is `constriction`'s range coder with a
//! two-symbol model at 24-bit precision.

use bitvec::prelude::*;

/// The storage word of every bit vector (`planes`, `gate`, hash-grid `levels`): `u64` where
/// bitvec has it (64-bit targets), `u32` on 32-bit ones such as wasm32 (bitvec implements
/// `BitStore` for `u64` only when pointers are 64 bits). Same bits either way (Lsb0).
#[cfg(target_pointer_width = "64")]
pub type BitWord = u64;
#[cfg(not(target_pointer_width = "64"))]
pub type BitWord = u32;
const WORD_BITS: usize = BitWord::BITS as usize;
use constriction::stream::model::ContiguousCategoricalEntropyModel;
use constriction::stream::queue::DefaultRangeEncoder;
use constriction::stream::Encode;

/// Probability precision of the two-symbol model.
pub const PRECISION: usize = 24;
type Model = ContiguousCategoricalEntropyModel<u32, Vec<u32>, PRECISION>;

/// Fixed-point probability of a 1 bit for `ones` of `n`, kept inside (0, 2^24).
pub fn probability_of_one(ones: u64, n: u64) -> u32 {
    let one = 1u64 << PRECISION;
    let p = (ones as u128 * one as u128 + n as u128 / 2) / (n.max(1) as u128);
    (p as u64).clamp(1, one - 1) as u32
}

fn model(p1: u32) -> Model {
    let p0 = (1u32 << PRECISION) - p1;
    Model::from_nonzero_fixed_point_probabilities([p0, p1], false)
        .expect("p0, p1 >= 1 and sum to 2^24")
}

/// Range-code `bits` with probability `p1` (from [`probability_of_one`]) into 32-bit words.
pub fn encode(bits: &BitSlice<BitWord, Lsb0>, p1: u32) -> Vec<u32> {
    let m = model(p1);
    let mut enc = DefaultRangeEncoder::new();
    enc.encode_iid_symbols(bits.iter().by_vals().map(usize::from), &m)
        .expect("symbols 0 and 1 are in the model");
    enc.into_compressed().expect("in-memory backend")
}

/// Decode `n` bits; `None` if the words are not a valid stream for this model. The decoder of
/// Appendix A specialised to the two-symbol model (`BinaryRangeDecoder::binary24`); the same
/// bits and errors as `constriction`'s (test `fast_decode_agrees_with_constriction`).
pub fn decode(words: Vec<u32>, n: usize, p1: u32) -> Option<BitVec<BitWord, Lsb0>> {
    let p0 = (1u32 << PRECISION) - p1;
    let mut dec = super::binary_range_decoder::BinaryRangeDecoder::new(words);
    let mut raw = vec![0 as BitWord; n.div_ceil(WORD_BITS)];
    for i in 0..n {
        raw[i / WORD_BITS] |= (dec.binary24(p0).ok()? as BitWord) << (i % WORD_BITS);
    }
    let mut out = BitVec::from_vec(raw);
    out.truncate(n);
    Some(out)
}

/// [`decode`] with `constriction`'s generic decoder (the reference for the test).
#[cfg(test)]
fn decode_constriction(words: Vec<u32>, n: usize, p1: u32) -> Option<BitVec<BitWord, Lsb0>> {
    use constriction::stream::queue::DefaultRangeDecoder;
    use constriction::stream::Decode;
    let m = model(p1);
    let mut dec = DefaultRangeDecoder::from_compressed(words).ok()?;
    // Assemble whole words instead of pushing bit by bit.
    let mut raw = vec![0 as BitWord; n.div_ceil(WORD_BITS)];
    for (i, s) in dec.decode_iid_symbols(n, &m).enumerate() {
        raw[i / WORD_BITS] |= (s.ok()? as BitWord) << (i % WORD_BITS);
    }
    let mut out = BitVec::from_vec(raw);
    out.truncate(n);
    Some(out)
}

/// Per segment probability of a 1 bit (§6.6.3, §6.13.4): with `groups` `None` each segment's
/// own count of ones over its own size; with `Some(g)` the counts and sizes summed over every
/// segment of the same group label `g[i]`.
pub fn segment_probabilities(ones: &[u64], lens: &[usize], groups: Option<&[u8]>) -> Vec<u32> {
    match groups {
        None => ones
            .iter()
            .zip(lens)
            .map(|(&o, &n)| probability_of_one(o, n as u64))
            .collect(),
        Some(g) => (0..ones.len())
            .map(|i| {
                let same = (0..ones.len()).filter(|&j| g[j] == g[i]);
                let o: u64 = same.clone().map(|j| ones[j]).sum();
                let n: u64 = same.map(|j| lens[j] as u64).sum();
                probability_of_one(o, n)
            })
            .collect(),
    }
}

/// Code every segment with the probabilities of [`segment_probabilities`]; a constant segment
/// (all 0 or all 1) codes to no words. Segments are coded in parallel.
pub fn encode_segments(
    segs: &[&BitSlice<BitWord, Lsb0>],
    ones: &[u64],
    groups: Option<&[u8]>,
) -> Vec<Vec<u32>> {
    use rayon::prelude::*;
    let lens: Vec<usize> = segs.iter().map(|s| s.len()).collect();
    let p = segment_probabilities(ones, &lens, groups);
    segs.par_iter()
        .enumerate()
        .map(|(i, s)| {
            if ones[i] == 0 || ones[i] == lens[i] as u64 {
                Vec::new()
            } else {
                encode(s, p[i])
            }
        })
        .collect()
}

/// Decode one segment of `n` bits holding `ones` 1 bits with probability `p1` (the rules of
/// §6.6.3: constant segments have no words; the decoded count of ones must match).
pub fn decode_segment(
    words: &[u8],
    n: usize,
    ones: u64,
    p1: u32,
) -> std::result::Result<BitVec<BitWord, Lsb0>, String> {
    if ones == 0 || ones == n as u64 {
        return Ok(BitVec::repeat(ones != 0, n));
    }
    let w = words
        .chunks_exact(4)
        .map(|w| u32::from_le_bytes(w.try_into().expect("4 bytes")))
        .collect();
    let bits = decode(w, n, p1).ok_or("invalid range-coder stream")?;
    if bits.count_ones() as u64 != ones {
        return Err(format!(
            "decodes to {} ones, {ones} stored",
            bits.count_ones()
        ));
    }
    Ok(bits)
}

/// Shannon bound `n * H(ones / n)` in bits.
#[allow(clippy::disallowed_methods)] // an encoder report, not decoded data
pub fn entropy_bits(ones: u64, n: u64) -> f64 {
    if ones == 0 || ones == n {
        return 0.0;
    }
    let p = ones as f64 / n as f64;
    -(n as f64) * (p * p.log2() + (1.0 - p) * (1.0 - p).log2())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_decode_agrees_with_constriction() {
        let mut rng = fastrand::Rng::with_seed(17);
        let mut errors = 0;
        for case in 0..4000 {
            let p1 = match case % 4 {
                0 => 1,
                1 => (1 << PRECISION) - 1,
                _ => rng.u32(1..1 << PRECISION),
            };
            let n = rng.usize(0..300);
            let words: Vec<u32> = if case % 2 == 0 {
                (0..rng.usize(0..12))
                    .map(|_| match rng.u8(0..4) {
                        0 => 0,
                        1 => u32::MAX,
                        _ => rng.u32(..),
                    })
                    .collect()
            } else {
                let bits: BitVec<BitWord, Lsb0> = (0..n).map(|_| rng.bool()).collect();
                encode(&bits, p1)
            };
            let a = decode(words.clone(), n, p1);
            errors += a.is_none() as usize;
            assert_eq!(a, decode_constriction(words, n, p1), "case {case}");
        }
        assert!(errors > 10, "{errors} garbage streams stopped at an error");
    }

    #[test]
    fn round_trip_near_entropy() {
        let mut rng = fastrand::Rng::with_seed(7);
        for p in [0.5, 0.1, 0.01] {
            let n = 1 << 17;
            let bits: BitVec<BitWord, Lsb0> = (0..n).map(|_| rng.f64() < p).collect();
            let ones = bits.count_ones() as u64;
            let p1 = probability_of_one(ones, n as u64);
            let words = encode(&bits, p1);
            assert_eq!(decode(words.clone(), n, p1).unwrap(), bits);
            let bound = entropy_bits(ones, n as u64);
            let coded = words.len() as f64 * 32.0;
            assert!(coded <= bound * 1.01 + 64.0, "p {p}: {coded} vs {bound}");
        }
    }
}
