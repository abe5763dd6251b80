//! Where the synthetic language puts each category's 3-dim code (`labels.rs`).
//!
//! Alpha blending mixes the codes of Gaussians that share a pixel. With the decoder's first
//! layer `ReLU(c_j . x - 1/2)`, a pixel holding share `a` of category A and `b` of B switches
//! A's unit on when `a + b (c_A . c_B) > 1/2`: exactly the majority rule (`a > 1/2`) when
//! `c_A . c_B = 0`, already at `a < 1/2` when the two codes point the same way, and only
//! above `a > 1/2` when they point apart. So codes of categories that touch in 3D should be
//! orthogonal, and every pair of codes far enough apart that a pure code never switches on
//! another unit. 3 dimensions cannot make every touching pair orthogonal, so the placement
//! weighs pairs by how much they touch.

use dlgs::Gaussians;

/// Largest cosine allowed between any two codes (below the decoder's cap of 1/2 with margin,
/// so a pure code switches on only its own unit).
pub const MAX_COSINE: f64 = 0.45;
const TARGET_COSINE: f64 = 0.4;
const STARTS: usize = 48;
const STEPS: usize = 1500;
const STEP_SIZE: f64 = 0.01;
const SEPARATION_WEIGHT: f64 = 50.0;

/// How much each pair of labels touches in 3D: the number of Gaussian pairs with different
/// labels closer than twice the sum of their largest scales (each radius capped at half a grid
/// cell, cells four median radii wide, so one huge Gaussian cannot make the search quadratic).
/// Label 0 ("not annotated") and non-finite Gaussians are ignored.
pub fn touch_weights(g: &Gaussians, labels: &[u16], classes: usize) -> Vec<Vec<f64>> {
    let mut w = vec![vec![0.0; classes]; classes];
    let items: Vec<(usize, [f32; 3], f32)> = (0..g.len().min(labels.len()))
        .filter(|&i| labels[i] != 0 && (labels[i] as usize) < classes)
        .filter_map(|i| {
            let p = g.positions[i];
            let s = 2.0
                * g.log_scales[i]
                    .iter()
                    .copied()
                    .fold(f32::MIN, f32::max)
                    .exp();
            (p.iter().all(|v| v.is_finite()) && s.is_finite()).then_some((i, p, s))
        })
        .collect();
    if items.is_empty() {
        return w;
    }
    let mut radii: Vec<f32> = items.iter().map(|x| x.2).collect();
    radii.sort_by(f32::total_cmp);
    let cell = (4.0 * radii[radii.len() / 2]).max(1e-12);
    let key = |p: [f32; 3]| p.map(|v| (v / cell).floor() as i64);
    let mut grid: std::collections::BTreeMap<[i64; 3], Vec<usize>> = Default::default();
    for (k, it) in items.iter().enumerate() {
        grid.entry(key(it.1)).or_default().push(k);
    }
    for (k, &(i, p, s)) in items.iter().enumerate() {
        let c = key(p);
        let ri = s.min(cell * 0.5);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(cands) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) else {
                        continue;
                    };
                    for &m in cands.iter().filter(|&&m| m > k) {
                        let (j, q, t) = items[m];
                        let (a, b) = (labels[i] as usize, labels[j] as usize);
                        if a == b {
                            continue;
                        }
                        let d2: f32 = (0..3).map(|x| (p[x] - q[x]).powi(2)).sum();
                        let r = ri + t.min(cell * 0.5);
                        if d2 < r * r {
                            w[a][b] += 1.0;
                            w[b][a] += 1.0;
                        }
                    }
                }
            }
        }
    }
    w
}

