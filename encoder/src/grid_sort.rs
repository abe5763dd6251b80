//! Sorting Gaussians into a 2D grid so that grid neighbours are similar (format-spec §6.5.1),
//! in the spirit of PLAS (Morgenstern et al., "Compact 3D Scene Representation via
//! Self-Organizing Gaussian Grids"): an initial layout by recursive median splits of the
//! positions (a k-d tree unrolled onto the grid), then, only when asked (`passes` above
//! zero; the layout alone codes smaller on every real scene measured), rounds of "move towards
//! the blurred grid": the grid of feature vectors is box-filtered, and within groups of four
//! cells the permutation (of 24) closest to the blurred target is kept. Radii shrink from a
//! quarter of the grid to 1. Deterministic: no randomness, groups are disjoint so rounds run in parallel
//! with the same result on any thread count.

use dlgs::chunks::csog::grid_codecs::{first_valid, halves, valid_in};
use dlgs::chunks::csog::grid_width;
use dlgs::model::Gaussians;
use rayon::prelude::*;

/// Feature dimensions the sort compares: position, DC colour, mean log-scale, opacity.
const DIMS: usize = 8;
const WEIGHTS: [f32; DIMS] = [1.0, 1.0, 1.0, 0.6, 0.6, 0.6, 0.3, 0.3];

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SortSpec {
    /// Refinement passes per radius (0 = k-d layout only, fastest).
    pub passes: u32,
}

impl SortSpec {
    pub const FAST: SortSpec = SortSpec { passes: 1 };
    /// The k-d layout alone: on every real scene measured the PLAS-style refinement lowers the
    /// neighbour distance but *raises* the coded size (the predictive grid coder gains more
    /// from the layout's coherent positions than from smoother colours), by 0-15 % at 3 passes
    /// and 0-8 % at 8 (docs/benchmarks/canonical-levers.md "Grid sort"), so refinement is opt-in.
    pub const DEFAULT: SortSpec = SortSpec::NONE;
    pub const NONE: SortSpec = SortSpec { passes: 0 };
    /// The refinement at three passes per radius (the default before it was measured).
    pub const REFINED: SortSpec = SortSpec { passes: 3 };
}

/// Per-Gaussian feature vectors, each dimension standardised then weighted.
fn features(g: &Gaussians) -> Vec<[f32; DIMS]> {
    let n = g.len();
    let stride = g.sh_stride();
    let mut f: Vec<[f32; DIMS]> = (0..n)
        .map(|i| {
            let p = g.positions[i];
            let s = g.log_scales[i];
            let sh = &g.sh[i * stride..i * stride + 3];
            [
                p[0],
                p[1],
                p[2],
                sh[0],
                sh[1],
                sh[2],
                (s[0] + s[1] + s[2]) / 3.0,
                g.opacity[i],
            ]
        })
        .collect();
    for d in 0..DIMS {
        let mean = f.iter().map(|v| v[d] as f64).sum::<f64>() / n.max(1) as f64;
        let var = f.iter().map(|v| (v[d] as f64 - mean).powi(2)).sum::<f64>() / n.max(1) as f64;
        let k = if var > 0.0 {
            WEIGHTS[d] as f64 / var.sqrt()
        } else {
            0.0
        };
        for v in &mut f {
            v[d] = ((v[d] as f64 - mean) * k) as f32;
        }
    }
    f
}

/// Recursive median split: the rectangle's Gaussians are split along the position axis of
/// largest spread into the two halves of the rectangle's longer side.
fn place(
    idx: &mut [u32],
    f: &[[f32; DIMS]],
    rect: (usize, usize, usize, usize),
    width: usize,
    n: usize,
    grid: &mut [u32],
) {
    let (_, _, w, h) = rect;
    if idx.is_empty() {
        return;
    }
    if idx.len() == 1 || w * h == 1 {
        if let Some(c) = first_valid(rect, width, n) {
            grid[c] = idx[0];
        }
        return;
    }
    let (ra, rb) = halves(rect);
    let na = valid_in(ra.0, ra.1, ra.2, ra.3, width, n);
    let axis = (0..3)
        .max_by(|&a, &b| {
            let spread = |d: usize| {
                let (lo, hi) = idx
                    .iter()
                    .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &i| {
                        (lo.min(f[i as usize][d]), hi.max(f[i as usize][d]))
                    });
                hi - lo
            };
            spread(a).total_cmp(&spread(b)).then(b.cmp(&a))
        })
        .expect("three axes");
    // The rectangle's orientation picks which grid direction the axis maps to; ties broken by
    // index so the order is total.
    let key = |i: &u32| (f[*i as usize][axis], *i);
    if na > 0 && na < idx.len() {
        idx.select_nth_unstable_by(na, |a, b| {
            let (ka, kb) = (key(a), key(b));
            ka.0.total_cmp(&kb.0).then(ka.1.cmp(&kb.1))
        });
    }
    let (a, b) = idx.split_at_mut(na.min(idx.len()));
    place(a, f, ra, width, n, grid);
    place(b, f, rb, width, n, grid);
}

