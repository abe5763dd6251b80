//! Lossless coding of one quantised attribute channel laid out as a sorted 2D grid
//! (format-spec §6.5.3). Cell `i` is at column `i % width`, row `i / width`; the last row may be
//! partial. The predictive codec is LOCO-I's median edge detector on the grid neighbours, the
//! residual taken modulo `2^bits`, zigzag-mapped, split into a magnitude class (range-coded
//! with `constriction`, one static model per activity context) and raw mantissa bits (packed
//! with `bitvec`).

use crate::container::ChunkType;
use crate::Error;
use bitvec::prelude::*;
use constriction::stream::model::ContiguousCategoricalEntropyModel;
use constriction::stream::queue::{DefaultRangeDecoder, DefaultRangeEncoder};
use constriction::stream::{Decode, Encode};

use super::adaptive_coder::{self, Mode, Previous};
use super::cells::{
    activity_threshold, class_of, context, neighbours, predict, read_words, unzigzag, zigzag,
};
use crate::bytes::{ByteReader, PutLe};
use crate::error::Result;

/// Probability precision of the class models (probabilities are stored as u16 < 2^12).
pub const PRECISION: usize = 12;
/// Activity contexts.
pub const CONTEXTS: usize = 3;
type Model = ContiguousCategoricalEntropyModel<u32, Vec<u32>, PRECISION>;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GridCodec {
    /// Every cell is 0 (no data).
    Constant = 0,
    /// Values as u8 (bits <= 8) or u16 LE, zstd-compressed.
    Zstd = 1,
    /// Median predictor + context-modelled range coding.
    Predictive = 2,
    /// The values range-coded with their own stored histogram (order 0).
    Histogram = 3,
    /// The difference from the previous channel's cells (mod `2^bits`, same `bits`),
    /// range-coded with its stored histogram: colour and scale channels of one Gaussian move
    /// together, so the difference is narrower than either.
    HistogramDelta = 4,
    /// Adaptive binary context coding ([`super::adaptive_coder`]), since 1.9.
    Adaptive = 5,
}

impl GridCodec {
    pub fn from_u8(v: u8) -> Option<Self> {
        match v {
            0 => Some(GridCodec::Constant),
            1 => Some(GridCodec::Zstd),
            2 => Some(GridCodec::Predictive),
            3 => Some(GridCodec::Histogram),
            4 => Some(GridCodec::HistogramDelta),
            5 => Some(GridCodec::Adaptive),
            _ => None,
        }
    }
}

/// Normalise counts to `2^PRECISION` with every symbol at least 1 (largest absorbs rounding).
fn normalise(counts: &[u64]) -> Vec<u32> {
    let total: u64 = counts.iter().sum::<u64>().max(1);
    let one = 1u64 << PRECISION;
    let mut p: Vec<u32> = counts
        .iter()
        .map(|&c| ((c * one) / total).max(1) as u32)
        .collect();
    let sum: i64 = p.iter().map(|&v| v as i64).sum();
    let (imax, _) = p
        .iter()
        .enumerate()
        .max_by_key(|&(i, v)| (*v, std::cmp::Reverse(i)))
        .expect("non-empty");
    p[imax] = (p[imax] as i64 + one as i64 - sum) as u32;
    p
}

fn model(p: &[u32]) -> Option<Model> {
    Model::from_nonzero_fixed_point_probabilities(p, false).ok()
}