/// Unit codes for `count` slots whose pairwise touch weights are `weights` (`count x count`;
/// slots without touches are only kept apart). Minimises `sum w_ab (c_a . c_b)^2`
/// subject to every cosine below [`MAX_COSINE`], by projected gradient descent from seeded
/// random starts; deterministic. `None` when no start meets the separation.
pub fn place_codes(weights: &[Vec<f64>], seed: u64) -> Option<Vec<[f64; 3]>> {
    let n = weights.len();
    let top = weights
        .iter()
        .flatten()
        .copied()
        .fold(0.0f64, f64::max)
        .max(1e-300);
    let mut rng = fastrand::Rng::with_seed(seed);
    let mut best: Option<(f64, Vec<[f64; 3]>)> = None;
    for _ in 0..STARTS {
        let mut c: Vec<[f64; 3]> = (0..n).map(|_| random_unit(&mut rng)).collect();
        for _ in 0..STEPS {
            let mut grad = vec![[0.0f64; 3]; n];
            for a in 0..n {
                for b in 0..n {
                    if a == b {
                        continue;
                    }
                    let d = dot(c[a], c[b]);
                    let g = 2.0 * (weights[a][b] / top) * d
                        + 2.0 * SEPARATION_WEIGHT * (d - TARGET_COSINE).max(0.0);
                    for x in 0..3 {
                        grad[a][x] += g * c[b][x];
                    }
                }
            }
            for a in 0..n {
                let v = [0, 1, 2].map(|x| c[a][x] - STEP_SIZE * grad[a][x]);
                c[a] = normalise(v).unwrap_or(c[a]);
            }
        }
        let separated = (0..n).all(|a| (0..a).all(|b| dot(c[a], c[b]) < MAX_COSINE));
        if !separated {
            continue;
        }
        let loss: f64 = (0..n)
            .flat_map(|a| (0..a).map(move |b| (a, b)))
            .map(|(a, b)| weights[a][b] / top * dot(c[a], c[b]).powi(2))
            .sum();
        if best.as_ref().is_none_or(|(l, _)| loss < *l) {
            best = Some((loss, c));
        }
    }
    best.map(|(_, c)| c)
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn normalise(v: [f64; 3]) -> Option<[f64; 3]> {
    let n = dot(v, v).sqrt();
    (n > 1e-12).then(|| v.map(|x| x / n))
}

fn random_unit(rng: &mut fastrand::Rng) -> [f64; 3] {
    loop {
        let v = [0; 3].map(|_| rng.f64() * 2.0 - 1.0);
        if let Some(u) = normalise(v).filter(|_| dot(v, v) <= 1.0) {
            return u;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn touching_slots_end_up_at_least_orthogonal_and_all_are_separated() {
        // A star: slot 0 touches every other one, as a table touches the things on it. The
        // other 5 fit on the great circle orthogonal to slot 0 (72 degrees apart).
        let n = 6;
        let mut w = vec![vec![0.0; n]; n];
        for b in 1..n {
            w[0][b] = 1.0;
            w[b][0] = 1.0;
        }
        let c = place_codes(&w, 1).expect("six codes fit");
        for a in 0..n {
            for b in 0..a {
                assert!(dot(c[a], c[b]) < MAX_COSINE, "{a},{b}");
            }
        }
        for b in 1..n {
            assert!(
                dot(c[0], c[b]).abs() < 1e-2,
                "0 and {b}: {}",
                dot(c[0], c[b])
            );
        }
        assert_eq!(place_codes(&w, 1), Some(c), "deterministic");
    }

    #[test]
    fn touch_weights_count_close_pairs_of_different_labels() {
        let mut g = Gaussians::new(0, 0);
        for (p, s) in [
            ([0.0, 0.0, 0.0], 0.1),
            ([0.3, 0.0, 0.0], 0.1),
            ([5.0, 0.0, 0.0], 0.1),
        ] {
            g.positions.push(p);
            g.log_scales.push([f32::ln(s); 3]);
        }
        let w = touch_weights(&g, &[1, 2, 2], 3);
        assert_eq!(w[1][2], 1.0);
        assert_eq!(w[2][1], 1.0);
        let w = touch_weights(&g, &[1, 0, 2], 3);
        assert_eq!(w[1][2], 0.0, "label 0 and far pairs do not count");
    }
}
