//! What the grid codecs share (format-spec §6.5.3): a cell's grid neighbours, LOCO-I's median
//! edge prediction, activity classes and contexts, the zigzag map of residuals modulo
//! `2^bits`, and reading a range-coded stream's words. Both the classic codecs
//! ([`super::grid_coder`]) and the adaptive one ([`super::adaptive_coder`]) build on these.

use crate::bytes::ByteReader;
use crate::container::ChunkType;
use crate::error::Result;
use crate::Error;

/// Left, up and up-left neighbours of cell `i` (0 where absent) and whether each exists.
#[inline]
pub(crate) fn neighbours(q: &[u16], i: usize, width: usize) -> (u16, u16, u16, bool, bool) {
    let (x, y) = (i % width, i / width);
    let a = if x > 0 { q[i - 1] } else { 0 };
    let b = if y > 0 { q[i - width] } else { 0 };
    let c = if x > 0 && y > 0 { q[i - width - 1] } else { 0 };
    (a, b, c, x > 0, y > 0)
}

/// Median edge detector; the first row predicts from the left, the first column from above.
#[inline]
pub(crate) fn predict(a: u16, b: u16, c: u16, has_a: bool, has_b: bool) -> u16 {
    match (has_a, has_b) {
        (true, true) => {
            let (lo, hi) = (a.min(b), a.max(b));
            if c >= hi {
                lo
            } else if c <= lo {
                hi
            } else {
                (a as i32 + b as i32 - c as i32) as u16
            }
        }
        (true, false) => a,
        (false, true) => b,
        (false, false) => 0,
    }
}

/// Bit length of `v` (0 for 0).
#[inline]
pub(crate) fn class_of(v: u32) -> u32 {
    32 - v.leading_zeros()
}

#[inline]
pub(crate) fn context(a: u16, b: u16, c: u16, t0: u32) -> usize {
    let act = (a as i32 - c as i32).unsigned_abs()
        + (b as i32 - c as i32).unsigned_abs()
        + (a as i32 - b as i32).unsigned_abs();
    let k = class_of(act);
    if k <= t0 {
        0
    } else if k <= t0 + 2 {
        1
    } else {
        2
    }
}

/// Residual `q - pred` modulo `2^bits`, as a signed value in `[-2^(bits-1), 2^(bits-1))`,
/// zigzag-mapped to `[0, 2^bits)`.
#[inline]
pub(crate) fn zigzag(q: u16, pred: u16, bits: u8) -> u32 {
    let m = 1i32 << bits;
    let mut r = (q as i32 - pred as i32).rem_euclid(m);
    if r >= m / 2 {
        r -= m;
    }
    ((r << 1) ^ (r >> 31)) as u32
}

#[inline]
pub(crate) fn unzigzag(z: u32, pred: u16, bits: u8) -> u16 {
    let r = ((z >> 1) as i32) ^ -((z & 1) as i32);
    (pred as i32 + r).rem_euclid(1 << bits) as u16
}

/// Context threshold: the median activity class, so the three contexts split the cells.
pub(crate) fn activity_threshold(q: &[u16], width: usize) -> u32 {
    let mut hist = [0u64; 34];
    for i in 0..q.len() {
        let (a, b, c, ..) = neighbours(q, i, width);
        let act = (a as i32 - c as i32).unsigned_abs()
            + (b as i32 - c as i32).unsigned_abs()
            + (a as i32 - b as i32).unsigned_abs();
        hist[class_of(act) as usize] += 1;
    }
    let mut acc = 0;
    hist.iter()
        .position(|&h| {
            acc += h;
            acc * 2 >= q.len() as u64
        })
        .unwrap_or(0) as u32
}

/// A word count (u32) and that many u32 LE words of a range-coded stream.
pub(crate) fn read_words(r: &mut ByteReader) -> Result<Vec<u32>> {
    let nwords = r.u32("range coder word count")? as usize;
    let raw = r.take(
        nwords
            .checked_mul(4)
            .ok_or_else(|| Error::payload(ChunkType::CSOG, "word count overflows", r.offset()))?,
        "range coder words",
    )?;
    Ok(raw
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")))
        .collect())
}