/// Encode with the predictive codec.
pub fn encode_predictive(q: &[u16], width: usize, bits: u8) -> Vec<u8> {
    let t0 = activity_threshold(q, width);

    let symbols: Vec<(usize, u32, u32)> = (0..q.len())
        .map(|i| {
            let (a, b, c, ha, hb) = neighbours(q, i, width);
            let z = zigzag(q[i], predict(a, b, c, ha, hb), bits);
            (context(a, b, c, t0), class_of(z), z)
        })
        .collect();
    let mut counts = vec![vec![0u64; bits as usize + 1]; CONTEXTS];
    for &(ctx, cl, _) in &symbols {
        counts[ctx][cl as usize] += 1;
    }
    let mut out = vec![t0 as u8];
    let mut models = Vec::with_capacity(CONTEXTS);
    for c in &counts {
        // Classes up to the largest used one; an unused context stores 0 classes.
        let n = c.iter().rposition(|&v| v > 0).map_or(0, |p| p + 1);
        out.push(n as u8);
        if n == 0 {
            models.push(None);
            continue;
        }
        let p = normalise(&c[..n]);
        for &v in &p {
            out.put_u16(v as u16);
        }
        models.push(model(&p));
    }
    let mut enc = DefaultRangeEncoder::new();
    let mut mantissa: BitVec<u8, Lsb0> = BitVec::new();
    for &(ctx, cl, z) in &symbols {
        let m = models[ctx]
            .as_ref()
            .expect("context with symbols has a model");
        enc.encode_symbol(cl as usize, m)
            .expect("class is inside the model");
        if cl >= 2 {
            let extra = z - (1 << (cl - 1));
            for k in 0..cl - 1 {
                mantissa.push(extra >> k & 1 == 1);
            }
        }
    }
    let words = enc.into_compressed().expect("in-memory backend");
    out.put_u32(words.len() as u32);
    for w in &words {
        out.put_u32(*w);
    }
    out.extend_from_slice(mantissa.as_raw_slice());
    out
}

/// Decode `n` cells coded with [`encode_predictive`]. `r` holds exactly the channel's bytes.
pub fn decode_predictive(mut r: ByteReader, n: usize, width: usize, bits: u8) -> Result<Vec<u16>> {
    let t0 = r.u8("grid context threshold")? as u32;
    let mut models = Vec::with_capacity(CONTEXTS);
    for _ in 0..CONTEXTS {
        let k = r.u8("grid class count")? as usize;
        if k > bits as usize + 1 {
            return Err(Error::payload(
                ChunkType::CSOG,
                format!("{k} magnitude classes for {bits}-bit values"),
                r.offset(),
            ));
        }
        if k == 0 {
            models.push(None);
            continue;
        }
        let mut p = Vec::with_capacity(k);
        for _ in 0..k {
            p.push(r.u16("grid class probability")? as u32);
        }
        if p.contains(&0) || p.iter().sum::<u32>() != 1 << PRECISION {
            return Err(Error::payload(
                ChunkType::CSOG,
                "class probabilities must be >= 1 and sum to 4096",
                r.offset(),
            ));
        }
        models.push(Some(model(&p).ok_or_else(|| {
            Error::payload(ChunkType::CSOG, "invalid class model", r.offset())
        })?));
    }
    let words = read_words(&mut r)?;
    let at = r.offset();
    let mantissa = BitSlice::<u8, Lsb0>::from_slice(r.rest());
    let mut mpos = 0usize;
    let mut dec = DefaultRangeDecoder::from_compressed(words)
        .map_err(|_| Error::payload(ChunkType::CSOG, "range coder stream", r.offset()))?;
    let mut q = vec![0u16; n];
    for i in 0..n {
        let (a, b, c, ha, hb) = neighbours(&q, i, width);
        let ctx = context(a, b, c, t0);
        let m = models[ctx].as_ref().ok_or_else(|| {
            Error::payload(
                ChunkType::CSOG,
                format!("cell {i} falls in context {ctx}, which has no model"),
                r.offset(),
            )
        })?;
        let cl = dec.decode_symbol(m).map_err(|_| {
            Error::payload(
                ChunkType::CSOG,
                format!("range coder failed at cell {i}"),
                r.offset(),
            )
        })? as u32;
        let z = if cl >= 2 {
            let nb = (cl - 1) as usize;
            let Some(bits_) = mantissa.get(mpos..mpos + nb) else {
                return Err(crate::Error::format(
                    crate::error::FormatErrorKind::Truncated {
                        what: "grid mantissa bits",
                        needed: (mpos + nb).div_ceil(8) as u64,
                        available: (mantissa.len() / 8) as u64,
                    },
                    at,
                ));
            };
            mpos += nb;
            let extra = bits_
                .iter()
                .by_vals()
                .enumerate()
                .fold(0u32, |v, (k, b)| v | (b as u32) << k);
            (1 << (cl - 1)) + extra
        } else {
            cl
        };
        q[i] = unzigzag(z, predict(a, b, c, ha, hb), bits);
    }
    Ok(q)
}

