//! Encoder-side shaping of a quantised grid channel (rate-distortion optimised quantisation):
//! each cell takes, among the levels near its value, the one with the least estimated coded
//! bits plus weighted squared error, so a Gaussian that adds little to any image (low weight)
//! takes a level the entropy coder pays little for. The decoder is unchanged: it restores
//! whatever levels were chosen, exactly (format-spec §6.5.4, informative).
//!
//! One shaper per codec family, because "cheap" differs: the predictive codec (§6.5.3) pays
//! little for a value near the median prediction from the already coded neighbours; the
//! histogram codecs pay little for a frequent value, of the channel (codec 3) or of its
//! difference from the previous channel (codec 4).

use super::cells::{activity_threshold, class_of, context, neighbours, predict, zigzag};

/// Farthest a cell moves from its nearest value, in steps.
pub const MAX_MOVE: u16 = 4;

/// What a channel's cells are shaped from: per cell the exact value in quantisation steps
/// (`(v - min) / (max - min) * (2^bits - 1)`, clamped), its nearest level and the weight of one
/// squared step of error against one bit (0 = free to move anywhere in the window).
pub struct Cells<'a> {
    pub exact: &'a [f32],
    pub nearest: &'a [u16],
    pub weight: &'a [f32],
    pub bits: u8,
}

impl Cells<'_> {
    /// The candidate levels of cell `i`: within [`MAX_MOVE`] of the nearest, inside `bits`.
    #[inline]
    fn window(&self, i: usize) -> std::ops::RangeInclusive<u16> {
        let top = ((1u32 << self.bits) - 1) as u16;
        let q0 = self.nearest[i];
        q0.saturating_sub(MAX_MOVE)..=q0.saturating_add(MAX_MOVE).min(top)
    }
    #[inline]
    fn distortion(&self, i: usize, v: u16) -> f32 {
        let e = v as f32 - self.exact[i];
        self.weight[i] * e * e
    }
    /// The window's level with the least `rate(v) + distortion`, ties to the nearest level.
    #[inline]
    fn best(&self, i: usize, rate: impl Fn(u16) -> f32) -> u16 {
        let q0 = self.nearest[i];
        let mut best = (rate(q0) + self.distortion(i, q0), q0);
        for v in self.window(i) {
            let c = rate(v) + self.distortion(i, v);
            if c < best.0 {
                best = (c, v);
            }
        }
        best.1
    }
}

/// Bits of `-log2(count / total)`, with every count at least one half.
#[allow(clippy::disallowed_methods)] // encoder-side cost estimate
fn bits_of(count: u64, total: u64) -> f32 {
    ((total as f64).max(1.0) / (count as f64).max(0.5)).log2() as f32
}

/// For the predictive codec: in raster order, the level with the least estimated bits
/// (magnitude class under the class statistics of the nearest levels, plus its raw mantissa
/// bits) plus weighted distortion, given the already chosen neighbours.
pub fn for_prediction(c: &Cells, width: usize) -> Vec<u16> {
    let q0 = c.nearest;
    let t0 = activity_threshold(q0, width);
    let bits = c.bits;
    let mut counts = vec![[0u64; 17]; 3];
    for i in 0..q0.len() {
        let (a, b, cc, ha, hb) = neighbours(q0, i, width);
        let z = zigzag(q0[i], predict(a, b, cc, ha, hb), bits);
        counts[context(a, b, cc, t0)][class_of(z) as usize] += 1;
    }
    let cost: Vec<[f32; 17]> = counts
        .iter()
        .map(|row| {
            let total: u64 = row.iter().sum();
            std::array::from_fn(|k| bits_of(row[k], total) + k.saturating_sub(1) as f32)
        })
        .collect();
    let mut q = q0.to_vec();
    for i in 0..q.len() {
        let (a, b, cc, ha, hb) = neighbours(&q, i, width);
        let pred = predict(a, b, cc, ha, hb);
        let row = &cost[context(a, b, cc, t0)];
        q[i] = c.best(i, |v| row[class_of(zigzag(v, pred, bits)) as usize]);
    }
    q
}

