//! The decoder's own walks of codec 5's value trees (format-spec §6.5.3): modes 3 and 4 (one
//! adaptive model per tree node and context) and the mixed modes 5 and 6. They give the same
//! cells as [`super::adaptive_coder`]'s walk, which both directions share, in fewer steps per
//! bit. That walk stays the definition (the encoder runs it, and test
//! `the_fast_walks_decode_as_the_shared_one` holds these to it on coded and on random
//! streams); these are only faster:
//!
//! * the range decoder's error check leaves the loop ([`BinaryRangeDecoder::binary_deferred`]:
//!   one check per channel instead of a branch and an error path per bit);
//! * the model tables are reached through fixed-size views, so that the index of a tree node
//!   needs no bounds check;
//! * in the mixed modes each model keeps its log-odds next to its probability, worked out when
//!   it learns (after the bit), so the prediction of the next bit reads it instead of looking
//!   it up; the mixer's output gives the coder's 16-bit probability and the 12-bit one in one
//!   load ([`SQUASH_AND_P16`]); the weights live on the stack.

use super::adaptive_coder::{top_bits, Mode, Previous, NEIGHBOUR_CONTEXTS};
use super::bit_coder::{Adaptive, ONE, P_MIN};
use crate::entropy::binary_range_decoder::BinaryRangeDecoder;
use crate::entropy::bit_mixer::{BIAS, LEARNING_SHIFT, SQUASH_AND_P16, STRETCH_X8, WEIGHT_LIMIT};

/// Tree nodes of the widest tree (`TREE_MAX_BITS` = 10): every table is padded so that a view
/// of this many models starts at any context's first node.
const NODES: usize = 1 << 10;
/// Weight vectors: one per tree level, at most 10.
const LEVELS: usize = 16;

/// An adaptive binary model as `bit_coder::Adaptive` (the same probability after every
/// bit), with its log-odds kept: `aux` is `stretch(p >> 4) << 3` plus, in the low 3 bits, how
/// many bits it has seen, up to 5 (from then on its adaptation rate stays `1/2^MAX_SHIFT`).
#[derive(Clone, Copy)]
struct Model {
    p: u16,
    aux: i16,
}

impl Model {
    /// Probability 1/2 (log-odds 0), nothing seen.
    const NEW: Model = Model {
        p: (ONE / 2) as u16,
        aux: 0,
    };

    #[inline(always)]
    fn stretch(self) -> i32 {
        (self.aux >> 3) as i32
    }

    /// `Adaptive::update`: a step of `1/2^(seen + 1)` towards the bit, at most `1/64`.
    #[inline(always)]
    fn update(&mut self, bit: bool) {
        let seen = (self.aux & 7) as u32;
        let shift = seen + 1;
        let p = self.p as u32;
        let down = p - (p >> shift);
        let up = p + ((ONE - p) >> shift);
        let p = if bit { down } else { up }.clamp(P_MIN, ONE - P_MIN);
        self.p = p as u16;
        self.aux = STRETCH_X8[(p >> 4) as usize & 4095] | (seen + 1).min(5) as i16;
    }
}

/// `contexts * 2^bits` models plus the padding of [`NODES`].
fn table<T: Copy>(new: T, contexts: usize, bits: u8) -> Vec<T> {
    vec![new; (contexts << bits) + NODES]
}

/// The view of `NODES` models from `base` on.
#[inline(always)]
fn view<T>(t: &mut [T], base: usize) -> &mut [T; NODES] {
    (&mut t[base..base + NODES])
        .try_into()
        .expect("tables are padded by NODES")
}

/// Decode the cells of a channel in `mode` into `q` (zeros on entry): whether the stream was
/// valid, or for modes 0-2 `dec` back. The caller has checked the mode against `bits`, `prev`
/// and `prev2`.
#[allow(clippy::too_many_arguments)]
pub(super) fn decode(
    mode: Mode,
    dec: BinaryRangeDecoder,
    q: &mut [u16],
    width: usize,
    bits: u8,
    prev: Previous,
    prev2: Previous,
) -> Result<bool, BinaryRangeDecoder> {
    Ok(match mode {
        Mode::Mixed(k) => decode_mixed(dec, q, width, bits, k, 0, prev, prev2),
        Mode::MixedTwo(k, k2) => decode_mixed(dec, q, width, bits, k, k2, prev, prev2),
        Mode::TreeGivenPrevious(k) => decode_tree(dec, q, bits, Some((prev, k))),
        Mode::Tree => decode_tree(dec, q, bits, None),
        Mode::Residual | Mode::ResidualGivenPrevious | Mode::ResidualMinusPrevious => {
            return Err(dec)
        }
    })
}

