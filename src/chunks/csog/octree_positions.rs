//! Quantised positions of a set as an octree (format-spec §6.5.5, since 1.10). A sorted grid
//! codes each position against its grid neighbours, so it also pays for the order the
//! Gaussians happen to sit in; a set of points coded as an octree does not, and the decoder
//! rebuilds the grid order from the decoded positions ([`kd_layout`]). On the real scenes this
//! takes the position channels from 29 to 25 bits per Gaussian (donut, 14 bits per axis).
//!
//! The tree is walked depth first, children in order `j = 4 x + 2 y + z` of their bits at the
//! level, so points come out in Morton order. A node holding two or more points codes which of
//! its 8 children are occupied, then for each occupied child whether it holds exactly one
//! point; a lone point's remaining bits are one uniform symbol per axis (they are close to
//! uniform), and a voxel of the
//! last level that holds several points codes how many.

use crate::container::ChunkType;
use crate::Error;
use constriction::stream::queue::DefaultRangeEncoder;

use super::bit_coder::{open_stream, Adaptive, BitCoder, Decoder, Encoder};
use crate::bytes::{ByteReader, PutLe};
use crate::error::Result;

/// Largest bits per axis: Morton keys of 3 x 16 bits fit a u64.
pub const MAX_BITS: u8 = 16;

/// Occupancy models: level (capped), child index, occupied children so far (capped), and the
/// node's own occupied siblings (capped): a crowded parent has crowded children.
const LEVELS: usize = 16;
const SO_FAR: usize = 4;
const SIBLINGS: usize = 4;

fn occupancy_model(level: usize, j: usize, so_far: usize, siblings: usize) -> usize {
    ((level.min(LEVELS - 1) * 8 + j) * SO_FAR + so_far.min(SO_FAR - 1)) * SIBLINGS
        + (siblings.clamp(1, SIBLINGS) - 1)
}

/// "Exactly one point" models: the child's level and its parent's occupied children (2..=4+).
fn single_model(child_level: usize, occupied: usize) -> usize {
    child_level.min(LEVELS) * 3 + (occupied.clamp(2, 4) - 2)
}

/// Duplicate counts: the unary prefix of an Elias-gamma code, at most 32 long.
const COUNT_PREFIX: usize = 32;

struct Models {
    occupancy: Vec<Adaptive>,
    single: Vec<Adaptive>,
    count: Vec<Adaptive>,
}

impl Models {
    fn new() -> Models {
        Models {
            occupancy: vec![Adaptive::NEW; LEVELS * 8 * SO_FAR * SIBLINGS],
            single: vec![Adaptive::NEW; (LEVELS + 1) * 3],
            count: vec![Adaptive::NEW; COUNT_PREFIX],
        }
    }
}

/// Morton key: the child index `4 x + 2 y + z` of every level, most significant level first.
fn morton(p: [u16; 3], bits: u8) -> u64 {
    let mut k = 0u64;
    for level in (0..bits).rev() {
        let d = (p[0] >> level & 1) << 2 | (p[1] >> level & 1) << 1 | (p[2] >> level & 1);
        k = k << 3 | d as u64;
    }
    k
}

/// Child index of `p` at tree level `level` (0 = the root's children).
fn digit(p: [u16; 3], bits: u8, level: usize) -> usize {
    let s = bits as usize - 1 - level;
    ((p[0] >> s & 1) << 2 | (p[1] >> s & 1) << 1 | (p[2] >> s & 1)) as usize
}

/// Code the `bits - level` low bits of each axis of a lone point, x then y then z, each axis
/// as one uniform symbol (they are close to uniform; one coder step instead of one per bit).
fn code_lone<C: BitCoder>(c: &mut C, p: &mut [u16; 3], bits: u8, level: usize) -> Result<()> {
    let k = bits - level as u8;
    for v in p.iter_mut() {
        let low = c.uniform(*v as u32, k)?;
        *v = ((*v as u32 >> k << k) | low) as u16;
    }
    Ok(())
}

/// Code `count >= 2` as Elias gamma of `count - 1`: the bit length minus one in unary (models),
/// then the bits under the leading one (raw).
fn code_count<C: BitCoder>(c: &mut C, m: &mut Models, count: u64) -> Result<Option<u64>> {
    let v = count.wrapping_sub(1);
    let len = 64 - v.leading_zeros() as usize;
    let mut got = 1usize;
    while got < COUNT_PREFIX && c.code(&mut m.count[got - 1], len > got)? {
        got += 1;
    }
    if got >= COUNT_PREFIX {
        return Ok(None);
    }
    let mut out = 1u64;
    for s in (0..got - 1).rev() {
        out = out << 1 | c.raw(v >> s & 1 == 1)? as u64;
    }
    Ok(Some(out + 1))
}

