//! Grid codec 5 (format-spec §6.5.3, since 1.9): every cell binarised and range-coded bit by
//! bit with adaptive binary models, so no probability table is stored and the statistics may
//! depend on many contexts. Four modes:
//!
//! * 0: the predictive codec's residual (median edge detector, modulo `2^bits`, zigzag), as a
//!   magnitude class (unary) and mantissa, in one of 7 spatial activity contexts;
//! * 1: as 0, with the class of the previous channel's residual at the same cell as a second
//!   context (the attributes of one Gaussian are surprised together);
//! * 2: as 1, coding the residual minus the previous channel's residual (same `bits`);
//! * 3: the value itself, most significant bit first down a binary tree, in the context of the
//!   previous channel's value at the same cell (its top `k` bits): colours cluster, so one
//!   channel narrows the next more than any neighbour does.
//!
//! One function ([`code_cells`]) walks the cells for both directions, so the encoder and the
//! decoder cannot disagree on a context.
//!
//! The binary models and the range coder's two directions are in `bit_coder`.

use crate::container::ChunkType;
use crate::Error;

use constriction::stream::queue::DefaultRangeEncoder;

use super::bit_coder::{
    ended_early, open_stream, Adaptive, BitCoder, Decoder, Encoder, ONE, P_MIN,
};
use super::cells::{class_of, neighbours, predict, zigzag};
use super::tree_walks;
use crate::bytes::{ByteReader, PutLe};
use crate::entropy::bit_mixer::Mixer;
use crate::error::Result;

/// Activity contexts (modes 0-2) and previous-residual classes (modes 1-2).
const ACTIVITY_CONTEXTS: usize = 7;
const PREV_CLASSES: usize = 8;
/// Mode 3 only for `bits <= TREE_MAX_BITS`, with `1..=TREE_MAX_CONTEXT_BITS` context bits:
/// at most `2^8 * 2^10` tree nodes.
pub const TREE_MAX_BITS: u8 = 10;
pub const TREE_MAX_CONTEXT_BITS: u8 = 8;
/// Mode 6: at most this many context bits of the channel before the previous one.
pub const MIXED_TWO_MAX_K2: u8 = 4;

/// A channel coded against: its cells and bits (`None`: there is none).
pub type Previous<'a> = Option<(&'a [u16], u8)>;

/// Coding mode of a codec-5 channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    Residual,
    ResidualGivenPrevious,
    ResidualMinusPrevious,
    /// Value tree with the previous channel's top `k` bits as context.
    TreeGivenPrevious(u8),
    /// Value tree in one context (an adaptive order-0 model that needs no other channel).
    Tree,
    /// Value tree whose every bit mixes the predictions of an order-0 model, a model in the
    /// context of the left and upper neighbours' top bits and, for `k > 0`, one in the context
    /// of the previous channel's top `k` bits ([`bit_mixer`](crate::entropy::bit_mixer), since 1.13).
    Mixed(u8),
    /// As `Mixed(k)` with `k > 0`, plus a model in the context of the previous channel's top
    /// `k` bits together with the top `k2` bits of the channel before it (since 1.13): a
    /// Gaussian's third colour or log-scale follows the other two.
    MixedTwo(u8, u8),
}

impl Mode {
    fn byte(self) -> (u8, u8) {
        match self {
            Mode::Residual => (0, 0),
            Mode::ResidualGivenPrevious => (1, 0),
            Mode::ResidualMinusPrevious => (2, 0),
            Mode::TreeGivenPrevious(k) => (3, k),
            Mode::Tree => (4, 0),
            Mode::Mixed(k) => (5, k),
            Mode::MixedTwo(k, k2) => (6, k | k2 << 4),
        }
    }

    /// Whether decoding needs the cells of the channel before the previous one too (mode 6).
    pub fn needs_two_previous(self) -> bool {
        matches!(self, Mode::MixedTwo(..))
    }

    /// Whether decoding needs the previous channel's cells (a reader decodes the channels
    /// that do not in parallel).
    pub fn needs_previous(self) -> bool {
        !matches!(self, Mode::Residual | Mode::Tree | Mode::Mixed(0))
    }