/// Decode the cells of a mode 3 (`given`: the previous channel and its top `k` bits) or mode
/// 4 channel into `q`; `false` if the stream is not valid. The caller has checked the mode.
fn decode_tree(
    dec: BinaryRangeDecoder,
    q: &mut [u16],
    bits: u8,
    given: Option<(Previous, u8)>,
) -> bool {
    match given {
        Some((Some(p), k)) => {
            let (contexts, x) = top_bits(p, k);
            tree(dec, q, bits, contexts, x)
        }
        _ => tree(dec, q, bits, 1, |_| 0),
    }
}

/// The walk of modes 3 and 4: the value, most significant bit first, each bit in the model of
/// its tree node in context `context(i)` (one of `contexts`).
fn tree(
    mut dec: BinaryRangeDecoder,
    q: &mut [u16],
    bits: u8,
    contexts: usize,
    context: impl Fn(usize) -> usize,
) -> bool {
    debug_assert!(bits <= 10);
    let b = bits as usize;
    let mut models = table(Adaptive::NEW, contexts, bits);
    for (i, cell) in q.iter_mut().enumerate() {
        let m = view(&mut models, context(i) << b);
        let mut node = 1usize;
        for _ in 0..b {
            let model = &mut m[node & (NODES - 1)];
            let bit = dec.binary_deferred(model.p());
            model.update(bit);
            node = node * 2 + bit as usize;
        }
        *cell = (node - (1 << b)) as u16;
    }
    !dec.failed()
}

/// Decode the cells of a mode 5 (`k2 = 0`) or mode 6 channel into `q` (zeros on entry);
/// `false` if the stream is not valid (`adaptive_coder`'s walk would fail at some bit). The
/// caller has checked the mode against `bits`, `prev` and `prev2`.
#[allow(clippy::too_many_arguments)]
fn decode_mixed(
    dec: BinaryRangeDecoder,
    q: &mut [u16],
    width: usize,
    bits: u8,
    k: u8,
    k2: u8,
    prev: Previous,
    prev2: Previous,
) -> bool {
    match (prev, prev2) {
        (Some(p), Some(p2)) if k > 0 && k2 > 0 => {
            let (c1, x1) = top_bits(p, k);
            let (c2, x2) = top_bits(p2, k2);
            walk::<5>(dec, q, width, bits, [c1, c1 * c2], |i| {
                [x1(i), x2(i) * c1 + x1(i)]
            })
        }
        (Some(p), _) if k > 0 => {
            let (c1, x1) = top_bits(p, k);
            walk::<4>(dec, q, width, bits, [c1, 0], |i| [x1(i), 0])
        }
        _ => walk::<3>(dec, q, width, bits, [0, 0], |_| [0, 0]),
    }
}