/// Box filter of radius `r` over the valid cells (mean of the valid cells in the window).
fn blur(cells: &[[f32; DIMS]], width: usize, n: usize, r: usize) -> Vec<[f32; DIMS]> {
    let height = n.div_ceil(width);
    // Horizontal pass per row with running sums, then vertical.
    let mut hsum = vec![[0f32; DIMS]; width * height];
    let mut hcnt = vec![0u32; width * height];
    hsum.par_chunks_mut(width)
        .zip(hcnt.par_chunks_mut(width))
        .enumerate()
        .for_each(|(y, (hs, hc))| {
            let row_n = n.saturating_sub(y * width).min(width);
            let mut pre = vec![[0f64; DIMS]; row_n + 1];
            for x in 0..row_n {
                for d in 0..DIMS {
                    pre[x + 1][d] = pre[x][d] + cells[y * width + x][d] as f64;
                }
            }
            for x in 0..row_n {
                let (a, b) = (x.saturating_sub(r), (x + r + 1).min(row_n));
                for d in 0..DIMS {
                    hs[x][d] = (pre[b][d] - pre[a][d]) as f32;
                }
                hc[x] = (b - a) as u32;
            }
        });
    (0..n)
        .into_par_iter()
        .map(|c| {
            let (x, y) = (c % width, c / width);
            let (a, b) = (y.saturating_sub(r), (y + r + 1).min(height));
            let mut s = [0f32; DIMS];
            let mut cnt = 0u32;
            for yy in a..b {
                let cc = yy * width + x;
                if cc < n {
                    for d in 0..DIMS {
                        s[d] += hsum[cc][d];
                    }
                    cnt += hcnt[cc];
                }
            }
            s.map(|v| v / cnt.max(1) as f32)
        })
        .collect()
}

const PERMS: [[usize; 4]; 24] = {
    let mut out = [[0; 4]; 24];
    let mut k = 0;
    let mut a = 0;
    while a < 4 {
        let mut b = 0;
        while b < 4 {
            let mut c = 0;
            while c < 4 {
                if a != b && a != c && b != c {
                    out[k] = [a, b, c, 6 - a - b - c];
                    k += 1;
                }
                c += 1;
            }
            b += 1;
        }
        a += 1;
    }
    out
};

fn dist2(a: &[f32; DIMS], b: &[f32; DIMS]) -> f32 {
    (0..DIMS).map(|d| (a[d] - b[d]) * (a[d] - b[d])).sum()
}

/// One refinement pass: groups of four cells `(x, y), (x+s, y), (x, y+s), (x+s, y+s)` tiling
/// the grid with period `2s` (shifted by `shift`), each permuted to best match the target.
fn pass(
    grid: &mut [u32],
    f: &[[f32; DIMS]],
    width: usize,
    n: usize,
    r: usize,
    s: usize,
    shift: usize,
) {
    let cells: Vec<[f32; DIMS]> = grid.iter().map(|&i| f[i as usize]).collect();
    let target = blur(&cells, width, n, r);
    let height = n.div_ceil(width);
    let period = 2 * s;
    // Each group is identified by its top-left cell; groups are disjoint.
    let groups: Vec<[usize; 4]> = (0..height)
        .flat_map(|y| (0..width).map(move |x| (x, y)))
        .filter_map(|(x, y)| {
            let (xs, ys) = (x + shift, y + shift);
            if xs % period >= s || ys % period >= s {
                return None;
            }
            let c = [
                y * width + x,
                y * width + x + s,
                (y + s) * width + x,
                (y + s) * width + x + s,
            ];
            (x + s < width && c[3] < n).then_some(c)
        })
        .collect();
    let moves: Vec<Option<([usize; 4], [u32; 4])>> = groups
        .par_iter()
        .map(|c| {
            let mut cost = [[0f32; 4]; 4];
            for (a, row) in cost.iter_mut().enumerate() {
                for (p, v) in row.iter_mut().enumerate() {
                    *v = dist2(&cells[c[a]], &target[c[p]]);
                }
            }
            let (best, _) = PERMS
                .iter()
                .enumerate()
                .map(|(k, perm)| (k, (0..4).map(|a| cost[a][perm[a]]).sum::<f32>()))
                .min_by(|x, y| x.1.total_cmp(&y.1).then(x.0.cmp(&y.0)))
                .expect("24 permutations");
            if best == 0 {
                return None; // identity
            }
            let perm = PERMS[best];
            let mut moved = [0u32; 4];
            for a in 0..4 {
                moved[perm[a]] = grid[c[a]];
            }
            Some((*c, moved))
        })
        .collect();
    for (c, moved) in moves.into_iter().flatten() {
        for k in 0..4 {
            grid[c[k]] = moved[k];
        }
    }
}