    /// The mode in words, with its number (§6.5.3).
    pub fn describe(self) -> String {
        match self {
            Mode::Residual => "residual (mode 0)".into(),
            Mode::ResidualGivenPrevious => "residual, previous residual class (mode 1)".into(),
            Mode::ResidualMinusPrevious => "residual minus previous residual (mode 2)".into(),
            Mode::TreeGivenPrevious(k) => format!("value tree, previous top {k} bits (mode 3)"),
            Mode::Tree => "value tree (mode 4)".into(),
            Mode::Mixed(0) => "mixed: order 0, neighbours (mode 5)".into(),
            Mode::Mixed(k) => format!("mixed: order 0, neighbours, previous top {k} bits (mode 5)"),
            Mode::MixedTwo(k, k2) => format!(
                "mixed: order 0, neighbours, previous top {k} bits, with the one before's top {k2} (mode 6)"
            ),
        }
    }

    /// The mode named by a codec-5 channel's first two bytes.
    pub fn from_bytes(mode: u8, k: u8) -> Option<Mode> {
        match (mode, k) {
            (0, 0) => Some(Mode::Residual),
            (1, 0) => Some(Mode::ResidualGivenPrevious),
            (2, 0) => Some(Mode::ResidualMinusPrevious),
            (3, k) => Some(Mode::TreeGivenPrevious(k)),
            (4, 0) => Some(Mode::Tree),
            (5, k) => Some(Mode::Mixed(k)),
            (6, k) => Some(Mode::MixedTwo(k & 15, k >> 4)),
            _ => None,
        }
    }

    /// Why this mode cannot code a `bits`-bit channel after `prev` (and `prev2`, the channel
    /// before it), if it cannot.
    fn unusable(self, bits: u8, prev: Previous, prev2: Previous) -> Option<String> {
        let too_wide = (bits > TREE_MAX_BITS)
            .then(|| format!("value tree for {bits} bits (at most {TREE_MAX_BITS})"));
        if let Mode::MixedTwo(k, k2) = self {
            return if prev2.is_none() {
                Some("needs two previous channels in the set".into())
            } else if !(1..=MIXED_TWO_MAX_K2).contains(&k2) {
                Some(format!(
                    "{k2} context bits of the channel before (1..={MIXED_TWO_MAX_K2})"
                ))
            } else {
                // As mode 3 with `k` (so `k > 0`, unlike mode 5).
                Mode::TreeGivenPrevious(k).unusable(bits, prev, None)
            };
        }
        match (self, prev) {
            (Mode::Residual, _) => None,
            (Mode::Tree, _) | (Mode::Mixed(0), _) => too_wide,
            (_, None) => Some("needs a previous channel in the set".into()),
            (Mode::ResidualGivenPrevious, _) => None,
            (Mode::ResidualMinusPrevious, Some((_, pb))) => {
                (pb != bits).then(|| format!("needs a previous channel of {bits} bits, not {pb}"))
            }
            (Mode::TreeGivenPrevious(k), _) | (Mode::Mixed(k), _) | (Mode::MixedTwo(k, _), _) => {
                if too_wide.is_some() {
                    too_wide
                } else if !(1..=TREE_MAX_CONTEXT_BITS).contains(&k) {
                    Some(format!("{k} context bits (1..={TREE_MAX_CONTEXT_BITS})"))
                } else {
                    None
                }
            }
        }
    }
}

/// The signed residual of cell `i` as the predictive codec forms it, zigzag-mapped.
#[inline]
fn residual_at(q: &[u16], i: usize, width: usize, bits: u8) -> u32 {
    let (a, b, c, ha, hb) = neighbours(q, i, width);
    zigzag(q[i], predict(a, b, c, ha, hb), bits)
}

#[inline]
fn signed(z: u32) -> i32 {
    ((z >> 1) as i32) ^ -((z & 1) as i32)
}

/// Activity context: bit length of `|a-c| + |b-c| + |a-b|` (0 without both neighbours),
/// capped at 12, halved.
#[inline]
fn activity(a: u16, b: u16, c: u16, ha: bool, hb: bool) -> usize {
    if !(ha && hb) {
        return 0;
    }
    let act = (a as i32 - c as i32).unsigned_abs()
        + (b as i32 - c as i32).unsigned_abs()
        + (a as i32 - b as i32).unsigned_abs();
    (class_of(act).min(12) / 2) as usize
}