/// Probability precision of the histogram codecs.
pub const HIST_PRECISION: usize = 16;
/// Largest alphabet of the histogram codecs.
pub const HIST_MAX_SYMBOLS: usize = 4096;
type HistModel = ContiguousCategoricalEntropyModel<u32, Vec<u32>, HIST_PRECISION>;

/// `(q - prev) mod 2^bits` per cell: what codec 4 codes.
pub fn delta(q: &[u16], prev: &[u16], bits: u8) -> Vec<u16> {
    let mask = ((1u32 << bits) - 1) as u16;
    q.iter()
        .zip(prev)
        .map(|(&a, &b)| a.wrapping_sub(b) & mask)
        .collect()
}

/// Encode with the histogram codec (codec 3; codec 4 codes [`delta`] with it). `None` when the
/// alphabet is too large.
pub fn encode_histogram(q: &[u16], zstd_level: i32) -> Option<Vec<u8>> {
    let symbols = (*q.iter().max()? as usize + 1).max(2);
    if symbols > HIST_MAX_SYMBOLS {
        return None;
    }
    let mut counts = vec![0u64; symbols];
    for &v in q {
        counts[v as usize] += 1;
    }
    // Every symbol gets 1 and the rest shares 2^16 - S by count, so no normalisation can
    // underflow; the largest symbol absorbs the rounding.
    let one = 1u64 << HIST_PRECISION;
    let free = one - symbols as u64;
    let total = q.len() as u64;
    let mut p: Vec<u32> = counts
        .iter()
        .map(|&c| (1 + c * free / total) as u32)
        .collect();
    let sum: u64 = p.iter().map(|&v| v as u64).sum();
    let imax = (0..symbols)
        .max_by_key(|&i| (p[i], std::cmp::Reverse(i)))
        .expect("2+ symbols");
    p[imax] += (one - sum) as u32;
    let model = HistModel::from_nonzero_fixed_point_probabilities(&p, false)
        .expect("probabilities are positive and sum to 2^16");
    let mut enc = DefaultRangeEncoder::new();
    enc.encode_iid_symbols(q.iter().map(|&v| v as usize), &model)
        .expect("every value is inside the model");
    let words = enc.into_compressed().expect("in-memory backend");
    let mut table = Vec::with_capacity(2 * symbols);
    for &v in &p {
        table.put_u16(v as u16);
    }
    let table = zstd::bulk::compress(&table, zstd_level).expect("zstd of a memory buffer");
    let mut out = Vec::with_capacity(10 + table.len() + 4 * words.len());
    out.put_u16(symbols as u16);
    out.put_u32(table.len() as u32);
    out.extend_from_slice(&table);
    out.put_u32(words.len() as u32);
    for w in &words {
        out.put_u32(*w);
    }
    Some(out)
}

/// Decode `n` symbols coded with [`encode_histogram`] for a `bits`-bit channel.
pub fn decode_histogram(mut r: ByteReader, n: usize, bits: u8) -> Result<Vec<u16>> {
    let at = r.offset();
    let symbols = r.u16("histogram symbol count")? as usize;
    if !(2..=HIST_MAX_SYMBOLS).contains(&symbols) || symbols > 1 << bits {
        return Err(Error::payload(
            ChunkType::CSOG,
            format!("{symbols} histogram symbols for {bits}-bit values (2..=min(4096, 2^bits))"),
            r.offset(),
        ));
    }
    let tlen = r.u32("histogram table length")? as usize;
    let table = crate::bytes::zstd_exact(r.take(tlen, "histogram table")?, 2 * symbols as u64, at)?;
    let p: Vec<u32> = table
        .chunks_exact(2)
        .map(|b| u16::from_le_bytes([b[0], b[1]]) as u32)
        .collect();
    if p.contains(&0) || p.iter().map(|&v| v as u64).sum::<u64>() != 1 << HIST_PRECISION {
        return Err(Error::payload(
            ChunkType::CSOG,
            "histogram probabilities must be >= 1 and sum to 65536",
            r.offset(),
        ));
    }
    let model = HistModel::from_nonzero_fixed_point_probabilities(&p, false)
        .map_err(|_| Error::payload(ChunkType::CSOG, "invalid histogram model", r.offset()))?;
    let words = read_words(&mut r)?;
    if r.remaining() != 0 {
        return Err(Error::payload(
            ChunkType::CSOG,
            format!("{} bytes after the histogram stream", r.remaining()),
            r.offset(),
        ));
    }
    let mut dec = DefaultRangeDecoder::from_compressed(words)
        .map_err(|_| Error::payload(ChunkType::CSOG, "range coder stream", r.offset()))?;
    let mut q = Vec::with_capacity(n);
    for i in 0..n {
        let v = dec.decode_symbol(&model).map_err(|_| {
            Error::payload(
                ChunkType::CSOG,
                format!("range coder failed at cell {i}"),
                r.offset(),
            )
        })?;
        q.push(v as u16);
    }
    Ok(q)
}