/// Rounds of re-counting in the histogram shaper: each round moves cells onto the values the
/// previous one made more frequent.
const HISTOGRAM_ROUNDS: usize = 2;

/// For the histogram codecs: the level with the least `-log2(frequency)` of its symbol
/// `(v - base) mod 2^bits` (`base` = the previous channel's cells for codec 4, none for
/// codec 3) plus weighted distortion.
pub fn for_histogram(c: &Cells, base: Option<&[u16]>) -> Vec<u16> {
    let mask = ((1u32 << c.bits) - 1) as u16;
    let symbol = |i: usize, v: u16| match base {
        Some(b) => v.wrapping_sub(b[i]) & mask,
        None => v,
    } as usize;
    let mut q = c.nearest.to_vec();
    let mut counts = vec![0u64; 1usize << c.bits];
    for _ in 0..HISTOGRAM_ROUNDS {
        counts.iter_mut().for_each(|n| *n = 0);
        for (i, &v) in q.iter().enumerate() {
            counts[symbol(i, v)] += 1;
        }
        let total = q.len() as u64;
        for (i, qi) in q.iter_mut().enumerate() {
            *qi = c.best(i, |v| bits_of(counts[symbol(i, v)], total));
        }
    }
    q
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::chunks::csog::grid_coder::{encode_histogram, encode_predictive};

    /// A ramp plus 4 bits of noise, as exact values half a step off the levels.
    fn noisy(n: usize, seed: u32) -> (Vec<f32>, Vec<u16>) {
        let mut s = seed;
        let exact: Vec<f32> = (0..n)
            .map(|i| {
                s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                ((i % 64) * 8) as f32 + (s >> 28) as f32 + 0.3
            })
            .collect();
        let nearest = exact.iter().map(|v| v.round() as u16).collect();
        (exact, nearest)
    }

    #[test]
    fn shaped_cells_stay_in_the_window_and_heavy_weights_keep_the_nearest() {
        let (exact, nearest) = noisy(4096, 7);
        let weight: Vec<f32> = (0..exact.len()).map(|i| (i % 3) as f32 * 0.5).collect();
        let c = Cells {
            exact: &exact,
            nearest: &nearest,
            weight: &weight,
            bits: 10,
        };
        for q in [
            for_prediction(&c, 64),
            for_histogram(&c, None),
            for_histogram(&c, Some(&nearest[..])),
        ] {
            for i in 0..exact.len() {
                let d = (q[i] as i32 - nearest[i] as i32).unsigned_abs();
                assert!(d <= MAX_MOVE as u32, "cell {i} moved {d}");
                assert!(q[i] < 1 << 10);
            }
        }
        let heavy = vec![1e6f32; exact.len()];
        let c = Cells {
            weight: &heavy,
            ..c
        };
        assert_eq!(for_prediction(&c, 64), nearest);
        assert_eq!(for_histogram(&c, None), nearest);
    }

    #[test]
    fn shaping_makes_the_channel_cheaper_for_its_codec() {
        let (exact, nearest) = noisy(16384, 3);
        let weight = vec![0.05f32; exact.len()];
        let c = Cells {
            exact: &exact,
            nearest: &nearest,
            weight: &weight,
            bits: 10,
        };
        let before = encode_predictive(&nearest, 128, 10).len();
        let after = encode_predictive(&for_prediction(&c, 128), 128, 10).len();
        assert!(after * 10 < before * 9, "predictive {before} -> {after}");
        let before = encode_histogram(&nearest, 3).unwrap().len();
        let after = encode_histogram(&for_histogram(&c, None), 3).unwrap().len();
        assert!(after * 10 < before * 9, "histogram {before} -> {after}");
    }
}