/// `adaptive_coder::mixed_tree` for the decoder: `N - 1` models (order 0, neighbours, and for
/// `N >= 4` the previous channel, for `N = 5` both previous channels) and the bias.
fn walk<const N: usize>(
    mut dec: BinaryRangeDecoder,
    q: &mut [u16],
    width: usize,
    bits: u8,
    counts: [usize; 2],
    contexts: impl Fn(usize) -> [usize; 2],
) -> bool {
    debug_assert!(bits <= 10 && (3..=5).contains(&N));
    let b = bits as usize;
    let top = bits.saturating_sub(2);
    let mut order0 = table(Model::NEW, 1, bits);
    let mut given_neighbours = table(Model::NEW, NEIGHBOUR_CONTEXTS, bits);
    let mut given_prev = table(Model::NEW, counts[0], bits);
    let mut given_both = table(Model::NEW, counts[1], bits);
    let mut first = [65536 / (N as i32 - 1); N];
    first[N - 1] = 0;
    let mut weights = [first; LEVELS];
    let o0 = view(&mut order0, 0);
    // The cell's column, kept as the walk goes (what `neighbours` works out with a division).
    let mut x = 0usize;
    for i in 0..q.len() {
        let (ha, hu) = (x > 0, i >= width);
        let a = if ha { q[i - 1] } else { 0 };
        let up = if hu { q[i - width] } else { 0 };
        x = if x + 1 == width { 0 } else { x + 1 };
        let side = |v: u16, has: bool| if has { 1 + (v >> top) as usize } else { 0 };
        let nbase = (side(a, ha) * 5 + side(up, hu)).min(NEIGHBOUR_CONTEXTS - 1) << b;
        let [x1, x2] = if N >= 4 { contexts(i) } else { [0, 0] };
        let gn = view(&mut given_neighbours, nbase);
        let gp = view(&mut given_prev, if N >= 4 { x1 << b } else { 0 });
        let gb = view(&mut given_both, if N == 5 { x2 << b } else { 0 });
        let mut node = 1usize;
        for level in 0..b {
            let n = node & (NODES - 1);
            let mut st = [BIAS; N];
            st[0] = o0[n].stretch();
            st[1] = gn[n].stretch();
            if N >= 4 {
                st[2] = gp[n].stretch();
            }
            if N == 5 {
                st[3] = gb[n].stretch();
            }
            let w = &mut weights[level & (LEVELS - 1)];
            let mut dot = 0i64;
            for j in 0..N {
                dot += w[j] as i64 * st[j] as i64;
            }
            let d = (dot >> 16).clamp(-2047, 2047) as i32;
            let both = SQUASH_AND_P16[(d + 2047) as usize];
            let bit = dec.binary_deferred(both >> 16);
            let err = if bit { 0 } else { 4095 } - (both & 0xffff) as i32;
            for j in 0..N {
                w[j] =
                    (w[j] + ((st[j] * err) >> LEARNING_SHIFT)).clamp(-WEIGHT_LIMIT, WEIGHT_LIMIT);
            }
            o0[n].update(bit);
            gn[n].update(bit);
            if N >= 4 {
                gp[n].update(bit);
            }
            if N == 5 {
                gb[n].update(bit);
            }
            node = node * 2 + bit as usize;
        }
        q[i] = (node - (1 << b)) as u16;
    }
    !dec.failed()
}

#[cfg(test)]
mod tests {
    use super::super::adaptive_coder::{decode, decode_with_shared_walk, encode, Mode};
    use crate::bytes::{ByteReader, PutLe};

    fn noise(n: usize, seed: u32, bits: u8) -> Vec<u16> {
        let mut s = seed | 1;
        (0..n)
            .map(|i| {
                s ^= s << 13;
                s ^= s >> 17;
                s ^= s << 5;
                (((i as u32 / 5) + (s % 7)) % (1u32 << bits)) as u16
            })
            .collect()
    }

    #[test]
    fn the_fast_walks_decode_as_the_shared_one() {
        let mut s = 0x2545_f491u32;
        let mut rnd = move || {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            s
        };
        let modes = [
            Mode::Tree,
            Mode::TreeGivenPrevious(2),
            Mode::TreeGivenPrevious(8),
            Mode::Mixed(0),
            Mode::Mixed(2),
            Mode::Mixed(4),
            Mode::MixedTwo(4, 3),
            Mode::MixedTwo(2, 1),
        ];
        for bits in [0u8, 1, 3, 7, 8, 9, 10] {
            for n in [1usize, 9, 300, 3000] {
                let width = (n as f64).sqrt().ceil() as usize;
                let (p, p2) = (noise(n, 5, 8), noise(n, 7, 3));
                let (pv, pv2) = (Some((p.as_slice(), 8)), Some((p2.as_slice(), 3)));
                let q = noise(n, 11, bits);
                for mode in modes {
                    // A coded stream, then random words: the same cells, or both an error.
                    let mut streams = vec![];
                    if let Some(e) = encode(&q, pv, pv2, width, bits, mode) {
                        streams.push(e);
                    }
                    for _ in 0..4 {
                        let (m, k) = match mode {
                            Mode::Mixed(k) => (5, k),
                            Mode::MixedTwo(k, k2) => (6, k | k2 << 4),
                            Mode::Tree => (4, 0),
                            Mode::TreeGivenPrevious(k) => (3, k),
                            _ => unreachable!(),
                        };
                        let words = rnd() % 60;
                        let mut e = vec![m, k];
                        e.put_u32(words);
                        for _ in 0..words {
                            e.put_u32(if rnd() % 5 == 0 { u32::MAX } else { rnd() });
                        }
                        streams.push(e);
                    }
                    for e in streams {
                        let fast = decode(ByteReader::new(&e, 0), n, width, bits, pv, pv2);
                        let shared = decode_with_shared_walk(
                            ByteReader::new(&e, 0),
                            n,
                            width,
                            bits,
                            pv,
                            pv2,
                        );
                        assert_eq!(fast, shared, "bits {bits} n {n} {mode:?}");
                    }
                }
            }
        }
    }
}
