//! Opacities on their quantiser's levels that make one set of Gaussians render closer to target
//! images, everything else held: the encoder's opacity refit lets the stored opacities absorb
//! part of the error that quantising the other attributes (and the opacities themselves) made.
//!
//! Unlike colour, a pixel is not linear in the opacities, so the search works on the local
//! (Gauss-Newton) model: with `a_i = o_i g_i` and `C = sum_i c_i a_i T_i + T_end bg`,
//! `dC/do_i = g_i (T_i c_i - R_i / (1 - a_i))`, where `R_i = C - sum_{j <= i} c_j a_j T_j` is
//! what the splats behind `i` (and the background) add. Per Gaussian the gradient of the squared
//! error and the diagonal of `J^T J` give its best move alone; as in the colour lattice search
//! ([`crate::colour_fit::snap_colour_offsets`]) interleaved groups move one level at a time and
//! the images are rendered again before the next group, and the best levels by the damped
//! objective are kept. Alpha clamped at 0.99 has no gradient; the 1/255 cut and the early stop
//! are ignored by the model (the objective, from real renders, sees them).
//!
//! Deterministic: tiles are walked in parallel but summed in tile order.

use rayon::prelude::*;

use crate::camera::Camera;
use crate::colour_fit::LATTICE_GROUPS;
use crate::contribution::for_each_blend;
use crate::project::project_all;
use crate::raster::{bin_tiles, rasterize, tile_rect, ALPHA_MAX};
use dlgs::Gaussians;

/// Per Gaussian, where its opacity may go: alpha `start + m * step` for whole `m` in
/// `moves` (step 0: it stays).
pub struct OpacityLattice<'a> {
    pub steps: &'a [f32],
    pub moves: &'a [(i32, i32)],
}

/// Levels moved per Gaussian (0 = unchanged) that bring `g`'s renders from `cams` closer to
/// `targets` (one 3-channel image per camera, background included), after `sweeps` sweeps
/// over the [`LATTICE_GROUPS`] groups. `damping` weighs the squared alpha change against the
/// squared pixel error.
pub fn snap_opacities(
    g: &Gaussians,
    cams: &[Camera],
    targets: &[Vec<f32>],
    background: [f32; 3],
    lattice: &OpacityLattice,
    sweeps: usize,
    damping: f64,
) -> Vec<i32> {
    let n = g.len();
    assert!(lattice.steps.len() == n && lattice.moves.len() == n);
    assert_eq!(cams.len(), targets.len(), "one target per camera");
    let start: Vec<f32> = g.opacity.iter().map(|&o| dlgs::model::sigmoid(o)).collect();
    let mut m = vec![0i32; n];
    let mut best: Option<(f64, Vec<i32>)> = None;
    let mut moved = g.clone();
    let last = sweeps * LATTICE_GROUPS;
    for step in 0..=last {
        let x: Vec<f32> = m
            .iter()
            .zip(lattice.steps)
            .map(|(&mi, &s)| mi as f32 * s)
            .collect();
        for (i, o) in moved.opacity.iter_mut().enumerate() {
            *o = logit(start[i] + x[i]);
        }
        let mut grad = vec![0.0f64; n];
        let mut hess = vec![0.0f64; n];
        let mut cost = 0.0;
        for (cam, target) in cams.iter().zip(targets) {
            cost += view_gradient(&moved, cam, target, background, &mut grad, &mut hess);
        }
        cost += damping * x.iter().map(|&v| (v as f64) * (v as f64)).sum::<f64>();
        if best.as_ref().is_none_or(|b| cost < b.0) {
            best = Some((cost, m.clone()));
        }
        if step == last {
            break;
        }
        for i in (step % LATTICE_GROUPS..n).step_by(LATTICE_GROUPS) {
            let s = lattice.steps[i] as f64;
            if s <= 0.0 {
                continue;
            }
            // This Gaussian's best move alone, in levels.
            let want = (grad[i] - damping * x[i] as f64) / ((hess[i] + damping) * s);
            let (lo, hi) = lattice.moves[i];
            if want > 0.5 && m[i] < hi {
                m[i] += 1;
            } else if want < -0.5 && m[i] > lo {
                m[i] -= 1;
            }
        }
    }
    best.expect("the start is scored").1
}

/// Pre-sigmoid opacity of alpha `a` (kept inside (0, 1)).
pub fn logit(a: f32) -> f32 {
    let a = a.clamp(1e-6, 1.0 - 1e-6);
    (a / (1.0 - a)).ln()
}