/// Encode `points` (each axis below `2^bits`). Returns the data and the Morton order the
/// decoder will produce: `order[k]` = index in `points` of the `k`-th decoded point
/// (duplicates keep their input order).
pub fn encode(points: &[[u16; 3]], bits: u8) -> (Vec<u8>, Vec<u32>) {
    assert!((1..=MAX_BITS).contains(&bits), "1..=16 bits per axis");
    let mut order: Vec<u32> = (0..points.len() as u32).collect();
    order.sort_by_key(|&i| (morton(points[i as usize], bits), i));
    let sorted: Vec<[u16; 3]> = order.iter().map(|&i| points[i as usize]).collect();
    let mut coder = Encoder(DefaultRangeEncoder::new());
    let mut m = Models::new();
    match sorted.len() {
        0 => {}
        1 => {
            let mut p = sorted[0];
            code_lone(&mut coder, &mut p, bits, 0).expect("encoding cannot fail");
        }
        _ => encode_node(&mut coder, &mut m, &sorted, bits, 0, 1),
    }
    let words = coder.0.into_compressed().expect("in-memory backend");
    let mut out = Vec::with_capacity(4 + 4 * words.len());
    out.put_u32(words.len() as u32);
    for w in &words {
        out.put_u32(*w);
    }
    (out, order)
}

/// A node at `level` holding the Morton-sorted `pts` (at least two).
fn encode_node(
    c: &mut Encoder,
    m: &mut Models,
    pts: &[[u16; 3]],
    bits: u8,
    level: usize,
    siblings: usize,
) {
    // Children: runs of equal digits (the points are Morton-sorted).
    let mut kids: Vec<&[[u16; 3]]> = Vec::with_capacity(8);
    let mut digits = Vec::with_capacity(8);
    let mut start = 0;
    for i in 1..=pts.len() {
        if i == pts.len() || digit(pts[i], bits, level) != digit(pts[start], bits, level) {
            kids.push(&pts[start..i]);
            digits.push(digit(pts[start], bits, level));
            start = i;
        }
    }
    let mut so_far = 0;
    for j in 0..8 {
        let occupied = digits.contains(&j);
        if j == 7 && so_far == 0 {
            break; // a node with two points has a child: the last one, if no other
        }
        let model = occupancy_model(level, j, so_far, siblings);
        c.code(&mut m.occupancy[model], occupied)
            .expect("encoding cannot fail");
        so_far += occupied as usize;
    }
    let k = kids.len();
    if k > 1 {
        for kid in &kids {
            let model = single_model(level + 1, k);
            c.code(&mut m.single[model], kid.len() == 1)
                .expect("encoding cannot fail");
        }
    }
    for kid in kids {
        if kid.len() == 1 {
            let mut p = kid[0];
            code_lone(c, &mut p, bits, level + 1).expect("encoding cannot fail");
        } else if level + 1 == bits as usize {
            code_count(c, m, kid.len() as u64).expect("encoding cannot fail");
        } else {
            encode_node(c, m, kid, bits, level + 1, k);
        }
    }
}

/// Decode `n` points of `bits` per axis from exactly the bytes of `r`, in Morton order.
pub fn decode(mut r: ByteReader, n: usize, bits: u8) -> Result<Vec<[u16; 3]>> {
    if !(1..=MAX_BITS).contains(&bits) {
        return Err(Error::payload(
            ChunkType::CSOG,
            format!("octree of {bits} bits per axis (1..=16)"),
            r.offset(),
        ));
    }
    let dec = open_stream(&mut r, "octree")?;
    let mut c = Decoder { dec, r: &r };
    let mut m = Models::new();
    let mut out = Vec::with_capacity(n);
    match n {
        0 => {}
        1 => {
            let mut p = [0u16; 3];
            code_lone(&mut c, &mut p, bits, 0)?;
            out.push(p);
        }
        _ => {
            // Points the tree must hold at least: 2 per node known to hold several.
            let mut least = 2usize;
            decode_node(&mut c, &mut m, &mut out, &mut least, n, [0; 3], bits, 0, 1)?;
        }
    }
    if out.len() != n {
        return Err(Error::payload(
            ChunkType::CSOG,
            format!("the octree holds {} points, the set {n}", out.len()),
            r.offset(),
        ));
    }
    Ok(out)
}