/// Walk the cells in order, coding (encoder: `q` holds the values) or filling (decoder: `q`
/// starts at zeros) each one.
fn code_cells<C: BitCoder>(
    coder: &mut C,
    q: &mut [u16],
    width: usize,
    bits: u8,
    mode: Mode,
    prev: Previous,
    prev2: Previous,
) -> Result<()> {
    let b = bits as usize;
    match mode {
        Mode::Mixed(k) => code_mixed(coder, q, width, bits, k, 0, prev, None)?,
        Mode::MixedTwo(k, k2) => code_mixed(coder, q, width, bits, k, k2, prev, prev2)?,
        Mode::TreeGivenPrevious(_) | Mode::Tree => {
            // The plain tree has one context; the other takes the previous cell's top `k` bits.
            let given = match (mode, prev) {
                (Mode::TreeGivenPrevious(k), Some(p)) => Some(top_bits(p, k)),
                _ => None,
            };
            let contexts = given.as_ref().map_or(1, |g| g.0);
            let nodes = 1usize << b;
            let mut models = vec![Adaptive::NEW; contexts * nodes];
            for i in 0..q.len() {
                let base = given.as_ref().map_or(0, |g| (g.1)(i)) * nodes;
                let mut node = 1usize;
                for level in (0..b).rev() {
                    let bit = q[i] >> level & 1 == 1;
                    let got = coder.code(&mut models[base + node], bit)?;
                    node = node * 2 + got as usize;
                }
                q[i] = (node - nodes) as u16;
            }
        }
        _ => {
            let with_prev = mode != Mode::Residual;
            let contexts = ACTIVITY_CONTEXTS * PREV_CLASSES;
            let mut unary = vec![Adaptive::NEW; contexts * b];
            let mut top = vec![Adaptive::NEW; contexts * (b + 1)];
            let m = 1i32 << bits;
            for i in 0..q.len() {
                let (a, bb, c, ha, hb) = neighbours(q, i, width);
                let pred = predict(a, bb, c, ha, hb);
                let (pclass, pres) = match (with_prev, prev) {
                    (true, Some((pq, pb))) => {
                        let z = residual_at(pq, i, width, pb);
                        ((class_of(z) as usize).min(PREV_CLASSES - 1), signed(z))
                    }
                    _ => (0, 0),
                };
                let ctx = activity(a, bb, c, ha, hb) * PREV_CLASSES + pclass;
                // The symbol: the residual (mode 2: minus the previous one), mod 2^bits, zigzag.
                let z = if mode == Mode::ResidualMinusPrevious {
                    let r = signed(zigzag(q[i], pred, bits));
                    zigzag(((r - pres).rem_euclid(m)) as u16, 0, bits)
                } else {
                    zigzag(q[i], pred, bits)
                };
                // Class: unary, at most `bits` ones (class `bits` has no closing zero).
                let class = class_of(z) as usize;
                let mut k = 0;
                while k < b {
                    if !coder.code(&mut unary[ctx * b + k], class > k)? {
                        break;
                    }
                    k += 1;
                }
                // Mantissa: the bit under the leading one modelled, the rest raw.
                let z = if k >= 2 {
                    let mut v = 1u32;
                    let hi = coder.code(&mut top[ctx * (b + 1) + k], z >> (k - 2) & 1 == 1)?;
                    v = v << 1 | hi as u32;
                    for level in (0..k - 2).rev() {
                        v = v << 1 | coder.raw(z >> level & 1 == 1)? as u32;
                    }
                    v
                } else {
                    k as u32
                };
                let r = if mode == Mode::ResidualMinusPrevious {
                    signed(z) + pres
                } else {
                    signed(z)
                };
                q[i] = (pred as i32 + r).rem_euclid(m) as u16;
            }
        }
    }
    Ok(())
}

/// Neighbour contexts of mode 5: each of the left and upper neighbours is absent (0) or its
/// top two bits plus one (1..=4).
pub(super) const NEIGHBOUR_CONTEXTS: usize = 25;