/// Renders `g` from `cam`, adds every Gaussian's `J^T r` to `grad` and its `sum J^2` to
/// `hess` (r = target - render, J = d render / d alpha), and returns `|r|^2`.
fn view_gradient(
    g: &Gaussians,
    cam: &Camera,
    target: &[f32],
    background: [f32; 3],
    grad: &mut [f64],
    hess: &mut [f64],
) -> f64 {
    let (width, height) = (cam.width, cam.height);
    let splats = project_all(g, cam, false);
    let lists = bin_tiles(&splats, width, height);
    let image = rasterize(&splats, width, height, background, None).color;
    let cost = image
        .iter()
        .zip(target)
        .map(|(c, t)| ((t - c) as f64).powi(2))
        .sum();
    let per_tile: Vec<Vec<(f64, f64)>> = lists
        .par_iter()
        .enumerate()
        .map(|(i, list)| {
            let (x0, y0, w, h) = tile_rect(width, height, i);
            // What the splats in front of (and including) the current one added, per pixel.
            let mut front = vec![[0.0f32; 3]; (w * h) as usize];
            let mut sums = vec![(0.0f64, 0.0f64); list.len()];
            for_each_blend(&splats, list, (x0, y0, w, h), |slot, x, y, a, t| {
                let s = &splats[list[slot] as usize];
                let f = &mut front[((y - y0) * w + (x - x0)) as usize];
                for (fc, c) in f.iter_mut().zip(s.color) {
                    *fc += c * a * t;
                }
                if a >= ALPHA_MAX || s.opacity <= 0.0 {
                    return;
                }
                let (gauss, p) = (a / s.opacity, (y * width + x) as usize * 3);
                let (mut gr, mut hh) = (0.0f32, 0.0f32);
                for ch in 0..3 {
                    let behind = image[p + ch] - f[ch];
                    let j = gauss * (t * s.color[ch] - behind / (1.0 - a));
                    gr += j * (target[p + ch] - image[p + ch]);
                    hh += j * j;
                }
                sums[slot].0 += gr as f64;
                sums[slot].1 += hh as f64;
            });
            sums
        })
        .collect();
    for (list, sums) in lists.iter().zip(per_tile) {
        for (&k, (gr, hh)) in list.iter().zip(sums) {
            let i = splats[k as usize].index as usize;
            grad[i] += gr;
            hess[i] += hh;
        }
    }
    cost
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{orbit_cameras, OrbitSpec};
    use crate::contribution::tests::blob;
    use crate::RenderOptions;

    fn cams(g: &Gaussians) -> Vec<Camera> {
        orbit_cameras(
            g,
            &OrbitSpec {
                count: 3,
                width: 96,
                height: 72,
                ..OrbitSpec::default()
            },
        )
    }

    fn renders(g: &Gaussians, cams: &[Camera]) -> Vec<Vec<f32>> {
        cams.iter()
            .map(|c| {
                crate::render(g, c, &RenderOptions::default())
                    .unwrap()
                    .color
            })
            .collect()
    }

    /// Half-transparent Gaussians on a 1/15 alpha lattice, apart from each other (a grid in
    /// the x-y plane) so each one's opacity shows in its own pixels.
    fn lattice_grid() -> (Gaussians, Vec<f32>) {
        let mut g = blob(120);
        for (i, p) in g.positions.iter_mut().enumerate() {
            *p = [
                (i % 12) as f32 * 0.1 - 0.55,
                (i / 12) as f32 * 0.1 - 0.45,
                0.0,
            ];
        }
        g.log_scales.iter_mut().for_each(|s| *s = [-3.5; 3]);
        for (i, o) in g.opacity.iter_mut().enumerate() {
            *o = logit((4 + i % 8) as f32 / 15.0);
        }
        (g, vec![1.0 / 15.0; 120])
    }

    #[test]
    fn the_gradient_matches_finite_differences() {
        // Few Gaussians: with many, a step of alpha moves pixels across the 1/255 cut, which
        // the model leaves out and finite differences see.
        let mut g = blob(5);
        for (i, o) in g.opacity.iter_mut().enumerate() {
            *o = logit((4 + 2 * i) as f32 / 15.0);
        }
        let cam = &cams(&g)[0];
        let mut target = renders(&g, std::slice::from_ref(cam)).remove(0);
        target.iter_mut().for_each(|v| *v += 0.05);
        let n = g.len();
        let (mut grad, mut hess) = (vec![0.0; n], vec![0.0; n]);
        view_gradient(&g, cam, &target, [0.0; 3], &mut grad, &mut hess);
        let cost_at = |i: usize, h: f32| {
            let mut moved = g.clone();
            moved.opacity[i] = logit(dlgs::model::sigmoid(g.opacity[i]) + h);
            let (mut g2, mut h2) = (vec![0.0; n], vec![0.0; n]);
            view_gradient(&moved, cam, &target, [0.0; 3], &mut g2, &mut h2)
        };
        let mut checked = 0;
        for i in 0..n {
            // d cost / d alpha_i = -2 J^T r.
            let h = 1e-4;
            let numeric = (cost_at(i, h) - cost_at(i, -h)) / (2.0 * h as f64);
            let analytic = -2.0 * grad[i];
            assert!(
                (numeric - analytic).abs() <= 0.02 * analytic.abs() + 1e-2,
                "Gaussian {i}: numeric {numeric} vs analytic {analytic}"
            );
            checked += usize::from(analytic.abs() > 1.0);
        }
        assert!(checked >= 3, "{checked} Gaussians with a gradient");
    }

    #[test]
    fn the_search_recovers_moved_opacities_and_is_deterministic() {
        let (truth, steps) = lattice_grid();
        let cams = cams(&truth);
        let targets = renders(&truth, &cams);
        // Every third Gaussian one level off; each may move two levels either way.
        let mut g = truth.clone();
        for i in (0..g.len()).step_by(3) {
            g.opacity[i] = logit(dlgs::model::sigmoid(truth.opacity[i]) + 1.0 / 15.0);
        }
        let moves = vec![(-2, 2); g.len()];
        let bg = RenderOptions::default().background;
        let lattice = OpacityLattice {
            steps: &steps,
            moves: &moves,
        };
        let m = snap_opacities(&g, &cams, &targets, bg, &lattice, 2, 1e-3);
        let fixed = (0..g.len()).step_by(3).filter(|&i| m[i] == -1).count();
        let broken = (0..g.len()).filter(|&i| i % 3 != 0 && m[i] != 0).count();
        assert!(fixed >= 30, "{fixed} of 40 moved back");
        assert!(broken <= 4, "{broken} right ones moved");
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let again = one.install(|| snap_opacities(&g, &cams, &targets, bg, &lattice, 2, 1e-3));
        assert_eq!(m, again);
    }
}