/// Decode a node at `level` whose top `level` bits per axis are `prefix` and which holds at
/// least two points. `least` counts the points decoded plus those the open nodes must hold;
/// it never exceeds `n`, which bounds the walk.
#[allow(clippy::too_many_arguments)]
fn decode_node(
    c: &mut Decoder,
    m: &mut Models,
    out: &mut Vec<[u16; 3]>,
    least: &mut usize,
    n: usize,
    prefix: [u16; 3],
    bits: u8,
    level: usize,
    siblings: usize,
) -> Result<()> {
    let mut digits = [0usize; 8];
    let mut k = 0;
    for j in 0..8 {
        let occupied = if j == 7 && k == 0 {
            true
        } else {
            let model = occupancy_model(level, j, k, siblings);
            c.code(&mut m.occupancy[model], false)?
        };
        if occupied {
            digits[k] = j;
            k += 1;
        }
    }
    let mut single = [false; 8];
    if k > 1 {
        for s in single.iter_mut().take(k) {
            *s = c.code(&mut m.single[single_model(level + 1, k)], false)?;
        }
    }
    // This node was counted as 2; its children replace it.
    *least = *least - 2
        + single[..k]
            .iter()
            .map(|&s| if s { 1 } else { 2 })
            .sum::<usize>();
    if *least > n {
        return Err(Error::payload(
            ChunkType::CSOG,
            format!("the octree holds more than {n} points"),
            c.r.offset(),
        ));
    }
    let shift = bits as usize - 1 - level;
    for (&j, &lone) in digits[..k].iter().zip(&single) {
        let child = [
            prefix[0] | ((j >> 2 & 1) as u16) << shift,
            prefix[1] | ((j >> 1 & 1) as u16) << shift,
            prefix[2] | ((j & 1) as u16) << shift,
        ];
        if lone {
            let mut p = child;
            code_lone(c, &mut p, bits, level + 1)?;
            out.push(p);
        } else if level + 1 == bits as usize {
            let count = code_count(c, m, 0)?
                .filter(|&v| v <= (n - *least + 2) as u64)
                .ok_or_else(|| {
                    Error::payload(
                        ChunkType::CSOG,
                        format!("the octree holds more than {n} points"),
                        c.r.offset(),
                    )
                })?;
            *least = *least - 2 + count as usize;
            out.extend(std::iter::repeat_n(child, count as usize));
        } else {
            decode_node(c, m, out, least, n, child, bits, level + 1, k)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud(n: usize, bits: u8, seed: u32) -> Vec<[u16; 3]> {
        let mut s = seed;
        let mask = ((1u32 << bits) - 1) as u16;
        (0..n)
            .map(|_| {
                let mut r = || {
                    s ^= s << 13;
                    s ^= s >> 17;
                    s ^= s << 5;
                    s as u16 & mask
                };
                [r(), r(), r()]
            })
            .collect()
    }

    fn round_trip(points: &[[u16; 3]], bits: u8) -> usize {
        let (data, order) = encode(points, bits);
        let back = decode(ByteReader::new(&data, 0), points.len(), bits).expect("decodes");
        let expect: Vec<[u16; 3]> = order.iter().map(|&i| points[i as usize]).collect();
        assert_eq!(back, expect, "{bits} bits, {} points", points.len());
        data.len()
    }

    #[test]
    fn sets_round_trip_with_duplicates_extremes_and_any_size() {
        for bits in [1u8, 2, 5, 13, 16] {
            for n in [0usize, 1, 2, 3, 17, 500] {
                let mut p = cloud(n, bits, 7 + n as u32);
                if n > 4 {
                    // Duplicates, and the corners of the cube.
                    p[1] = p[0];
                    p[2] = p[0];
                    p[3] = [0; 3];
                    p[4] = [((1u32 << bits) - 1) as u16; 3];
                }
                round_trip(&p, bits);
            }
        }
        // All points in one voxel.
        round_trip(&vec![[3, 1, 2]; 40], 2);
    }

    #[test]
    fn clustered_points_cost_less_than_raw() {
        // Points on a plane: far fewer than 3 x 14 bits each.
        let p: Vec<[u16; 3]> = cloud(4000, 14, 3)
            .into_iter()
            .map(|[x, y, _]| [x, y, 8000])
            .collect();
        let bytes = round_trip(&p, 14);
        assert!(
            bytes * 8 < p.len() * 30,
            "{} bits/point",
            bytes * 8 / p.len()
        );
    }

    #[test]
    fn damaged_streams_give_errors_not_panics() {
        let p = cloud(300, 12, 5);
        let (data, _) = encode(&p, 12);
        for cut in [0, 3, 4, 9, data.len() / 2, data.len() - 1] {
            let _ = decode(ByteReader::new(&data[..cut], 0), p.len(), 12);
        }
        let mut s = 11u32;
        for _ in 0..200 {
            let mut d = data.clone();
            s = s.wrapping_mul(1_103_515_245).wrapping_add(12_345);
            let at = 4 + (s as usize >> 8) % (d.len() - 4);
            d[at] ^= 1 << (s % 8);
            let _ = decode(ByteReader::new(&d, 0), p.len(), 12);
            // Fewer or more points than coded.
            let _ = decode(ByteReader::new(&data, 0), p.len() - 1, 12);
            let _ = decode(ByteReader::new(&data, 0), p.len() + 1, 12);
        }
    }
}
