//! The grid order of an octree set (format-spec §6.5.5): a k-d layout of the decoded quantised
//! positions, computed the same way by the encoder and every reader, so the order costs no
//! bits. Recursive median splits: a rectangle of the grid and the points it holds are halved
//! along the rectangle's longer side, the points by the axis of largest extent in scene units.

use super::grid_width;

/// Cells `0..n` of a `width`-wide grid inside the rectangle are those with row-major index < n.
pub fn valid_in(x0: usize, y0: usize, w: usize, h: usize, width: usize, n: usize) -> usize {
    (y0..y0 + h)
        .map(|y| {
            let row_start = y * width;
            if row_start >= n {
                0
            } else {
                (n - row_start).saturating_sub(x0).min(w)
            }
        })
        .sum()
}

/// A grid rectangle: first column, first row, width, height.
pub type Rect = (usize, usize, usize, usize);

/// The two halves of a rectangle, split across its longer side (columns when `w >= h`).
pub fn halves((x0, y0, w, h): Rect) -> (Rect, Rect) {
    if w >= h {
        let w1 = w / 2;
        ((x0, y0, w1, h), (x0 + w1, y0, w - w1, h))
    } else {
        let h1 = h / 2;
        ((x0, y0, w, h1), (x0, y0 + h1, w, h - h1))
    }
}

/// The rectangle's first valid cell (index below `n`) in row-major order, if any.
pub fn first_valid((x0, y0, _, h): Rect, width: usize, n: usize) -> Option<usize> {
    (y0..y0 + h).map(|y| y * width + x0).find(|&c| c < n)
}

/// Below this many points a rectangle is split on the calling thread.
const PARALLEL_MIN: usize = 16_384;

/// A point and its index, kept together so the splits read memory in order.
type Entry = ([u16; 3], u32);

struct Layout {
    /// Scene units per quantisation step, per axis.
    step: [f64; 3],
    width: usize,
    n: usize,
}

impl Layout {
    /// The axis of largest `(max - min) × step` over `idx` (ties: the lowest axis).
    fn axis(&self, idx: &[Entry]) -> usize {
        let mut lo = [u16::MAX; 3];
        let mut hi = [0u16; 3];
        for &(p, _) in idx {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        let extent = |a: usize| (hi[a] - lo[a]) as f64 * self.step[a];
        let mut best = 0;
        for a in 1..3 {
            if extent(a) > extent(best) {
                best = a;
            }
        }
        best
    }

    /// Place `idx` (exactly the rectangle's valid cells in number): `cell[k]` becomes the
    /// grid cell of point `idx[k]`. Both slices split at the same point with the points, so
    /// every split may run in parallel.
    fn place(&self, idx: &mut [Entry], rect: Rect, cell: &mut [u32]) {
        let (_, _, w, h) = rect;
        if idx.is_empty() {
            return;
        }
        if idx.len() == 1 || w * h == 1 {
            if let Some(c) = first_valid(rect, self.width, self.n) {
                cell[0] = c as u32;
            }
            return;
        }
        let (ra, rb) = halves(rect);
        let na = valid_in(ra.0, ra.1, ra.2, ra.3, self.width, self.n).min(idx.len());
        let axis = self.axis(idx);
        if na > 0 && na < idx.len() {
            // Points are ordered by the coordinate, then by index: a total order, so the split
            // is the same whatever the selection algorithm. Both in one integer, which
            // compares faster than the pair.
            idx.select_nth_unstable_by_key(na, |&(p, i)| (p[axis] as u64) << 32 | i as u64);
        }
        let (a, b) = idx.split_at_mut(na);
        let (ca, cb) = cell.split_at_mut(na);
        if a.len() + b.len() >= PARALLEL_MIN {
            rayon::join(|| self.place(a, ra, ca), || self.place(b, rb, cb));
        } else {
            self.place(a, ra, ca);
            self.place(b, rb, cb);
        }
    }
}

/// Grid order of `points` (indices into them, cell by cell, row-major in a
/// [`grid_width`]-wide grid). `step[a]` is the scene distance of one quantisation step on
/// axis `a`; only the comparison of extents uses it.
pub fn kd_layout(points: &[[u16; 3]], step: [f64; 3]) -> Vec<u32> {
    let n = points.len();
    if n == 0 {
        return Vec::new();
    }
    let width = grid_width(n);
    let height = n.div_ceil(width);
    let layout = Layout { step, width, n };
    let mut idx: Vec<Entry> = points.iter().zip(0..).map(|(&p, i)| (p, i)).collect();
    let mut cell = vec![0u32; n];
    layout.place(&mut idx, (0, 0, width, height), &mut cell);
    let mut grid = vec![0u32; n];
    for (&(_, i), &c) in idx.iter().zip(&cell) {
        grid[c as usize] = i;
    }
    grid
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud(n: usize) -> Vec<[u16; 3]> {
        let mut s = 9u32;
        (0..n)
            .map(|_| {
                let mut r = || {
                    s ^= s << 13;
                    s ^= s >> 17;
                    s ^= s << 5;
                    (s % 4096) as u16
                };
                [r(), r() / 4, r() / 16]
            })
            .collect()
    }

    #[test]
    fn layout_is_a_permutation_with_close_neighbours_on_any_thread_count() {
        for n in [1usize, 2, 3, 5, 17, 1000, 40_000] {
            let p = cloud(n);
            let order = kd_layout(&p, [1.0, 1.0, 1.0]);
            let mut seen = order.clone();
            seen.sort_unstable();
            assert_eq!(seen, (0..n as u32).collect::<Vec<_>>(), "{n}");
            let one = rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .build()
                .expect("pool")
                .install(|| kd_layout(&p, [1.0, 1.0, 1.0]));
            assert_eq!(order, one, "{n}: same order on one thread");
        }
        // Neighbours in the grid are closer than random pairs.
        let p = cloud(10_000);
        let order = kd_layout(&p, [1.0, 1.0, 1.0]);
        let d = |a: [u16; 3], b: [u16; 3]| -> f64 {
            (0..3).map(|k| (a[k] as f64 - b[k] as f64).abs()).sum()
        };
        let near: f64 = order
            .windows(2)
            .map(|w| d(p[w[0] as usize], p[w[1] as usize]))
            .sum::<f64>()
            / (order.len() - 1) as f64;
        let far: f64 = p.windows(2).map(|w| d(w[0], w[1])).sum::<f64>() / (p.len() - 1) as f64;
        assert!(near * 4.0 < far, "neighbours {near} vs random {far}");
    }
}
