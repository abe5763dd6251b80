//! Which Gaussian of one frame is which of the next. Per-frame splat files are often sorted
//! independently (PlayCanvas SOG sorts each frame along a space-filling curve), so Gaussian i
//! of one frame is not Gaussian i of the next. The match is recovered from position
//! continuity: each Gaussian's nearest neighbour in the other frame, kept where the two agree
//! (mutual nearest neighbours); the few left over are paired greedily by distance. A match is
//! *confident* when it is mutual and the nearest neighbour is at most half as far as the
//! second nearest; a sequence whose share of confident matches falls below a floor is refused,
//! never encoded with a wrong correspondence.

use std::collections::HashMap;

/// How frame `b` maps onto frame `a`.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameMatch {
    /// `prev_of[j]`: the Gaussian of `a` that Gaussian `j` of `b` continues.
    pub prev_of: Vec<u32>,
    /// Matches that are mutual nearest neighbours with a clear margin (see the module doc).
    pub confident: usize,
    /// Matches that are mutual nearest neighbours.
    pub mutual: usize,
    /// Largest distance between matched positions.
    pub max_distance: f32,
}

impl FrameMatch {
    /// The share of confident matches, 0..=1.
    pub fn confident_share(&self) -> f64 {
        self.confident as f64 / self.prev_of.len().max(1) as f64
    }
}

/// Largest number of Gaussians left after mutual matching that are paired greedily (the
/// pairing compares every leftover pair); more means the frames do not correspond.
pub const MAX_LEFTOVER: usize = 4096;

/// A uniform grid over points for exact nearest-neighbour queries.
struct Grid<'a> {
    points: &'a [[f32; 3]],
    origin: [f32; 3],
    cell: f32,
    /// Cells per axis (the search stops once it has covered them all).
    extent: i32,
    cells: HashMap<[i32; 3], Vec<u32>>,
}