/// The top `k` bits of a channel's cells as a context: how many contexts there are, and cell
/// `i`'s (previous cells fit their bits when decoded; `min` keeps a bad caller in range).
pub(super) fn top_bits((cells, b): (&[u16], u8), k: u8) -> (usize, impl Fn(usize) -> usize + '_) {
    let shift = b.saturating_sub(k);
    let contexts = 1usize << k.min(b);
    (contexts, move |i: usize| {
        ((cells[i] >> shift) as usize).min(contexts - 1)
    })
}

/// Modes 5 and 6: the value tree of [`Mode::Mixed`] (`k2 = 0`, `prev2` unused) or
/// [`Mode::MixedTwo`] over every cell.
#[allow(clippy::too_many_arguments)]
fn code_mixed<C: BitCoder>(
    coder: &mut C,
    q: &mut [u16],
    width: usize,
    bits: u8,
    k: u8,
    k2: u8,
    prev: Previous,
    prev2: Previous,
) -> Result<()> {
    match (prev, prev2) {
        (Some(p), Some(p2)) if k > 0 && k2 > 0 => {
            let (c1, x1) = top_bits(p, k);
            let (c2, x2) = top_bits(p2, k2);
            mixed_tree::<C, 5>(coder, q, width, bits, [c1, c1 * c2], |i| {
                [x1(i), x2(i) * c1 + x1(i)]
            })
        }
        (Some(p), _) if k > 0 => {
            let (c1, x1) = top_bits(p, k);
            mixed_tree::<C, 4>(coder, q, width, bits, [c1, 0], |i| [x1(i), 0])
        }
        _ => mixed_tree::<C, 3>(coder, q, width, bits, [0, 0], |_| [0, 0]),
    }
}

/// The walk of modes 5 and 6 with `N - 1` models: order 0, the neighbours' context and, for
/// `N >= 4`, the previous channel's context `contexts(i)[0]` (one of `counts[0]`), for `N = 5`
/// also the context of both previous channels `contexts(i)[1]` (one of `counts[1]`).
fn mixed_tree<C: BitCoder, const N: usize>(
    coder: &mut C,
    q: &mut [u16],
    width: usize,
    bits: u8,
    counts: [usize; 2],
    contexts: impl Fn(usize) -> [usize; 2],
) -> Result<()> {
    let b = bits as usize;
    let nodes = 1usize << b;
    let top = bits.saturating_sub(2);
    let mut order0 = vec![Adaptive::NEW; nodes];
    let mut given_neighbours = vec![Adaptive::NEW; NEIGHBOUR_CONTEXTS * nodes];
    let mut given_prev = vec![Adaptive::NEW; counts[0] * nodes];
    let mut given_both = vec![Adaptive::NEW; counts[1] * nodes];
    let mut mixer = Mixer::<N>::new(b);
    for i in 0..q.len() {
        let (a, up, _, ha, hu) = neighbours(q, i, width);
        let side = |v: u16, has: bool| if has { 1 + (v >> top) as usize } else { 0 };
        // Neighbours fit their bits (decoded ones by construction); `min` keeps a bad caller
        // from indexing past the models.
        let nbase = (side(a, ha) * 5 + side(up, hu)).min(NEIGHBOUR_CONTEXTS - 1) * nodes;
        let [x1, x2] = if N >= 4 { contexts(i) } else { [0, 0] };
        let (pbase, bbase) = (x1 * nodes, x2 * nodes);
        let mut node = 1usize;
        for level in (0..b).rev() {
            let bit = q[i] >> level & 1 == 1;
            let mut p0 = [0u16; N];
            p0[0] = order0[node].p;
            p0[1] = given_neighbours[nbase + node].p;
            if N >= 4 {
                p0[2] = given_prev[pbase + node].p;
            }
            if N == 5 {
                p0[3] = given_both[bbase + node].p;
            }
            let p12 = mixer.predict(p0, b - 1 - level);
            let got = coder.code_p((p12 << 4).clamp(P_MIN, ONE - P_MIN), bit)?;
            mixer.update(got);
            order0[node].update(got);
            given_neighbours[nbase + node].update(got);
            if N >= 4 {
                given_prev[pbase + node].update(got);
            }
            if N == 5 {
                given_both[bbase + node].update(got);
            }
            node = node * 2 + got as usize;
        }
        q[i] = (node - nodes) as u16;
    }
    Ok(())
}