/// The grid order: `order[cell] = index of the Gaussian placed there`, cells row-major in a
/// [`grid_width`]-wide grid.
pub fn grid_order(g: &Gaussians, spec: SortSpec) -> Vec<u32> {
    grid_order_with_width(g, spec, grid_width(g.len()))
}

/// [`grid_order`] for a grid `width` cells wide (e.g. the tiles of the time features, §6.2).
pub fn grid_order_with_width(g: &Gaussians, spec: SortSpec, width: usize) -> Vec<u32> {
    let n = g.len();
    if n == 0 {
        return Vec::new();
    }
    let width = width.clamp(1, n);
    let height = n.div_ceil(width);
    let f = features(g);
    let mut idx: Vec<u32> = (0..n as u32).collect();
    let mut grid = vec![0u32; n];
    place(&mut idx, &f, (0, 0, width, height), width, n, &mut grid);
    if spec.passes > 0 {
        let mut r = (width.max(height) / 4).max(1);
        loop {
            for p in 0..spec.passes as usize {
                let s = (r / 2).max(1);
                pass(&mut grid, &f, width, n, r, s, p % 2 * s);
            }
            if r == 1 {
                break;
            }
            r /= 2;
        }
    }
    grid
}

/// Mean squared feature distance between grid neighbours (right and down): what sorting lowers.
pub fn neighbour_distance(g: &Gaussians, order: &[u32]) -> f32 {
    let n = order.len();
    if n < 2 {
        return 0.0;
    }
    let f = features(g);
    let width = grid_width(n);
    let (mut s, mut c) = (0f64, 0u64);
    for i in 0..n {
        let a = &f[order[i] as usize];
        if i % width + 1 < width && i + 1 < n {
            s += dist2(a, &f[order[i + 1] as usize]) as f64;
            c += 1;
        }
        if i + width < n {
            s += dist2(a, &f[order[i + width] as usize]) as f64;
            c += 1;
        }
    }
    (s / c as f64) as f32
}

/// `g` reordered: Gaussian `k` of the result is `g[order[k]]`.
pub fn permute(g: &Gaussians, order: &[u32]) -> Gaussians {
    let mut out = Gaussians::new(g.sh_degree, g.lang_width);
    for &i in order {
        out.push_from(g, i as usize);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud(n: usize) -> Gaussians {
        let mut g = Gaussians::new(0, 0);
        let mut s = 9u32;
        let mut rnd = || {
            s = s.wrapping_mul(1664525).wrapping_add(1013904223);
            (s >> 8) as f32 / (1u32 << 24) as f32
        };
        for _ in 0..n {
            g.positions.push([rnd(), rnd(), rnd()]);
            g.log_scales.push([-3.0; 3]);
            g.rotations.push([1.0, 0.0, 0.0, 0.0]);
            g.opacity.push(rnd());
            g.sh.extend([rnd(), rnd(), rnd()]);
        }
        g
    }

    #[test]
    fn order_is_a_permutation_and_sorting_helps() {
        for n in [1, 2, 3, 10, 99, 1000, 2477] {
            let g = cloud(n);
            let o = grid_order(&g, SortSpec::REFINED);
            let mut seen = o.clone();
            seen.sort();
            assert_eq!(seen, (0..n as u32).collect::<Vec<_>>(), "n = {n}");
            if n >= 99 {
                let id: Vec<u32> = (0..n as u32).collect();
                let kd = grid_order(&g, SortSpec::NONE);
                let (d0, d1, d2) = (
                    neighbour_distance(&g, &id),
                    neighbour_distance(&g, &kd),
                    neighbour_distance(&g, &o),
                );
                assert!(d1 < d0 * 0.6 && d2 < d1, "n = {n}: {d0} {d1} {d2}");
            }
        }
    }

    #[test]
    fn same_order_on_any_thread_count() {
        let g = cloud(3000);
        let run = |t| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .unwrap()
                .install(|| grid_order(&g, SortSpec::REFINED))
        };
        assert_eq!(run(1), run(2));
    }
}