impl<'a> Grid<'a> {
    fn new(points: &'a [[f32; 3]]) -> Grid<'a> {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in points {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        let span = (0..3).map(|a| hi[a] - lo[a]).fold(0.0f32, f32::max);
        // About a handful of points per cell for volumes; surfaces get a few more.
        let cell = (span / (points.len().max(1) as f32).cbrt()).max(1e-6);
        let extent = ((span / cell).ceil() as i32).max(1);
        let mut cells: HashMap<[i32; 3], Vec<u32>> = HashMap::new();
        let grid = Grid {
            points,
            origin: lo,
            cell,
            extent,
            cells: HashMap::new(),
        };
        for (i, p) in points.iter().enumerate() {
            cells.entry(grid.key(p)).or_default().push(i as u32);
        }
        Grid { cells, ..grid }
    }

    fn key(&self, p: &[f32; 3]) -> [i32; 3] {
        std::array::from_fn(|a| ((p[a] - self.origin[a]) / self.cell).floor() as i32)
    }

    /// The nearest and second-nearest points to `q` as (index, squared distance); ties go to
    /// the lower index.
    fn nearest2(&self, q: &[f32; 3]) -> ((u32, f32), (u32, f32)) {
        let c = self.key(q);
        let mut best = (u32::MAX, f32::INFINITY);
        let mut second = (u32::MAX, f32::INFINITY);
        for r in 0..=self.extent + 1 {
            for dx in -r..=r {
                for dy in -r..=r {
                    for dz in -r..=r {
                        if dx.abs().max(dy.abs()).max(dz.abs()) != r {
                            continue;
                        }
                        let Some(list) = self.cells.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) else {
                            continue;
                        };
                        for &i in list {
                            let p = &self.points[i as usize];
                            let d = (p[0] - q[0]).powi(2)
                                + (p[1] - q[1]).powi(2)
                                + (p[2] - q[2]).powi(2);
                            let cand = (i, d);
                            if (d, i) < (best.1, best.0) {
                                second = best;
                                best = cand;
                            } else if (d, i) < (second.1, second.0) {
                                second = cand;
                            }
                        }
                    }
                }
            }
            // Every point not yet seen is at least r cells away.
            let reach = r as f32 * self.cell;
            if second.1 <= reach * reach {
                break;
            }
        }
        (best, second)
    }
}

/// Match frame `b` onto frame `a` (equal counts). `Err` with the reason when they cannot be
/// matched one to one.
pub fn match_frames(a: &[[f32; 3]], b: &[[f32; 3]]) -> Result<FrameMatch, String> {
    if a.len() != b.len() {
        return Err(format!("{} Gaussians, then {}", a.len(), b.len()));
    }
    let n = a.len();
    if n == 0 {
        return Ok(FrameMatch {
            prev_of: Vec::new(),
            confident: 0,
            mutual: 0,
            max_distance: 0.0,
        });
    }
    if n == 1 {
        let d = dist2(&a[0], &b[0]).sqrt();
        return Ok(FrameMatch {
            prev_of: vec![0],
            confident: 1,
            mutual: 1,
            max_distance: d,
        });
    }
    let ga = Grid::new(a);
    let gb = Grid::new(b);
    let from_b: Vec<((u32, f32), (u32, f32))> = b.iter().map(|q| ga.nearest2(q)).collect();
    let from_a: Vec<u32> = a.iter().map(|q| gb.nearest2(q).0 .0).collect();
    let mut prev_of = vec![u32::MAX; n];
    let mut taken = vec![false; n];
    let (mut mutual, mut confident) = (0, 0);
    for (j, &((i, d1), (_, d2))) in from_b.iter().enumerate() {
        if from_a[i as usize] == j as u32 {
            prev_of[j] = i;
            taken[i as usize] = true;
            mutual += 1;
            // Squared distances: nearest at most half as far as the second.
            if d1 <= 0.25 * d2 {
                confident += 1;
            }
        }
    }
    let left_b: Vec<usize> = (0..n).filter(|&j| prev_of[j] == u32::MAX).collect();
    let left_a: Vec<usize> = (0..n).filter(|&i| !taken[i]).collect();
    if left_b.len() > MAX_LEFTOVER {
        return Err(format!(
            "{} of {n} Gaussians have no mutual nearest neighbour (at most {MAX_LEFTOVER} are \
             paired by distance)",
            left_b.len()
        ));
    }
    let mut pairs: Vec<(f32, usize, usize)> = left_b
        .iter()
        .flat_map(|&j| left_a.iter().map(move |&i| (dist2(&a[i], &b[j]), j, i)))
        .collect();
    pairs.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)).then(x.2.cmp(&y.2)));
    for (_, j, i) in pairs {
        if prev_of[j] == u32::MAX && !taken[i] {
            prev_of[j] = i as u32;
            taken[i] = true;
        }
    }
    let max_distance = (0..n)
        .map(|j| dist2(&a[prev_of[j] as usize], &b[j]))
        .fold(0.0f32, f32::max)
        .sqrt();
    Ok(FrameMatch {
        prev_of,
        confident,
        mutual,
        max_distance,
    })
}

fn dist2(p: &[f32; 3], q: &[f32; 3]) -> f32 {
    (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lattice(n: usize) -> Vec<[f32; 3]> {
        (0..n * n)
            .map(|i| {
                [
                    (i % n) as f32 * 0.1,
                    ((i / n) as f32 * 0.1).sin() * 0.05,
                    (i / n) as f32 * 0.1,
                ]
            })
            .collect()
    }

    #[test]
    fn a_known_shuffle_of_a_moved_frame_is_recovered() {
        let a = lattice(40);
        let mut rng = fastrand::Rng::with_seed(7);
        let mut perm: Vec<u32> = (0..a.len() as u32).collect();
        rng.shuffle(&mut perm);
        // b[j] is a[perm[j]] moved by a fifth of the spacing.
        let b: Vec<[f32; 3]> = perm
            .iter()
            .map(|&i| {
                let p = a[i as usize];
                [p[0] + 0.01, p[1] + 0.02 * (p[0] * 3.0).sin(), p[2] - 0.005]
            })
            .collect();
        let m = match_frames(&a, &b).unwrap();
        assert_eq!(m.prev_of, perm);
        assert_eq!(m.confident, a.len());
    }

    #[test]
    fn different_counts_and_coincident_points_are_handled() {
        assert!(match_frames(&lattice(3), &lattice(4)).is_err());
        // Two Gaussians at the same place: a one-to-one match, not confident.
        let a = vec![[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
        let m = match_frames(&a, &a).unwrap();
        let mut seen = m.prev_of.clone();
        seen.sort();
        assert_eq!(seen, vec![0, 1, 2]);
        assert_eq!(m.prev_of[2], 2);
        assert!(m.confident < 3);
        assert_eq!(match_frames(&[], &[]).unwrap().prev_of, Vec::<u32>::new());
    }
}