/// Encode with whichever of codecs 0-2 is smaller (the codecs `RDLT` channels may use).
pub fn encode_classic(q: &[u16], width: usize, bits: u8, zstd_level: i32) -> (GridCodec, Vec<u8>) {
    if q.iter().all(|&v| v == 0) {
        return (GridCodec::Constant, Vec::new());
    }
    let p = encode_predictive(q, width, bits);
    let z = encode_zstd(q, bits, zstd_level);
    if z.len() < p.len() {
        (GridCodec::Zstd, z)
    } else {
        (GridCodec::Predictive, p)
    }
}

/// Encode with whichever of codecs 0-4 is smaller for this channel (the codecs with stored
/// tables: fast to try, which level shaping does for every variant). `prev` is the previous
/// channel's cells and bits; codec 4 codes the difference from it when the bits match.
pub fn encode_best_tabled(
    q: &[u16],
    prev: Option<(&[u16], u8)>,
    width: usize,
    bits: u8,
    zstd_level: i32,
) -> (GridCodec, Vec<u8>) {
    let mut best = encode_classic(q, width, bits, zstd_level);
    if best.0 == GridCodec::Constant {
        return best;
    }
    let mut consider = |codec: GridCodec, data: Option<Vec<u8>>| {
        if let Some(d) = data {
            if d.len() < best.1.len() {
                best = (codec, d);
            }
        }
    };
    consider(GridCodec::Histogram, encode_histogram(q, zstd_level));
    consider(
        GridCodec::HistogramDelta,
        encode_histogram_delta(q, prev, bits, zstd_level),
    );
    best
}

/// Codec 4's data: the histogram of the difference from `prev`, when it has the same bits.
fn encode_histogram_delta(
    q: &[u16],
    prev: Option<(&[u16], u8)>,
    bits: u8,
    zstd_level: i32,
) -> Option<Vec<u8>> {
    let (p, _) = prev.filter(|p| p.1 == bits)?;
    encode_histogram(&delta(q, p, bits), zstd_level)
}

/// A coding that needs the previous channel must be this much smaller than the best one that
/// does not: chains of dependent channels decode one after another, independent ones in
/// parallel.
pub const DEPENDENT_MARGIN: f64 = 0.005;

/// Codec 5's mixed modes (5 and 6) must be this much smaller than the channel's best other
/// coding by default: they decode about 3 times slower than the value trees. Larger margins
/// (`dlgs encode --mixed-margin`) trade a little size for decode time.
pub const MIXED_MARGIN: f64 = 0.01;