/// Codec 5 data for `q` in `mode`; `None` when the mode cannot code this channel.
pub fn encode(
    q: &[u16],
    prev: Previous,
    prev2: Previous,
    width: usize,
    bits: u8,
    mode: Mode,
) -> Option<Vec<u8>> {
    if mode.unusable(bits, prev, prev2).is_some() {
        return None;
    }
    let mut coder = Encoder(DefaultRangeEncoder::new());
    let mut cells = q.to_vec();
    code_cells(&mut coder, &mut cells, width, bits, mode, prev, prev2)
        .expect("encoding cannot fail");
    debug_assert_eq!(cells, q, "the walk reconstructs what it codes");
    let words = coder.0.into_compressed().expect("in-memory backend");
    let (m, k) = mode.byte();
    let mut out = vec![m, k];
    out.put_u32(words.len() as u32);
    for w in &words {
        out.put_u32(*w);
    }
    Some(out)
}

/// The modes the encoder tries.
pub fn candidate_modes(bits: u8, prev: Previous, prev2: Previous) -> Vec<Mode> {
    let mut modes = vec![
        Mode::Residual,
        Mode::ResidualGivenPrevious,
        Mode::ResidualMinusPrevious,
    ];
    modes.push(Mode::Tree);
    modes.extend([2, 4, 6, 8].map(Mode::TreeGivenPrevious));
    modes.extend([0, 2, 4].map(Mode::Mixed));
    for k in [2, 4] {
        modes.extend([1, 2, 3].map(|k2| Mode::MixedTwo(k, k2)));
    }
    modes
        .into_iter()
        .filter(|m| m.unusable(bits, prev, prev2).is_none())
        .collect()
}

/// Decode `n` cells of codec 5; `prev` is the previous channel record's cells and bits,
/// `prev2` the record's before it.
pub fn decode(
    r: ByteReader,
    n: usize,
    width: usize,
    bits: u8,
    prev: Previous,
    prev2: Previous,
) -> Result<Vec<u16>> {
    decode_walk(r, n, width, bits, prev, prev2, true)
}

/// [`decode`] through the walk both directions share in every mode (the reference of
/// [`tree_walks`]).
#[cfg(test)]
pub(super) fn decode_with_shared_walk(
    r: ByteReader,
    n: usize,
    width: usize,
    bits: u8,
    prev: Previous,
    prev2: Previous,
) -> Result<Vec<u16>> {
    decode_walk(r, n, width, bits, prev, prev2, false)
}

fn decode_walk(
    mut r: ByteReader,
    n: usize,
    width: usize,
    bits: u8,
    prev: Previous,
    prev2: Previous,
    fast: bool,
) -> Result<Vec<u16>> {
    let (m, k) = (r.u8("adaptive mode")?, r.u8("adaptive context bits")?);
    let mode = Mode::from_bytes(m, k).ok_or_else(|| {
        Error::payload(
            ChunkType::CSOG,
            format!("adaptive mode {m} with {k} context bits"),
            r.offset(),
        )
    })?;
    if let Some(why) = mode.unusable(bits, prev, prev2) {
        return Err(Error::payload(
            ChunkType::CSOG,
            format!("adaptive mode {mode:?}: {why}"),
            r.offset(),
        ));
    }
    let dec = open_stream(&mut r, "adaptive")?;
    let mut q = vec![0u16; n];
    // Modes 3-6 through the decoder's own walks (the same cells, faster).
    let dec = if fast {
        match tree_walks::decode(mode, dec, &mut q, width, bits, prev, prev2) {
            Ok(true) => return Ok(q),
            Ok(false) => return Err(ended_early(&r)),
            Err(dec) => dec,
        }
    } else {
        dec
    };
    let mut coder = Decoder { dec, r: &r };
    code_cells(&mut coder, &mut q, width, bits, mode, prev, prev2)?;
    Ok(q)
}

#[cfg(test)]
#[path = "adaptive_coder_tests.rs"]
mod tests;