/// Encode with whichever codec is smallest for this channel: codecs 0-4
/// ([`encode_best_tabled`]) and every usable mode of codec 5, preferring by
/// [`DEPENDENT_MARGIN`] those that decode without the previous channel (`prev`; `prev2` is
/// the channel before it, for codec 5 mode 6) and by `mixed_margin` (a fraction, usually
/// [`MIXED_MARGIN`]) the others. With `mixed_margin` `None`, codec 5's mixed modes (5 and 6)
/// are not tried: the file decodes faster for a few percent more bytes (`dlgs encode
/// --fast-decode`, docs/benchmarks/canonical-levers.md "Mixed contexts").
pub fn encode_best(
    q: &[u16],
    prev: Previous,
    prev2: Previous,
    width: usize,
    bits: u8,
    zstd_level: i32,
    mixed_margin: Option<f64>,
) -> (GridCodec, Vec<u8>) {
    // Codecs 0-3 never need the previous channel; codec 4 always does.
    let plain = encode_best_tabled(q, None, width, bits, zstd_level);
    if plain.0 == GridCodec::Constant {
        return plain;
    }
    let mut candidates: Vec<(bool, GridCodec, Vec<u8>)> = vec![(false, plain.0, plain.1)];
    if let Some(d) = encode_histogram_delta(q, prev, bits, zstd_level) {
        candidates.push((true, GridCodec::HistogramDelta, d));
    }
    for mode in adaptive_coder::candidate_modes(bits, prev, prev2) {
        if mixed_margin.is_none() && matches!(mode, Mode::Mixed(_) | Mode::MixedTwo(..)) {
            continue;
        }
        if let Some(d) = adaptive_coder::encode(q, prev, prev2, width, bits, mode) {
            candidates.push((mode.needs_previous(), GridCodec::Adaptive, d));
        }
    }
    // Modes 5 and 6 are judged by their size plus the margin.
    let judged = |c: &(bool, GridCodec, Vec<u8>)| {
        let mixed = c.1 == GridCodec::Adaptive && matches!(c.2.first(), Some(5 | 6));
        c.2.len() as f64
            * if mixed {
                1.0 + mixed_margin.unwrap_or(0.0)
            } else {
                1.0
            }
    };
    let smallest = |dep: bool| {
        candidates
            .iter()
            .filter(|c| c.0 == dep)
            .min_by(|a, b| judged(a).total_cmp(&judged(b)))
            .map(|c| (c.1, c.2.clone()))
    };
    let independent = smallest(false).expect("codecs 0-3 always code");
    match smallest(true) {
        Some(d) if (d.1.len() as f64) < independent.1.len() as f64 * (1.0 - DEPENDENT_MARGIN) => d,
        _ => independent,
    }
}

pub fn encode_zstd(q: &[u16], bits: u8, level: i32) -> Vec<u8> {
    let raw: Vec<u8> = if bits <= 8 {
        q.iter().map(|&v| v as u8).collect()
    } else {
        q.iter().flat_map(|v| v.to_le_bytes()).collect()
    };
    zstd::bulk::compress(&raw, level).expect("zstd compression of a memory buffer")
}

/// Decode one channel of `n` cells; every value is checked to be below `2^bits`. For
/// [`GridCodec::HistogramDelta`] the result is the coded difference: add the previous channel
/// with [`undo_delta`]. [`GridCodec::Adaptive`] reads `prev`, the previous channel's final
/// cells and bits (a typed error if its mode needs them and they are absent).
pub fn decode(
    codec: GridCodec,
    r: ByteReader,
    n: usize,
    width: usize,
    bits: u8,
    prev: Previous,
    prev2: Previous,
) -> Result<Vec<u16>> {
    let at = r.offset();
    let q = match codec {
        GridCodec::Constant => vec![0u16; n],
        GridCodec::Predictive => decode_predictive(r, n, width, bits)?,
        GridCodec::Histogram | GridCodec::HistogramDelta => decode_histogram(r, n, bits)?,
        GridCodec::Adaptive => adaptive_coder::decode(r, n, width, bits, prev, prev2)?,
        GridCodec::Zstd => {
            let mut r = r;
            let per = if bits <= 8 { 1 } else { 2 };
            let raw = crate::bytes::zstd_exact(r.rest(), (n * per) as u64, at)?;
            if per == 1 {
                raw.into_iter().map(u16::from).collect()
            } else {
                raw.chunks_exact(2)
                    .map(|b| u16::from_le_bytes([b[0], b[1]]))
                    .collect()
            }
        }
    };
    if let Some(i) = q.iter().position(|&v| (v as u32) >> bits != 0) {
        return Err(crate::Error::payload(
            crate::container::ChunkType::CSOG,
            format!("cell {i} holds {} which does not fit {bits} bits", q[i]),
            at,
        ));
    }
    Ok(q)
}

/// Codec 4's cells from the decoded difference and the previous channel's cells.
pub fn undo_delta(d: &mut [u16], prev: &[u16], bits: u8) {
    let mask = ((1u32 << bits) - 1) as u16;
    for (v, &b) in d.iter_mut().zip(prev) {
        *v = v.wrapping_add(b) & mask;
    }
}

#[cfg(test)]
#[allow(clippy::disallowed_methods)] // the platform libm as a reference or test data
#[path = "grid_coder_tests.rs"]
mod tests;
